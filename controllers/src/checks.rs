//! The thresholds a scenario checks a run against ([`Checks`], the `[checks]` table of a
//! scenario file) and each one's outcome ([`Threshold`]).
//!
//! Data flows from the run's measurements to lines of PASS/FAIL: the gait summary
//! ([`GaitSummary`]) through [`Checks::evaluate`], the grasp measurements through the grasp
//! check, the controller's tracking ([`TrackingSummary`]: commanded against actual joint
//! positions, for any controller that says its position targets) through
//! [`Checks::evaluate_tracking`]; the scenario gathers them into the run's
//! [`twin_core::engine::Verdict`]. This module sits
//! below both the scenario and the grasp check, so neither imports the other for them.

use crate::walk::GaitSummary;
use twin_core::tracking::TrackingSummary;

/// Thresholds on [`GaitSummary`]; each one present is checked.
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checks {
    /// Most falls allowed (0 or 1 in a single run).
    pub falls: Option<u32>,
    /// Least displacement along the initial heading, m.
    pub min_forward: Option<f64>,
    /// Largest lateral drift (absolute), m.
    pub max_lateral_drift: Option<f64>,
    /// Largest net displacement, m (standing).
    pub max_distance: Option<f64>,
    /// Least average speed, m/s.
    pub min_average_speed: Option<f64>,
    /// Largest foot slide in one stance, m.
    pub max_slip: Option<f64>,
    /// Largest mean foot slide per stance, m.
    pub max_mean_slip: Option<f64>,
    /// Largest RMS velocity-tracking error, m/s.
    pub max_velocity_error: Option<f64>,
    /// Least heading change, degrees (signed as the command: a negative threshold asks for at
    /// least that much turning right).
    pub min_turn_deg: Option<f64>,
    /// Least number of steps.
    pub min_steps: Option<u64>,
    /// Largest RMS step-length error, m.
    pub max_step_length_error: Option<f64>,
    /// Largest cost of transport.
    pub max_cost_of_transport: Option<f64>,
    /// Grasp: least clearance between the arms and the rest of the robot, and no robot contact
    /// with the world other than feet and gripper–cup, m (0: touching fails).
    pub min_clearance_m: Option<f64>,
    /// Grasp: largest finger–cup normal force of one finger, N.
    pub max_grip_force_n: Option<f64>,
    /// Grasp: least mean finger–cup normal force of each finger while the cup is held up, N.
    pub min_grip_force_n: Option<f64>,
    /// Grasp: largest cup displacement in the grasp frame after the lift started (the grasp
    /// frame, once at the cup, rose 1 cm), m.
    pub max_slip_m: Option<f64>,
    /// Grasp: largest cup tilt in the grasp frame after the lift started, degrees.
    pub max_tilt_deg: Option<f64>,
    /// Grasp: least margin of the CoM's ground projection inside the support polygon, m.
    pub min_com_margin_m: Option<f64>,
    /// Grasp: least cup height above its start, held for `min_hold_secs` at the end of the
    /// run, m.
    pub min_lift_m: Option<f64>,
    /// Grasp: how long the cup must stay lifted at the end of the run, s (default with
    /// `min_lift_m`: 2).
    pub min_hold_secs: Option<f64>,
    /// Tracking: largest RMS of commanded − actual position of the worst-tracking joint over
    /// the run, rad (m for slides). Fails a controller that gives no position targets.
    pub max_tracking_rms_rad: Option<f64>,
    /// Tracking: largest |commanded − actual| position of any joint at any step, rad (m).
    /// Fails a controller that gives no position targets.
    pub max_tracking_error_rad: Option<f64>,
    /// Tracking: largest fraction (0–1) of the run's simulated time with some actuator
    /// command at its limit (saturated).
    pub max_saturated_fraction: Option<f64>,
}

impl Checks {
    /// Whether any tracking threshold is set (the tracking metrics are then measured).
    pub fn has_tracking(&self) -> bool {
        self.max_tracking_rms_rad.is_some()
            || self.max_tracking_error_rad.is_some()
            || self.max_saturated_fraction.is_some()
    }

    /// Checks the values of the thresholds that have a range: `Err((key, message))`.
    ///
    /// # Errors
    /// The first key out of range.
    pub fn validate(&self) -> std::result::Result<(), (&'static str, String)> {
        for (key, v) in [
            ("max_tracking_rms_rad", self.max_tracking_rms_rad),
            ("max_tracking_error_rad", self.max_tracking_error_rad),
        ] {
            if let Some(v) = v
                && !(v >= 0.0 && v.is_finite())
            {
                return Err((key, format!("must be a non-negative number of radians (m for slide joints) (got {v})")));
            }
        }
        if let Some(f) = self.max_saturated_fraction
            && !(0.0..=1.0).contains(&f)
        {
            return Err(("max_saturated_fraction", format!("must be a fraction of the run within 0..=1 (got {f})")));
        }
        Ok(())
    }

    /// Each tracking threshold present against `summary`. Without position targets from the
    /// controller the tracking errors are unknown (NaN) and their thresholds fail.
    pub fn evaluate_tracking(&self, summary: &TrackingSummary) -> Vec<Threshold> {
        let unknown = summary.joints.is_empty();
        let (rms, max) = if unknown { (f64::NAN, f64::NAN) } else { (summary.rms(), summary.max()) };
        let fraction = if summary.sim_secs > 0.0 { summary.saturated_secs / summary.sim_secs } else { 0.0 };
        let mut out = Thresholds::default();
        out.at_most("max_tracking_rms_rad", rms, self.max_tracking_rms_rad);
        out.at_most("max_tracking_error_rad", max, self.max_tracking_error_rad);
        out.at_most("max_saturated_fraction", fraction, self.max_saturated_fraction);
        out.0
    }

    /// Whether any grasp threshold is set (the grasp check then runs).
    pub fn has_grasp(&self) -> bool {
        self.min_clearance_m.is_some()
            || self.max_grip_force_n.is_some()
            || self.min_grip_force_n.is_some()
            || self.max_slip_m.is_some()
            || self.max_tilt_deg.is_some()
            || self.min_com_margin_m.is_some()
            || self.min_lift_m.is_some()
            || self.min_hold_secs.is_some()
    }
}

/// One threshold's outcome: the measured value against the threshold (a line of a scenario's
/// report; the run's [`twin_core::engine::Verdict`] gathers them).
#[derive(Debug, Clone, PartialEq)]
pub struct Threshold {
    /// Check name (its key).
    pub name: &'static str,
    /// Measured value.
    pub value: f64,
    /// `<=` or `>=`.
    pub op: &'static str,
    /// Threshold.
    pub threshold: f64,
    /// Whether it passed.
    pub passed: bool,
}

impl std::fmt::Display for Threshold {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {:<22} {:.4} {} {}",
            if self.passed { "PASS" } else { "FAIL" },
            self.name,
            self.value,
            self.op,
            self.threshold
        )
    }
}

impl Threshold {
    /// `value` must be at most `threshold`.
    pub fn at_most(name: &'static str, value: f64, threshold: f64) -> Threshold {
        Threshold { name, value, op: "<=", threshold, passed: value <= threshold }
    }

    /// `value` must be at least `threshold`.
    pub fn at_least(name: &'static str, value: f64, threshold: f64) -> Threshold {
        Threshold { name, value, op: ">=", threshold, passed: value >= threshold }
    }
}

/// The thresholds a set of checks names, in the order they are added: a check the scenario
/// leaves out (`None`) adds nothing.
#[derive(Debug, Default)]
pub struct Thresholds(pub Vec<Threshold>);

impl Thresholds {
    /// [`Threshold::at_most`] when `threshold` is set.
    pub fn at_most(&mut self, name: &'static str, value: f64, threshold: Option<f64>) {
        if let Some(t) = threshold {
            self.0.push(Threshold::at_most(name, value, t));
        }
    }

    /// [`Threshold::at_least`] when `threshold` is set.
    pub fn at_least(&mut self, name: &'static str, value: f64, threshold: Option<f64>) {
        if let Some(t) = threshold {
            self.0.push(Threshold::at_least(name, value, t));
        }
    }
}

impl Checks {
    /// Each threshold present against `summary`; a fall fails every non-empty set of checks.
    pub fn evaluate(&self, summary: &GaitSummary) -> Vec<Threshold> {
        let c = self;
        let mut out = Thresholds::default();
        out.at_most("falls", f64::from(u8::from(summary.fell)), c.falls.map(f64::from));
        out.at_most("max_lateral_drift", summary.lateral_m.abs(), c.max_lateral_drift);
        out.at_most("max_distance", summary.distance_m, c.max_distance);
        out.at_most("max_slip", summary.slip_max_m, c.max_slip);
        out.at_most("max_mean_slip", summary.slip_mean_m, c.max_mean_slip);
        out.at_most("max_velocity_error", summary.velocity_rms_error_mps, c.max_velocity_error);
        out.at_most("max_step_length_error", summary.step_length_rms_error_m, c.max_step_length_error);
        out.at_most("max_cost_of_transport", summary.cost_of_transport, c.max_cost_of_transport);
        out.at_least("min_forward", summary.forward_m, c.min_forward);
        out.at_least("min_average_speed", summary.average_speed_mps, c.min_average_speed);
        out.at_least("min_steps", summary.steps as f64, c.min_steps.map(|s| s as f64));
        if let Some(t) = c.min_turn_deg {
            let sign = if t < 0.0 { -1.0 } else { 1.0 };
            let turned = summary.yaw_change_rad.to_degrees();
            out.0.push(Threshold {
                name: "min_turn_deg",
                value: turned,
                op: ">=",
                threshold: t,
                passed: sign * turned >= sign * t,
            });
        }
        // A fall fails every run that has checks, whether or not `falls` is among them.
        if summary.fell && c.falls.is_none() && !out.0.is_empty() {
            out.0.push(Threshold::at_most("falls", 1.0, 0.0));
        }
        out.0
    }
}
