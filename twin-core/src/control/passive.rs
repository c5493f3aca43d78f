//! [`Passive`]: no command.

use super::{Controller, Observation};
use crate::mj::Model;

/// Applies no command at all: the passive model (a baseline: how the robot does unpowered).
#[derive(Debug, Clone, Default)]
pub struct Passive;

impl Controller for Passive {
    fn name(&self) -> &'static str {
        "passive"
    }

    fn compute(&mut self, _model: &Model, _observation: &Observation<'_>, command: &mut [f64]) {
        command.fill(0.0);
    }
}
