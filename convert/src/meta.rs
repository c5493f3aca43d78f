//! What twin knows about a robot beyond MuJoCo (name, IMU and sensor topics, rates, noise,
//! frame ids, joint velocity limits, command interfaces, differential transmissions), carried
//! inside the written MJCF as MuJoCo `<custom><text>` elements and read back from a compiled
//! model's texts ([`RobotMeta::from_custom_texts`]), so `twin sim robot.xml` publishes what
//! `twin sim robot.urdf` does.
//!
//! Each record is one text element named `twin:<kind>:<index>` whose data is
//! `key=value;key=value`, with `%`, `;`, `=` and `,` percent-encoded in values.

use super::{DifferentialMeta, ImuBias, ImuMeta, Interface, JointMeta, ScanMeta, SensorMeta};
use std::collections::HashMap;

/// The robot's ROS side, as the converter produced it. The default is a robot with no name
/// (twin then names it after the model or the file) and no metadata.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RobotMeta {
    /// Robot name (`<robot name>`): the topic prefix.
    pub name: String,
    /// Whether the root has a free joint.
    pub floating_base: bool,
    /// IMUs.
    pub imus: Vec<ImuMeta>,
    /// Other sensors.
    pub sensors: Vec<SensorMeta>,
    /// Joints in URDF order.
    pub joints: Vec<JointMeta>,
    /// Differential transmissions.
    pub differentials: Vec<DifferentialMeta>,
    /// Where the home pose (keyframe `home`) comes from, in words: an SRDF's named pose or the
    /// zero pose clamped into the joint ranges (empty for models converted before twin said).
    pub home_pose: String,
}

fn enc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '%' | ';' | '=' | ',' | '\n' | '\r' | '\t' => out.push_str(&format!("%{:02X}", c as u32)),
            c => out.push(c),
        }
    }
    out
}

fn dec(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%'
            && let Some(hex) = s.get(i + 1..i + 3)
            && let Ok(v) = u8::from_str_radix(hex, 16)
        {
            out.push(v);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// An IMU bias as `mean,stddev,dynamic_stddev,dynamic_correlation_time,random_walk` (shortest
/// round-trip decimals); empty when zero, so models without bias keep their metadata short.
fn bias_fields(b: &ImuBias) -> Vec<String> {
    if b.is_zero() {
        return Vec::new();
    }
    [b.mean, b.stddev, b.dynamic_stddev, b.dynamic_correlation_time_secs, b.random_walk]
        .iter()
        .map(|x| format!("{x}"))
        .collect()
}

/// The inverse of [`bias_fields`]; missing or unparsable entries are 0.
fn bias_from_fields(items: &[String]) -> ImuBias {
    let at = |k: usize| items.get(k).and_then(|x| x.parse::<f64>().ok()).filter(|x| x.is_finite()).unwrap_or(0.0);
    ImuBias {
        mean: at(0),
        stddev: at(1),
        dynamic_stddev: at(2),
        dynamic_correlation_time_secs: at(3),
        random_walk: at(4),
    }
}

fn opt_num(x: Option<f64>) -> String {
    x.map(|v| format!("{v}")).unwrap_or_default()
}

fn iface_name(i: Interface) -> &'static str {
    match i {
        Interface::Effort => "effort",
        Interface::Position => "position",
        Interface::Velocity => "velocity",
    }
}

fn iface_of(s: &str) -> Option<Interface> {
    match s {
        "effort" => Some(Interface::Effort),
        "position" => Some(Interface::Position),
        "velocity" => Some(Interface::Velocity),
        _ => None,
    }
}

/// One record being written: keys and encoded values.
struct Rec(Vec<(&'static str, String)>);

impl Rec {
    fn put(mut self, key: &'static str, value: impl AsRef<str>) -> Rec {
        self.0.push((key, enc(value.as_ref())));
        self
    }
    /// A list: items encoded, joined by commas.
    fn put_list(mut self, key: &'static str, items: &[String]) -> Rec {
        self.0.push((key, items.iter().map(|i| enc(i)).collect::<Vec<_>>().join(",")));
        self
    }
    fn data(&self) -> String {
        self.0.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(";")
    }
}

/// One record being read.
struct Fields(HashMap<String, String>);

impl Fields {
    fn parse(data: &str) -> Fields {
        Fields(
            data.split(';').filter_map(|kv| kv.split_once('=')).map(|(k, v)| (k.to_string(), v.to_string())).collect(),
        )
    }
    /// Raw (still encoded) value.
    fn raw(&self, key: &str) -> &str {
        self.0.get(key).map_or("", String::as_str)
    }
    fn s(&self, key: &str) -> String {
        dec(self.raw(key))
    }
    fn opt_s(&self, key: &str) -> Option<String> {
        let v = self.s(key);
        (!v.is_empty()).then_some(v)
    }
    fn num(&self, key: &str) -> Option<f64> {
        self.s(key).parse().ok()
    }
    fn list(&self, key: &str) -> Vec<String> {
        let raw = self.raw(key);
        if raw.is_empty() { Vec::new() } else { raw.split(',').map(dec).collect() }
    }
}

impl RobotMeta {
    /// The `<custom>` element carrying this metadata.
    pub(crate) fn to_custom_xml(&self) -> String {
        let mut recs: Vec<(String, Rec)> = Vec::new();
        recs.push((
            "twin:robot".into(),
            Rec(Vec::new())
                .put("name", &self.name)
                .put("floating_base", if self.floating_base { "1" } else { "0" })
                .put("home_pose", &self.home_pose),
        ));
        for (k, i) in self.imus.iter().enumerate() {
            recs.push((
                format!("twin:imu:{k}"),
                Rec(Vec::new())
                    .put("name", &i.name)
                    .put("link", &i.link)
                    .put("site", &i.site)
                    .put("rate_hz", opt_num(i.update_rate_hz))
                    .put("gyro_noise_std", format!("{}", i.gyro_noise_std))
                    .put("accel_noise_std", format!("{}", i.accel_noise_std))
                    .put_list("gyro_bias", &bias_fields(&i.gyro_bias))
                    .put_list("accel_bias", &bias_fields(&i.accel_bias))
                    .put("topic", i.topic.clone().unwrap_or_default())
                    .put("frame_id", &i.frame_id),
            ));
        }
        for (k, s) in self.sensors.iter().enumerate() {
            recs.push((
                format!("twin:sensor:{k}"),
                Rec(Vec::new())
                    .put("name", &s.name)
                    .put("kind", &s.kind)
                    .put("reference", &s.reference)
                    .put("rate_hz", opt_num(s.update_rate_hz))
                    .put("topic", s.topic.clone().unwrap_or_default())
                    .put("frame_id", s.frame_id.clone().unwrap_or_default())
                    .put_list("mujoco", &s.mujoco)
                    .put("range", s.range_m.map(|r| format!("{}:{}", r[0], r[1])).unwrap_or_default())
                    .put("noise_std", format!("{}", s.noise_std))
                    .put("distortion", s.distortion.map(|d| d.map(|c| c.to_string()).join(":")).unwrap_or_default())
                    .put(
                        "scan",
                        s.scan
                            .map(|c| {
                                let (h, v) = (c.horizontal, c.vertical);
                                format!("{}:{}:{}:{}:{}:{}", h.0, h.1, h.2, v.0, v.1, v.2)
                            })
                            .unwrap_or_default(),
                    ),
            ));
        }
        for (k, j) in self.joints.iter().enumerate() {
            let mut r = Rec(Vec::new())
                .put("name", &j.name)
                .put("type", &j.urdf_type)
                .put("effort", opt_num(j.effort_limit))
                .put("velocity", opt_num(j.velocity_limit))
                .put("range", j.range.map(|r| format!("{}:{}", r[0], r[1])).unwrap_or_default())
                .put("gear", format!("{}", j.gear))
                .put("mimic_of", j.mimic_of.clone().unwrap_or_default())
                .put("transmission", j.transmission.clone().unwrap_or_default());
            if let Some((a, i)) = &j.actuator {
                r = r.put("actuator", a).put("interface", iface_name(*i));
            }
            recs.push((format!("twin:joint:{k}"), r));
        }
        for (k, d) in self.differentials.iter().enumerate() {
            let c = d.coefficients;
            recs.push((
                format!("twin:differential:{k}"),
                Rec(Vec::new())
                    .put("name", &d.name)
                    .put("half", if d.half { "1" } else { "0" })
                    .put("actuator1", &d.actuators[0])
                    .put("actuator2", &d.actuators[1])
                    .put("joint1", &d.joints[0])
                    .put("joint2", &d.joints[1])
                    .put("coefficients", format!("{}:{}:{}:{}", c[0][0], c[0][1], c[1][0], c[1][1]))
                    .put("interface", iface_name(d.interface)),
            ));
        }
        let mut x = String::from("  <custom>\n");
        for (name, rec) in recs {
            let data = rec.data();
            x.push_str(&format!("    <text name=\"{}\" data=\"{}\"/>\n", super::esc(&name), super::esc(&data)));
        }
        x.push_str("  </custom>\n");
        x
    }

    /// The metadata an MJCF written by `twin convert` carries, read from its `<custom><text>`
    /// elements as `(name, data)` pairs (a compiled model's texts), or `None` for other models.
    pub fn from_custom_texts(texts: &[(&str, &str)]) -> Option<RobotMeta> {
        let robot = texts.iter().find(|(n, _)| *n == "twin:robot")?;
        let f = Fields::parse(robot.1);
        let mut meta = RobotMeta {
            name: f.s("name"),
            floating_base: f.s("floating_base") == "1",
            imus: Vec::new(),
            sensors: Vec::new(),
            joints: Vec::new(),
            differentials: Vec::new(),
            home_pose: f.s("home_pose"),
        };
        // Records in index order (model order is the written order; sort to be safe).
        let mut records: Vec<(&str, usize, Fields)> = texts
            .iter()
            .filter_map(|(n, d)| {
                let rest = n.strip_prefix("twin:")?;
                let (kind, idx) = rest.split_once(':')?;
                Some((kind, idx.parse().ok()?, Fields::parse(d)))
            })
            .collect();
        records.sort_by(|a, b| (a.0, a.1).cmp(&(b.0, b.1)));
        for (kind, _, f) in records {
            match kind {
                "imu" => meta.imus.push(ImuMeta {
                    name: f.s("name"),
                    link: f.s("link"),
                    site: f.s("site"),
                    update_rate_hz: f.num("rate_hz"),
                    gyro_noise_std: f.num("gyro_noise_std").unwrap_or(0.0),
                    accel_noise_std: f.num("accel_noise_std").unwrap_or(0.0),
                    gyro_bias: bias_from_fields(&f.list("gyro_bias")),
                    accel_bias: bias_from_fields(&f.list("accel_bias")),
                    topic: f.opt_s("topic"),
                    frame_id: f.s("frame_id"),
                }),
                "sensor" => meta.sensors.push(SensorMeta {
                    name: f.s("name"),
                    kind: f.s("kind"),
                    reference: f.s("reference"),
                    update_rate_hz: f.num("rate_hz"),
                    topic: f.opt_s("topic"),
                    frame_id: f.opt_s("frame_id"),
                    mujoco: f.list("mujoco"),
                    range_m: {
                        let r = f.s("range");
                        r.split_once(':').and_then(|(a, b)| Some([a.parse().ok()?, b.parse().ok()?]))
                    },
                    noise_std: f.num("noise_std").unwrap_or(0.0),
                    distortion: {
                        let v: Vec<f64> = f.s("distortion").split(':').filter_map(|x| x.parse().ok()).collect();
                        <[f64; 5]>::try_from(v.as_slice()).ok()
                    },
                    scan: {
                        let v: Vec<f64> = f.s("scan").split(':').filter_map(|x| x.parse().ok()).collect();
                        match v.as_slice() {
                            &[hn, hlo, hhi, vn, vlo, vhi] => Some(ScanMeta {
                                horizontal: (hn as usize, hlo, hhi),
                                vertical: (vn as usize, vlo, vhi),
                            }),
                            _ => None,
                        }
                    },
                }),
                "joint" => {
                    let range = f.s("range");
                    let range = range.split_once(':').and_then(|(a, b)| Some([a.parse().ok()?, b.parse().ok()?]));
                    let actuator = match (f.opt_s("actuator"), iface_of(&f.s("interface"))) {
                        (Some(a), Some(i)) => Some((a, i)),
                        _ => None,
                    };
                    meta.joints.push(JointMeta {
                        name: f.s("name"),
                        urdf_type: f.s("type"),
                        effort_limit: f.num("effort"),
                        velocity_limit: f.num("velocity"),
                        range,
                        actuator,
                        gear: f.num("gear").unwrap_or(1.0),
                        mimic_of: f.opt_s("mimic_of"),
                        transmission: f.opt_s("transmission"),
                    });
                }
                "differential" => {
                    let c: Vec<f64> = f.s("coefficients").split(':').filter_map(|v| v.parse().ok()).collect();
                    let (Some(interface), [c00, c01, c10, c11]) = (iface_of(&f.s("interface")), c.as_slice()) else {
                        continue;
                    };
                    meta.differentials.push(DifferentialMeta {
                        name: f.s("name"),
                        half: f.s("half") == "1",
                        actuators: [f.s("actuator1"), f.s("actuator2")],
                        joints: [f.s("joint1"), f.s("joint2")],
                        coefficients: [[*c00, *c01], [*c10, *c11]],
                        interface,
                    });
                }
                _ => {}
            }
        }
        Some(meta)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encoding_round_trips() {
        for s in ["/humanoid/imu/data", "a;b=c,d%e", "", "ünï cödé"] {
            assert_eq!(dec(&enc(s)), s);
        }
    }
}
