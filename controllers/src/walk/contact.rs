//! Touch-down from contact ([`super::WalkOptions::touchdown_from_contact`]): when a swinging
//! foot has landed, read from what the robot senses rather than from the plan's clock. The
//! same foot sensors tell the ground reads whether a landed foot is still in the air
//! (`landing_read_at_rest`) and hold a swing foot where it met the ground
//! (`swing_holds_at_contact`).
//!
//! Data flow, each solve of a walking step: the swing foot's sensors (or its sole's motion) and
//! the swing progress go in, [`ContactSensing::landed`] says whether the foot is on the ground;
//! the walker then ends the step at that solve (early: ground higher than planned). A foot not
//! down at the planned end (late: ground lower) ends its step on time, and its target goes on
//! down through the next double support, looking for the ground, up to
//! [`super::WalkOptions::touchdown_reach_m`] below where it was planned to land. Either way
//! the sole's height when it lands is the ground under that foot.
//!
//! Two sources, found in the model once (any robot with feet; no names assumed):
//! - **Foot sensors**: MuJoCo `touch` or `force` sensors on a site of the foot's body or a body
//!   below it (a Gazebo `contact` or `force_torque` sensor after `twin convert`). The foot has
//!   landed when the load they read exceeds [`TOUCHDOWN_LOAD_FRACTION`] of the robot's weight
//!   (a force sensor's reading less the weight of the bodies below its site). A URDF without
//!   them gets touch sensors from a scenario's `contact_sensors` or `twin convert
//!   --contact-sensor LINK`.
//! - **The sole's motion** (robots without foot sensors, e.g. the shipped humanoid): forward
//!   kinematics of the observed joints gives the swing sole's height; in the second half of
//!   the swing the foot has landed when its sole has stopped ([`TOUCHDOWN_STILL_MPS`] for
//!   [`TOUCHDOWN_STILL_SECS`]) while its target is below it: more than
//!   [`TOUCHDOWN_BLOCKED_M`] below (the foot is held up by the ground ahead of time), or at all
//!   once the target goes on down past the planned end (a free foot follows a descending
//!   target; a foot on the ground does not), or, still or not, more than [`TOUCHDOWN_HELD_M`]
//!   below it then (a sole rocking on an edge). A free foot lagging its trajectory (the soft swing
//!   leg lags it by ~2.5 cm late in the swing) is still moving down, so it does not count: this
//!   is why the sole's height at the planned touchdown is no ground, and a plain tracking-error
//!   threshold is no contact.

use twin_core::mj::{Model, ObjType, SensorType};

/// A foot whose sensors read more than this fraction of the robot's weight carries load: it
/// is on the ground (a swinging foot's own inertia reads a few per cent).
pub const TOUCHDOWN_LOAD_FRACTION: f64 = 0.1;

/// A sole moving up or down slower than this is still, m/s (as the walker's ground reads,
/// [`super::GROUND_READ_MAX_SPEED_MPS`]).
pub const TOUCHDOWN_STILL_MPS: f64 = 0.05;

/// How long a swing sole must be still before it counts as landed, s: an impact's bounce
/// (a few milliseconds) is not a landing.
pub const TOUCHDOWN_STILL_SECS: f64 = 0.01;

/// A still swing sole more than this above its target is held up by the ground, m: the ground
/// is higher than planned (the sole's tracking error in free swing is below it while the
/// target rises and while the sole moves, which the still test excludes).
pub const TOUCHDOWN_BLOCKED_M: f64 = 0.01;

/// A swing sole this far above a target that goes on down looking for the ground
/// ([`TOUCHDOWN_SEARCH_MPS`]) is held up, still or not (a sole rocking on an edge is never
/// still), m: a free foot follows that target within 1.6 cm (the shipped humanoid, from a
/// swing that ended 1.1 cm above its target).
pub const TOUCHDOWN_HELD_M: f64 = 0.025;

/// Part of the swing after which a foot can land (before, it rises: a still sole at the apex
/// is not a landing).
pub const TOUCHDOWN_ARM_PHASE: f64 = 0.6;

/// Part of the swing by which the swing foot's profile has come down to where it is to land
/// (with touch-down from contact); for the rest its target goes on down at
/// [`TOUCHDOWN_SEARCH_MPS`] until the foot lands. The soft swing leg lags its trajectory: on
/// flat ground, the shipped humanoid's foot was still 1.1 cm up and coming down at 0.3 m/s at
/// the planned end of a swing that ends there, and landed ~55 ms later; every step waiting for
/// that contact lasted ~20 % longer than planned and the walker fell within 10 s.
pub const TOUCHDOWN_PROFILE_END: f64 = 0.85;

/// How fast a late foot's target goes on down below where it was planned to land, m/s (as
/// fast as the swing's own descent of 0.1 m in ~0.15 s at the shipped humanoid's 0.35-s
/// steps, so that a foot over lower ground keeps its landing speed).
pub const TOUCHDOWN_SEARCH_MPS: f64 = 0.3;

/// Where a foot's contact is read from.
#[derive(Debug, Clone, PartialEq)]
pub enum FootSensor {
    /// `touch` sensors (normal force, N) at these `sensordata` addresses.
    Touch(Vec<usize>),
    /// `force` sensors (3-vector, N, site frame) at these addresses, each with the weight of
    /// the bodies below its site (N), which it reads while the foot is in the air.
    Force(Vec<(usize, f64)>),
    /// No sensor on this foot: the sole's motion.
    Motion,
}

/// What the walker knows of its feet's contact: per foot (left, right) its sensors, and the
/// motion state of the swing sole.
#[derive(Debug, Clone)]
pub struct ContactSensing {
    /// Per foot.
    pub feet: [FootSensor; 2],
    /// Load threshold, N ([`TOUCHDOWN_LOAD_FRACTION`] of the weight).
    load_n: f64,
    /// Each sole's height at the last solve, m.
    prev_z: [Option<f64>; 2],
    /// How long each sole has been still, s.
    still_secs: [f64; 2],
}

impl ContactSensing {
    /// The feet's contact sensors in `model`: `feet` are the foot bodies (left, right), `weight_n`
    /// the robot's weight.
    pub fn new(model: &Model, feet: [usize; 2], weight_n: f64) -> ContactSensing {
        let g = -model.gravity()[2];
        let mass = model.body_mass();
        let find = |foot: usize| {
            let (mut touch, mut force) = (Vec::new(), Vec::new());
            for s in 0..model.nsensor() {
                if model.sensor_object(s) != Some(ObjType::Site) {
                    continue;
                }
                let body = model.site_bodyid()[model.sensor_objid()[s] as usize] as usize;
                if !model.in_subtree(foot, body) {
                    continue;
                }
                let adr = model.sensor_adr()[s] as usize;
                match model.sensor_kind(s) {
                    SensorType::Touch => touch.push(adr),
                    SensorType::Force => {
                        let below: f64 = model.subtree(body).iter().map(|&b| mass[b]).sum();
                        force.push((adr, below * g));
                    }
                    _ => {}
                }
            }
            if !touch.is_empty() {
                FootSensor::Touch(touch)
            } else if !force.is_empty() {
                FootSensor::Force(force)
            } else {
                FootSensor::Motion
            }
        };
        ContactSensing {
            feet: [find(feet[0]), find(feet[1])],
            load_n: TOUCHDOWN_LOAD_FRACTION * weight_n,
            prev_z: [None; 2],
            still_secs: [0.0; 2],
        }
    }

    /// Tracks each sole's motion: call once per solve with the soles' heights (m) and the
    /// solve period `dt_secs`.
    pub fn update(&mut self, sole_z: [f64; 2], dt_secs: f64) {
        for ((z, prev), still) in sole_z.iter().zip(&mut self.prev_z).zip(&mut self.still_secs) {
            let moved = prev.is_none_or(|p| (z - p).abs() > TOUCHDOWN_STILL_MPS * dt_secs);
            *still = if moved { 0.0 } else { *still + dt_secs };
            *prev = Some(*z);
        }
    }

    /// The load foot `leg`'s sensors read, N (`None` without sensors).
    pub fn load_n(&self, leg: usize, sensordata: &[f64]) -> Option<f64> {
        let at = |a: usize| sensordata.get(a).copied().unwrap_or(0.0);
        match &self.feet[leg] {
            FootSensor::Touch(adrs) => Some(adrs.iter().map(|&a| at(a)).sum()),
            FootSensor::Force(adrs) => Some(
                adrs.iter()
                    .map(|&(a, below)| {
                        let f = (at(a).powi(2) + at(a + 1).powi(2) + at(a + 2).powi(2)).sqrt();
                        (f - below).max(0.0)
                    })
                    .fold(0.0, f64::max),
            ),
            FootSensor::Motion => None,
        }
    }

    /// Whether foot `leg` is on the ground by its sensors: they read more than
    /// [`TOUCHDOWN_LOAD_FRACTION`] of the robot's weight (`None` without sensors).
    pub fn on_ground(&self, leg: usize, sensordata: &[f64]) -> Option<bool> {
        self.load_n(leg, sensordata).map(|load| load > self.load_n)
    }

    /// Whether the swinging foot `leg` has landed: `swing_s` its swing progress, `gap_m` its
    /// sole's height above its target (m), `searching` whether its target goes on down past
    /// the planned end ([`TOUCHDOWN_SEARCH_MPS`]).
    pub fn landed(&self, leg: usize, sensordata: &[f64], swing_s: f64, gap_m: f64, searching: bool) -> bool {
        if swing_s < TOUCHDOWN_ARM_PHASE {
            return false;
        }
        match self.on_ground(leg, sensordata) {
            Some(on) => on,
            None => {
                (self.still_secs[leg] >= TOUCHDOWN_STILL_SECS
                    && (gap_m > TOUCHDOWN_BLOCKED_M || (searching && gap_m > 0.0)))
                    || (searching && gap_m > TOUCHDOWN_HELD_M)
            }
        }
    }
}
