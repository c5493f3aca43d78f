//! Mesh files: `package://` resolution and conversion of what MuJoCo cannot read (ASCII STL,
//! Collada) into OBJ.

use nalgebra::{Matrix4, Vector3, Vector4};
use std::path::{Path, PathBuf};

/// Finds the folder of ROS package `pkg`: a folder named `pkg`, or one whose `package.xml`
/// says `<name>pkg</name>`, directly under one of `search` (or being one of them).
pub(crate) fn find_package(pkg: &str, search: &[PathBuf]) -> Option<PathBuf> {
    for dir in search {
        if dir.file_name().is_some_and(|n| n == pkg) && dir.is_dir() {
            return Some(dir.clone());
        }
        let direct = dir.join(pkg);
        if direct.is_dir() {
            return Some(direct);
        }
    }
    for dir in search {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        let mut entries: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
        entries.sort();
        for e in entries {
            let manifest = e.join("package.xml");
            if let Ok(text) = std::fs::read_to_string(&manifest)
                && let Some(name) =
                    text.split_once("<name>").and_then(|(_, r)| r.split_once("</name>")).map(|(n, _)| n.trim())
                && name == pkg
            {
                return Some(e);
            }
        }
    }
    None
}

/// Where `package://` URIs of the URDF at `urdf_path` are looked for: `package_paths` (the
/// user's), then `ROS_PACKAGE_PATH`, then the URDF's folder's ancestors (a vendored
/// description package keeps the URDF in `PKG/urdf/`), then its folder. Returns the URDF's
/// absolute folder (for relative mesh paths) and that search list. The one place that decides
/// how twin finds meshes.
pub fn search_paths(urdf_path: &Path, package_paths: &[PathBuf]) -> (PathBuf, Vec<PathBuf>) {
    let mut search = package_paths.to_vec();
    if let Some(env) = std::env::var_os("ROS_PACKAGE_PATH") {
        search.extend(std::env::split_paths(&env).filter(|p| !p.as_os_str().is_empty()));
    }
    let urdf_dir = urdf_path.parent().map(Path::to_path_buf).unwrap_or_default();
    let urdf_dir = if urdf_dir.as_os_str().is_empty() { PathBuf::from(".") } else { urdf_dir };
    let abs_dir = std::path::absolute(&urdf_dir).unwrap_or(urdf_dir);
    search.extend(abs_dir.ancestors().skip(1).take(4).map(Path::to_path_buf));
    search.push(abs_dir.clone());
    (abs_dir, search)
}

/// Resolves a URDF mesh `filename` to a file on disk. `search` lists package paths (user's,
/// then `ROS_PACKAGE_PATH`, then the URDF's ancestor folders).
pub fn resolve(filename: &str, urdf_dir: &Path, search: &[PathBuf]) -> std::result::Result<PathBuf, String> {
    if let Some(rest) = filename.strip_prefix("package://") {
        // `package:///pkg/...` is seen in the wild.
        let rest = rest.trim_start_matches('/');
        let (pkg, rel) = rest
            .split_once('/')
            .ok_or_else(|| format!("mesh URI \"{filename}\" has no path after the package name"))?;
        let root = find_package(pkg, search).ok_or_else(|| {
            format!(
                "package \"{pkg}\" of mesh \"{filename}\" not found (searched {}); pass \
                 --package-path DIR (the folder containing {pkg}/) or set ROS_PACKAGE_PATH",
                if search.is_empty() {
                    "nothing".to_string()
                } else {
                    search.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
                }
            )
        })?;
        let file = root.join(rel);
        return if file.is_file() {
            Ok(file)
        } else {
            Err(format!(
                "mesh file not found: \"{filename}\" (package {pkg} is {}, but it has no {rel})",
                root.display()
            ))
        };
    }
    if filename.starts_with("model://") {
        return Err(format!(
            "mesh \"{filename}\" uses a Gazebo model:// URI; give a package:// URI or a path relative to the URDF"
        ));
    }
    let plain = filename.strip_prefix("file://").unwrap_or(filename);
    let candidate = urdf_dir.join(plain);
    if candidate.is_file() {
        Ok(candidate)
    } else {
        Err(format!(
            "mesh file not found: \"{filename}\" (looked at {}); fix the path or copy the mesh there",
            candidate.display()
        ))
    }
}

/// What MuJoCo can do with a mesh file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum MeshKind {
    /// Binary STL or OBJ (or MuJoCo's MSH): MuJoCo reads it directly.
    Native,
    /// ASCII STL: converted to OBJ.
    AsciiStl,
    /// Collada: converted to OBJ.
    Collada,
}

pub(crate) fn classify(path: &Path) -> std::result::Result<MeshKind, String> {
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
    match ext.as_str() {
        "obj" | "msh" => Ok(MeshKind::Native),
        "dae" => Ok(MeshKind::Collada),
        "stl" => {
            let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
            Ok(if is_ascii_stl(&bytes) { MeshKind::AsciiStl } else { MeshKind::Native })
        }
        other => {
            Err(format!("mesh format .{other} is not supported ({}): use STL, OBJ or Collada (.dae)", path.display()))
        }
    }
}

/// ASCII STL starts with `solid`, but so do some binary files: trust the binary size formula
/// first.
fn is_ascii_stl(bytes: &[u8]) -> bool {
    if bytes.len() >= 84 {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if 84 + 50 * n == bytes.len() {
            return false;
        }
    }
    let head = &bytes[..bytes.len().min(512)];
    let text = String::from_utf8_lossy(head);
    text.trim_start().starts_with("solid")
}

/// Triangles as vertex triples, metres.
pub(crate) type Triangles = Vec<[Vector3<f64>; 3]>;

pub(crate) fn read_ascii_stl(path: &Path) -> std::result::Result<Triangles, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut verts = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        if it.next() == Some("vertex") {
            let v: Vec<f64> = it.filter_map(super::ir::parse_num).collect();
            if v.len() != 3 {
                return Err(format!("{}:{}: `vertex` needs three numbers", path.display(), i + 1));
            }
            verts.push(Vector3::new(v[0], v[1], v[2]));
        }
    }
    if verts.is_empty() || verts.len() % 3 != 0 {
        return Err(format!(
            "{}: ASCII STL with {} vertices (needs a positive multiple of 3)",
            path.display(),
            verts.len()
        ));
    }
    Ok(verts.chunks(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Reads the triangles of a Collada file: `<triangles>`, `<polylist>` and `<polygons>` of every
/// geometry instanced in the visual scene (with node transforms), scaled by `<unit meter>`.
/// Geometries not instanced anywhere are taken as they are.
pub(crate) fn read_collada(path: &Path) -> std::result::Result<Triangles, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let doc = roxmltree::Document::parse(&text)
        .map_err(|e| format!("{}:{}: not well-formed XML: {e}", path.display(), e.pos().row))?;
    let root = doc.root_element();
    let named = |n: roxmltree::Node<'_, '_>, tag: &str| n.tag_name().name() == tag;
    let unit = root
        .descendants()
        .find(|n| named(*n, "unit"))
        .and_then(|u| u.attribute("meter"))
        .and_then(super::ir::parse_num)
        .unwrap_or(1.0);
    let by_id = |id: &str| {
        let id = id.trim_start_matches('#');
        root.descendants().find(|n| n.attribute("id") == Some(id))
    };
    let floats = |n: roxmltree::Node<'_, '_>| -> Vec<f64> {
        n.text().unwrap_or("").split_whitespace().filter_map(|t| t.parse().ok()).collect()
    };
    let ints = |n: roxmltree::Node<'_, '_>| -> Vec<usize> {
        n.text().unwrap_or("").split_whitespace().filter_map(|t| t.parse().ok()).collect()
    };
    // Triangles of one <geometry>, in its own frame.
    let geometry_tris = |g: roxmltree::Node<'_, '_>| -> std::result::Result<Triangles, String> {
        let mut out = Vec::new();
        for prim in g.descendants().filter(|n| named(*n, "triangles") || named(*n, "polylist") || named(*n, "polygons"))
        {
            let inputs: Vec<_> = prim.children().filter(|n| named(*n, "input")).collect();
            let stride = inputs
                .iter()
                .filter_map(|i| i.attribute("offset").and_then(|o| o.parse::<usize>().ok()))
                .max()
                .unwrap_or(0)
                + 1;
            let Some(vin) = inputs.iter().find(|i| i.attribute("semantic") == Some("VERTEX")) else {
                continue;
            };
            let voff: usize = vin.attribute("offset").and_then(|o| o.parse().ok()).unwrap_or(0);
            // VERTEX → <vertices> → POSITION source → float_array.
            let vertices = vin
                .attribute("source")
                .and_then(by_id)
                .ok_or_else(|| format!("{}: VERTEX input names no <vertices>", path.display()))?;
            let pos_src = vertices
                .children()
                .find(|n| named(*n, "input") && n.attribute("semantic") == Some("POSITION"))
                .and_then(|i| i.attribute("source"))
                .and_then(by_id)
                .ok_or_else(|| format!("{}: <vertices> without POSITION source", path.display()))?;
            let arr = pos_src
                .descendants()
                .find(|n| named(*n, "float_array"))
                .ok_or_else(|| format!("{}: position source without <float_array>", path.display()))?;
            let pos = floats(arr);
            let stride_pos = pos_src
                .descendants()
                .find(|n| named(*n, "accessor"))
                .and_then(|a| a.attribute("stride"))
                .and_then(|s| s.parse::<usize>().ok())
                .unwrap_or(3);
            let vertex = |k: usize| -> std::result::Result<Vector3<f64>, String> {
                let b = k * stride_pos;
                if b + 2 >= pos.len() {
                    return Err(format!("{}: vertex index {k} out of range", path.display()));
                }
                Ok(Vector3::new(pos[b], pos[b + 1], pos[b + 2]))
            };
            let polys: Vec<Vec<usize>> = if named(prim, "triangles") {
                let p: Vec<usize> = prim.children().filter(|n| named(*n, "p")).flat_map(ints).collect();
                let idx: Vec<usize> = p.chunks(stride).filter_map(|c| c.get(voff).copied()).collect();
                idx.chunks(3).filter(|c| c.len() == 3).map(<[usize]>::to_vec).collect()
            } else if named(prim, "polylist") {
                let vcount = prim.children().find(|n| named(*n, "vcount")).map(ints).unwrap_or_default();
                let p = prim.children().find(|n| named(*n, "p")).map(ints).unwrap_or_default();
                let idx: Vec<usize> = p.chunks(stride).filter_map(|c| c.get(voff).copied()).collect();
                let mut out = Vec::new();
                let mut at = 0;
                for c in vcount {
                    if at + c > idx.len() {
                        return Err(format!("{}: <polylist> <vcount> exceeds <p>", path.display()));
                    }
                    out.push(idx[at..at + c].to_vec());
                    at += c;
                }
                out
            } else {
                prim.children()
                    .filter(|n| named(*n, "p"))
                    .map(|p| ints(p).chunks(stride).filter_map(|c| c.get(voff).copied()).collect())
                    .collect()
            };
            for poly in polys {
                // Fan triangulation of convex polygons.
                for k in 1..poly.len().saturating_sub(1) {
                    out.push([vertex(poly[0])?, vertex(poly[k])?, vertex(poly[k + 1])?]);
                }
            }
        }
        Ok(out)
    };

    let mut tris = Vec::new();
    let scene = root.descendants().find(|n| named(*n, "visual_scene"));
    let mut instanced = false;
    if let Some(scene) = scene {
        // Depth-first over nodes with accumulated transforms.
        let mut stack: Vec<(roxmltree::Node<'_, '_>, Matrix4<f64>)> =
            scene.children().filter(|n| named(*n, "node")).map(|n| (n, Matrix4::identity())).collect();
        while let Some((node, parent)) = stack.pop() {
            let mut m = parent;
            for t in node.children().filter(|n| n.is_element()) {
                let v = floats(t);
                match t.tag_name().name() {
                    "matrix" if v.len() == 16 => {
                        m *= Matrix4::from_row_slice(&v);
                    }
                    "translate" if v.len() == 3 => {
                        m *= Matrix4::new_translation(&Vector3::new(v[0], v[1], v[2]));
                    }
                    "rotate" if v.len() == 4 => {
                        let axis = Vector3::new(v[0], v[1], v[2]);
                        if axis.norm() > 0.0 {
                            m *= nalgebra::Rotation3::from_axis_angle(
                                &nalgebra::Unit::new_normalize(axis),
                                v[3].to_radians(),
                            )
                            .to_homogeneous();
                        }
                    }
                    "scale" if v.len() == 3 => {
                        m *= Matrix4::new_nonuniform_scaling(&Vector3::new(v[0], v[1], v[2]));
                    }
                    _ => {}
                }
            }
            for inst in node.children().filter(|n| named(*n, "instance_geometry")) {
                if let Some(g) = inst.attribute("url").and_then(by_id) {
                    instanced = true;
                    for t in geometry_tris(g)? {
                        tris.push(t.map(|v| (m * Vector4::new(v.x, v.y, v.z, 1.0)).xyz()));
                    }
                }
            }
            for inst in node.children().filter(|n| named(*n, "instance_node")) {
                if let Some(n) = inst.attribute("url").and_then(by_id) {
                    stack.push((n, m));
                }
            }
            for c in node.children().filter(|n| named(*n, "node")) {
                stack.push((c, m));
            }
        }
    }
    if !instanced {
        for g in root.descendants().filter(|n| named(*n, "geometry")) {
            tris.extend(geometry_tris(g)?);
        }
    }
    if tris.is_empty() {
        return Err(format!("{}: no triangles found (Collada <triangles>/<polylist>/<polygons>)", path.display()));
    }
    for t in &mut tris {
        for v in t.iter_mut() {
            *v *= unit;
        }
    }
    Ok(tris)
}

/// Wavefront OBJ text of `tris` (MuJoCo's STL reader caps meshes at 200 000 faces; OBJ has no
/// such cap).
pub(crate) fn obj(tris: &Triangles) -> Vec<u8> {
    use std::fmt::Write as _;
    let mut s = String::with_capacity(tris.len() * 100);
    s.push_str("# twin: converted mesh\n");
    for t in tris {
        for v in t {
            let _ = writeln!(s, "v {} {} {}", v.x as f32, v.y as f32, v.z as f32);
        }
    }
    for k in 0..tris.len() {
        let _ = writeln!(s, "f {} {} {}", 3 * k + 1, 3 * k + 2, 3 * k + 3);
    }
    s.into_bytes()
}

/// Binary STL bytes of `tris`.
#[cfg(test)]
pub(crate) fn binary_stl(tris: &Triangles) -> Vec<u8> {
    let mut out = Vec::with_capacity(84 + 50 * tris.len());
    let mut header = [0u8; 80];
    let tag = b"twin: converted mesh";
    header[..tag.len()].copy_from_slice(tag);
    out.extend_from_slice(&header);
    out.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        let n = (t[1] - t[0]).cross(&(t[2] - t[0]));
        let n = if n.norm() > 0.0 { n.normalize() } else { n };
        for v in std::iter::once(&n).chain(t.iter()) {
            for c in [v.x, v.y, v.z] {
                out.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

/// FNV-1a: stable across runs and platforms, for cache file names.
pub(crate) fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        h ^= u64::from(*b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_and_binary_stl_are_told_apart() {
        let tris = vec![[Vector3::zeros(), Vector3::x(), Vector3::y()]];
        let bin = binary_stl(&tris);
        assert!(!is_ascii_stl(&bin));
        assert!(is_ascii_stl(b"solid x\nfacet normal 0 0 1\n"));
        // A binary STL whose header starts with "solid" is still binary.
        let mut tricky = bin.clone();
        tricky[..5].copy_from_slice(b"solid");
        assert!(!is_ascii_stl(&tricky));
    }
}
