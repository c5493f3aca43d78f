//! The built-in controllers run as scenarios (walking, grasping, terrain): one test binary, each
//! file a module. They live here, above `twin-controllers`, because they load scenario files.

#[path = "../../../twin-core/tests/it/example_robot_data.rs"]
mod example_robot_data;
mod grasp;
mod terrain;
#[path = "../../../twin-core/tests/it/test_python.rs"]
mod test_python;
mod walk;
