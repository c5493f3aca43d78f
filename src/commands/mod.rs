//! One module per subcommand, each with `run(args) -> anyhow::Result<()>`.

pub mod calibrate;
pub mod check;
pub mod convert;
pub mod info;
pub mod log;
pub mod randomize;
pub mod sim;
pub mod sysid;
pub mod view;

use crate::cli::{Cli, Command};
use std::path::PathBuf;

/// `twin --version`: twin's version and the MuJoCo version it was built for.
pub const VERSION_LINE: &str = concat!(env!("CARGO_PKG_VERSION"), " (MuJoCo 4.0.1)");

/// Dispatches to the subcommand.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info(args) => info::run(args),
        Command::Convert(args) => convert::run(args),
        Command::Check(args) => check::run(args),
        Command::Log(args) => log::run(args),
        Command::Randomize(args) => randomize::run(*args),
        Command::Sysid(args) => sysid::run(args),
        Command::Sim(args) => sim::run(*args),
        Command::View(args) => view::run(args),
        Command::Calibrate(args) => calibrate::run(args),
    }
}

/// The shipped humanoid, the default model of every command: `models/humanoid.urdf` in the
/// current directory if there is one, else the copy in the source tree twin was built from.
pub fn default_model() -> PathBuf {
    let local = PathBuf::from("models/humanoid.urdf");
    if local.is_file() { local } else { PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf")) }
}
