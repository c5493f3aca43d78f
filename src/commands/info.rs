//! `twin info [MODEL]`: what a model contains, as MuJoCo compiled it.

use anyhow::Context;
use std::io::Write;
use std::path::PathBuf;
use twin_core::mj::{BiasType, DynType, Model, ObjType};
use twin_core::robot::Robot;

#[derive(Debug, clap::Args)]
pub struct Args {
    /// MJCF (.xml) or URDF (.urdf) file (default: the shipped humanoid).
    pub model: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let path = args.model.unwrap_or_else(super::default_model);
    let robot = Robot::load(&path).with_context(|| format!("loading {}", path.display()))?;
    let model = &robot.model;
    let mut out = std::io::stdout().lock();
    write_info(&mut out, &path, model)?;
    Ok(())
}

fn write_info(out: &mut impl Write, path: &std::path::Path, m: &Model) -> std::io::Result<()> {
    writeln!(out, "model: {}", path.display())?;
    writeln!(
        out,
        "MuJoCo {} · timestep {} s · gravity {:?} m/s² · nq {} · nv {} · nu {}",
        twin_core::mj::version(),
        m.timestep_secs(),
        m.gravity(),
        m.nq(),
        m.nv(),
        m.nu()
    )?;

    writeln!(out, "\nbodies ({}):", m.nbody())?;
    writeln!(out, "  {:>3}  {:<28} {:<28} {:>10}", "id", "name", "parent", "mass_kg")?;
    for b in 0..m.nbody() {
        let parent = m.body_parentid()[b] as usize;
        let parent = if b == 0 { "-" } else { m.name(ObjType::Body, parent) };
        writeln!(out, "  {:>3}  {:<28} {:<28} {:>10.4}", b, m.name(ObjType::Body, b), parent, m.body_mass()[b])?;
    }

    writeln!(out, "\njoints ({}):", m.njnt())?;
    writeln!(
        out,
        "  {:<28} {:<6} {:<28} {:>10} {:>12} {:>10}",
        "name", "type", "range", "damping", "frictionloss", "armature"
    )?;
    for j in 0..m.njnt() {
        let kind = m.joint_type(j);
        let range = if m.jnt_limited()[j] {
            let [lo, hi] = m.jnt_range()[j];
            format!("[{lo:.4}, {hi:.4}]")
        } else {
            "unlimited".to_string()
        };
        let dof = m.jnt_dofadr()[j] as usize;
        writeln!(
            out,
            "  {:<28} {:<6} {:<28} {:>10.4} {:>12.4} {:>10.4}",
            m.name(ObjType::Joint, j),
            kind.label(),
            range,
            m.dof_damping()[dof],
            m.dof_frictionloss()[dof],
            m.dof_armature()[dof]
        )?;
    }

    writeln!(out, "\nactuators ({}):", m.nu())?;
    for a in 0..m.nu() {
        let target = m.actuator_trnid()[a][0];
        let target = if target >= 0 { m.name(ObjType::Joint, target as usize) } else { "-" };
        let [lo, hi] = m.actuator_ctrlrange()[a];
        let range = if m.actuator_ctrllimited()[a] { format!("[{lo}, {hi}]") } else { "unlimited".into() };
        writeln!(
            out,
            "  {:<28} joint {:<28} gear {:<8} ctrlrange {} · drive: {}",
            m.name(ObjType::Actuator, a),
            target,
            m.actuator_gear()[a][0],
            range,
            drive_model(m, a)
        )?;
    }

    writeln!(out, "\nsensors ({}):", m.nsensor())?;
    for s in 0..m.nsensor() {
        writeln!(out, "  {:<28} type {:<3} dim {}", m.name(ObjType::Sensor, s), m.sensor_type()[s], m.sensor_dim()[s])?;
    }

    writeln!(out, "\ntotal mass: {:.4} kg", m.total_mass_kg())?;
    let home = twin_core::convert::robot_meta(m).map(|r| r.home_pose).filter(|h| !h.is_empty());
    let home = match home {
        Some(h) => h,
        None if m.id(ObjType::Key, "home").is_some() => "keyframe \"home\"".into(),
        None => "qpos0 (no keyframe \"home\")".into(),
    };
    writeln!(out, "home pose: {home}")?;
    Ok(())
}

/// Actuator `a`'s drive model as MuJoCo compiled it, in joint space (the `<twin_actuator>` block
/// of a URDF, or the MJCF's own actuator): its loop gains, its command delay and its
/// torque–speed envelope; "ideal" for a torque motor that obeys at once at any speed.
fn drive_model(m: &Model, a: usize) -> String {
    let g = m.actuator_gear()[a][0];
    let g2 = g * g;
    let mut parts = Vec::new();
    let (gain, bias) = (m.actuator_gainprm()[a], m.actuator_biasprm()[a]);
    if m.actuator_dyn(a) == DynType::Dcmotor {
        if gain[4] != 0.0 || gain[6] != 0.0 {
            parts.push(format!("position loop kp {} kd {}", gain[4] * g2, gain[6] * g2));
        }
    } else if m.actuator_bias(a) == BiasType::Affine && bias[1] != 0.0 {
        parts.push(format!("position loop kp {} kd {}", -bias[1] * g2, -bias[2] * g2));
    } else if m.actuator_bias(a) == BiasType::Affine && bias[2] != 0.0 {
        parts.push(format!("velocity loop kd {}", -bias[2] * g2));
    }
    let delay = m.actuator_delay()[a];
    if delay > 0.0 {
        parts.push(format!("delay {:.2} ms", delay * 1e3));
    }
    if let Some((stall, no_load)) = m.actuator_envelope(a) {
        parts.push(format!(
            "DC motor stall {:.4} no-load {:.4} (joint units, torque falls with speed)",
            stall * g.abs(),
            no_load / g.abs()
        ));
    }
    if m.actuator_armature()[a] > 0.0 {
        parts.push(format!("rotor armature {}", m.actuator_armature()[a]));
    }
    if parts.is_empty() { "ideal".into() } else { parts.join(" · ") }
}
