//! Walking parameters from the robot: the [`Proportions`] of a biped (leg length, hip spacing,
//! standing centre-of-mass height, soles), measured in its home pose from the legs
//! [`Body::find`] finds, and the [`WalkOptions`] they give ([`WalkOptions::for_robot`]).
//!
//! The walker's defaults are the gait tuned on the shipped humanoid (`models/humanoid.urdf`,
//! legs of [`REFERENCE_LEG_LENGTH_M`]). Another biped gets that gait dynamically scaled
//! (equal Froude number `v²/(g·L)`, Alexander 1984): lengths × `s`, times × `√s`, with `s`
//! its leg length over the reference's, in steps of 5 % (so that the shipped humanoid's
//! options are its defaults bit for bit); the step width is its hip spacing; the walking CoM
//! height keeps the reference's crouch as a fraction of the standing CoM height, lowered
//! further while the legs can't reach the longest step with it ([`Walker::new`]'s reach check)
//! or reach it with a knee bent less than [`MIN_KNEE_BEND_RAD`] (the crouch from the legs'
//! kinematics: [`Walker::least_knee_bend_rad`]); the swing foot's clearance rises with the
//! legs' static load in that crouch past [`SAG_FREE_LOAD`] ([`Walker::crouch_load`]). Joint
//! gains come from the one gain rule ([`twin_core::control::PdHold`]) on the robot's effort limits.
//! Options a user gives keep their values.
//!
//! Where: `twin_scenario::Scenario::fit_walk` derives them once from the nominal model,
//! for `twin sim --controller walk` (a scenario or the defaults; it prints what it derived),
//! `twin test` and `twin randomize` (every episode's walker gets the nominal robot's
//! options); the `[walk]` keys a scenario writes keep their values.

use super::kin::{Body, BodyNames, Tree};
use super::{WalkOptions, Walker};
use twin_core::control::nominal_pose;
use twin_core::error::{Error, Result};
use twin_core::mj::Model;

/// Leg length of the shipped humanoid (its legs' first joints to the soles, home pose), m: the reference of
/// the scaling.
pub const REFERENCE_LEG_LENGTH_M: f64 = 0.66;
/// Standing centre-of-mass height of the shipped humanoid (home pose, above its soles), m.
pub const REFERENCE_COM_HEIGHT_M: f64 = 0.68;

/// A biped's measures in its home pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Proportions {
    /// Height of the legs' first joints above the soles, mean of both legs, m.
    pub leg_length_m: f64,
    /// Lateral distance between the legs' first joints, m.
    pub hip_spacing_m: f64,
    /// Standing centre-of-mass height above the soles, m.
    pub com_height_m: f64,
    /// Sole length and width (the smaller foot's), m.
    pub sole_m: [f64; 2],
    /// Total mass, kg.
    pub mass_kg: f64,
}

impl Proportions {
    /// The proportions of `model`'s biped (legs and feet as the walker finds them, `names`
    /// overriding).
    ///
    /// # Errors
    /// [`Error::Walk`] when the walker finds no two legs with feet ([`Body::find`]).
    pub fn of(model: &Model, names: &BodyNames) -> Result<Proportions> {
        let tree = Tree::new(model);
        let home = nominal_pose(model);
        let body = Body::find(model, &tree, &home, names)?;
        let mut frames = tree.frames();
        tree.forward(&home, &mut frames);
        let sole_z = |leg: usize| {
            let l = &body.legs[leg];
            (frames.xpos[l.foot] + frames.xrot[l.foot] * l.sole_in_foot).z
        };
        let hip = |leg: usize| frames.anchor[body.legs[leg].joints[0]];
        let soles_z = (sole_z(0) + sole_z(1)) / 2.0;
        let pelvis_rot = frames.xrot[body.pelvis];
        let lateral = (pelvis_rot.inverse() * (hip(0) - hip(1))).y.abs();
        let sole = |k: usize| body.legs[0].sole_half[k].min(body.legs[1].sole_half[k]) * 2.0;
        Ok(Proportions {
            leg_length_m: (hip(0).z + hip(1).z) / 2.0 - soles_z,
            hip_spacing_m: lateral,
            com_height_m: frames.com().z - soles_z,
            sole_m: [sole(0), sole(1)],
            mass_kg: tree.total_mass_kg,
        })
    }

    /// The length scale against the shipped humanoid, in steps of 5 %.
    pub fn scale(&self) -> f64 {
        quantize(self.leg_length_m / REFERENCE_LEG_LENGTH_M)
    }
}

/// `x` rounded to a multiple of 0.05 (at least 0.05).
fn quantize(x: f64) -> f64 {
    ((x * 20.0).round() / 20.0).max(0.05)
}

/// The options [`WalkOptions::for_robot`] derives, by name (the other options are the
/// defaults or what the user gave).
pub const DERIVED: &[&str] = &[
    "step_period",
    "step_width",
    "com_height",
    "foot_clearance",
    "max_step_length",
    "max_step_lateral",
    "max_step_adjust",
    "line_hold_step",
    "stride_hold_step",
    "recovery_margin",
    "min_single_support_secs",
    "recovery_swing_secs",
    "recovery_double_support_secs",
    "start_double_support",
    "preview_horizon",
];

/// How far the reach check may lower the walking CoM below the scaled crouch, in steps of
/// [`CROUCH_STEP`] of the leg length.
const CROUCH_STEPS: usize = 8;
/// One step of the crouch search, as a fraction of the leg length.
const CROUCH_STEP: f64 = 0.02;
/// The least knee bend the walking crouch keeps in the gait's extreme poses
/// ([`Walker::least_knee_bend_rad`]), rad. Near the straight knee a leg's length stops
/// following its knee (it changes by `sin` of the bend per radian): the joint loops lose hold
/// of the body's height and the knee runs into its stop. The shipped humanoid keeps 0.79 rad
/// and the G1 0.71 at their scaled crouches (unchanged). At the highest crouch that reaches
/// their steps Romeo kept 0.27 (0.680 m) and fell walking at 3.3 s, Talos (motors) 0.12
/// (0.924 m) and fell at 4.7 s; kept to 0.5 they crouch to 0.664 m (0.53 rad) and 0.887 m
/// (0.65 rad) and walk (docs/src/benchmarks-notebook.md, "Romeo walking").
pub const MIN_KNEE_BEND_RAD: f64 = 0.5;
/// The legs' static load in the crouch ([`Walker::crouch_load`]: the largest part of a leg
/// actuator's torque spent holding the robot on both feet) above which the swing foot is
/// lifted higher, in proportion. In single support a stance leg carries twice that load; on
/// Romeo (0.32) its hip and knee saturate, the swing foot (placed from the measured pelvis)
/// lags pitched toe-down and its toe strikes the ground short of the landing spot (a
/// mechanism the joint log suggests, not measured as such). The shipped humanoid's legs are
/// loaded 0.12, the G1's 0.16, Talos's (motors) 0.21 at their crouches: unchanged. Fitted on
/// Romeo, the one robot above it (docs/src/benchmarks-notebook.md, "Romeo walking"): at its crouch it walks at
/// 0.2 and 0.22 m/s and follows `steer.toml` with a clearance of 0.08 to 0.09 m (derived:
/// 0.087); with 0.075 it falls at 0.22 m/s, with 0.0955 in `steer.toml`.
pub const SAG_FREE_LOAD: f64 = 0.22;

impl WalkOptions {
    /// These options for `model`: each of [`DERIVED`] that `given` does not name scaled from
    /// the defaults to the robot's [`Proportions`] (see the [module docs](self)); the others as
    /// they are. The shipped humanoid gets its defaults unchanged.
    ///
    /// # Errors
    /// [`Error::Walk`] when the model is not a biped the walker can drive (no floating base, no
    /// two legs with feet and six joints each).
    pub fn for_robot(&self, model: &Model, given: &dyn Fn(&str) -> bool) -> Result<WalkOptions> {
        let p = Proportions::of(model, &self.bodies)?;
        let s = p.scale();
        let t = s.sqrt();
        let d = WalkOptions::default();
        let mut o = self.clone();
        let set = |name: &str, field: &mut f64, value: f64| {
            if !given(name) {
                *field = value;
            }
        };
        set("step_period", &mut o.step_period, d.step_period * t);
        // The hip spacing, to the centimetre (the shipped humanoid's 0.18 m).
        set("step_width", &mut o.step_width, ((p.hip_spacing_m * 100.0).round() / 100.0).max(0.01));
        set("foot_clearance", &mut o.foot_clearance, d.foot_clearance * s);
        set("max_step_length", &mut o.max_step_length, d.max_step_length * s);
        set("max_step_lateral", &mut o.max_step_lateral, d.max_step_lateral * s);
        set("max_step_adjust", &mut o.max_step_adjust, d.max_step_adjust * s);
        set("line_hold_step", &mut o.line_hold_step, d.line_hold_step * s);
        set("stride_hold_step", &mut o.stride_hold_step, d.stride_hold_step * s);
        set("recovery_margin", &mut o.recovery_margin, d.recovery_margin * s);
        set("min_single_support_secs", &mut o.min_single_support_secs, d.min_single_support_secs * t);
        set("recovery_swing_secs", &mut o.recovery_swing_secs, d.recovery_swing_secs * t);
        set("recovery_double_support_secs", &mut o.recovery_double_support_secs, d.recovery_double_support_secs * t);
        set("start_double_support", &mut o.start_double_support, d.start_double_support * t);
        set("preview_horizon", &mut o.preview_horizon, d.preview_horizon * t);
        let crouched = d.com_height * quantize(p.com_height_m / REFERENCE_COM_HEIGHT_M);
        set("com_height", &mut o.com_height, crouched);
        if !given("com_height") {
            // The crouch from the legs' kinematics: lower until the longest step is reachable
            // with the knees bent by MIN_KNEE_BEND_RAD; if no crouch bends them that far, the
            // reachable one that bends them most.
            let mut most_bent: Option<(f64, f64)> = None;
            for k in 0..=CROUCH_STEPS {
                o.com_height = crouched - k as f64 * CROUCH_STEP * p.leg_length_m;
                match Walker::new(model, o.clone()) {
                    Ok(walker) => {
                        let bend = walker.least_knee_bend_rad();
                        if bend >= MIN_KNEE_BEND_RAD {
                            most_bent = None;
                            break;
                        }
                        if most_bent.is_none_or(|(_, b)| bend > b) {
                            most_bent = Some((o.com_height, bend));
                        }
                    }
                    // Lower only while the steps are out of reach or the knees too straight (a
                    // lower crouch needs more torque, not less, of actuators too weak to hold it).
                    Err(Error::WalkReach { .. }) if k < CROUCH_STEPS => continue,
                    Err(e) if most_bent.is_none() => return Err(e),
                    Err(_) => break,
                }
            }
            if let Some((height, _)) = most_bent {
                o.com_height = height;
            }
        }
        if !given("foot_clearance") {
            // Legs loaded past SAG_FREE_LOAD sag in single support: lift the swing foot more.
            let load = Walker::new(model, o.clone())?.crouch_load();
            o.foot_clearance *= (load / SAG_FREE_LOAD).max(1.0);
        }
        Ok(o)
    }

    /// The options that differ from `before`, as `name = value` (TOML), in field order: what
    /// [`WalkOptions::for_robot`] changed.
    pub fn changes_from(&self, before: &WalkOptions) -> Vec<String> {
        let (Ok(toml::Value::Table(b)), Ok(toml::Value::Table(a))) =
            (toml::Value::try_from(before), toml::Value::try_from(self))
        else {
            return Vec::new();
        };
        a.iter().filter(|(k, v)| b.get(*k) != Some(*v)).map(|(k, v)| format!("{k} = {v}")).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantized_scale_is_exact_at_the_reference() {
        assert_eq!(quantize(1.02), 1.0);
        assert_eq!(quantize(0.66 / REFERENCE_LEG_LENGTH_M), 1.0);
        assert_eq!(quantize(1.43), 1.45);
        // Scaling the defaults by exactly 1 keeps them bit for bit.
        let d = WalkOptions::default();
        assert_eq!(d.step_period * 1.0f64.sqrt(), d.step_period);
    }
}
