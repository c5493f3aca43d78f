//! Gazebo sensors → MuJoCo sites, sensors and cameras, with the metadata twin publishes them by.

use super::ir::{Pose, SensorIr, Shape};
use super::{Converter, ImuMeta, ScanMeta, SensorMeta, esc, f, fv, pose_attrs};
use crate::error::Result;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

impl Converter<'_> {
    /// Link that a `<gazebo reference>` of a sensor resolves to, and the pose of the reference
    /// frame in that link.
    pub(super) fn sensor_link(&self, s: &SensorIr) -> (usize, Pose) {
        if let Some(&l) = self.tree.link_index.get(&s.reference) {
            return (l, Pose::IDENTITY);
        }
        let j = self.robot.joints.iter().find(|j| j.name == s.reference).expect("reference checked at parse time");
        (self.tree.link_index[&j.child], Pose::IDENTITY)
    }

    pub(super) fn unique_sensor_name(&mut self, base: &str) -> String {
        let mut name = base.to_string();
        let mut k = 1;
        while !self.sensor_names.insert(name.clone()) {
            k += 1;
            name = format!("{base}_{k}");
        }
        name
    }

    pub(super) fn sensors(&mut self) -> Result<()> {
        let robot = self.robot;
        for s in &robot.sensors {
            let (link, frame) = self.sensor_link(s);
            let pose = frame.then(&s.pose);
            let link_name = robot.links[link].name.clone();
            let unique = self.unique_sensor_name(&s.name);
            if unique != s.name {
                self.notes.push(format!(
                    "sensor \"{}\" (line {}) repeats an earlier sensor's name: converted as \"{unique}\"",
                    s.name, s.line
                ));
            }
            let name = esc(&unique);
            let topic = s.topic.clone();
            // What every sensor's record takes from its Gazebo tag; each kind below adds the
            // names of what it made in MuJoCo and, where it has them, its range, noise and beams.
            let meta = |mujoco: Vec<String>| SensorMeta {
                name: s.name.clone(),
                kind: s.kind.clone(),
                reference: s.reference.clone(),
                update_rate_hz: s.update_rate_hz,
                topic: s.topic.clone(),
                frame_id: s.frame_name.clone(),
                mujoco,
                range_m: None,
                noise_std: 0.0,
                distortion: None,
                scan: None,
            };
            match s.kind.as_str() {
                "imu" => {
                    let (gyro, accel) = (s.gyro_noise_std, s.accel_noise_std);
                    self.sites[link]
                        .push(format!("<site name=\"{name}\"{} size=\"0.005\" group=\"4\"/>", pose_attrs(&pose)));
                    let noise = |x: f64| {
                        if x > 0.0 { format!(" noise=\"{}\"", f(x)) } else { String::new() }
                    };
                    self.sensor_xml
                        .push(format!("<framequat name=\"{name}_quat\" objtype=\"site\" objname=\"{name}\"/>"));
                    self.sensor_xml.push(format!("<gyro name=\"{name}_gyro\" site=\"{name}\"{}/>", noise(gyro)));
                    self.sensor_xml
                        .push(format!("<accelerometer name=\"{name}_accel\" site=\"{name}\"{}/>", noise(accel)));
                    let frame_id = s.frame_name.clone().unwrap_or_else(|| link_name.clone());
                    self.imus.push(ImuMeta {
                        name: s.name.clone(),
                        link: link_name,
                        site: s.name.clone(),
                        update_rate_hz: s.update_rate_hz,
                        gyro_noise_std: gyro,
                        accel_noise_std: accel,
                        gyro_bias: s.gyro_bias,
                        accel_bias: s.accel_bias,
                        topic: topic.clone(),
                        frame_id,
                    });
                }
                "camera" | "depth" | "depth_camera" | "rgbd_camera" | "wideanglecamera" | "multicamera"
                | "segmentation" => {
                    let cams = &s.cameras;
                    let mut made = Vec::new();
                    for (k, cam) in cams.iter().enumerate() {
                        let (w, h) = (cam.width, cam.height);
                        let fovy = 2.0 * ((cam.hfov / 2.0).tan() * h / w).atan();
                        let cam_pose = cam.pose;
                        // Gazebo: view along +X, up +Z. MuJoCo: view along −Z, up +Y.
                        let gz_from_mj =
                            UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix_unchecked(
                                Matrix3::new(0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 0.0, 1.0, 0.0),
                            ));
                        let p = pose.then(&cam_pose).then(&Pose { xyz: Vector3::zeros(), rot: gz_from_mj });
                        let cname = if cams.len() == 1 { name.clone() } else { format!("{name}_{k}") };
                        self.cameras[link].push(format!(
                            "<camera name=\"{cname}\"{} fovy=\"{}\" resolution=\"{} {}\"/>",
                            pose_attrs(&p),
                            f(fovy.to_degrees()),
                            w as i64,
                            h as i64
                        ));
                        made.push(cname);
                    }
                    self.sensor_meta.push(SensorMeta {
                        range_m: cams.first().and_then(|c| c.clip_m),
                        noise_std: cams.first().map_or(0.0, |c| c.noise_std),
                        distortion: cams.first().and_then(|c| c.distortion),
                        ..meta(made)
                    });
                }
                "ray" | "gpu_ray" | "lidar" | "gpu_lidar" => {
                    let Some(ray) = &s.ray else {
                        self.notes.push(format!(
                            "ray sensor \"{}\" (line {}) has no <ray> or <lidar> scan: not converted",
                            s.name, s.line
                        ));
                        continue;
                    };
                    // One site in the sensor frame (x forward, z up); its beams are cast at full
                    // resolution on scan ticks (crate::sense::lidar), not every physics step.
                    self.sites[link]
                        .push(format!("<site name=\"{name}\"{} size=\"0.005\" group=\"4\"/>", pose_attrs(&pose)));
                    self.sensor_meta.push(SensorMeta {
                        range_m: Some([ray.min_range_m, ray.max_range_m]),
                        noise_std: ray.noise_std,
                        scan: Some(ScanMeta { horizontal: ray.horizontal, vertical: ray.vertical }),
                        ..meta(vec![unique.clone()])
                    });
                }
                "force_torque" => {
                    let site = format!("{name}_site");
                    self.sites[link]
                        .push(format!("<site name=\"{site}\"{} size=\"0.005\" group=\"4\"/>", pose_attrs(&pose)));
                    self.sensor_xml.push(format!("<force name=\"{name}_force\" site=\"{site}\"/>"));
                    self.sensor_xml.push(format!("<torque name=\"{name}_torque\" site=\"{site}\"/>"));
                    self.sensor_meta.push(meta(vec![format!("{}_force", s.name), format!("{}_torque", s.name)]));
                }
                "contact" => {
                    let l = &robot.links[link];
                    if l.collisions.is_empty() {
                        self.notes.push(format!(
                            "contact sensor \"{}\": link \"{}\" has no collision geom; not converted",
                            s.name, l.name
                        ));
                        continue;
                    }
                    // Gazebo's sensor reports its link's (first) collision; one asked for by
                    // `contact_sensors` covers each (a foot of several spheres), one touch
                    // sensor per geom (the walker sums a foot's).
                    let covered = if s.every_collision { l.collisions.len() } else { 1 };
                    let mut made = Vec::new();
                    for (k, g) in l.collisions.iter().take(covered).enumerate() {
                        // The touch sensor counts contacts inside the site: cover the geom, 5 % larger.
                        let (ty, size) = match &g.shape {
                            Shape::Box(sz) => ("box", vec![sz[0] * 0.525, sz[1] * 0.525, sz[2] * 0.525]),
                            Shape::Sphere(r) => ("sphere", vec![r * 1.05]),
                            Shape::Cylinder { radius, length } => ("cylinder", vec![radius * 1.05, length * 0.525]),
                            Shape::Capsule { radius, length } => ("capsule", vec![radius * 1.05, length * 0.525]),
                            Shape::Mesh { .. } => {
                                self.notes.push(format!(
                                    "contact sensor \"{}\": mesh collision (line {}) approximated by a 10 cm sphere site",
                                    s.name, g.line
                                ));
                                ("sphere", vec![0.1])
                            }
                        };
                        let touch = if k == 0 { name.clone() } else { format!("{name}_{}", k + 1) };
                        let site = format!("{touch}_site");
                        self.sites[link].push(format!(
                            "<site name=\"{site}\" type=\"{ty}\" size=\"{}\"{} group=\"4\" rgba=\"1 0 0 0.2\"/>",
                            fv(&size),
                            pose_attrs(&g.pose)
                        ));
                        self.sensor_xml.push(format!("<touch name=\"{touch}\" site=\"{site}\"/>"));
                        made.push(if k == 0 { s.name.clone() } else { format!("{}_{}", s.name, k + 1) });
                    }
                    self.sensor_meta.push(meta(made));
                }
                other => {
                    self.notes.push(format!(
                        "sensor \"{}\" of type {other} (line {}) has no MuJoCo equivalent here: not converted",
                        s.name, s.line
                    ));
                }
            }
        }
        Ok(())
    }
}
