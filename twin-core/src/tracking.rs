//! Tracking metrics: are the commanded and the actual joint positions matching? An
//! [`Observer`] of the rollout engine, for any controller that says its position targets
//! ([`crate::control::Controller::position_targets`]: `pd-hold`, position commands of the live
//! bridge and of external controllers).
//!
//! Each step it takes the targets the controller's last command steers to and the joint
//! positions at that step's start (the instant the command was computed from), and keeps per
//! joint the RMS and the largest absolute error over the steps with a target; besides, the time
//! with some command entry at its limit (saturated).

use crate::engine::{Flow, Measurement, Observer, StepView};
use crate::error::Result;
use crate::mj::{Data, JointType, Model, ObjType};

/// How one joint tracked its targets.
#[derive(Debug, Clone, PartialEq)]
pub struct JointTracking {
    /// Joint name.
    pub joint: String,
    /// RMS of target − actual, rad (m).
    pub rms: f64,
    /// Largest |target − actual|, rad (m).
    pub max: f64,
}

/// A rollout's tracking, worst joints first.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TrackingSummary {
    /// Joints with targets, by RMS error, largest first.
    pub joints: Vec<JointTracking>,
    /// Time with some command entry at its limit, s.
    pub saturated_secs: f64,
    /// Simulated time observed, s.
    pub sim_secs: f64,
}

impl TrackingSummary {
    /// The worst joint's RMS error, rad (0 without targets).
    pub fn rms(&self) -> f64 {
        self.joints.first().map_or(0.0, |j| j.rms)
    }

    /// The largest error of any joint, rad (0 without targets).
    pub fn max(&self) -> f64 {
        self.joints.iter().map(|j| j.max).fold(0.0, f64::max)
    }

    /// The numbers as measurements: `tracking_rms_rad` (worst joint), `tracking_max_rad`,
    /// `saturated_secs`.
    pub fn measurements(&self) -> Vec<Measurement> {
        vec![
            Measurement::new("tracking_rms", self.rms(), "rad"),
            Measurement::new("tracking_max", self.max(), "rad"),
            Measurement::new("saturated", self.saturated_secs, "s"),
        ]
    }
}

impl std::fmt::Display for TrackingSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.joints.is_empty() {
            return write!(
                f,
                "tracking: the controller gave no position targets; saturated {:.3} s",
                self.saturated_secs
            );
        }
        let worst: Vec<String> =
            self.joints.iter().take(3).map(|j| format!("{} {:.4}/{:.4}", j.joint, j.rms, j.max)).collect();
        write!(
            f,
            "tracking (commanded − actual position, {} joints): RMS {:.4} rad, max {:.4} rad; worst (RMS/max): {}; \
             saturated {:.3} s of {:.3} s",
            self.joints.len(),
            self.rms(),
            self.max(),
            worst.join(", "),
            self.saturated_secs,
            self.sim_secs
        )
    }
}

/// Measures tracking during a rollout (see the [module docs](self)).
#[derive(Debug, Clone, Default)]
pub struct Tracking {
    /// Joint of each qpos address (hinge/slide joints only).
    joint_of: Vec<Option<usize>>,
    names: Vec<String>,
    sum_sq: Vec<f64>,
    max_abs: Vec<f64>,
    count: Vec<u64>,
    saturated_secs: f64,
    sim_secs: f64,
}

impl Tracking {
    /// A tracker (sized at the rollout's start).
    pub fn new() -> Tracking {
        Tracking::default()
    }

    /// The tracking so far.
    pub fn summary(&self) -> TrackingSummary {
        let mut joints: Vec<JointTracking> = (0..self.names.len())
            .filter(|&j| self.count[j] > 0)
            .map(|j| JointTracking {
                joint: self.names[j].clone(),
                rms: (self.sum_sq[j] / self.count[j] as f64).sqrt(),
                max: self.max_abs[j],
            })
            .collect();
        joints.sort_by(|a, b| b.rms.total_cmp(&a.rms).then(a.joint.cmp(&b.joint)));
        TrackingSummary { joints, saturated_secs: self.saturated_secs, sim_secs: self.sim_secs }
    }
}

impl Observer for Tracking {
    fn start(&mut self, model: &Model, _data: &Data) -> Result<()> {
        self.joint_of = vec![None; model.nq()];
        self.names.clear();
        for j in 0..model.njnt() {
            if matches!(model.joint_type(j), JointType::Hinge | JointType::Slide) {
                self.joint_of[model.jnt_qposadr()[j] as usize] = Some(self.names.len());
                self.names.push(model.name(ObjType::Joint, j).to_string());
            }
        }
        let n = self.names.len();
        self.sum_sq = vec![0.0; n];
        self.max_abs = vec![0.0; n];
        self.count = vec![0; n];
        self.saturated_secs = 0.0;
        self.sim_secs = 0.0;
        Ok(())
    }

    fn observe(&mut self, step: &StepView<'_>) -> Result<Flow> {
        let (joint_of, sum_sq, max_abs, count) = (&self.joint_of, &mut self.sum_sq, &mut self.max_abs, &mut self.count);
        step.controller.position_targets(&mut |adr, target| {
            if let Some(Some(j)) = joint_of.get(adr) {
                let e = target - step.qpos[adr];
                sum_sq[*j] += e * e;
                max_abs[*j] = max_abs[*j].max(e.abs());
                count[*j] += 1;
            }
        });
        if step.saturated {
            self.saturated_secs += step.dt_secs;
        }
        self.sim_secs = step.sim_secs;
        Ok(Flow::Continue)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{PdHold, PdHoldOptions};
    use crate::engine::{Engine, Episode};
    use rand::SeedableRng;
    use std::sync::Arc;

    /// A pendulum held level by pd-hold sags under gravity: the steady error of a PD hold is
    /// m·g·l / kp, here with kp = effort / 0.25 rad.
    #[test]
    fn a_pd_hold_under_gravity_lags_by_its_steady_state_error() {
        let xml = r#"<mujoco><option timestep="0.001"/><worldbody><body>
            <joint name="hinge" axis="0 1 0" damping="0"/>
            <geom type="capsule" fromto="0 0 0 0.5 0 0" size="0.02" mass="0.001"/>
            <body pos="0.5 0 0"><geom type="sphere" size="0.03" mass="1"/></body>
            </body></worldbody>
            <actuator><motor joint="hinge" ctrlrange="-20 20" ctrllimited="true"/></actuator></mujoco>"#;
        let model = Arc::new(Model::from_xml_str(xml).unwrap());
        let mut hold = PdHold::new(&model, PdHoldOptions::default());
        let mut tracking = Tracking::new();
        let episode = Episode { steps: 3000, ..Episode::default() };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        Engine::new().run(&model, &episode, &mut hold, &mut [], &mut [&mut tracking], &mut rng).unwrap();
        let s = tracking.summary();
        assert_eq!(s.joints.len(), 1);
        assert_eq!(s.joints[0].joint, "hinge");
        // kp = 20 N·m / 0.25 rad = 80 N·m/rad; the load m·g·l = 1 · 9.81 · 0.5 = 4.905 N·m
        // (plus the capsule's, massless): the error settles at 4.905 / 80 = 0.0613 rad, and
        // the largest error is about that (a critically damped approach does not overshoot).
        let steady = 9.81 * 0.5 / 80.0;
        assert!((s.max() - steady).abs() < 0.1 * steady, "{s}");
        assert!(s.rms() < s.max() && s.rms() > 0.7 * steady, "{s}");
        assert_eq!(s.saturated_secs, 0.0);
    }
}
