//! The real drive of each joint, beyond URDF `<limit effort velocity>`: the `<twin_actuator>`
//! block.
//!
//! A URDF says how strong a joint's drive is (`effort`) and what its command interface is
//! (`<transmission>`, `ros2_control`); it cannot say that commands arrive late, that torque falls
//! with speed, or what gains the drive's own position loop runs. The block, one top-level
//! element that URDF readers (urdfdom, Gazebo's) ignore as unknown, holds them, written by hand
//! from a datasheet or by `twin sysid actuator`:
//!
//! ```xml
//! <twin_actuator version="1">
//!   <joint name="elbow" delay_secs="0.005" kp="120" kd="4" stall_torque="60" no_load_speed="8"/>
//! </twin_actuator>
//! ```
//!
//! Every attribute but `name` is optional; the conversion turns each into MuJoCo's own
//! actuator mechanisms, so that every controller's commands, built in or over ROS 2, pass
//! through the same drive (they all write MuJoCo's `ctrl`):
//!
//! - `delay_secs` (s): the actuator's `delay`, read from a history buffer (`nsample`) with linear
//!   interpolation between physics steps (`interp="linear"`).
//! - `kp` (N·m/rad or N/m), `kd` (N·m·s/rad or N·s/m): the gains of the drive's position loop,
//!   in joint space, replacing the converter's defaults for a `position` interface (`kd` alone is
//!   the gain of a `velocity` interface).
//! - `stall_torque` (N·m or N) and `no_load_speed` (rad/s or m/s), both or neither: a DC motor's
//!   four-quadrant torque–speed envelope `|τ| ≤ stall_torque·(1 − ω/no_load_speed)` in the
//!   direction of motion, MuJoCo's `dcmotor` with a current-controlled driver (`controller`
//!   with `Vmax` at the nominal voltage), still clipped at the URDF effort (`saturation`).
//!
//! The rotor's reflected inertia (armature) is the `armature` of the joint's `<twin_sysid>` entry,
//! MuJoCo's joint `armature`: it has one place. The observation latency of the sensors is a
//! separate term of the randomization, not of the drive.

pub use crate::error::{Error, Result};
use roxmltree::{Document, Node};
use std::fmt::Write as _;
use std::path::Path;

/// Name of the block's element.
pub const BLOCK: &str = "twin_actuator";

/// One joint's drive model (see the module docs).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct DriveModel {
    /// URDF joint name.
    pub joint: String,
    /// Command delay, seconds (0: none).
    pub delay_secs: f64,
    /// Position-loop stiffness in joint space, N·m/rad or N/m.
    pub kp: Option<f64>,
    /// Position-loop (or velocity-loop) damping in joint space, N·m·s/rad or N·s/m.
    pub kd: Option<f64>,
    /// Stall torque of the torque–speed envelope, N·m or N.
    pub stall_torque: Option<f64>,
    /// No-load speed of the torque–speed envelope, rad/s or m/s.
    pub no_load_speed: Option<f64>,
    /// Line of the entry in its file (0 when not from a file).
    pub line: u32,
}

impl DriveModel {
    /// The envelope `(stall_torque, no_load_speed)` when both are given.
    pub fn envelope(&self) -> Option<(f64, f64)> {
        self.stall_torque.zip(self.no_load_speed)
    }

    /// Whether the entry changes nothing of the ideal drive.
    pub fn is_ideal(&self) -> bool {
        self.delay_secs == 0.0 && self.kp.is_none() && self.kd.is_none() && self.envelope().is_none()
    }

    /// The largest torque the envelope lets the drive apply in the direction of motion at joint
    /// speed `speed` (the driving quadrant), before the effort clip.
    pub fn envelope_torque(&self, speed: f64) -> Option<f64> {
        self.envelope().map(|(tau, w0)| (tau * (1.0 - speed.abs() / w0)).max(0.0))
    }

    /// One line for `twin info`: "ideal", or the terms present.
    pub fn describe(&self) -> String {
        let mut parts = Vec::new();
        if self.delay_secs > 0.0 {
            parts.push(format!("delay {:.1} ms", self.delay_secs * 1e3));
        }
        if let Some((t, w)) = self.envelope() {
            parts.push(format!("DC motor stall {} no-load {} rad/s", g(t), g(w)));
        }
        if let Some(kp) = self.kp {
            parts.push(format!("kp {}", g(kp)));
        }
        if let Some(kd) = self.kd {
            parts.push(format!("kd {}", g(kd)));
        }
        if parts.is_empty() { "ideal".into() } else { parts.join(", ") }
    }
}

fn g(x: f64) -> String {
    let s = format!("{x:.4e}");
    let v: f64 = s.parse().unwrap_or(x);
    format!("{v}")
}

/// The `<twin_actuator>` entries of `doc` (the URDF at `path`), empty without a block.
///
/// # Errors
/// [`Error::Urdf`] naming the line for a block of another version, an element other than
/// `<joint>` inside it, an entry without a name or named twice, a value that is not a finite
/// number, a negative delay or gain, a non-positive envelope term, or only one of
/// `stall_torque` and `no_load_speed`.
pub fn read_block(path: &Path, doc: &Document<'_>) -> Result<Vec<DriveModel>> {
    let Some(block) = doc.root_element().children().find(|n| n.has_tag_name(BLOCK)) else {
        return Ok(Vec::new());
    };
    let err = |n: Node<'_, '_>, message: String| Error::Urdf {
        path: path.to_path_buf(),
        line: doc.text_pos_at(n.range().start).row,
        element: n.tag_name().name().to_string(),
        name: n.attribute("name").map(str::to_string),
        message,
    };
    if let Some(v) = block.attribute("version")
        && v != "1"
    {
        return Err(err(block, format!("<{BLOCK} version=\"{v}\"> is not version 1: this twin reads version 1")));
    }
    let mut out: Vec<DriveModel> = Vec::new();
    for j in block.children().filter(|n| n.is_element()) {
        if !j.has_tag_name("joint") {
            return Err(err(
                j,
                format!(
                    "<{}> inside <{BLOCK}>: only <joint name=… delay_secs=… kp=… kd=… stall_torque=… \
                     no_load_speed=…/> entries belong there",
                    j.tag_name().name()
                ),
            ));
        }
        let name = j.attribute("name").ok_or_else(|| err(j, format!("<joint> inside <{BLOCK}> without name")))?;
        if let Some(prev) = out.iter().find(|m| m.joint == name) {
            return Err(err(j, format!("joint \"{name}\" has a second <{BLOCK}> entry (first at line {})", prev.line)));
        }
        let num = |attr: &str, positive: bool| -> Result<Option<f64>> {
            let Some(v) = j.attribute(attr) else { return Ok(None) };
            let x = v.trim().parse::<f64>().ok().filter(|x| x.is_finite());
            match x {
                Some(x) if (positive && x > 0.0) || (!positive && x >= 0.0) => Ok(Some(x)),
                _ => Err(err(
                    j,
                    format!(
                        "joint \"{name}\" {attr}=\"{v}\" must be a finite {} number",
                        if positive { "positive" } else { "non-negative" }
                    ),
                )),
            }
        };
        for a in j.attributes() {
            if !["name", "delay_secs", "kp", "kd", "stall_torque", "no_load_speed"].contains(&a.name()) {
                return Err(err(
                    j,
                    format!(
                        "joint \"{name}\": unknown attribute {}=\"…\" (known: delay_secs, kp, kd, stall_torque, \
                         no_load_speed; armature belongs in <twin_sysid>)",
                        a.name()
                    ),
                ));
            }
        }
        let m = DriveModel {
            joint: name.to_string(),
            delay_secs: num("delay_secs", false)?.unwrap_or(0.0),
            kp: num("kp", false)?,
            kd: num("kd", false)?,
            stall_torque: num("stall_torque", true)?,
            no_load_speed: num("no_load_speed", true)?,
            line: doc.text_pos_at(j.range().start).row,
        };
        if m.stall_torque.is_some() != m.no_load_speed.is_some() {
            return Err(err(
                j,
                format!("joint \"{name}\": give both stall_torque and no_load_speed (the envelope needs the two)"),
            ));
        }
        out.push(m);
    }
    Ok(out)
}

/// The block's text for `models` (indented two spaces, ending in a newline), with `comment`
/// (e.g. how the values were found) above it. Absent terms are left out.
pub fn block_text(models: &[DriveModel], comment: &str) -> String {
    let mut s = String::new();
    let comment = comment.replace("--", "- -");
    let _ = writeln!(s, "  <!-- twin actuator: {comment} -->");
    let _ = writeln!(s, "  <{BLOCK} version=\"1\">");
    for m in models {
        let _ = write!(s, "    <joint name=\"{}\"", m.joint);
        if m.delay_secs > 0.0 {
            let _ = write!(s, " delay_secs=\"{}\"", g7(m.delay_secs));
        }
        for (attr, v) in
            [("kp", m.kp), ("kd", m.kd), ("stall_torque", m.stall_torque), ("no_load_speed", m.no_load_speed)]
        {
            if let Some(v) = v {
                let _ = write!(s, " {attr}=\"{}\"", g7(v));
            }
        }
        let _ = writeln!(s, "/>");
    }
    let _ = writeln!(s, "  </{BLOCK}>");
    s
}

/// 7 significant digits, as the write-backs write URDF numbers.
fn g7(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let s = format!("{x:.6e}");
    let v: f64 = s.parse().unwrap_or(x);
    format!("{v}")
}

/// The MJCF attributes of a delay of `delay_secs` at a `timestep_secs` step: the delay, a
/// history buffer long enough for it (MuJoCo reads a buffer too short at its oldest sample: a
/// shorter delay), linear interpolation between samples; empty for none.
pub fn delay_attrs(delay_secs: f64, timestep_secs: f64, buffer_secs: f64) -> String {
    let span = delay_secs.max(buffer_secs);
    if span <= 0.0 {
        return String::new();
    }
    let nsample = (span / timestep_secs - 1e-9).ceil() as usize + 2;
    let delay = if delay_secs > 0.0 { format!(" delay=\"{}\"", g7(delay_secs)) } else { String::new() };
    format!("{delay} nsample=\"{nsample}\" interp=\"linear\"")
}

/// Nominal voltage of the `dcmotor`s the envelope becomes: the envelope depends on the stall
/// torque and no-load speed only (`K = V/ω₀`, `R = K·V/τ_s`), so any voltage gives the same drive.
const NOMINAL_VOLTS: f64 = 1.0;

impl crate::Converter<'_> {
    /// Every `joint_drive` entry names a joint with an actuator; an entry on a passive joint or
    /// with gains its interface does not use is noted.
    pub(crate) fn check_drives(&mut self) -> Result<()> {
        for (name, m) in &self.opts.joint_drive {
            let Some(meta) = self.joint_meta.iter().find(|j| &j.name == name) else {
                return Err(Error::Urdf {
                    path: self.robot.path.clone(),
                    line: m.line,
                    element: "joint".into(),
                    name: Some(name.clone()),
                    message: format!(
                        "<{BLOCK}> names joint \"{name}\", which the URDF does not have: fix the name or remove the entry"
                    ),
                });
            };
            match &meta.actuator {
                None => self.notes.push(format!(
                    "joint \"{name}\": its drive model ({}) is not applied: the joint has no actuator",
                    m.describe()
                )),
                Some((_, crate::Interface::Effort)) if m.kp.is_some() || m.kd.is_some() => self.notes.push(format!(
                    "joint \"{name}\": kp/kd of its drive model are not used: its command interface is effort"
                )),
                Some((_, crate::Interface::Velocity)) if m.envelope().is_some() || m.kp.is_some() => {
                    self.notes.push(format!(
                        "joint \"{name}\": only delay_secs and kd of its drive model apply to its velocity interface"
                    ))
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The `dcmotor` of joint `joint` (actuator `name`, command interface `iface`) with the
    /// torque–speed envelope `(stall_torque, no_load_speed)` of drive model `m`; `extra` holds
    /// gear and delay attributes, `effort` the URDF limit (the continuous clip).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn dcmotor_xml(
        &self,
        name: &str,
        joint: &str,
        iface: crate::Interface,
        m: &DriveModel,
        (stall_torque, no_load_speed): (f64, f64),
        meta: &crate::JointMeta,
        extra: &str,
        effort: Option<f64>,
    ) -> String {
        let g = meta.gear.abs();
        let f = |x: f64| g7(x);
        // Actuator space: force = τ/g, length rate = g·q̇.
        let nominal = format!("{} {} {}", f(NOMINAL_VOLTS), f(stall_torque / g), f(no_load_speed * g));
        let saturation = effort.map(|e| format!(" saturation=\"{} 0 0\"", f(e / g))).unwrap_or_default();
        let (input, controller, range) = match iface {
            crate::Interface::Position => {
                let kp = effort.map_or(100.0, |e| self.opts.position_kp_per_effort * e);
                let kv = kp * self.opts.position_kv_per_kp;
                let kp = m.kp.map_or(kp, |k| k / (g * g));
                let kv = m.kd.map_or(kv, |k| k / (g * g));
                let range = meta.range.map(|r| [r[0] * meta.gear, r[1] * meta.gear]);
                ("pos", format!("{} 0 {} 0 0 {}", f(kp), f(kv), f(NOMINAL_VOLTS)), range)
            }
            _ => ("ff", format!("0 0 0 0 0 {}", f(NOMINAL_VOLTS)), effort.map(|e| [-e / g, e / g])),
        };
        let range = range.map(|r| format!(" ctrlrange=\"{} {}\"", f(r[0]), f(r[1]))).unwrap_or_default();
        format!(
            "<dcmotor name=\"{}\" joint=\"{}\"{extra} input=\"{input}\" nominal=\"{nominal}\" controller=\"{controller}\"{saturation}{range}/>",
            crate::esc(name),
            crate::esc(joint),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(block: &str) -> Result<Vec<DriveModel>> {
        let text = format!("<robot name=\"r\">\n  <link name=\"a\"/>\n{block}\n</robot>\n");
        let doc = Document::parse(&text).unwrap();
        read_block(Path::new("r.urdf"), &doc)
    }

    #[test]
    fn block_round_trips_and_bad_entries_name_their_line() {
        let m = DriveModel {
            joint: "j1".into(),
            delay_secs: 0.005,
            kp: Some(120.0),
            kd: Some(4.5),
            stall_torque: Some(60.0),
            no_load_speed: Some(8.0),
            line: 0,
        };
        let got = parse(&block_text(std::slice::from_ref(&m), "by hand")).unwrap();
        assert_eq!(got.len(), 1);
        assert_eq!(DriveModel { line: 0, ..got[0].clone() }, m);
        assert_eq!(m.envelope_torque(4.0), Some(30.0));
        assert_eq!(m.describe(), "delay 5.0 ms, DC motor stall 60 no-load 8 rad/s, kp 120, kd 4.5");
        let e = parse("<twin_actuator>\n<joint name=\"j\" delay_secs=\"-1\"/></twin_actuator>").unwrap_err();
        assert!(e.to_string().contains("r.urdf:4") && e.to_string().contains("delay_secs=\"-1\""), "{e}");
        let e = parse("<twin_actuator><joint name=\"j\" stall_torque=\"3\"/></twin_actuator>").unwrap_err();
        assert!(e.to_string().contains("both stall_torque and no_load_speed"), "{e}");
        let e = parse("<twin_actuator><joint name=\"j\" armature=\"3\"/></twin_actuator>").unwrap_err();
        assert!(e.to_string().contains("armature belongs in <twin_sysid>"), "{e}");
        assert_eq!(delay_attrs(0.005, 0.002, 0.0), " delay=\"0.005\" nsample=\"5\" interp=\"linear\"");
        assert_eq!(delay_attrs(0.0, 0.002, 0.015), " nsample=\"10\" interp=\"linear\"");
        assert_eq!(delay_attrs(0.0, 0.002, 0.0), "");
    }
}
