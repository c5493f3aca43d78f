//! The friction and sensor model beyond what URDF `<dynamics>` holds: the `<twin_sysid>` block.
//!
//! URDF `<dynamics damping friction>` holds a viscous and a Coulomb coefficient. Real joints
//! need more: a torque sensor's offset, a smooth (sigmoid) Coulomb term whose switch is not at
//! zero velocity (asymmetric), armature. `twin sysid` writes the first two where URDF puts them
//! and the whole model in one top-level element of the URDF, which URDF readers (urdfdom,
//! Gazebo's) ignore as an unknown element:
//!
//! ```xml
//! <twin_sysid version="1">
//!   <joint name="panda_joint1" offset="0.12" viscous="0.05" coulomb="0.31" smoothing="0.05"
//!          velocity_shift="0" asymmetry="-0.02" armature="0.01"/>
//! </twin_sysid>
//! ```
//!
//! Each joint's friction torque (N·m or N), the torque the joint's sensor reads beyond the
//! rigid-body torque, is
//!
//! ```text
//! τ_f = offset + viscous·q̇ + coulomb·s(q̇ + velocity_shift) + asymmetry·sech²(q̇/smoothing) + armature·q̈
//! ```
//!
//! with `s(v) = tanh(v/smoothing)`, or `sign(v)` when `smoothing` is absent or 0. `twin sysid`
//! fits `asymmetry` (linear in the data) and leaves `velocity_shift` at 0; a published model
//! with a shifted sigmoid (Gaz et al. 2019: `A/(1+e^{−α(q̇+φ)}) − A/(1+e^{−αφ})` is
//! `A/2·tanh((q̇+φ)/(2/α))` plus a constant) is written with `velocity_shift` instead.
//! `twin sysid --compare OTHER.urdf` evaluates a model with this block exactly; `twin convert`
//! and `twin sim` take the block's `armature` (MuJoCo's joint `armature`) and leave the
//! rest (offset, sigmoid, asymmetry: no MuJoCo joint property holds them) to the report.

use crate::error::{Error, Result};
use std::fmt::Write as _;
use std::path::Path;

/// Name of the block's element.
pub const BLOCK: &str = "twin_sysid";

/// One joint's friction and sensor model (see the module docs for the formula).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JointFriction {
    /// URDF joint name.
    pub name: String,
    /// Constant torque (sensor offset), N·m or N.
    pub offset: f64,
    /// Viscous coefficient, N·m·s/rad or N·s/m.
    pub viscous: f64,
    /// Coulomb level, N·m or N.
    pub coulomb: f64,
    /// Velocity scale of the smooth Coulomb term (`None`: `sign`), rad/s or m/s.
    pub smoothing: Option<f64>,
    /// Velocity at which the Coulomb term switches, negated (rad/s or m/s).
    pub velocity_shift: f64,
    /// Coefficient of `sech²(q̇/smoothing)`, N·m or N.
    pub asymmetry: f64,
    /// Armature (reflected rotor inertia), kg·m² or kg.
    pub armature: f64,
}

impl JointFriction {
    /// A joint with URDF `<dynamics damping friction>` only.
    pub fn from_dynamics(name: &str, damping: f64, friction: f64, armature: f64) -> JointFriction {
        JointFriction {
            name: name.to_string(),
            offset: 0.0,
            viscous: damping,
            coulomb: friction,
            smoothing: None,
            velocity_shift: 0.0,
            asymmetry: 0.0,
            armature,
        }
    }

    /// The friction torque at velocity `qd` and acceleration `qdd`.
    pub fn torque(&self, qd: f64, qdd: f64) -> f64 {
        let v = qd + self.velocity_shift;
        let (s, bump) = match self.smoothing {
            Some(eps) if eps > 0.0 => ((v / eps).tanh(), 1.0 / (qd / eps).cosh().powi(2)),
            _ => (
                if v > 0.0 {
                    1.0
                } else if v < 0.0 {
                    -1.0
                } else {
                    0.0
                },
                0.0,
            ),
        };
        self.offset + self.viscous * qd + self.coulomb * s + self.asymmetry * bump + self.armature * qdd
    }
}

/// The `<twin_sysid>` joints of URDF `text` (of `path`), empty when there is no block.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML, a block of another version, a joint entry without a name
/// or with a value that is not a finite number (naming the line).
pub fn read_block(path: &Path, text: &str) -> Result<Vec<JointFriction>> {
    let err = |message: String| Error::Urdf { path: path.to_path_buf(), message };
    let doc = roxmltree::Document::parse(text).map_err(|e| err(e.to_string()))?;
    let Some(block) = doc.root_element().children().find(|n| n.has_tag_name(BLOCK)) else {
        return Ok(Vec::new());
    };
    let line = |n: roxmltree::Node<'_, '_>| doc.text_pos_at(n.range().start).row;
    if let Some(v) = block.attribute("version")
        && v != "1"
    {
        return Err(err(format!("line {}: <{BLOCK} version=\"{v}\"> is not version 1", line(block))));
    }
    let mut out = Vec::new();
    for j in block.children().filter(|n| n.is_element()) {
        if !j.has_tag_name("joint") {
            return Err(err(format!(
                "line {}: <{}> inside <{BLOCK}>: only <joint name=… offset=… viscous=… coulomb=… smoothing=… \
                 velocity_shift=… asymmetry=… armature=…/> entries belong there",
                line(j),
                j.tag_name().name()
            )));
        }
        let name = j
            .attribute("name")
            .ok_or_else(|| err(format!("line {}: <joint> inside <{BLOCK}> without name", line(j))))?;
        let num = |attr: &str| -> Result<f64> {
            match j.attribute(attr) {
                None => Ok(0.0),
                Some(v) => v.trim().parse::<f64>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                    err(format!("line {}: joint \"{name}\" {attr}=\"{v}\" is not a finite number", line(j)))
                }),
            }
        };
        let smoothing = num("smoothing")?;
        out.push(JointFriction {
            name: name.to_string(),
            offset: num("offset")?,
            viscous: num("viscous")?,
            coulomb: num("coulomb")?,
            smoothing: (smoothing > 0.0).then_some(smoothing),
            velocity_shift: num("velocity_shift")?,
            asymmetry: num("asymmetry")?,
            armature: num("armature")?,
        });
    }
    Ok(out)
}

/// The block's text for `joints` (indented two spaces, ending in a newline), with `comment`
/// (e.g. how the values were chosen) above it.
pub fn block_text(joints: &[JointFriction], comment: &str) -> String {
    let mut s = String::new();
    let comment = comment.replace("--", "- -");
    let _ = writeln!(
        s,
        "  <!-- twin sysid: tau_f = offset + viscous*qd + coulomb*tanh((qd + velocity_shift)/smoothing) + \
         asymmetry*sech^2(qd/smoothing) + armature*qdd (sign() without smoothing). {comment} -->"
    );
    let _ = writeln!(s, "  <{BLOCK} version=\"1\">");
    for j in joints {
        let _ = writeln!(
            s,
            "    <joint name=\"{}\" offset=\"{}\" viscous=\"{}\" coulomb=\"{}\" smoothing=\"{}\" velocity_shift=\"{}\" \
             asymmetry=\"{}\" armature=\"{}\"/>",
            j.name,
            g7(j.offset),
            g7(j.viscous),
            g7(j.coulomb),
            g7(j.smoothing.unwrap_or(0.0)),
            g7(j.velocity_shift),
            g7(j.asymmetry),
            g7(j.armature)
        );
    }
    let _ = writeln!(s, "  </{BLOCK}>");
    s
}

/// 7 significant digits, as the write-back writes URDF numbers.
fn g7(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let s = format!("{x:.6e}");
    let v: f64 = s.parse().unwrap_or(x);
    format!("{v}")
}

/// `text` (a URDF of `path`) with its `<twin_sysid>` block (and the comment right before it)
/// replaced by `block`, or `block` inserted before `</robot>` when it has none.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML.
pub fn splice_block(path: &Path, text: &str, block: &str) -> Result<String> {
    splice_element(path, text, BLOCK, "twin sysid", block)
}

/// `text` (a URDF of `path`) with its top-level `<element>` (and the comment right before it
/// that contains `marker`) replaced by `block`, or `block` inserted before `</robot>` when it
/// has none: the one way twin's blocks (`<twin_sysid>`, `<twin_actuator>`) are written back,
/// every other byte kept.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML.
pub fn splice_element(path: &Path, text: &str, element: &str, marker: &str, block: &str) -> Result<String> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: e.to_string() })?;
    let root = doc.root_element();
    if let Some(old) = root.children().find(|n| n.has_tag_name(element)) {
        // From the start of the line of the comment before it (if any) to the end of its line.
        let mut start = old.range().start;
        let mut prev = old.prev_sibling();
        while let Some(p) = prev {
            if p.is_text() && p.text().is_some_and(|t| t.trim().is_empty()) {
                prev = p.prev_sibling();
                continue;
            }
            if p.is_comment() && p.text().is_some_and(|t| t.contains(marker)) {
                start = p.range().start;
            }
            break;
        }
        let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
        let start = if text[line_start..start].trim().is_empty() { line_start } else { start };
        let end = old.range().end;
        let end = text[end..].find('\n').map_or(end, |i| end + i + 1);
        return Ok(format!("{}{}{}", &text[..start], block, &text[end..]));
    }
    let close = root.range().end;
    let tag_start = text[..close].rfind("</").unwrap_or(close);
    let line_start = text[..tag_start].rfind('\n').map_or(0, |i| i + 1);
    let at = if text[line_start..tag_start].trim().is_empty() { line_start } else { tag_start };
    let sep = if at == line_start { "" } else { "\n" };
    Ok(format!("{}{sep}{}{}", &text[..at], block, &text[at..]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_round_trips_and_replaces_itself() {
        let urdf = "<robot name=\"r\">\n  <link name=\"a\"/>\n</robot>\n";
        let j = JointFriction {
            name: "j1".into(),
            offset: 0.125,
            viscous: 0.5,
            coulomb: 0.3,
            smoothing: Some(0.05),
            velocity_shift: 0.01,
            asymmetry: -0.02,
            armature: 0.1,
        };
        let path = Path::new("r.urdf");
        let once = splice_block(path, urdf, &block_text(std::slice::from_ref(&j), "first")).unwrap();
        assert_eq!(read_block(path, &once).unwrap(), vec![j.clone()]);
        assert!(once.starts_with("<robot name=\"r\">\n  <link name=\"a\"/>\n  <!--"), "{once}");
        let mut k = j.clone();
        k.offset = -1.0;
        let twice = splice_block(path, &once, &block_text(std::slice::from_ref(&k), "second")).unwrap();
        assert_eq!(read_block(path, &twice).unwrap(), vec![k]);
        assert_eq!(twice.matches("<twin_sysid").count(), 1);
        assert!(!twice.contains("first") && twice.contains("second"), "{twice}");
        assert!(twice.starts_with("<robot name=\"r\">\n  <link name=\"a\"/>\n  <!--"), "{twice}");
        // The Gaz et al. sigmoid: A/(1+e^{−α(v+φ)}) − A/(1+e^{−αφ}).
        let (a, alpha, phi) = (0.54615_f64, 5.1181_f64, 0.039533_f64);
        let gaz = JointFriction {
            name: "j".into(),
            offset: a / 2.0 - a / (1.0 + (-alpha * phi).exp()),
            viscous: 0.0,
            coulomb: a / 2.0,
            smoothing: Some(2.0 / alpha),
            velocity_shift: phi,
            asymmetry: 0.0,
            armature: 0.0,
        };
        for v in [-1.0, -0.1, 0.0, 0.03, 0.5] {
            let paper = a / (1.0 + (-alpha * (v + phi)).exp()) - a / (1.0 + (-alpha * phi).exp());
            assert!((gaz.torque(v, 0.0) - paper).abs() < 1e-12, "{v}");
        }
        let bad = urdf.replace("</robot>", "<twin_sysid><joint name=\"j\" offset=\"x\"/></twin_sysid></robot>");
        let e = read_block(path, &bad).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("offset=\"x\""), "{e}");
    }
}
