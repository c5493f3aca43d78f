//! twin's built-in controllers, the floor above the twin (`twin-core`): model-based walking
//! ([`walk`]: footsteps, DCM balance, leg IK, gait metrics), reach-grasp-lift ([`grasp`]), the
//! thresholds a scenario checks a run against ([`checks`]) and the one registry by name
//! ([`registry`]) that `twin sim`, `twin randomize` and scenario files use.
//!
//! Data flows in through `twin_core::control::Controller`: each control period the engine hands a
//! controller the observation (what the robot's sensors read, with their noise) and takes its
//! actuator commands; the walker and the grasper compute from that observation alone, the same
//! one a user's ROS 2 node receives. Their metrics (gait, grasp) go out to [`checks`] and to the
//! scenario and randomization tools above.
//!
//! `unsafe` code is denied here; MuJoCo is reached through `twin_core::mj` (the `twin-mj` crate).

#![deny(unsafe_code)]

pub mod checks;
pub mod grasp;
pub mod registry;
pub mod walk;
