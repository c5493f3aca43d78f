//! Worlds composed with the robot: a Gazebo SDF world (`<sdf><world>`) or an MJCF file whose
//! `<asset>` and `<worldbody>` children are copied in.

use super::ir::{self, Ctx, Pose, child, child_text, children, parse_vec};
use super::{esc, f, fv, pose_attrs};
use crate::error::Result;
use crate::hfield::Heightfield;
use nalgebra::Matrix3;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The parts of a world that go into the robot's MJCF.
#[derive(Debug, Default)]
pub(crate) struct World {
    /// Lines for `<asset>`.
    pub assets: String,
    /// Lines for `<worldbody>`; geom priorities are `prio_tag(mu)` placeholders.
    pub worldbody: String,
    /// Friction coefficients used by the world's geoms.
    pub mus: Vec<f64>,
    pub timestep_secs: Option<f64>,
    pub gravity: Option<[f64; 3]>,
    pub notes: Vec<String>,
    /// The `<heightmap>`s, in world coordinates (the robot is seated on them).
    pub heightfields: Vec<Heightfield>,
}

pub(crate) fn prio_tag(mu: f64) -> String {
    format!("@PRIO{:016x}@", mu.to_bits())
}

pub(crate) fn load(path: &Path) -> Result<World> {
    let text = twin_fsio::read_to_string(path)?;
    let doc = crate::urdf::parse(path, &text)?;
    let ctx = Ctx { path, doc: &doc };
    let root = doc.root_element();
    match root.tag_name().name() {
        "sdf" => sdf(&ctx, root),
        "mujoco" => mjcf(path, &text, root),
        other => Err(ctx.err(
            root,
            format!("<{other}> is not a world: give a Gazebo SDF world (<sdf><world>) or an MJCF file (<mujoco>)"),
        )),
    }
}

fn mjcf(path: &Path, text: &str, root: roxmltree::Node<'_, '_>) -> Result<World> {
    let mut w = World::default();
    let dir = std::path::absolute(path.parent().unwrap_or(Path::new("."))).unwrap_or_default();
    let slice = |n: roxmltree::Node<'_, '_>| -> String {
        let mut s = text[n.range()].to_string();
        // Relative asset files resolve against the world file's folder.
        if let Some(file) = n.attribute("file")
            && !Path::new(file).is_absolute()
        {
            s = s.replacen(
                &format!("file=\"{file}\""),
                &format!("file=\"{}\"", esc(&dir.join(file).display().to_string())),
                1,
            );
        }
        s
    };
    for a in children(root, "asset") {
        for c in a.children().filter(|c| c.is_element()) {
            let _ = writeln!(w.assets, "    {}", slice(c));
        }
    }
    for b in children(root, "worldbody") {
        for c in b.children().filter(|c| c.is_element()) {
            let _ = writeln!(w.worldbody, "    {}", slice(c));
        }
    }
    for o in children(root, "option") {
        w.timestep_secs = o.attribute("timestep").and_then(ir::parse_num);
        w.gravity = o.attribute("gravity").and_then(parse_vec::<3>);
    }
    for other in root.children().filter(|c| {
        c.is_element()
            && !["asset", "worldbody", "option", "compiler", "visual", "statistic"].contains(&c.tag_name().name())
    }) {
        w.notes.push(format!(
            "world {}: <{}> not composed (only <asset>, <worldbody> and <option> are)",
            path.display(),
            other.tag_name().name()
        ));
    }
    Ok(w)
}

fn sdf_pose(ctx: &Ctx<'_, '_>, node: roxmltree::Node<'_, '_>) -> Result<Pose> {
    match child(node, "pose") {
        Some(p) => {
            let t = p.text().unwrap_or("").trim();
            if t.is_empty() {
                return Ok(Pose::IDENTITY);
            }
            let v = parse_vec::<6>(t)
                .ok_or_else(|| ctx.err(p, format!("<pose>{t}</pose> must be 6 numbers: x y z roll pitch yaw")))?;
            Ok(Pose::from_xyz_rpy([v[0], v[1], v[2]], [v[3], v[4], v[5]]))
        }
        None => Ok(Pose::IDENTITY),
    }
}

fn num_text(ctx: &Ctx<'_, '_>, node: roxmltree::Node<'_, '_>, tag: &str) -> Result<f64> {
    ctx.child_num(node, tag)?.ok_or_else(|| ctx.err(node, format!("missing <{tag}>")))
}

/// `type` and `size` attributes of an SDF `<geometry>`.
fn sdf_geometry(ctx: &Ctx<'_, '_>, geom: roxmltree::Node<'_, '_>, w: &mut World, name: &str) -> Result<Option<String>> {
    let g = child(geom, "geometry").ok_or_else(|| ctx.err(geom, "missing <geometry>"))?;
    let Some(shape) = g.children().find(|n| n.is_element()) else {
        return Err(ctx.err(g, "empty <geometry>"));
    };
    Ok(Some(match shape.tag_name().name() {
        "box" => {
            let t = child_text(shape, "size").unwrap_or("");
            let s = parse_vec::<3>(t).ok_or_else(|| ctx.err(shape, "<box><size> must be 3 numbers"))?;
            format!(" type=\"box\" size=\"{}\"", fv(&[s[0] / 2.0, s[1] / 2.0, s[2] / 2.0]))
        }
        "cylinder" => format!(
            " type=\"cylinder\" size=\"{} {}\"",
            f(num_text(ctx, shape, "radius")?),
            f(num_text(ctx, shape, "length")? / 2.0)
        ),
        "sphere" => format!(" type=\"sphere\" size=\"{}\"", f(num_text(ctx, shape, "radius")?)),
        "capsule" => format!(
            " type=\"capsule\" size=\"{} {}\"",
            f(num_text(ctx, shape, "radius")?),
            f(num_text(ctx, shape, "length")? / 2.0)
        ),
        "plane" => {
            let n = child_text(shape, "normal").and_then(parse_vec::<3>).unwrap_or([0.0, 0.0, 1.0]);
            if n != [0.0, 0.0, 1.0] {
                let rot =
                    nalgebra::UnitQuaternion::rotation_between(&nalgebra::Vector3::z(), &nalgebra::Vector3::from(n))
                        .unwrap_or_default();
                return Ok(Some(format!(" type=\"plane\" size=\"0 0 0.05\"{}", super::quat_attr(&rot))));
            }
            " type=\"plane\" size=\"0 0 0.05\"".to_string()
        }
        "mesh" => {
            let p = world_file(ctx, shape, child_text(shape, "uri").unwrap_or(""), "mesh", "a path")?;
            let p = std::path::absolute(&p).unwrap_or(p);
            let scale = child_text(shape, "scale").and_then(parse_vec::<3>).unwrap_or([1.0; 3]);
            let mname = format!("world_{name}");
            let _ = writeln!(
                w.assets,
                "    <mesh name=\"{}\" file=\"{}\" scale=\"{}\"/>",
                esc(&mname),
                esc(&p.display().to_string()),
                fv(&scale)
            );
            format!(" type=\"mesh\" mesh=\"{}\"", esc(&mname))
        }
        other => {
            w.notes.push(format!("{}:{}: SDF geometry <{other}> not converted", ctx.path.display(), ctx.line(shape)));
            return Ok(None);
        }
    }))
}

fn sdf_rgba(node: roxmltree::Node<'_, '_>) -> Option<[f64; 4]> {
    let m = child(node, "material")?;
    child_text(m, "diffuse")
        .or_else(|| child_text(m, "ambient"))
        .and_then(|t| parse_vec::<4>(t).or_else(|| parse_vec::<3>(t).map(|c| [c[0], c[1], c[2], 1.0])))
}

fn sdf(ctx: &Ctx<'_, '_>, root: roxmltree::Node<'_, '_>) -> Result<World> {
    let world = child(root, "world").ok_or_else(|| ctx.err(root, "<sdf> has no <world>: give a world file"))?;
    let mut w = World::default();
    if let Some(g) = child_text(world, "gravity") {
        w.gravity = Some(
            parse_vec::<3>(g)
                .ok_or_else(|| ctx.err(child(world, "gravity").unwrap_or(world), "<gravity> must be 3 numbers"))?,
        );
    }
    if let Some(p) = children(world, "physics").next() {
        w.timestep_secs = ctx.child_num(p, "max_step_size")?;
    }
    let mut body = String::new();
    for l in children(world, "light") {
        let name = l.attribute("name").unwrap_or("light");
        let pose = sdf_pose(ctx, l)?;
        let dir = child_text(l, "direction").and_then(parse_vec::<3>).unwrap_or([0.0, 0.0, -1.0]);
        let diffuse = child_text(l, "diffuse").and_then(parse_vec::<4>).unwrap_or([0.8, 0.8, 0.8, 1.0]);
        let directional = l.attribute("type") == Some("directional");
        let _ = writeln!(
            body,
            "    <light name=\"{}\" directional=\"{}\" pos=\"{}\" dir=\"{}\" diffuse=\"{}\"/>",
            esc(name),
            directional,
            fv(pose.xyz.as_slice()),
            fv(&dir),
            fv(&diffuse[..3])
        );
    }
    for inc in children(world, "include") {
        let uri = child_text(inc, "uri").unwrap_or("");
        match uri {
            "model://ground_plane" => {
                w.mus.push(1.0);
                let _ = writeln!(
                    body,
                    "    <geom name=\"ground_plane\" type=\"plane\" size=\"0 0 0.05\" rgba=\"0.8 0.8 0.8 1\" friction=\"1 0.005 0.0001\" priority=\"{}\"/>",
                    prio_tag(1.0)
                );
            }
            "model://sun" => {
                let _ = writeln!(
                    body,
                    "    <light name=\"sun\" directional=\"true\" pos=\"0 0 10\" dir=\"-0.5 0.1 -0.9\" diffuse=\"0.8 0.8 0.8\"/>"
                );
            }
            other => {
                return Err(ctx.err(
                    inc,
                    format!("<include> of \"{other}\" cannot be resolved: inline the model in the world file"),
                ));
            }
        }
    }
    for m in children(world, "model") {
        let mname = m.attribute("name").unwrap_or("model").to_string();
        let is_static = child_text(m, "static").is_some_and(|t| t == "true" || t == "1");
        let model_pose = sdf_pose(ctx, m)?;
        if children(m, "joint").next().is_some() {
            w.notes.push(format!(
                "world model \"{mname}\": SDF joints are not converted (links become independent bodies)"
            ));
        }
        let links: Vec<_> = children(m, "link").collect();
        for l in &links {
            let lname = l.attribute("name").unwrap_or("link");
            let full = if links.len() == 1 { mname.clone() } else { format!("{mname}_{lname}") };
            let world_from_link = model_pose.then(&sdf_pose(ctx, *l)?);
            let mut inner = String::new();
            let ind = if is_static { "    " } else { "      " };
            // Static models: geoms on the world body in world coordinates.
            let frame = |local: &Pose| {
                if is_static { world_from_link.then(local) } else { *local }
            };
            for (k, c) in children(*l, "collision").enumerate() {
                let cname = c.attribute("name").map_or_else(|| format!("collision{k}"), str::to_string);
                let gname = format!("{full}_{cname}");
                if let Some(hm) = heightmap_of(c) {
                    if !is_static {
                        return Err(ctx.err(
                            hm,
                            format!(
                                "a <heightmap> in the dynamic model \"{mname}\": make the model <static>true</static>"
                            ),
                        ));
                    }
                    heightmap(ctx, hm, &world_from_link.then(&sdf_pose(ctx, c)?), c, &gname, &mut w, &mut inner)?;
                    continue;
                }
                let Some(shape) = sdf_geometry(ctx, c, &mut w, &gname)? else {
                    continue;
                };
                let mu = ode_mu(c);
                w.mus.push(mu);
                let rgba = children(*l, "visual")
                    .find_map(sdf_rgba)
                    .map(|c| format!(" rgba=\"{}\"", fv(&c)))
                    .unwrap_or_default();
                let _ = writeln!(
                    inner,
                    "{ind}<geom name=\"{}\"{shape}{} friction=\"{} 0.005 0.0001\" priority=\"{}\"{rgba}/>",
                    esc(&gname),
                    pose_attrs(&frame(&sdf_pose(ctx, c)?)),
                    f(mu),
                    prio_tag(mu)
                );
            }
            for (k, v) in children(*l, "visual").enumerate() {
                let vname =
                    format!("{full}_{}", v.attribute("name").map_or_else(|| format!("visual{k}"), str::to_string));
                if let Some(hm) = heightmap_of(v) {
                    heightmap_notes(ctx, hm, &mut w);
                    // The collision's heightfield is drawn; a visual-only one has no ground to draw.
                    if !children(*l, "collision").any(|c| heightmap_of(c).is_some()) {
                        w.notes.push(format!(
                            "{}:{}: <heightmap> only in a <visual> not converted (give it a <collision> to walk on it)",
                            ctx.path.display(),
                            ctx.line(hm)
                        ));
                    }
                    continue;
                }
                let Some(shape) = sdf_geometry(ctx, v, &mut w, &vname)? else {
                    continue;
                };
                if shape.contains("plane") {
                    continue;
                }
                let rgba = sdf_rgba(v).map(|c| format!(" rgba=\"{}\"", fv(&c))).unwrap_or_default();
                let _ = writeln!(
                    inner,
                    "{ind}<geom name=\"{}\"{shape}{} contype=\"0\" conaffinity=\"0\" group=\"2\"{rgba}/>",
                    esc(&vname),
                    pose_attrs(&frame(&sdf_pose(ctx, v)?))
                );
            }
            if is_static {
                body.push_str(&inner);
                continue;
            }
            let inertial = match child(*l, "inertial") {
                Some(i) => {
                    let mass = ctx.child_num(i, "mass")?.unwrap_or(1.0);
                    if mass <= 0.0 {
                        return Err(ctx.err(
                            child(i, "mass").unwrap_or(i),
                            format!("mass {mass} kg must be > 0 for a dynamic model"),
                        ));
                    }
                    let mut v = [0.0; 6];
                    if let Some(t) = child(i, "inertia") {
                        for (slot, tag) in v.iter_mut().zip(["ixx", "ixy", "ixz", "iyy", "iyz", "izz"]) {
                            *slot = ctx.child_num(t, tag)?.unwrap_or(0.0);
                        }
                    } else {
                        v = [1.0, 0.0, 0.0, 1.0, 0.0, 1.0];
                    }
                    crate::urdf::check_inertia(v).map_err(|m| ctx.err(i, m))?;
                    let p = sdf_pose(ctx, i)?;
                    let r = p.rot.to_rotation_matrix();
                    let [ixx, ixy, ixz, iyy, iyz, izz] = v;
                    let t = Matrix3::new(ixx, ixy, ixz, ixy, iyy, iyz, ixz, iyz, izz);
                    let b = r.matrix() * t * r.matrix().transpose();
                    format!(
                        "      <inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{}\"/>\n",
                        fv(p.xyz.as_slice()),
                        f(mass),
                        fv(&[b[(0, 0)], b[(1, 1)], b[(2, 2)], b[(0, 1)], b[(0, 2)], b[(1, 2)]])
                    )
                }
                None => {
                    return Err(ctx.err(*l, "dynamic model link without <inertial>: add <inertial><mass> or make the model <static>true</static>"));
                }
            };
            let _ = writeln!(body, "    <body name=\"{}\"{}>", esc(&full), pose_attrs(&world_from_link));
            let _ = writeln!(body, "      <freejoint name=\"{}_free\"/>", esc(&full));
            body.push_str(&inertial);
            body.push_str(&inner);
            let _ = writeln!(body, "    </body>");
        }
    }
    w.worldbody = body;
    Ok(w)
}

/// The `<heightmap>` of a `<collision>` or `<visual>`'s `<geometry>`, if that is its shape.
fn heightmap_of<'a, 'input>(node: roxmltree::Node<'a, 'input>) -> Option<roxmltree::Node<'a, 'input>> {
    child(node, "geometry").and_then(|g| child(g, "heightmap"))
}

/// The file a `<uri>` names (`file://` or a plain path, relative to the world file); a `model://`
/// URI or a missing file is an error at `node` naming the `what` and asking for `wanted`.
fn world_file(
    ctx: &Ctx<'_, '_>,
    node: roxmltree::Node<'_, '_>,
    uri: &str,
    what: &str,
    wanted: &str,
) -> Result<PathBuf> {
    let file = uri.strip_prefix("file://").unwrap_or(uri);
    let p = ctx.path.parent().unwrap_or(Path::new(".")).join(file);
    if uri.starts_with("model://") || !p.is_file() {
        return Err(ctx.err(
            node,
            format!("{what} \"{uri}\" not found (looked at {}): give {wanted} relative to the world file", p.display()),
        ));
    }
    Ok(p)
}

/// A `<collision>`'s Coulomb friction, `<surface><friction><ode><mu>` (SDFormat's default 1).
fn ode_mu(collision: roxmltree::Node<'_, '_>) -> f64 {
    child(collision, "surface")
        .and_then(|s| child(s, "friction"))
        .and_then(|fr| child(fr, "ode"))
        .and_then(|o| child_text(o, "mu"))
        .and_then(ir::parse_num)
        .unwrap_or(1.0)
}

/// A `<heightmap>` (`<uri>` a grayscale PNG relative to the world file, `<size>` its extent and
/// height range, `<pos>` its centre in the collision's frame) as an `<hfield>` asset and an
/// `hfield` geom in world coordinates (Gazebo's surface: the image's top row at +y, black at
/// `pos` z, white `size` z above). Its `<texture>`, `<blend>` and other elements (how Gazebo
/// draws it) are notes.
fn heightmap(
    ctx: &Ctx<'_, '_>,
    hm: roxmltree::Node<'_, '_>,
    world_from_collision: &Pose,
    collision: roxmltree::Node<'_, '_>,
    gname: &str,
    w: &mut World,
    body: &mut String,
) -> Result<()> {
    let uri_node = child(hm, "uri").ok_or_else(|| ctx.err(hm, "<heightmap> without <uri>: name a grayscale PNG"))?;
    let p = world_file(ctx, uri_node, uri_node.text().unwrap_or("").trim(), "heightmap", "a PNG path")?;
    let vec3 = |tag: &str, default: [f64; 3]| -> Result<[f64; 3]> {
        match child(hm, tag) {
            Some(n) => {
                parse_vec::<3>(n.text().unwrap_or("")).ok_or_else(|| ctx.err(n, format!("<{tag}> must be 3 numbers")))
            }
            None => Ok(default),
        }
    };
    let size = vec3("size", [1.0, 1.0, 1.0])?;
    if size.iter().any(|v| v.is_nan() || *v <= 0.0) {
        return Err(ctx.err(
            child(hm, "size").unwrap_or(hm),
            "<size> must be 3 positive numbers: x y extent and height range, m",
        ));
    }
    let pos = vec3("pos", [0.0; 3])?;
    let (roll, pitch, yaw) = world_from_collision.rot.euler_angles();
    if roll.abs() > 1e-9 || pitch.abs() > 1e-9 {
        return Err(ctx.err(
            hm,
            "a tilted <heightmap> (roll or pitch in its poses): only a turn about z maps onto a MuJoCo heightfield",
        ));
    }
    let centre = world_from_collision.xyz + world_from_collision.rot * nalgebra::Vector3::from(pos);
    let h = Heightfield::from_png(&p, size, [centre.x, centre.y, centre.z], yaw).map_err(|m| ctx.err(uri_node, m))?;
    heightmap_notes(ctx, hm, w);
    let mu = ode_mu(collision);
    w.mus.push(mu);
    let asset = format!("world_{gname}");
    let _ = writeln!(w.assets, "    {}", h.hfield_element(&esc(&asset)));
    let _ = writeln!(
        body,
        "    <geom name=\"{}\" type=\"hfield\" hfield=\"{}\" {} friction=\"{} 0.005 0.0001\" priority=\"{}\" rgba=\"0.45 0.42 0.36 1\"/>",
        esc(gname),
        esc(&asset),
        h.placement(),
        f(mu),
        prio_tag(mu)
    );
    w.heightfields.push(h);
    Ok(())
}

/// Notes for a `<heightmap>`'s elements other than `<uri>`, `<size>` and `<pos>` (`<texture>`,
/// `<blend>`, `<sampling>`…: how Gazebo draws and samples it).
fn heightmap_notes(ctx: &Ctx<'_, '_>, hm: roxmltree::Node<'_, '_>, w: &mut World) {
    for other in hm.children().filter(|n| n.is_element() && !["uri", "size", "pos"].contains(&n.tag_name().name())) {
        w.notes.push(format!(
            "{}:{}: <heightmap><{}> not converted (how Gazebo draws the terrain; the surface is the PNG's pixels)",
            ctx.path.display(),
            ctx.line(other),
            other.tag_name().name()
        ));
    }
}
