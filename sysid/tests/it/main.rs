//! sysid's integration tests, one test binary (each file a module: one link instead of one per file).

#[path = "../../../twin-core/tests/it/example_robot_data.rs"]
mod example_robot_data;
mod excite;
mod floating;
mod friction;
mod gap;
mod noise;
mod regressor;
mod synthetic;
#[path = "../../../twin-core/tests/it/test_python.rs"]
mod test_python;
