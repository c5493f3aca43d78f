//! One module per subcommand, each with `run(args) -> anyhow::Result<()>`; [`crate::cli`]
//! lists them and dispatches to them.

pub mod calibrate;
pub mod check;
pub mod convert;
pub mod excite;
pub mod gap;
pub mod info;
pub mod log;
pub mod randomize;
pub mod sim;
pub mod sysid;
pub mod sysid_actuator;
pub mod test;
pub mod view;
pub mod viewers;

use std::path::PathBuf;
use std::sync::LazyLock;

/// `twin --version`: twin's version and the version of the MuJoCo headers its bindings were
/// generated from (the library loaded at run time is checked against it).
pub static VERSION_LINE: LazyLock<String> =
    LazyLock::new(|| format!("{} (MuJoCo {})", env!("CARGO_PKG_VERSION"), twin_core::mj::header_version()));

/// A command that Ctrl-C (SIGINT, or SIGTERM/SIGHUP) stopped early and that then finished
/// cleanly: its outputs are closed and readable up to where it stopped and its summary is
/// printed. `main` prints the message and exits with status 130 (128 + SIGINT, what a shell
/// reports for a command stopped by Ctrl-C), so scripts can tell a cut run from a complete one.
#[derive(Debug)]
pub struct Interrupted(pub String);

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "interrupted: {}", self.0)
    }
}

impl std::error::Error for Interrupted {}

/// Exit status of a command stopped by Ctrl-C after finishing cleanly ([`Interrupted`]).
pub const EXIT_INTERRUPTED: u8 = 130;

/// Shortest simulated duration an option accepts, seconds.
pub const MIN_SECS: f64 = 1e-6;
/// Longest simulated duration an option accepts, seconds (one day: far beyond any twin run,
/// small enough that a typo such as `1e300` is refused instead of running forever).
pub const MAX_SIM_SECS: f64 = 86_400.0;
/// Highest publishing rate, Hz (MuJoCo timesteps are ≥ 1e-5 s in practice).
pub const MAX_RATE_HZ: f64 = 100_000.0;
/// Highest posed frame rate of `twin view` (a rerun viewer shows at most a few hundred).
pub const MAX_FPS: f64 = 1_000.0;

/// Checks a numeric option: finite and within `min..=max` (`unit` for the message).
pub fn check_range(option: &str, value: f64, min: f64, max: f64, unit: &str) -> anyhow::Result<()> {
    if !(value.is_finite() && value >= min && value <= max) {
        let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
        anyhow::bail!("{option} must be a number from {min} to {max}{unit}, got {value}");
    }
    Ok(())
}

/// The shipped humanoid, the default model of every command: `models/humanoid.urdf` in the
/// current directory if there is one, else the copy in the source tree twin was built from.
pub fn default_model() -> PathBuf {
    let local = PathBuf::from("models/humanoid.urdf");
    if local.is_file() { local } else { PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/models/humanoid.urdf")) }
}

/// Writes a text output a command produced (a report, a plot) atomically, without a backup
/// (it is the command's own output, not a file the user edits), and says where it went.
pub fn write_output(path: &std::path::Path, text: &str, what: &str) -> anyhow::Result<()> {
    twin_core::fsio::write_atomic(path, text.as_bytes(), twin_core::fsio::Backup::None)?;
    eprintln!("{what} written to {}", path.display());
    Ok(())
}

/// `--controller` of `twin sim` and `twin randomize`: the names of the one controller registry
/// ([`twin_controllers::registry::CONTROLLERS`]) and the scenario's own ROS 2 node. Parsed by clap, so an
/// unknown name is refused with the list of these before anything is loaded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ControllerName {
    /// PD hold of the home pose (alias `hold`).
    #[value(name = "pd-hold", alias = "hold")]
    PdHold,
    /// No torque.
    Passive,
    /// PD + velocity feed-forward tracking of `--trajectory`.
    Replay,
    /// The model-based walker (stands and balances at zero velocity).
    Walk,
    /// Reach, grasp and lift (its legs balance with the walker).
    Grasp,
    /// The scenario's own ROS 2 node (`controller = "ros"` and its `[ros]` table).
    Ros,
}

impl ControllerName {
    /// The name the registry and scenario files use.
    pub fn name(self) -> &'static str {
        match self {
            ControllerName::PdHold => "pd-hold",
            ControllerName::Passive => "passive",
            ControllerName::Replay => "replay",
            ControllerName::Walk => "walk",
            ControllerName::Grasp => "grasp",
            ControllerName::Ros => twin_scenario::EXTERNAL_CONTROLLER,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::ControllerName;
    use clap::ValueEnum;

    #[test]
    fn controller_names_are_the_registry_and_ros() {
        let names: Vec<&str> = ControllerName::value_variants().iter().map(|c| c.name()).collect();
        let mut expected = twin_controllers::registry::CONTROLLERS.to_vec();
        expected.push("ros");
        assert_eq!(names, expected);
        for c in ControllerName::value_variants() {
            assert_eq!(c.to_possible_value().unwrap().get_name(), c.name());
        }
        assert_eq!(ControllerName::from_str("hold", false), Ok(ControllerName::PdHold));
    }
}
