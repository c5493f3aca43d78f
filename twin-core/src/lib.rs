//! The twin itself: what a robot is in simulation and how it runs. A robot's files are loaded
//! once ([`robot`], through [`convert`] and the MuJoCo wrapper [`mj`]); its sensors read the
//! physics ([`sense`]) into the ROS 2 topic table ([`topics`]); a controller ([`control`]: the
//! trait every controller implements, and the simple ones) closes the loop in the one rollout
//! engine ([`engine`]), with disturbances and observers; [`sim`] runs it with recording (MCAP
//! through [`log`], rerun through `viz` with the cargo feature `rerun`). Around it: terrain
//! ([`terrain`]), the step-by-step model validation ([`check`]), tracking metrics
//! ([`tracking`]), shared bounds ([`bounds`]) and deterministic SVG plots ([`plot`]).
//!
//! Data flows one way: files → [`robot::Robot`] → [`engine`] (physics step, observation,
//! controller, actuation) → sinks (recordings, live bridges). The floors above this crate:
//! `twin-controllers` (walking, grasping, scenario checks, the registry by name), `twin-bridges`
//! (the live ROS 2 bridge, viewers, external controllers), `twin-diagnose` (why a robot fell) and
//! `twin-scenario` (scenario files). Below it: `twin-mj` (the safe MuJoCo wrapper, re-exported
//! as [`mj`]), `twin-log` (ROS 2 logs, re-exported as [`log`]), `twin-convert` and `twin-fsio`.
//!
//! `unsafe` code is denied here; it lives in `twin-mj` and `mujoco-sys` only.
//!
//! MuJoCo errors never end the process: every call that can raise `mju_user_error` is wrapped by
//! a small C shim (in `twin-mj`) and comes back as [`Error::MuJoCo`].
//!
//! ```no_run
//! use std::sync::Arc;
//! use twin_core::mj::{Data, Model};
//!
//! let model = Arc::new(Model::from_file("models/humanoid.urdf")?);
//! let mut data = Data::new(model.clone())?;
//! for _ in 0..500 {
//!     data.step()?;
//! }
//! println!("t = {} s, total mass {} kg", data.time_secs(), model.total_mass_kg());
//! # Ok::<(), twin_core::Error>(())
//! ```

#![deny(unsafe_code)]

pub mod bounds;
pub mod check;
pub mod control;
/// Robot files to compiled models: the URDF converter with MuJoCo as its compiler
/// ([`twin_mj::convert`]).
pub use twin_mj::convert;
pub mod engine;
pub mod error;
/// How twin opens its inputs and rewrites the files a user owns ([`twin_fsio`]).
pub use twin_fsio as fsio;
/// ROS 2 logs: MCAP and rosbag2, CDR, typed messages ([`twin_log`]).
pub use twin_log as log;
/// The safe MuJoCo wrapper ([`twin_mj`]).
pub use twin_mj as mj;
pub mod plot;
pub mod robot;
pub mod sense;
pub mod sim;
pub mod terrain;
pub mod topics;
pub mod tracking;
/// URDF checks ([`twin_convert::urdf`]).
pub use twin_convert::urdf;
#[cfg(feature = "rerun")]
pub mod viz;

pub use error::{Error, Result};
