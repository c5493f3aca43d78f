//! The building blocks of twin: a safe MuJoCo wrapper ([`mj`]), URDF checks ([`urdf`]), the
//! URDF/Gazebo → MJCF converter ([`convert`]), the step-by-step model validation ([`check`]),
//! controllers ([`control`]), ROS 2 logs ([`log`]), simulation runs with recording ([`sim`])
//! and, with the cargo feature `rerun`, rerun recordings (`viz`).
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

pub mod check;
pub mod control;
pub mod convert;
pub mod error;
#[cfg(feature = "ros")]
pub mod live;
pub mod log;
pub mod mj;
pub mod sim;
pub mod urdf;
#[cfg(feature = "rerun")]
pub mod viz;

pub use error::{Error, Result};
