//! URDF write-back: only the numbers of `<inertial>` (origin `xyz`, `mass`, `inertia`) of the
//! identified links and `<dynamics damping friction>` of the identified joints change; every
//! other byte (comments, `<gazebo>` blocks, ordering, whitespace) stays as it was. Numbers are
//! spliced at the byte ranges roxmltree reports; a missing attribute, `<origin>`, `<mass>`,
//! `<inertia>`, `<inertial>` or `<dynamics>` is inserted with minimal text.
//!
//! The inertia is written in the frame the file already uses (`<origin rpy>` of the inertial
//! is kept), the centre of mass in the link frame.

use crate::error::{Error, Result};
use crate::number::format_number;
use nalgebra::{Matrix3, Rotation3, Vector3};
use roxmltree::{Document, Node};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// New inertial values of one link.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkUpdate {
    /// `<link name>`.
    pub name: String,
    /// Mass, kg.
    pub mass_kg: f64,
    /// Centre of mass in the link frame, m.
    pub com_link: Vector3<f64>,
    /// Inertia about the centre of mass, link axes, kg·m².
    pub inertia_com: Matrix3<f64>,
}

/// New friction values of one joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointUpdate {
    /// `<joint name>`.
    pub name: String,
    /// `<dynamics damping>`, N·m·s/rad or N·s/m.
    pub damping: f64,
    /// `<dynamics friction>`, N·m or N.
    pub friction: f64,
}

/// Whether `old` (file text) already holds `new` to the precision written.
fn same_number(old: &str, new: f64) -> bool {
    old.trim()
        .parse::<f64>()
        .is_ok_and(|o| (o - new).abs() <= 5e-7 * o.abs().max(new.abs()) || (o == 0.0 && new.abs() < 1e-300))
}

struct Editor<'a> {
    path: &'a Path,
    text: &'a str,
    edits: Vec<(Range<usize>, String)>,
}

impl<'a> Editor<'a> {
    fn err(&self, message: String) -> Error {
        Error::Urdf { path: self.path.to_path_buf(), message }
    }

    /// Sets attribute `name` of `node` to `value` (`value_text` pre-formatted).
    fn set_attr(&mut self, node: Node<'_, '_>, name: &str, value: f64) {
        let text = format_number(value);
        match node.attribute_node(name) {
            Some(a) => {
                if !same_number(a.value(), value) {
                    self.edits.push((a.range_value(), text));
                }
            }
            None => {
                let at = node
                    .attributes()
                    .next_back()
                    .map(|a| a.range().end)
                    .unwrap_or_else(|| node.range().start + 1 + node.tag_name().name().len());
                self.edits.push((at..at, format!(" {name}=\"{text}\"")));
            }
        }
    }

    /// Whitespace before the first child element of `node` (its children's indentation).
    fn child_indent(&self, node: Node<'_, '_>) -> String {
        if let Some(first) = node.children().find(|c| c.is_element())
            && let Some(prev) = first.prev_sibling().filter(|p| p.is_text())
        {
            return self.text[prev.range()].to_string();
        }
        // No child element: one level deeper than the node itself.
        let start = node.range().start;
        let line_start = self.text[..start].rfind('\n').map_or(0, |i| i + 1);
        format!("\n{}  ", &self.text[line_start..start])
    }

    /// Inserts `xml` as the first child of `node` (an element with a closing tag or empty).
    fn insert_child(&mut self, node: Node<'_, '_>, xml: &str) -> Result<()> {
        let indent = self.child_indent(node);
        let r = node.range();
        let tag = &self.text[r.clone()];
        if tag.ends_with("/>") {
            // <x .../> becomes <x ...>CHILD</x>.
            let line_start = self.text[..r.start].rfind('\n').map_or(0, |i| i + 1);
            let own_indent = &self.text[line_start..r.start];
            let end = r.end - 2;
            self.edits.push((end..r.end, format!(">{indent}{xml}\n{own_indent}</{}>", node.tag_name().name())));
        } else {
            let close = tag.find('>').ok_or_else(|| self.err(format!("<{}> has no end", node.tag_name().name())))?;
            let at = r.start + close + 1;
            self.edits.push((at..at, format!("{indent}{xml}")));
        }
        Ok(())
    }

    /// Appends `xml` as the last child of `node`, indented like the others.
    fn append_child(&mut self, node: Node<'_, '_>, xml: &str) -> Result<()> {
        let indent = self.child_indent(node);
        let r = node.range();
        let tag = &self.text[r.clone()];
        if tag.ends_with("/>") {
            return self.insert_child(node, xml);
        }
        let last = node.children().rfind(|c| c.is_element());
        let at = last.map_or_else(|| r.start + tag.find('>').map_or(0, |i| i + 1), |l| l.range().end);
        self.edits.push((at..at, format!("{indent}{xml}")));
        Ok(())
    }

    /// Sets the text of element `node` (`<stddev>0.002</stddev>`) to `value`, unless it
    /// already holds it.
    fn set_text(&mut self, node: Node<'_, '_>, value: f64) {
        let text = format_number(value);
        match node.children().find(|c| c.is_text()) {
            Some(t) if node.children().count() == 1 => {
                if !same_number(t.text().unwrap_or(""), value) {
                    // Keep surrounding whitespace of the old text.
                    let old = &self.text[t.range()];
                    let lead = old.len() - old.trim_start().len();
                    let trail = old.len() - old.trim_end().len();
                    self.edits.push((t.range().start + lead..t.range().end - trail, text));
                }
            }
            _ => {
                let name = node.tag_name().name();
                self.edits.push((node.range(), format!("<{name}>{text}</{name}>")));
            }
        }
    }

    /// Sets child element `<tag>` of `node` to `value`, appending it when missing.
    fn set_child_text(&mut self, node: Node<'_, '_>, tag: &str, value: f64) -> Result<()> {
        match child(node, tag) {
            Some(c) => {
                self.set_text(c, value);
                Ok(())
            }
            None => self.append_child(node, &format!("<{tag}>{}</{tag}>", format_number(value))),
        }
    }

    fn apply(mut self) -> String {
        self.edits.sort_by_key(|(r, _)| std::cmp::Reverse((r.start, r.end)));
        let mut out = self.text.to_string();
        for (r, s) in self.edits {
            out.replace_range(r, &s);
        }
        out
    }
}

fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

fn parse_triplet(s: Option<&str>) -> [f64; 3] {
    let mut out = [0.0; 3];
    if let Some(s) = s {
        for (o, v) in out.iter_mut().zip(s.split_whitespace()) {
            *o = v.parse().unwrap_or(0.0);
        }
    }
    out
}

/// Returns `text` (the URDF at `path`) with the given links' inertials and joints' dynamics
/// rewritten; nothing else changes.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML or a link/joint the file does not have.
pub fn rewrite_urdf(path: &Path, text: &str, links: &[LinkUpdate], joints: &[JointUpdate]) -> Result<String> {
    let doc = Document::parse(text)
        .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: format!("not well-formed XML: {e}") })?;
    let robot = doc.root_element();
    let mut ed = Editor { path, text, edits: Vec::new() };
    let find =
        |tag: &str, name: &str| robot.children().find(|n| n.has_tag_name(tag) && n.attribute("name") == Some(name));
    for up in links {
        let link = find("link", &up.name).ok_or_else(|| ed.err(format!("no <link name=\"{}\"> to update", up.name)))?;
        let c = up.com_link;
        let Some(inertial) = child(link, "inertial") else {
            let i = up.inertia_com;
            let xml = format!(
                "<inertial><origin xyz=\"{} {} {}\"/><mass value=\"{}\"/><inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/></inertial>",
                format_number(c.x),
                format_number(c.y),
                format_number(c.z),
                format_number(up.mass_kg),
                format_number(i[(0, 0)]),
                format_number(i[(0, 1)]),
                format_number(i[(0, 2)]),
                format_number(i[(1, 1)]),
                format_number(i[(1, 2)]),
                format_number(i[(2, 2)])
            );
            ed.insert_child(link, &xml)?;
            continue;
        };
        let origin = child(inertial, "origin");
        let rpy = parse_triplet(origin.and_then(|o| o.attribute("rpy")));
        // URDF rpy: fixed-axis roll about x, pitch about y, yaw about z.
        let link_from_inertial = Rotation3::from_euler_angles(rpy[0], rpy[1], rpy[2]);
        let mut inertia = link_from_inertial.inverse().matrix() * up.inertia_com * link_from_inertial.matrix();
        // Rounding noise of the rotation is not a product of inertia.
        let tiny = 1e-9 * inertia.abs().max();
        inertia.apply(|v| {
            if v.abs() < tiny {
                *v = 0.0;
            }
        });
        match origin {
            Some(o) => {
                let old = parse_triplet(o.attribute("xyz"));
                let new = [c.x, c.y, c.z];
                let unchanged =
                    o.attribute("xyz").is_some() && old.iter().zip(new).all(|(a, b)| same_number(&a.to_string(), b));
                if !unchanged {
                    let v = format!("{} {} {}", format_number(c.x), format_number(c.y), format_number(c.z));
                    match o.attribute_node("xyz") {
                        Some(a) => ed.edits.push((a.range_value(), v)),
                        None => {
                            let at = o.range().start + "<origin".len();
                            ed.edits.push((at..at, format!(" xyz=\"{v}\"")));
                        }
                    }
                }
            }
            None => {
                let v =
                    format!("<origin xyz=\"{} {} {}\"/>", format_number(c.x), format_number(c.y), format_number(c.z));
                ed.insert_child(inertial, &v)?;
            }
        }
        match child(inertial, "mass") {
            Some(m) => ed.set_attr(m, "value", up.mass_kg),
            None => {
                let v = format!("<mass value=\"{}\"/>", format_number(up.mass_kg));
                ed.insert_child(inertial, &v)?;
            }
        }
        let entries = [
            ("ixx", inertia[(0, 0)]),
            ("ixy", inertia[(0, 1)]),
            ("ixz", inertia[(0, 2)]),
            ("iyy", inertia[(1, 1)]),
            ("iyz", inertia[(1, 2)]),
            ("izz", inertia[(2, 2)]),
        ];
        match child(inertial, "inertia") {
            Some(i) => {
                for (name, v) in entries {
                    ed.set_attr(i, name, v);
                }
            }
            None => {
                let attrs: Vec<String> =
                    entries.iter().map(|(n, v)| format!("{n}=\"{}\"", format_number(*v))).collect();
                ed.insert_child(inertial, &format!("<inertia {}/>", attrs.join(" ")))?;
            }
        }
    }
    for up in joints {
        let joint =
            find("joint", &up.name).ok_or_else(|| ed.err(format!("no <joint name=\"{}\"> to update", up.name)))?;
        match child(joint, "dynamics") {
            Some(d) => {
                ed.set_attr(d, "damping", up.damping);
                ed.set_attr(d, "friction", up.friction);
            }
            None => {
                let xml = format!(
                    "<dynamics damping=\"{}\" friction=\"{}\"/>",
                    format_number(up.damping),
                    format_number(up.friction)
                );
                ed.append_child(joint, &xml)?;
            }
        }
    }
    Ok(ed.apply())
}

/// Returns `text` (the URDF at `path`) with the Gazebo IMU sensors' `<noise>` of each update
/// rewritten: per axis of `<angular_velocity>` and `<linear_acceleration>`, `<stddev>` and,
/// when resolved, `<dynamic_bias_stddev>` and `<dynamic_bias_correlation_time>` (the bias
/// instability) and `<bias_random_walk>` (the random walk, a twin extension); a missing
/// `<noise type="gaussian">`, axis, or `<angular_velocity>`/`<linear_acceleration>` is inserted.
/// Everything else stays byte for byte.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML, a reference without an IMU sensor, or the old Gazebo
/// classic form (`<imu><noise><rate>`), which has no per-axis noise.
pub fn rewrite_imu_noise(path: &Path, text: &str, updates: &[crate::noise::ImuNoiseUpdate]) -> Result<String> {
    let doc = Document::parse(text)
        .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: format!("not well-formed XML: {e}") })?;
    let mut ed = Editor { path, text, edits: Vec::new() };
    for up in updates {
        let sensor = doc
            .root_element()
            .children()
            .filter(|g| g.has_tag_name("gazebo") && g.attribute("reference") == Some(up.reference.as_str()))
            .flat_map(|g| g.children())
            .find(|s| s.has_tag_name("sensor") && s.attribute("type") == Some("imu"))
            .ok_or_else(|| {
                ed.err(format!("no <gazebo reference=\"{}\"><sensor type=\"imu\"> to update", up.reference))
            })?;
        let Some(imu) = child(sensor, "imu") else {
            let mut xml = String::from("<imu>");
            for (tag, axes) in [("angular_velocity", &up.gyro), ("linear_acceleration", &up.accel)] {
                xml.push_str(&format!("<{tag}>"));
                for (a, n) in ["x", "y", "z"].iter().zip(axes.iter()) {
                    xml.push_str(&format!("<{a}>{}</{a}>", noise_xml(n)));
                }
                xml.push_str(&format!("</{tag}>"));
            }
            xml.push_str("</imu>");
            ed.append_child(sensor, &xml)?;
            continue;
        };
        if child(imu, "noise").is_some() {
            return Err(ed.err(format!(
                "the IMU sensor on \"{}\" uses Gazebo classic's <imu><noise><rate>/<accel> form; rewrite it as \
                 <imu><angular_velocity><x><noise>… (SDF 1.5+) to receive per-axis noise",
                up.reference
            )));
        }
        for (tag, axes) in [("angular_velocity", &up.gyro), ("linear_acceleration", &up.accel)] {
            let Some(group) = child(imu, tag) else {
                let mut xml = format!("<{tag}>");
                for (a, n) in ["x", "y", "z"].iter().zip(axes.iter()) {
                    xml.push_str(&format!("<{a}>{}</{a}>", noise_xml(n)));
                }
                xml.push_str(&format!("</{tag}>"));
                ed.append_child(imu, &xml)?;
                continue;
            };
            for (a, n) in ["x", "y", "z"].iter().zip(axes.iter()) {
                let Some(axis) = child(group, a) else {
                    ed.append_child(group, &format!("<{a}>{}</{a}>", noise_xml(n)))?;
                    continue;
                };
                let Some(noise) = child(axis, "noise") else {
                    ed.append_child(axis, &noise_xml(n))?;
                    continue;
                };
                ed.set_child_text(noise, "stddev", n.stddev)?;
                if let (Some(s), Some(t)) = (n.dynamic_bias_stddev, n.dynamic_bias_correlation_time) {
                    ed.set_child_text(noise, "dynamic_bias_stddev", s)?;
                    ed.set_child_text(noise, "dynamic_bias_correlation_time", t)?;
                }
                if let Some(k) = n.bias_random_walk {
                    ed.set_child_text(noise, "bias_random_walk", k)?;
                }
            }
        }
    }
    Ok(ed.apply())
}

fn noise_xml(n: &crate::noise::AxisNoiseUpdate) -> String {
    let mut xml = format!("<noise type=\"gaussian\"><mean>0</mean><stddev>{}</stddev>", format_number(n.stddev));
    if let (Some(s), Some(t)) = (n.dynamic_bias_stddev, n.dynamic_bias_correlation_time) {
        xml.push_str(&format!(
            "<dynamic_bias_stddev>{}</dynamic_bias_stddev><dynamic_bias_correlation_time>{}</dynamic_bias_correlation_time>",
            format_number(s),
            format_number(t)
        ));
    }
    if let Some(k) = n.bias_random_walk {
        xml.push_str(&format!("<bias_random_walk>{}</bias_random_walk>", format_number(k)));
    }
    xml.push_str("</noise>");
    xml
}

/// A unified diff of `old` → `new` for `path`.
pub fn unified_diff(path: &Path, old: &str, new: &str) -> String {
    let name = path.display().to_string();
    similar::TextDiff::from_lines(old, new).unified_diff().context_radius(2).header(&name, &name).to_string()
}

/// What [`update_urdf_file`] did.
#[derive(Debug, Clone)]
pub struct UpdateOutcome {
    /// Unified diff of the change (empty when nothing changed).
    pub diff: String,
    /// The backup of the original (`ROBOT.urdf.bak`, or `.bak.1`, `.bak.2`, … when older backups
    /// exist: an older original is never overwritten), `None` on a dry run.
    pub backup: Option<PathBuf>,
}

/// A planned URDF rewrite (see [`plan_urdf_update`]): stage `new` in a
/// [`twin_core::fsio::Transaction`] with `expect_unchanged(original)`.
#[derive(Debug, Clone)]
pub struct UrdfUpdate {
    /// The file's content as read.
    pub original: String,
    /// The rewritten content.
    pub new: String,
    /// Unified diff `original` → `new`.
    pub diff: String,
}

/// Reads the URDF at `path` and rewrites it in memory (see [`rewrite_urdf`]).
///
/// # Errors
/// [`Error::Io`], [`Error::Urdf`].
pub fn plan_urdf_update(path: &Path, links: &[LinkUpdate], joints: &[JointUpdate]) -> Result<UrdfUpdate> {
    let original = twin_core::fsio::read_to_string(path)?;
    let new = rewrite_urdf(path, &original, links, joints)?;
    let diff = unified_diff(path, &original, &new);
    Ok(UrdfUpdate { original, new, diff })
}

/// Rewrites the URDF at `path` (see [`rewrite_urdf`]) through [`twin_core::fsio`]: the original
/// is kept as a numbered backup, the new file is written atomically (symlinks, mode and hard
/// links kept), and the write is refused if another process changed the file meanwhile. With
/// `dry_run` nothing is written.
///
/// # Errors
/// [`Error::Io`], [`Error::Urdf`], twin-core's path errors.
pub fn update_urdf_file(
    path: &Path,
    links: &[LinkUpdate],
    joints: &[JointUpdate],
    dry_run: bool,
) -> Result<UpdateOutcome> {
    update_file_with(path, dry_run, |text| rewrite_urdf(path, text, links, joints))
}

/// Rewrites the file at `path` with `rewrite` (text in, text out) through [`twin_core::fsio`]:
/// the original is kept as a numbered backup, the new text written atomically (symlinks, mode
/// and hard links kept), refused if another process changed the file meanwhile; with `dry_run`
/// nothing is written. The one place URDF write-backs (inertias, friction, sensor noise) touch
/// the disk.
///
/// # Errors
/// [`Error::Io`]; twin-core's path errors; whatever `rewrite` returns (the file is then
/// untouched).
pub fn update_file_with(
    path: &Path,
    dry_run: bool,
    rewrite: impl FnOnce(&str) -> Result<String>,
) -> Result<UpdateOutcome> {
    let target = twin_core::fsio::check_output(path, &[])?;
    let original = twin_core::fsio::read_to_string(path)?;
    let new = rewrite(&original)?;
    let diff = unified_diff(path, &original, &new);
    if dry_run {
        return Ok(UpdateOutcome { diff, backup: None });
    }
    let mut tx = twin_core::fsio::Transaction::new();
    tx.stage(&target, new.as_bytes(), twin_core::fsio::Backup::Numbered)?;
    tx.expect_unchanged(original.as_bytes());
    let backup = tx.commit()?.pop().and_then(|w| w.backup);
    Ok(UpdateOutcome { diff, backup })
}

#[cfg(test)]
mod tests {
    use super::*;

    const URDF: &str = r#"<?xml version="1.0"?>
<!-- keep me -->
<robot name="r">
  <link name="base"/>
  <joint name="j1" type="revolute">
    <parent link="base"/>  <child link="l1"/>
    <axis xyz="0 0 1"/>
  </joint>
  <link name="l1">
    <inertial>
      <origin xyz="0 0 0.1" rpy="0 0 1.5707963267948966"/>
      <mass   value="1.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/>
    </inertial>
  </link>
  <gazebo reference="l1"><mu1>1</mu1></gazebo>
</robot>
"#;

    #[test]
    fn rewrites_only_numbers_and_inserts_missing_dynamics() {
        let path = Path::new("r.urdf");
        let up = LinkUpdate {
            name: "l1".into(),
            mass_kg: 1.25,
            com_link: Vector3::new(0.0, 0.01, 0.1),
            inertia_com: Matrix3::new(0.02, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.03),
        };
        let j = JointUpdate { name: "j1".into(), damping: 0.5, friction: 0.125 };
        let out = rewrite_urdf(path, URDF, &[up], &[j]).unwrap();
        // The inertia frame is rotated 90° about z: link-frame ixx 0.02 is the frame's iyy.
        assert!(out.contains(r#"<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.03"/>"#), "{out}");
        assert!(out.contains(r#"<origin xyz="0 0.01 0.1" rpy="0 0 1.5707963267948966"/>"#), "{out}");
        assert!(out.contains(r#"<mass   value="1.25"/>"#), "{out}");
        assert!(
            out.contains("    <axis xyz=\"0 0 1\"/>\n    <dynamics damping=\"0.5\" friction=\"0.125\"/>\n  </joint>"),
            "{out}"
        );
        let diff = unified_diff(path, URDF, &out);
        assert_eq!(diff.lines().filter(|l| l.starts_with('+') && !l.starts_with("+++")).count(), 3, "{diff}");
        // Untouched values keep their text exactly, even when written differently.
        let same = rewrite_urdf(
            path,
            URDF,
            &[LinkUpdate {
                name: "l1".into(),
                mass_kg: 1.0,
                com_link: Vector3::new(0.0, 0.0, 0.1),
                inertia_com: Matrix3::new(0.02, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.03),
            }],
            &[],
        )
        .unwrap();
        assert_eq!(same, URDF);
    }

    #[test]
    fn numbers_are_short_and_round_trip_to_seven_digits() {
        assert_eq!(format_number(0.1), "0.1");
        assert_eq!(format_number(1.0), "1");
        assert_eq!(format_number(-2.5e-9), "-2.5e-9");
        let x = 0.012345678912;
        let back: f64 = format_number(x).parse().unwrap();
        assert!((back - x).abs() < 1e-7 * x);
    }
}
