//! The one controller registry of twin: the controllers `twin sim`, `twin randomize` and
//! scenario files name, and how a name becomes a [`Controller`] for a model.
//!
//! It sits above every controller ([`twin_core::control`]'s own, [`crate::walk`], [`crate::grasp`]),
//! so that no controller imports the list of the others: a name and [`ControllerOptions`] come
//! in, [`by_name_with`] picks the controller and builds it on the model.

use twin_core::control::{Controller, JointTrajectory, Passive, PdHold, PdHoldOptions, Replay, ReplayOptions};
use twin_core::error::{Error, Result};
use twin_core::mj::Model;

/// Names accepted by [`by_name`]: the one controller registry of twin (`twin sim`,
/// `twin randomize`).
pub const CONTROLLERS: &[&str] = &["pd-hold", "passive", "replay", "walk", "grasp"];

/// What [`by_name`] may need beyond the model.
#[derive(Debug, Clone, Default)]
pub struct ControllerOptions {
    /// Gains of `pd-hold` and `replay`. (default: [`PdHoldOptions::default`])
    pub gains: PdHoldOptions,
    /// The trajectory `replay` tracks (required for it). (default: none)
    pub trajectory: Option<JointTrajectory>,
    /// Parameters of `walk` (velocity command, gait, gains). (default: [`crate::walk::WalkOptions::default`])
    pub walk: crate::walk::WalkOptions,
    /// Parameters of `grasp` (its legs balance with `walk`). (default: [`crate::grasp::GraspOptions::default`])
    pub grasp: crate::grasp::GraspOptions,
}

/// The controller called `name` for `model`: `pd-hold` (alias `hold`) holds the nominal pose,
/// `passive` applies nothing, `replay` tracks `options.trajectory`, `walk` walks (or stands and
/// balances) with `options.walk` ([`crate::walk::Walker`]).
///
/// # Errors
/// [`Error::NotFound`] (kind `controller`) for an unknown name; [`Error::Options`] for
/// `replay` without a trajectory, or a trajectory given to another controller; as
/// [`Replay::new`] and [`crate::walk::Walker::new`].
pub fn by_name_with(name: &str, model: &Model, options: &ControllerOptions) -> Result<Box<dyn Controller>> {
    let canonical = if name == "hold" { "pd-hold" } else { name };
    if canonical != "replay" && options.trajectory.is_some() {
        return Err(Error::Options(format!("a trajectory is for the replay controller, not {name}")));
    }
    match canonical {
        "pd-hold" => Ok(Box::new(PdHold::new(model, options.gains.clone()))),
        "passive" => Ok(Box::new(Passive)),
        "replay" => {
            let Some(trajectory) = options.trajectory.clone() else {
                return Err(Error::Options(
                    "the replay controller needs a trajectory: a ROS 2 log or a CSV time_sec,<joint>,…".into(),
                ));
            };
            let replay_options = ReplayOptions { gains: options.gains.clone() };
            Ok(Box::new(Replay::new(model, trajectory, replay_options)?))
        }
        "walk" => Ok(Box::new(crate::walk::Walker::new(model, options.walk.clone())?)),
        "grasp" => Ok(Box::new(crate::grasp::Grasper::new(model, options.grasp.clone(), options.walk.clone())?)),
        _ => Err(Error::NotFound {
            kind: "controller (available: pd-hold, passive, replay, walk, grasp)",
            name: name.to_string(),
        }),
    }
}

/// [`by_name_with`] with default options (no trajectory).
///
/// # Errors
/// As [`by_name_with`].
pub fn by_name(name: &str, model: &Model) -> Result<Box<dyn Controller>> {
    by_name_with(name, model, &ControllerOptions::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_name_is_refused_with_the_names_there_are() {
        let model = Model::from_xml_str(
            r#"<mujoco><worldbody><body><joint name="hip"/><geom size="0.1"/></body></worldbody></mujoco>"#,
        )
        .unwrap();
        let e = by_name("dance", &model).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("\"dance\"") && e.contains("pd-hold, passive, replay, walk, grasp"), "{e}");
        assert!(by_name("passive", &model).is_ok());
    }
}
