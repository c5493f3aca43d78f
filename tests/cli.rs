//! End-to-end tests of the `twin` binary: one test binary, a module per area under `tests/cli/`.

#[path = "cli/calibrate.rs"]
mod calibrate;
#[path = "cli/camera.rs"]
mod camera;
#[path = "cli/common.rs"]
mod common;
#[path = "cli/convert.rs"]
mod convert;
#[path = "cli/deploy.rs"]
mod deploy;
#[path = "cli/diagnose.rs"]
mod diagnose;
#[path = "cli/engine.rs"]
mod engine;
#[path = "../twin-core/tests/it/example_robot_data.rs"]
mod example_robot_data;
#[path = "cli/excite.rs"]
mod excite;
#[cfg(feature = "ros")]
#[path = "cli/extctl.rs"]
mod extctl;
#[path = "cli/gap.rs"]
mod gap;
#[path = "cli/grasp.rs"]
mod grasp;
#[path = "cli/info.rs"]
mod info;
#[cfg(feature = "ros")]
#[path = "cli/live.rs"]
mod live;
#[cfg(feature = "ros")]
#[path = "cli/lockstep.rs"]
mod lockstep;
#[path = "cli/log.rs"]
mod log;
#[path = "cli/randomize.rs"]
mod randomize;
#[path = "cli/reliab.rs"]
mod reliab;
#[path = "cli/sense.rs"]
mod sense;
#[path = "cli/shards.rs"]
mod shards;
#[path = "cli/sim.rs"]
mod sim;
#[path = "cli/sweep.rs"]
mod sweep;
#[path = "cli/sysid.rs"]
mod sysid;
#[path = "cli/sysid_actuator.rs"]
mod sysid_actuator;
#[path = "cli/sysid_real.rs"]
mod sysid_real;
#[path = "../twin-core/tests/it/test_python.rs"]
mod test_python;
#[cfg(feature = "ros")]
#[path = "cli/viewers.rs"]
mod viewers;
#[path = "cli/walk.rs"]
mod walk;
