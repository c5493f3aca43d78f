//! URDF checks that MuJoCo reports poorly or not at all: every error names the file, the
//! element, its line and the link, and says what to do.
//!
//! ## Limitations
//! Only what is needed before handing a URDF to MuJoCo is checked here: well-formed XML, link
//! masses, inertia tensors, and that mesh files exist.

use crate::error::{Error, Result};
use roxmltree::{Document, Node};
use std::path::Path;

/// Whether `text` looks like a URDF document (root element `<robot>`).
pub fn is_urdf(text: &str) -> bool {
    // Cheap: skip the prolog and comments, look at the first element's name.
    let mut rest = text;
    loop {
        rest = rest.trim_start();
        if let Some(r) = rest.strip_prefix("<?") {
            rest = r.split_once("?>").map_or("", |(_, t)| t);
        } else if let Some(r) = rest.strip_prefix("<!--") {
            rest = r.split_once("-->").map_or("", |(_, t)| t);
        } else if let Some(r) = rest.strip_prefix("<!") {
            // A DOCTYPE with an internal subset `[ … ]` holds `>` of its own declarations: skip
            // to its `]>`, so such a file is still told a URDF (and refused by the parser the
            // same way in every command).
            let bracket = r.find('[');
            let close = r.find('>');
            rest = match (bracket, close) {
                (Some(b), Some(c)) if b < c => {
                    r[b..].split_once("]").map_or("", |(_, t)| t.split_once('>').map_or("", |(_, t)| t))
                }
                _ => r.split_once('>').map_or("", |(_, t)| t),
            };
        } else {
            return rest.starts_with("<robot") && rest[6..].starts_with(|c: char| c.is_whitespace() || c == '>');
        }
    }
}

/// Parses `text` as XML, with errors naming `path`, line and column.
pub(crate) fn parse<'a>(path: &Path, text: &'a str) -> Result<Document<'a>> {
    Document::parse(text).map_err(|e| {
        let pos = e.pos();
        let message = match e {
            roxmltree::Error::DtdDetected => "the file has a DOCTYPE declaration (DTD); twin does not read DTDs, \
                whose entities would change what the file means: expand the entities and remove the \
                <!DOCTYPE …> (e.g. run it through xacro or xmllint --noent)"
                .to_string(),
            e => e.to_string(),
        };
        Error::Xml { path: path.to_path_buf(), line: pos.row, column: pos.col, message }
    })
}

/// The `armature` of each joint in the URDF's `<twin_sysid>` block (written by `twin sysid`,
/// format in the sysid crate's `extension` module), by joint name; empty without a block.
/// MuJoCo's joint `armature` holds it; the block's other terms (offset, smooth and asymmetric
/// Coulomb) have no MuJoCo joint property and are not converted.
///
/// # Errors
/// A block entry whose `armature` is not a finite, non-negative number, naming its line.
pub(crate) fn sysid_armature(ctx: &crate::ir::Ctx<'_, '_>) -> Result<Vec<(String, f64)>> {
    let Some(block) = ctx.doc.root_element().children().find(|n| n.has_tag_name("twin_sysid")) else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    for j in block.children().filter(|n| n.has_tag_name("joint")) {
        let (Some(name), Some(value)) = (j.attribute("name"), j.attribute("armature")) else { continue };
        match value.trim().parse::<f64>() {
            Ok(a) if a.is_finite() && a >= 0.0 => out.push((name.to_string(), a)),
            _ => {
                return Err(ctx.err(
                    j,
                    format!("<twin_sysid> joint \"{name}\" armature=\"{value}\" must be a finite, non-negative number"),
                ));
            }
        }
    }
    Ok(out)
}

fn line_of(doc: &Document<'_>, node: Node<'_, '_>) -> u32 {
    doc.text_pos_at(node.range().start).row
}

/// Name of the enclosing `<link>` or `<joint>`.
fn owner_name(node: Node<'_, '_>) -> Option<String> {
    node.ancestors()
        .find(|n| n.has_tag_name("link") || n.has_tag_name("joint"))
        .and_then(|n| n.attribute("name"))
        .map(str::to_string)
}

/// Checks a URDF for errors MuJoCo would report without a line, or not at all.
///
/// # Errors
/// [`Error::Xml`] for malformed XML, [`Error::Urdf`] for a bad mass, a bad inertia or a missing
/// mesh file.
pub fn validate(path: &Path, text: &str) -> Result<()> {
    let doc = parse(path, text)?;
    let err = |node: Node<'_, '_>, message: String| Error::Urdf {
        path: path.to_path_buf(),
        line: line_of(&doc, node),
        element: node.tag_name().name().to_string(),
        name: owner_name(node),
        message,
    };
    let number = |node: Node<'_, '_>, attr: &str, default: Option<f64>| -> Result<f64> {
        match node.attribute(attr) {
            Some(v) => v
                .trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| err(node, format!("attribute {attr}=\"{v}\" is not a finite number"))),
            None => default.ok_or_else(|| err(node, format!("missing attribute {attr}"))),
        }
    };
    let (urdf_dir, search) = crate::mesh::search_paths(path, &[]);

    for link in doc.root_element().children().filter(|n| n.has_tag_name("link")) {
        if let Some(inertial) = link.children().find(|n| n.has_tag_name("inertial")) {
            if let Some(mass) = inertial.children().find(|n| n.has_tag_name("mass")) {
                let m = number(mass, "value", None)?;
                if m < 0.0 {
                    return Err(err(mass, format!("negative mass {m} kg; give the link's real mass in kg (> 0)")));
                }
            }
            if let Some(inertia) = inertial.children().find(|n| n.has_tag_name("inertia")) {
                let mut v = [0.0; 6];
                for (slot, attr) in v.iter_mut().zip(["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]) {
                    *slot = number(inertia, attr, Some(0.0))?;
                }
                check_inertia(v).map_err(|m| err(inertia, m))?;
            }
        }
        for mesh in link.descendants().filter(|n| n.has_tag_name("mesh")) {
            let Some(filename) = mesh.attribute("filename") else {
                return Err(err(mesh, "<mesh> without filename attribute".into()));
            };
            if let Err(message) = crate::mesh::resolve(filename, &urdf_dir, &search) {
                return Err(err(mesh, message));
            }
        }
    }
    Ok(())
}

/// Checks an inertia tensor `[ixx, ixy, ixz, iyy, iyz, izz]` (kg·m²): symmetric positive
/// definite and its principal moments satisfy the triangle inequality. The message says why not.
pub fn check_inertia(v: [f64; 6]) -> std::result::Result<(), String> {
    crate::inertia::check(&crate::inertia::tensor(v))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recognises_urdf_roots() {
        assert!(is_urdf("<?xml version=\"1.0\"?>\n<!-- c -->\n<robot name=\"r\">"));
        assert!(!is_urdf("<mujoco model=\"m\">"));
        assert!(!is_urdf("<robots>"));
    }

    #[test]
    fn inertia_checks() {
        assert!(check_inertia([1.0, 0.0, 0.0, 1.0, 0.0, 1.0]).is_ok());
        assert!(check_inertia([1.0, 0.0, 0.0, 1.0, 0.0, 3.0]).unwrap_err().contains("triangle"));
        assert!(check_inertia([1.0, 2.0, 0.0, 1.0, 0.0, 1.0]).unwrap_err().contains("positive definite"));
    }
}
