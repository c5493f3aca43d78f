//! Running a twin under a controller (`twin sim`) and recording what it does: ROS 2 MCAP
//! topics and rerun recordings, all stamped in simulation time ([`record`]).
//!
//! ```no_run
//! use twin_core::control::{Controller, PdHold, PdHoldOptions};
//! use twin_core::sim::{self, RecordOptions, Recording, SimOptions};
//!
//! let robot = sim::load_robot("models/humanoid.urdf")?;
//! let mut controller = PdHold::new(&robot.model, PdHoldOptions::default());
//! let options = RecordOptions { mcap: Some("run.mcap".into()), ..RecordOptions::default() };
//! let mut recording = Recording::new(&robot, &options)?;
//! let report = sim::simulate(&robot, &mut controller, &SimOptions::default(), Some(&mut recording), &mut |_| {})?;
//! let summary = recording.finish()?;
//! println!("{} steps, {} messages", report.steps, summary.messages());
//! # Ok::<(), twin_core::Error>(())
//! ```

pub mod record;

pub use record::{RecordOptions, RecordSummary, Recording, StepSample};

use crate::control::{Actuation, Controller, Observation, base_body, reset_to_home};
use crate::error::{Error, Result};
use crate::mj::{Data, JointType, Model, ObjType};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// An IMU as recording needs it: its MuJoCo sensors and its ROS side.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuInfo {
    /// Sensor name (the MuJoCo sensors are `<name>_quat`, `<name>_gyro`, `<name>_accel`).
    pub name: String,
    /// ROS topic (e.g. `/humanoid/imu/data`).
    pub topic: String,
    /// `frame_id` of the messages.
    pub frame_id: String,
    /// Body the IMU is mounted on.
    pub body: usize,
    /// IMU site pose in its body frame: position (m) and quaternion w x y z.
    pub body_from_imu: ([f64; 3], [f64; 4]),
    /// Publication rate, Hz (`None`: the joint-state rate).
    pub update_rate_hz: Option<f64>,
    /// Gyroscope noise standard deviation, rad/s.
    pub gyro_noise_std: f64,
    /// Accelerometer noise standard deviation, m/s².
    pub accel_noise_std: f64,
    /// Address of the framequat (w x y z), gyro and accelerometer values in `sensordata`.
    pub quat_adr: Option<usize>,
    /// See `quat_adr`.
    pub gyro_adr: usize,
    /// See `quat_adr`.
    pub accel_adr: usize,
}

/// A compiled robot with what logging needs beyond the model.
#[derive(Debug, Clone)]
pub struct Robot {
    /// The model.
    pub model: Arc<Model>,
    /// Robot name: topic prefix (`/<name>/joint_commands`).
    pub name: String,
    /// The file it came from.
    pub path: PathBuf,
    /// Floating base body (free joint), if any.
    pub base_body: Option<usize>,
    /// IMUs.
    pub imus: Vec<ImuInfo>,
}

/// Loads a robot from a URDF (through twin's converter, which gives the IMUs' topics, rates and
/// noise) or an MJCF (IMUs found as `<name>_gyro` + `<name>_accel` sensor pairs, with their
/// `noise` attribute, published on `/<robot>/<name>`).
///
/// # Errors
/// As [`Model::from_file`] / [`crate::convert::convert_urdf`].
pub fn load_robot(path: impl AsRef<Path>) -> Result<Robot> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_path_buf(), source })?;
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("robot").to_string();
    if crate::urdf::is_urdf(&text) {
        let converted = crate::convert::convert_urdf_str(path, &text, &crate::convert::ConvertOptions::default())?;
        let model = Model::from_xml_str(&converted.mjcf).map_err(|e| match e {
            Error::Load { message, .. } => Error::Load { path: Some(path.to_path_buf()), message },
            other => other,
        })?;
        let mut robot = Robot::from_model(Arc::new(model), &converted.robot_name, path);
        for meta in &converted.imus {
            if let Some(imu) = robot.imus.iter_mut().find(|i| i.name == meta.name) {
                imu.topic = meta.topic.clone().unwrap_or_else(|| format!("/{}/{}", converted.robot_name, meta.name));
                imu.frame_id = meta.frame_id.clone();
                imu.update_rate_hz = meta.update_rate_hz.filter(|r| *r > 0.0);
                imu.gyro_noise_std = meta.gyro_noise_std;
                imu.accel_noise_std = meta.accel_noise_std;
            }
        }
        return Ok(robot);
    }
    let model = Model::from_mujoco_file(path)?;
    Ok(Robot::from_model(Arc::new(model), &stem, path))
}

impl Robot {
    /// A robot from a compiled model alone (see [`load_robot`] for how IMUs are found).
    pub fn from_model(model: Arc<Model>, name: &str, path: &Path) -> Robot {
        let name: String = name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' { c } else { '_' }).collect();
        let mut imus = Vec::new();
        let sensor = |n: &str| model.id(ObjType::Sensor, n);
        for s in 0..model.nsensor() {
            let sname = model.name(ObjType::Sensor, s);
            let Some(base) = sname.strip_suffix("_gyro") else { continue };
            if model.sensor_type()[s] as u32 != mujoco_sys::mjtSensor_mjSENS_GYRO {
                continue;
            }
            let Some(accel) = sensor(&format!("{base}_accel")) else { continue };
            let quat = sensor(&format!("{base}_quat"));
            let site = model.sensor_objid()[s] as usize;
            let body = model.site_bodyid()[site] as usize;
            imus.push(ImuInfo {
                name: base.to_string(),
                topic: format!("/{name}/{base}"),
                frame_id: model.name(ObjType::Body, body).to_string(),
                body,
                body_from_imu: (model.site_pos()[site], model.site_quat()[site]),
                update_rate_hz: None,
                gyro_noise_std: model.sensor_noise()[s],
                accel_noise_std: model.sensor_noise()[accel],
                quat_adr: quat.map(|q| model.sensor_adr()[q] as usize),
                gyro_adr: model.sensor_adr()[s] as usize,
                accel_adr: model.sensor_adr()[accel] as usize,
            });
        }
        Robot { base_body: base_body(&model), model, name, path: path.to_path_buf(), imus }
    }

    /// The 1-DOF (hinge and slide) joints, in model order: what `/joint_states` carries.
    pub fn joints(&self) -> Vec<usize> {
        (0..self.model.njnt())
            .filter(|&j| matches!(self.model.joint_type(j), JointType::Hinge | JointType::Slide))
            .collect()
    }
}

/// How long and how to simulate.
#[derive(Debug, Clone, PartialEq)]
pub struct SimOptions {
    /// Simulated time, seconds (default: 5.0).
    pub duration_secs: f64,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions { duration_secs: 5.0 }
    }
}

/// What a run did.
#[derive(Debug, Clone, PartialEq)]
pub struct SimReport {
    /// Steps taken.
    pub steps: u64,
    /// Simulated time, seconds.
    pub sim_secs: f64,
    /// Wall time of the stepping loop (recording included), seconds.
    pub wall_secs: f64,
    /// Wall time spent inside [`Recording::record`], seconds.
    pub record_secs: f64,
    /// CPU time of the simulating thread during the loop, seconds (Linux; `None` elsewhere):
    /// unlike wall time, not inflated by waiting for a core on a busy machine, and without the
    /// MCAP writer thread's work.
    pub loop_cpu_secs: Option<f64>,
}

/// CPU time of the calling thread, seconds, from `/proc/thread-self/schedstat` (Linux).
fn thread_cpu_secs() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let nanos: u64 = text.split_whitespace().next()?.parse().ok()?;
    Some(nanos as f64 * 1e-9)
}

impl SimReport {
    /// Simulated seconds per wall second.
    pub fn real_time_factor(&self) -> f64 {
        if self.wall_secs > 0.0 { self.sim_secs / self.wall_secs } else { f64::INFINITY }
    }
}

/// Number of steps for `duration_secs` at the model's timestep (at least one).
pub fn steps_for(model: &Model, duration_secs: f64) -> u64 {
    ((duration_secs / model.timestep_secs()).round() as u64).max(1)
}

/// Runs `controller` on `robot` from its home pose ([`reset_to_home`]) for
/// `options.duration_secs`, recording into `recording` when given. `progress` is called with the
/// fraction done now and then.
///
/// Each step is `mj_step1` (positions, velocities, sensors at time t), the controller on that
/// observation, then `mj_step2` (accelerations, contact forces, actuator forces at t, and the
/// integration to t + dt); the recording then gets the state at t, so every message stamped t
/// describes the same instant.
///
/// # Errors
/// [`Error::MuJoCo`] if MuJoCo raises; [`Error::Trajectory`] and others from the controller's
/// reset; recording errors.
pub fn simulate(
    robot: &Robot,
    controller: &mut dyn Controller,
    options: &SimOptions,
    mut recording: Option<&mut Recording>,
    progress: &mut dyn FnMut(f64),
) -> Result<SimReport> {
    let model = robot.model.clone();
    let mut data = Data::new(model.clone())?;
    reset_to_home(&mut data)?;
    controller.initial_qpos(&model, data.qpos_mut());
    data.forward()?;
    controller.reset(&model, &Observation::of(&data))?;
    let actuation = Actuation::of(&model);
    let mut command = vec![0.0; actuation.len(&model)];
    let (mut qpos, mut qvel) = (vec![0.0; model.nq()], vec![0.0; model.nv()]);
    let steps = steps_for(&model, options.duration_secs);
    let report_every = (steps / 100).max(1);
    let mut record_secs = 0.0;
    let cpu_started = thread_cpu_secs();
    let started = std::time::Instant::now();
    let mut done = 0;
    for step in 0..steps {
        data.step1()?;
        controller.compute(&model, &Observation::of(&data), &mut command);
        actuation.apply(&mut data, &command);
        let time_secs = data.time_secs();
        if let Some(rec) = recording.as_deref_mut() {
            qpos.copy_from_slice(data.qpos());
            qvel.copy_from_slice(data.qvel());
            data.step2()?;
            let t = std::time::Instant::now();
            rec.record(&StepSample { time_secs, qpos: &qpos, qvel: &qvel, command: &command }, &data)?;
            record_secs += t.elapsed().as_secs_f64();
        } else {
            data.step2()?;
        }
        if data.diverged() {
            let (_, text) = crate::mj::thread_warnings();
            return Err(Error::MuJoCo {
                call: "mj_step",
                message: format!("the simulation diverged at t = {time_secs:.3} s: {text}"),
            });
        }
        if step % report_every == 0 {
            progress(step as f64 / steps as f64);
        }
        done = step + 1;
        if !controller.proceed()? {
            break;
        }
    }
    let wall_secs = started.elapsed().as_secs_f64();
    let loop_cpu_secs = cpu_started.zip(thread_cpu_secs()).map(|(a, b)| b - a);
    progress(1.0);
    Ok(SimReport { steps: done, sim_secs: done as f64 * model.timestep_secs(), wall_secs, record_secs, loop_cpu_secs })
}
