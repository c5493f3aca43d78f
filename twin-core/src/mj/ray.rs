//! Ray casting against the geoms of a simulation state, without OpenGL: MuJoCo's own
//! `mj_multiRay` ([`Data::multi_ray`]) and [`RayScene`], which casts bundles of rays from many
//! threads at once (depth cameras, LiDARs).
//!
//! [`RayScene`] tests each ray only against the geoms whose bounding sphere meets the cone of
//! its bundle, nearest first, with MuJoCo's exact per-geom intersections (`mju_rayGeom`,
//! `mj_rayMesh`, `mj_rayHfield`). It sees the geoms `mj_ray` sees for the same filter
//! (visible groups, alpha > 0, static bodies), minus any set of bodies; flexes, skins and SDF
//! geoms are not seen.

use super::model::raw_slice;
use super::{Data, Model, ffi, guarded};
use crate::error::{Error, Result};
use mujoco_sys as sys;
use std::ffi::c_int;

/// Which geoms rays see.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RayFilter {
    /// Geom groups 0–5 seen (groups above 5 count as 5). (default: 0, 1, 2: what MuJoCo's
    /// viewer shows; twin's converter puts URDF visuals in group 2 and collision geoms in 3)
    pub groups: [bool; 6],
    /// Whether geoms of bodies welded to the world (floor, table) are seen. (default: true)
    pub static_geoms: bool,
    /// Bodies whose geoms are not seen, e.g. the robot carrying the sensor. (default: none)
    pub exclude_bodies: Vec<usize>,
}

impl Default for RayFilter {
    fn default() -> Self {
        RayFilter { groups: [true, true, true, false, false, false], static_geoms: true, exclude_bodies: Vec::new() }
    }
}

impl RayFilter {
    /// Whether rays see geom `g` of `model` (the rules of MuJoCo's `mj_ray`, plus
    /// [`RayFilter::exclude_bodies`]).
    pub fn sees(&self, model: &Model, g: usize) -> bool {
        let body = model.geom_bodyid()[g] as usize;
        if self.exclude_bodies.contains(&body) {
            return false;
        }
        let mat = model.geom_matid()[g];
        let alpha = if mat >= 0 { model.mat_rgba()[mat as usize][3] } else { model.geom_rgba()[g][3] };
        if alpha == 0.0 {
            return false;
        }
        if !self.static_geoms && model.body_weldid()[body] == 0 {
            return false;
        }
        self.groups[model.geom_group()[g].clamp(0, 5) as usize]
    }

    /// The bodies of the kinematic subtree rooted at `body` (itself included), e.g. a whole
    /// robot from its root body, for [`RayFilter::exclude_bodies`].
    pub fn subtree(model: &Model, body: usize) -> Vec<usize> {
        let parent = model.body_parentid();
        (0..model.nbody())
            .filter(|&b| {
                let mut x = b;
                loop {
                    if x == body {
                        return true;
                    }
                    if x == 0 {
                        return false;
                    }
                    x = parent[x] as usize;
                }
            })
            .collect()
    }
}

/// Where a ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Distance along the (unit) ray direction, metres.
    pub dist_m: f64,
    /// The geom hit.
    pub geom: usize,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// A primitive `mju_rayGeom` handles (plane, sphere, capsule, ellipsoid, cylinder, box).
    Primitive(c_int),
    Mesh,
    Hfield,
}

/// One seen geom, posed at the state's instant.
#[derive(Debug, Clone, Copy)]
struct SceneGeom {
    id: usize,
    kind: Kind,
    pos: [f64; 3],
    mat: [f64; 9],
    size: [f64; 3],
    /// Bounding-sphere radius about `pos`; infinite for planes.
    rbound: f64,
}

/// The seen geoms of one simulation instant, for casting many rays, from many threads.
///
/// Borrowing the [`Data`] keeps the state unchanged while rays are cast.
pub struct RayScene<'a> {
    model: &'a Model,
    data: &'a Data,
    geoms: Vec<SceneGeom>,
}

// SAFETY: a RayScene reads its Data only through MuJoCo functions that take `const mjData*`
// (mj_rayMesh, mj_rayHfield) and its own copies; the shared borrow of the Data keeps every
// `&mut` method (and so any write) away while the scene lives, so concurrent reads are sound.
// The Model is Sync.
unsafe impl Sync for RayScene<'_> {}
// SAFETY: as above: moving the scene moves only shared borrows of state no one mutates.
unsafe impl Send for RayScene<'_> {}

impl std::fmt::Debug for RayScene<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RayScene").field("geoms", &self.geoms.len()).finish()
    }
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl<'a> RayScene<'a> {
    /// The geoms of `data`'s model that `filter` lets rays see, at `data`'s last forward pass
    /// (its `geom_xpos`/`geom_xmat`).
    pub fn new(data: &'a Data, filter: &RayFilter) -> RayScene<'a> {
        let model: &Model = data.model();
        let (types, sizes, rbound) = (model.geom_type(), model.geom_size(), model.geom_rbound());
        let (xpos, xmat) = (data.geom_xpos(), data.geom_xmat());
        let geoms = (0..model.ngeom())
            .filter(|&g| filter.sees(model, g))
            .filter_map(|g| {
                let ty = types[g] as u32;
                let kind = match ty {
                    sys::mjtGeom_mjGEOM_MESH => Kind::Mesh,
                    sys::mjtGeom_mjGEOM_HFIELD => Kind::Hfield,
                    sys::mjtGeom_mjGEOM_PLANE
                    | sys::mjtGeom_mjGEOM_SPHERE
                    | sys::mjtGeom_mjGEOM_CAPSULE
                    | sys::mjtGeom_mjGEOM_ELLIPSOID
                    | sys::mjtGeom_mjGEOM_CYLINDER
                    | sys::mjtGeom_mjGEOM_BOX => Kind::Primitive(ty as c_int),
                    _ => return None,
                };
                let r = if ty == sys::mjtGeom_mjGEOM_PLANE { f64::INFINITY } else { rbound[g] };
                Some(SceneGeom { id: g, kind, pos: xpos[g], mat: xmat[g], size: sizes[g], rbound: r })
            })
            .collect();
        RayScene { model, data, geoms }
    }

    /// Number of geoms rays can hit.
    pub fn len(&self) -> usize {
        self.geoms.len()
    }

    /// Whether rays can hit nothing.
    pub fn is_empty(&self) -> bool {
        self.geoms.is_empty()
    }

    /// Indices (into the scene) of the geoms whose bounding sphere meets the cone of apex
    /// `origin`, unit axis `axis` and half-angle `half_angle_rad` within `max_dist_m`, nearest
    /// first. Every ray inside the cone can only hit these.
    fn cull(&self, origin: [f64; 3], axis: [f64; 3], half_angle_rad: f64, max_dist_m: f64, out: &mut Vec<(f64, u32)>) {
        out.clear();
        let (sin_a, cos_a) = half_angle_rad.min(std::f64::consts::PI).sin_cos();
        for (k, g) in self.geoms.iter().enumerate() {
            if g.rbound.is_infinite() {
                out.push((0.0, k as u32));
                continue;
            }
            let v = sub(g.pos, origin);
            let d = dot(v, v).sqrt();
            if d <= g.rbound {
                out.push((0.0, k as u32));
                continue;
            }
            let near = d - g.rbound;
            if near > max_dist_m {
                continue;
            }
            // The sphere meets the cone when the angle between the axis and the centre is at
            // most the half-angle plus the sphere's angular radius asin(r/d):
            // cos(θ) ≥ cos(α + β) with β = asin(r / d).
            let (sin_b, cos_b) = (g.rbound / d, (1.0 - (g.rbound / d).powi(2)).max(0.0).sqrt());
            let cos_ab = if half_angle_rad + sin_b.asin() >= std::f64::consts::PI {
                -1.0
            } else {
                cos_a * cos_b - sin_a * sin_b
            };
            if dot(v, axis) >= d * cos_ab - 1e-12 {
                out.push((near, k as u32));
            }
        }
        out.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    }

    /// Distance along the unit direction `dir` from `origin` to geom `g`, if it is hit.
    fn hit(&self, g: &SceneGeom, origin: [f64; 3], dir: [f64; 3]) -> Option<f64> {
        if g.rbound.is_finite() {
            // Bounding sphere first: cheaper than MuJoCo's exact test.
            let v = sub(g.pos, origin);
            let t = dot(v, dir);
            let perp2 = dot(v, v) - t * t;
            if perp2 > g.rbound * g.rbound || t < -g.rbound {
                return None;
            }
        }
        let d = match g.kind {
            // SAFETY: pos, mat, size, origin and dir are arrays of the lengths mju_rayGeom reads
            // (3, 9, 3, 3, 3); the type is one of the primitives it handles, so it does not
            // raise; the normal is optional (null).
            Kind::Primitive(ty) => unsafe {
                sys::mju_rayGeom(
                    g.pos.as_ptr(),
                    g.mat.as_ptr(),
                    g.size.as_ptr(),
                    origin.as_ptr(),
                    dir.as_ptr(),
                    ty,
                    std::ptr::null_mut(),
                )
            },
            // SAFETY: the geom is a mesh of this live model; mj_rayMesh only reads the model and
            // the (borrowed, unmodified) data and raises only for non-mesh geoms.
            Kind::Mesh => unsafe {
                sys::mj_rayMesh(
                    self.model.as_ptr(),
                    self.data.raw(),
                    g.id as c_int,
                    origin.as_ptr(),
                    dir.as_ptr(),
                    std::ptr::null_mut(),
                )
            },
            // SAFETY: as for meshes, with a height field geom.
            Kind::Hfield => unsafe {
                sys::mj_rayHfield(
                    self.model.as_ptr(),
                    self.data.raw(),
                    g.id as c_int,
                    origin.as_ptr(),
                    dir.as_ptr(),
                    std::ptr::null_mut(),
                )
            },
        };
        (d >= 0.0).then_some(d)
    }

    /// The nearest hit of the ray from `origin` along the unit vector `dir` within
    /// `max_dist_m`.
    pub fn cast(&self, origin: [f64; 3], dir: [f64; 3], max_dist_m: f64) -> Option<RayHit> {
        let mut candidates = Vec::new();
        self.cull(origin, dir, 0.0, max_dist_m, &mut candidates);
        self.nearest(origin, dir, max_dist_m, &candidates)
    }

    fn nearest(&self, origin: [f64; 3], dir: [f64; 3], max_dist_m: f64, candidates: &[(f64, u32)]) -> Option<RayHit> {
        let mut best: Option<RayHit> = None;
        for &(near, k) in candidates {
            let limit = best.map_or(max_dist_m, |b| b.dist_m);
            if near > limit {
                break;
            }
            let g = &self.geoms[k as usize];
            if let Some(d) = self.hit(g, origin, dir)
                && d <= limit
                && best.is_none_or(|b| d < b.dist_m || (d == b.dist_m && g.id < b.geom))
            {
                best = Some(RayHit { dist_m: d, geom: g.id });
            }
        }
        best
    }

    /// Casts the rays from `origin` along the unit vectors `dirs`, writing each nearest hit
    /// within `max_dist_m` into `out` (same length). Consecutive rays are taken in bundles of
    /// `bundle` and culled together, so rays close in direction should be next to each other
    /// (an image tile, a stretch of a scan). Bundles run in parallel on the current rayon
    /// pool when `parallel`; the result does not depend on it.
    ///
    /// # Errors
    /// [`Error::Size`] when `out` and `dirs` differ in length.
    pub fn cast_bundles(
        &self,
        origin: [f64; 3],
        dirs: &[[f64; 3]],
        bundle: usize,
        max_dist_m: f64,
        parallel: bool,
        out: &mut [Option<RayHit>],
    ) -> Result<()> {
        if out.len() != dirs.len() {
            return Err(Error::Size { what: "ray output length", expected: dirs.len(), got: out.len() });
        }
        let bundle = bundle.max(1);
        let run = |(dirs, out): (&[[f64; 3]], &mut [Option<RayHit>]), candidates: &mut Vec<(f64, u32)>| {
            let (axis, half_angle) = bundle_cone(dirs);
            self.cull(origin, axis, half_angle, max_dist_m, candidates);
            for (d, o) in dirs.iter().zip(out.iter_mut()) {
                *o = self.nearest(origin, *d, max_dist_m, candidates);
            }
        };
        if parallel {
            use rayon::prelude::*;
            dirs.par_chunks(bundle).zip(out.par_chunks_mut(bundle)).for_each_init(Vec::new, |c, chunk| run(chunk, c));
        } else {
            let mut candidates = Vec::new();
            for chunk in dirs.chunks(bundle).zip(out.chunks_mut(bundle)) {
                run(chunk, &mut candidates);
            }
        }
        Ok(())
    }
}

/// The narrowest cone about the mean direction that holds every unit vector of `dirs`: its
/// unit axis and half-angle, radians (a little wider, for rounding).
fn bundle_cone(dirs: &[[f64; 3]]) -> ([f64; 3], f64) {
    let mut sum = [0.0; 3];
    for d in dirs {
        for i in 0..3 {
            sum[i] += d[i];
        }
    }
    let n = dot(sum, sum).sqrt();
    if n < 1e-9 {
        return ([0.0, 0.0, 1.0], std::f64::consts::PI);
    }
    let axis = sum.map(|x| x / n);
    let min_cos = dirs.iter().map(|d| dot(*d, axis)).fold(1.0f64, f64::min).clamp(-1.0, 1.0);
    (axis, min_cos.acos() + 1e-9)
}

impl Data {
    /// MuJoCo's `mj_multiRay`: the nearest geom along each of `dirs` (need not be unit
    /// vectors; distances are in multiples of them) from `origin`, or `None`. `groups`: the
    /// geom groups seen (`None`: all); `static_geoms`: whether geoms welded to the world are
    /// seen; `exclude_body`: one body whose geoms are not seen; geoms beyond `cutoff_m` are
    /// ignored. Needs a forward pass at the current state.
    ///
    /// # Errors
    /// [`Error::MuJoCo`] if MuJoCo raises (its stack is too small for the geom list).
    pub fn multi_ray(
        &mut self,
        origin: [f64; 3],
        dirs: &[[f64; 3]],
        groups: Option<[bool; 6]>,
        static_geoms: bool,
        exclude_body: Option<usize>,
        cutoff_m: f64,
    ) -> Result<Vec<Option<RayHit>>> {
        let n = dirs.len();
        let mut geom = vec![-1 as c_int; n];
        let mut dist = vec![-1.0f64; n];
        let group_bytes = groups.map(|g| g.map(u8::from));
        let group_ptr = group_bytes.as_ref().map_or(std::ptr::null(), |g| g.as_ptr());
        let exclude = exclude_body.map_or(-1, |b| b as c_int);
        let (m, d) = self.raw_parts();
        let (gp, dp) = (geom.as_mut_ptr(), dist.as_mut_ptr());
        // SAFETY: `dirs` holds n rows of 3 values, `geom` and `dist` n entries each, the group
        // array 6 bytes (or null); the pair is live and exclusive through &mut self.
        guarded("mj_multiRay", |e, len| unsafe {
            ffi::twin_multi_ray(
                m,
                d,
                origin.as_ptr(),
                dirs.as_ptr().cast(),
                group_ptr,
                u8::from(static_geoms),
                exclude,
                gp,
                dp,
                n as c_int,
                cutoff_m,
                e,
                len,
            )
        })?;
        Ok(geom
            .iter()
            .zip(&dist)
            .map(|(&g, &d)| (g >= 0 && d >= 0.0).then_some(RayHit { dist_m: d, geom: g as usize }))
            .collect())
    }
}

impl Model {
    /// Vertical field of view of each camera, radians (len `ncam`).
    pub fn cam_fovy_rad(&self) -> Vec<f64> {
        let m = self.raw();
        // SAFETY: cam_fovy has ncam entries (degrees); the model is immutable while borrowed.
        let fovy = unsafe { raw_slice(m.cam_fovy as *const f64, m.ncam as usize) };
        fovy.iter().map(|d| d.to_radians()).collect()
    }

    /// Resolution `[width, height]` of each camera, pixels (len `ncam`; MuJoCo's default 1×1
    /// when the model gives none).
    pub fn cam_resolution(&self) -> &[[i32; 2]] {
        let m = self.raw();
        // SAFETY: cam_resolution has ncam rows of 2 ints; the model is immutable while borrowed.
        unsafe { raw_slice(m.cam_resolution as *const [i32; 2], m.ncam as usize) }
    }
}

impl Data {
    /// Camera positions, world frame, metres (len `ncam`).
    pub fn cam_xpos(&self) -> &[[f64; 3]] {
        let n = self.model().raw().ncam as usize;
        // SAFETY: mj_makeData allocates cam_xpos with ncam rows of 3; read while self is
        // borrowed.
        unsafe { raw_slice(self.raw().cam_xpos as *const [f64; 3], n) }
    }

    /// Camera orientations as row-major 3×3 matrices, world frame (len `ncam`); MuJoCo cameras
    /// look along their −z axis with +y up.
    pub fn cam_xmat(&self) -> &[[f64; 9]] {
        let n = self.model().raw().ncam as usize;
        // SAFETY: as cam_xpos, 9 values per camera.
        unsafe { raw_slice(self.raw().cam_xmat as *const [f64; 9], n) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A scene of every primitive, a mesh and a floor, with some geoms of a body that is
    /// excluded and one invisible geom.
    const SCENE: &str = r#"<mujoco><asset><mesh name="tet" vertex="0 0 0 0.3 0 0 0 0.3 0 0 0 0.3"/></asset>
      <worldbody><geom type="plane" size="5 5 0.1"/>
        <geom type="box" pos="1 0 0.3" size="0.1 0.2 0.3" euler="0 0 20"/>
        <geom type="sphere" pos="1 0.8 0.4" size="0.15"/>
        <geom type="capsule" pos="1 -0.8 0.4" size="0.05 0.2" euler="30 0 0"/>
        <geom type="cylinder" pos="1.5 0.4 0.5" size="0.1 0.2"/>
        <geom type="ellipsoid" pos="1.5 -0.4 0.5" size="0.1 0.2 0.15"/>
        <geom type="mesh" mesh="tet" pos="0.8 0.3 0.6"/>
        <geom type="sphere" pos="0.6 0 0.5" size="0.05" rgba="1 1 1 0"/>
        <body name="robot" pos="0 0 0.5"><freejoint/><geom type="sphere" size="0.1"/></body>
      </worldbody></mujoco>"#;

    #[test]
    fn scene_matches_mj_multi_ray() {
        let model = Arc::new(Model::from_xml_str(SCENE).unwrap());
        let mut data = Data::new(model.clone()).unwrap();
        data.forward().unwrap();
        let robot = model.id(super::super::ObjType::Body, "robot").unwrap();
        let origin = [0.0, 0.0, 0.5];
        // A fan of unit rays over the scene, from inside the excluded body.
        let mut dirs = Vec::new();
        for i in 0..60 {
            for j in 0..40 {
                let yaw = -1.2 + 2.4 * i as f64 / 59.0;
                let pitch = -0.7 + 1.0 * j as f64 / 39.0;
                dirs.push([yaw.cos() * pitch.cos(), yaw.sin() * pitch.cos(), pitch.sin()]);
            }
        }
        let reference = data.multi_ray(origin, &dirs, None, true, Some(robot), 50.0).unwrap();
        let filter =
            RayFilter { groups: [true; 6], exclude_bodies: RayFilter::subtree(&model, robot), ..RayFilter::default() };
        let scene = RayScene::new(&data, &filter);
        let mut out = vec![None; dirs.len()];
        scene.cast_bundles(origin, &dirs, 16, 50.0, true, &mut out).unwrap();
        let mut hits = std::collections::BTreeSet::new();
        for (k, (a, b)) in reference.iter().zip(&out).enumerate() {
            match (a, b) {
                (Some(a), Some(b)) => {
                    assert!((a.dist_m - b.dist_m).abs() < 1e-9, "ray {k}: {a:?} vs {b:?}");
                    assert_eq!(a.geom, b.geom, "ray {k}");
                    hits.insert(b.geom);
                }
                (None, None) => {}
                _ => panic!("ray {k}: mj_multiRay {a:?}, RayScene {b:?}"),
            }
        }
        // Every visible geom but the invisible one and the robot's was hit by some ray.
        assert_eq!(hits.into_iter().collect::<Vec<_>>(), vec![0, 1, 2, 3, 4, 5, 6]);
        // Serial and parallel casts agree bit for bit.
        let mut serial = vec![None; dirs.len()];
        scene.cast_bundles(origin, &dirs, 7, 50.0, false, &mut serial).unwrap();
        assert_eq!(serial, out);
    }
}
