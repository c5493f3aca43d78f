//! `twin check [MODEL]`: incremental validation (physics, sensors, control, integration), each
//! step PASS/FAIL with numbers and the likely cause of a failure. Exits non-zero on a failure.

use std::io::Write;
use std::path::PathBuf;
use twin_core::check::{CheckOptions, check};
use twin_core::convert::ConvertOptions;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// MJCF (.xml) or URDF (.urdf) file (default: the shipped humanoid).
    pub model: Option<PathBuf>,
    /// Folder containing ROS packages for `package://` meshes (repeatable).
    #[arg(long = "package-path", value_name = "DIR")]
    pub package_paths: Vec<PathBuf>,
    /// Convert a URDF with a fixed base (for arms bolted to a table).
    #[arg(long)]
    pub fixed_base: bool,
    /// Refuse invalid inertias instead of repairing them by the smallest change.
    #[arg(long)]
    pub strict_inertia: bool,
    /// SRDF pose held as home (a `<group_state>` name; default: "standing", "home", …
    /// where an SRDF beside the URDF has one, else the zero pose clamped into every
    /// joint's range).
    #[arg(long, value_name = "NAME")]
    pub pose: Option<String>,
    /// SRDF file to take the pose from (default: one beside the URDF, in `srdf/` there or in
    /// `srdf/` one folder up, that names this robot's joints).
    #[arg(long, value_name = "FILE")]
    pub srdf: Option<PathBuf>,
    /// Duration of the standing hold, seconds.
    #[arg(long, default_value_t = 5.0)]
    pub hold_secs: f64,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    super::check_range("--hold-secs", args.hold_secs, super::MIN_SECS, super::MAX_SIM_SECS, "s")?;
    let path = args.model.clone().unwrap_or_else(super::default_model);
    let mut out = std::io::stdout().lock();
    // Joints that no transmission names get a motor (--actuators auto) so the PD hold can act
    // on them. The one path from a file (what `Robot::load` runs); a URDF is checked welded too.
    let opts = ConvertOptions {
        fixed_base: args.fixed_base,
        package_paths: args.package_paths.clone(),
        strict_inertia: args.strict_inertia,
        pose: args.pose.clone(),
        srdf: args.srdf.clone(),
        ..ConvertOptions::default()
    };
    let loaded = twin_core::convert::load(&path, &opts, "")?;
    let floating = loaded.model;
    let fixed = match loaded.converted {
        Some(_) => {
            Some(twin_core::convert::load(&path, &ConvertOptions { fixed_base: true, floor: false, ..opts }, "")?.model)
        }
        None => None,
    };
    writeln!(
        out,
        "checking {} ({} joints, {} actuators, {} sensors, {:.3} kg)",
        path.display(),
        floating.njnt(),
        floating.nu(),
        floating.nsensor(),
        floating.total_mass_kg()
    )?;
    let home = twin_core::convert::robot_meta(&floating).map(|m| m.home_pose).filter(|h| !h.is_empty());
    let home = match home {
        Some(h) => h,
        None if floating.id(twin_core::mj::ObjType::Key, "home").is_some() => "the model's keyframe \"home\"".into(),
        None => "the model's qpos0 (no keyframe \"home\")".into(),
    };
    writeln!(out, "home pose: {home}")?;
    let opts = CheckOptions { hold_secs: args.hold_secs, ..CheckOptions::default() };
    let report = check(&floating, fixed.as_ref(), &opts)?;
    for step in &report.steps {
        writeln!(out, "{} {}", if step.passed { "PASS" } else { "FAIL" }, step.name)?;
        for m in &step.metrics {
            writeln!(out, "     {:<42} {:>12.6} {}", m.name, m.value, m.unit)?;
        }
        for d in &step.details {
            writeln!(out, "     {d}")?;
        }
        if let Some(c) = &step.cause {
            writeln!(out, "     likely cause: {c}")?;
        }
    }
    out.flush()?;
    if report.passed() {
        Ok(())
    } else {
        let failed: Vec<&str> = report.steps.iter().filter(|s| !s.passed).map(|s| s.name.as_str()).collect();
        anyhow::bail!("check failed: {}", failed.join(", "))
    }
}
