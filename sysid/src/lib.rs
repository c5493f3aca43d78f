//! System identification of link inertias and joint friction from robot logs (`twin sysid`).

pub mod error;
pub mod log;
pub mod model;
pub mod regressor;
pub mod signal;
pub mod writeback;

pub use error::{Error, Result};
pub use log::JointLog;
pub use model::RobotModel;
