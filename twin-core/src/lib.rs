//! The building blocks of twin: a safe MuJoCo wrapper ([`mj`]), URDF checks ([`urdf`]), the
//! URDF/Gazebo → MJCF converter ([`convert`]), the robot loaded once ([`robot`]), the one
//! rollout engine ([`engine`]), the step-by-step model validation ([`check`]), controllers
//! ([`control`]) and their registry by name ([`registry`]), model-based walking with gait metrics ([`walk`]), scenario files
//! ([`scenario`]) and their terrain ([`terrain`]), the ROS 2 topic table and its sinks ([`topics`]), ROS 2 logs ([`log`]),
//! simulation runs with recording ([`sim`]), depth cameras, LiDARs and cup detection by ray
//! casting ([`sense`]), deterministic SVG plots ([`plot`]) and, with the cargo feature `rerun`, rerun
//! recordings (`viz`).
//!
//! `unsafe` code is denied everywhere but in [`mj`], the MuJoCo wrapper.
//!
//! MuJoCo errors never end the process: every call that can raise `mju_user_error` is wrapped by
//! a small C shim and comes back as [`Error::MuJoCo`].
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
pub mod checks;
pub mod control;
pub mod convert;
pub mod diagnose;
pub mod engine;
pub mod error;
pub mod external;
/// How twin opens its inputs and rewrites the files a user owns ([`twin_fsio`]).
pub use twin_fsio as fsio;
pub mod grasp;
#[cfg(feature = "ros")]
pub mod live;
pub mod log;
#[allow(unsafe_code)]
pub mod mj;
pub mod plot;
pub mod registry;
pub mod robot;
pub mod scenario;
pub mod sense;
pub mod sim;
pub mod terrain;
pub mod topics;
pub mod tracking;
/// URDF checks ([`twin_convert::urdf`]).
pub use twin_convert::urdf;
#[cfg(feature = "ros")]
pub mod viewer;
#[cfg(feature = "rerun")]
pub mod viz;
pub mod walk;

pub use error::{Error, Result};
