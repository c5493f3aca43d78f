//! twin-core's integration tests, one test binary (each file a module: one link instead of one per file).

mod actuator;
mod convert;
mod corpus;
mod errors;
mod example_robot_data;
mod legged;
mod log_interop;
mod physics;
mod public_sensors;
mod render;
mod sense;
mod sinks;
mod test_python;
