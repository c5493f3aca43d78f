//! `twin convert ROBOT.urdf`: URDF (+ Gazebo tags, transmissions, ros2_control) → MuJoCo MJCF
//! with actuators and sensors, optionally composed with a world.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};
use twin_core::convert::{ActuatorMode, ConvertOptions, ConvertedModel, convert_urdf};
use twin_core::fsio;
use twin_core::mj::Model;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// The robot's URDF file.
    pub urdf: PathBuf,
    /// Output MJCF file (default: `<robot name>.xml` next to the URDF).
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Weld the root link to the world instead of a free-floating base.
    #[arg(long)]
    pub fixed_base: bool,
    /// Folder containing ROS packages, for `package://` mesh URIs (repeatable; searched before
    /// ROS_PACKAGE_PATH).
    #[arg(long = "package-path", value_name = "DIR")]
    pub package_paths: Vec<PathBuf>,
    /// Refuse inertias that no rigid body has (triangle inequality, not positive definite)
    /// instead of repairing them by the smallest change (listed in the notes).
    #[arg(long)]
    pub strict_inertia: bool,
    /// Which joints get actuators: `auto` (transmissions / ros2_control where declared, a motor
    /// within ±effort on every other joint with an effort limit), `transmissions` (only
    /// declared ones), `motor`, `position` (every movable joint), `none`.
    #[arg(long, default_value = "auto", value_name = "MODE")]
    pub actuators: ActuatorMode,
    /// Gazebo SDF world or MJCF file to compose the robot into (default: a floor and a light).
    #[arg(long, value_name = "FILE")]
    pub world: Option<PathBuf>,
    /// Give this link a contact sensor, as a Gazebo `contact` sensor on it would (a MuJoCo
    /// `touch` sensor over each of its collision geoms), e.g. feet that sense load on the real
    /// robot while the URDF does not say so (repeatable).
    #[arg(long = "contact-sensor", value_name = "LINK")]
    pub contact_sensors: Vec<String>,
    /// SRDF pose written as keyframe `home` (a `<group_state>` name; default: "standing",
    /// "home", … where an SRDF beside the URDF has one, else the zero pose
    /// clamped into every joint's range).
    #[arg(long, value_name = "NAME")]
    pub pose: Option<String>,
    /// SRDF file to take the pose from (default: one beside the URDF, in `srdf/` there or in
    /// `srdf/` one folder up, that names this robot's joints).
    #[arg(long, value_name = "FILE")]
    pub srdf: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // Peek at the robot name for the default output path.
    let output = match &args.output {
        Some(o) => o.clone(),
        None => {
            let text = fsio::read_to_string(&args.urdf)?;
            let name = robot_name(&text)
                .unwrap_or_else(|| args.urdf.file_stem().and_then(|s| s.to_str()).unwrap_or("robot").to_string());
            args.urdf.parent().unwrap_or(Path::new(".")).join(format!("{name}.xml"))
        }
    };
    // Before any work: not a folder, device or the URDF itself; symlinks followed.
    let target = fsio::check_output(&output, &[&args.urdf])?;
    let out_dir = output.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let stem = output.file_stem().and_then(|s| s.to_str()).unwrap_or("robot");
    let opts = ConvertOptions {
        fixed_base: args.fixed_base,
        package_paths: args.package_paths.clone(),
        strict_inertia: args.strict_inertia,
        actuators: args.actuators,
        mesh_dir: Some(out_dir.join(format!("{stem}_meshes"))),
        world: args.world.clone(),
        contact_sensors: args.contact_sensors.clone(),
        pose: args.pose.clone(),
        srdf: args.srdf.clone(),
        ..ConvertOptions::default()
    };
    let converted = convert_urdf(&args.urdf, &opts)?;
    let model = Model::from_xml_str(&converted.mjcf)
        .with_context(|| format!("compiling the converted {}", args.urdf.display()))?;
    let mut tx = fsio::Transaction::new();
    tx.stage(&target, converted.mjcf.as_bytes(), fsio::Backup::Numbered)?;
    tx.commit()?;
    let mut out = std::io::stdout().lock();
    summary(&mut out, &output, &converted, &model)?;
    Ok(())
}

fn robot_name(text: &str) -> Option<String> {
    let doc = roxml_name(text)?;
    Some(doc)
}

/// `<robot name="…">` without a full parse (the converter reports XML errors properly).
fn roxml_name(text: &str) -> Option<String> {
    let start = text.find("<robot")?;
    let rest = &text[start..];
    let tag = &rest[..rest.find('>')?];
    let at = tag.find("name=")? + 5;
    let quote = tag[at..].chars().next()?;
    let value = &tag[at + 1..];
    let end = value.find(quote)?;
    let name: String =
        value[..end].chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect();
    (!name.is_empty()).then_some(name)
}

fn summary(out: &mut impl Write, output: &Path, c: &ConvertedModel, m: &Model) -> std::io::Result<()> {
    writeln!(out, "wrote {}", output.display())?;
    writeln!(
        out,
        "robot {}: {} bodies, {} joints, {} actuators, {} sensors, {} cameras, total mass {:.3} kg",
        c.meta.name,
        m.nbody() - 1,
        m.njnt(),
        m.nu(),
        m.nsensor(),
        m.ncam(),
        m.total_mass_kg()
    )?;
    writeln!(
        out,
        "base: {} (root at z = {:.4} m in keyframe `home`)",
        if c.meta.floating_base { "free-floating" } else { "fixed" },
        c.base_height_m
    )?;
    writeln!(out, "home pose: {}", c.meta.home_pose)?;
    for imu in &c.meta.imus {
        writeln!(
            out,
            "imu {} on {}: sensors {0}_quat/{0}_gyro/{0}_accel, rate {} Hz, gyro σ {} rad/s, accel σ {} m/s², topic {}",
            imu.name,
            imu.link,
            imu.update_rate_hz.map_or("-".into(), |r| r.to_string()),
            imu.gyro_noise_std,
            imu.accel_noise_std,
            imu.topic.as_deref().unwrap_or("-")
        )?;
    }
    for s in &c.meta.sensors {
        writeln!(out, "sensor {} ({}) on {}: {}", s.name, s.kind, s.reference, s.mujoco.join(", "))?;
    }
    if !c.notes.is_empty() {
        writeln!(out, "notes:")?;
        for n in &c.notes {
            writeln!(out, "  - {n}")?;
        }
    }
    Ok(())
}
