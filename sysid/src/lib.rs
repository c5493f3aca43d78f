//! System identification of link inertias and joint friction from robot logs (`twin sysid`).

pub mod condition;
pub mod error;
pub mod estimate;
pub mod identify;
pub mod log;
pub mod mjcf;
pub mod model;
pub mod regressor;
pub mod report;
pub mod signal;
pub mod synth;
pub mod writeback;

pub use error::{Error, Result};
pub use identify::{Base, Identification, SysidOptions, identify, urdf_updates, validate};
pub use log::JointLog;
pub use model::RobotModel;
pub use report::Report;
