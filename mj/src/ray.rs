//! Ray casting against the geoms of a simulation state, without OpenGL: MuJoCo's own
//! `mj_multiRay` ([`Data::multi_ray`]) and [`RayScene`], which casts bundles of rays from many
//! threads at once (depth cameras, LiDARs).
//!
//! [`RayScene`] tests each ray only against the geoms whose bounding sphere meets the cone of
//! its bundle, nearest first, with exact per-geom intersections: primitives in Rust
//! (`ray_shape`, MuJoCo's `mju_rayGeom` conventions, with the ray origin mapped into each
//! geom's frame once per cast), meshes and height fields with MuJoCo's `mj_rayMesh` and
//! `mj_rayHfield`. It sees the geoms `mj_ray` sees for the same filter
//! (visible groups, alpha > 0, static bodies), minus any set of bodies; flexes, skins and SDF
//! geoms are not seen.

use super::model::raw_slice;
use super::ray_shape::Shape;
use super::{Data, Model, ffi, guarded};
use crate::error::{Error, Result};
use mujoco_sys as sys;
use std::ffi::c_int;

/// Which geoms rays see.
#[derive(Debug, Clone, PartialEq, Eq, smart_default::SmartDefault)]
pub struct RayFilter {
    /// Geom groups 0–5 seen (groups above 5 count as 5). (default: 0, 1, 2: what MuJoCo's
    /// viewer shows; twin's converter puts URDF visuals in group 2 and collision geoms in 3)
    #[default([true, true, true, false, false, false])]
    pub groups: [bool; 6],
    /// Whether geoms of bodies welded to the world (floor, table) are seen. (default: true)
    #[default(true)]
    pub static_geoms: bool,
    /// Bodies whose geoms are not seen, e.g. the robot carrying the sensor. (default: none)
    pub exclude_bodies: Vec<usize>,
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
}

/// Where a ray hit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Distance along the (unit) ray direction, metres.
    pub dist_m: f64,
    /// The geom hit.
    pub geom: usize,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    /// A primitive, intersected in Rust ([`Shape::hit`]).
    Primitive(Shape),
    /// A mesh: MuJoCo's `mj_rayMesh` (its BVH).
    Mesh,
    /// A height field: MuJoCo's `mj_rayHfield`.
    Hfield,
}

/// One seen geom, posed at the state's instant.
#[derive(Debug, Clone, Copy)]
struct SceneGeom {
    id: usize,
    kind: Kind,
    pos: [f64; 3],
    /// Row-major `world_from_geom` rotation.
    mat: [f64; 9],
    /// Bounding-sphere radius about `pos`; infinite for planes.
    rbound: f64,
    /// Bounding box in the geom's frame: centre, half-sizes (MuJoCo's `geom_aabb`).
    aabb: [f64; 6],
}

/// A geom as seen from one ray origin (see [`RayScene::seen_from`]): what a ray test needs,
/// computed once per origin rather than once per ray.
#[derive(Debug, Clone, Copy)]
struct Seen {
    /// Index in the scene.
    k: u32,
    /// From the origin to the geom's centre, and its length.
    v: [f64; 3],
    d: f64,
    /// No point of the geom is nearer than this, metres.
    near: f64,
    /// Every direction may hit it (a plane, or the origin inside its bounding sphere).
    always: bool,
    /// Sine, cosine and angle of its bounding sphere's angular radius.
    sin_b: f64,
    cos_b: f64,
    beta: f64,
    /// Squared bounding radius (infinite for planes).
    r2: f64,
    /// The origin in the geom's frame.
    local_origin: [f64; 3],
    /// Row-major `world_from_geom` rotation and the geom's kind, copied for locality.
    mat: [f64; 9],
    kind: Kind,
    /// The corners of a box holding the geom, relative to the origin (`None`: unbounded, an
    /// infinite plane): tighter than the bounding sphere for long or flat geoms.
    corners: Option<[[f64; 3]; 8]>,
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

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `mat' · x` for a row-major 3×3 `mat`: a world vector in the geom's frame.
#[inline]
fn to_local(mat: &[f64; 9], x: [f64; 3]) -> [f64; 3] {
    [
        mat[0] * x[0] + mat[3] * x[1] + mat[6] * x[2],
        mat[1] * x[0] + mat[4] * x[1] + mat[7] * x[2],
        mat[2] * x[0] + mat[5] * x[1] + mat[8] * x[2],
    ]
}

/// Rays cast by one call, and the exact geom tests they needed (for benchmarks and for
/// checking that culling works).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RayStats {
    /// Rays cast.
    pub rays: u64,
    /// Exact ray–geom tests run (after the bounding-sphere test passed).
    pub exact_tests: u64,
    /// Bounding-sphere tests run.
    pub sphere_tests: u64,
}

impl std::ops::AddAssign for RayStats {
    fn add_assign(&mut self, o: RayStats) {
        self.rays += o.rays;
        self.exact_tests += o.exact_tests;
        self.sphere_tests += o.sphere_tests;
    }
}

impl<'a> RayScene<'a> {
    /// The geoms of `data`'s model that `filter` lets rays see, at `data`'s last forward pass
    /// (its `geom_xpos`/`geom_xmat`).
    pub fn new(data: &'a Data, filter: &RayFilter) -> RayScene<'a> {
        let model: &Model = data.model();
        let (types, sizes, rbound, aabb) =
            (model.geom_type(), model.geom_size(), model.geom_rbound(), model.geom_aabb());
        let (xpos, xmat) = (data.geom_xpos(), data.geom_xmat());
        let geoms = (0..model.ngeom())
            .filter(|&g| filter.sees(model, g))
            .filter_map(|g| {
                let ty = types[g] as u32;
                let kind = match ty {
                    sys::mjtGeom_mjGEOM_MESH => Kind::Mesh,
                    sys::mjtGeom_mjGEOM_HFIELD => Kind::Hfield,
                    _ => Kind::Primitive(Shape::of(ty, sizes[g])?),
                };
                let r = if ty == sys::mjtGeom_mjGEOM_PLANE { f64::INFINITY } else { rbound[g] };
                Some(SceneGeom { id: g, kind, pos: xpos[g], mat: xmat[g], rbound: r, aabb: aabb[g] })
            })
            .collect();
        RayScene { model, data, geoms: without_twins(geoms) }
    }

    /// Number of geoms rays can hit.
    pub fn len(&self) -> usize {
        self.geoms.len()
    }

    /// Whether rays can hit nothing.
    pub fn is_empty(&self) -> bool {
        self.geoms.is_empty()
    }

    /// The geoms as seen from `origin`, nearest first by a lower bound of their distance
    /// (planes: the perpendicular distance; others: to their bounding sphere), those beyond
    /// `max_dist_m` left out, and those wholly nearer than `clip_m` (inside the sphere where
    /// every ray's geometry is clipped). Computed once per origin, shared by every bundle.
    fn seen_from(&self, origin: [f64; 3], max_dist_m: f64, clip_m: f64) -> Vec<Seen> {
        let mut seen: Vec<Seen> = self
            .geoms
            .iter()
            .enumerate()
            .filter_map(|(k, g)| {
                let v = sub(g.pos, origin);
                let d = dot(v, v).sqrt();
                if d + g.rbound < clip_m || (clip_m > 0.0 && g.rbound.is_finite() && box_within(g, origin, clip_m)) {
                    return None;
                }
                let (near, always, sin_b) = if g.rbound.is_infinite() {
                    // A plane: no point of it is nearer than its perpendicular distance.
                    let n = [g.mat[2], g.mat[5], g.mat[8]];
                    (dot(v, n).abs(), true, 1.0)
                } else if d <= g.rbound {
                    (0.0, true, 1.0)
                } else {
                    (d - g.rbound, false, g.rbound / d)
                };
                (near <= max_dist_m).then(|| Seen {
                    k: k as u32,
                    v,
                    d,
                    near,
                    always,
                    sin_b,
                    cos_b: (1.0 - sin_b * sin_b).max(0.0).sqrt(),
                    beta: sin_b.min(1.0).asin(),
                    r2: g.rbound * g.rbound,
                    local_origin: to_local(&g.mat, sub(origin, g.pos)),
                    mat: g.mat,
                    kind: g.kind,
                    corners: box_half(g).map(|(centre, h)| {
                        // A hair larger, so that rounding never culls a geom a ray touches.
                        let h = h.map(|x| x * (1.0 + 1e-9) + 1e-12);
                        std::array::from_fn(|c| {
                            let l = [
                                centre[0] + if c & 1 == 0 { -h[0] } else { h[0] },
                                centre[1] + if c & 2 == 0 { -h[1] } else { h[1] },
                                centre[2] + if c & 4 == 0 { -h[2] } else { h[2] },
                            ];
                            let m = &g.mat;
                            [
                                v[0] + m[0] * l[0] + m[1] * l[1] + m[2] * l[2],
                                v[1] + m[3] * l[0] + m[4] * l[1] + m[5] * l[2],
                                v[2] + m[6] * l[0] + m[7] * l[1] + m[8] * l[2],
                            ]
                        })
                    }),
                })
            })
            .collect();
        seen.sort_by(|a, b| a.near.total_cmp(&b.near).then(a.k.cmp(&b.k)));
        seen
    }

    /// The indices `from` (in `seen`, nearest first) of the geoms the rays `dirs` (unit, from
    /// the origin of `seen`) may hit: whose bounding sphere meets the narrowest cone holding
    /// the rays and, `with_pyramid`, whose box is not wholly outside the pyramid holding them.
    /// Every ray of `dirs` can only hit these.
    fn cull(seen: &[Seen], from: impl Iterator<Item = u32>, dirs: &[[f64; 3]], with_pyramid: bool, out: &mut Vec<u32>) {
        out.clear();
        let (axis, half_angle_rad) = bundle_cone(dirs);
        let pyramid = if with_pyramid { bundle_pyramid(dirs, axis, half_angle_rad) } else { None };
        let pyramid = pyramid.as_ref();
        let (sin_a, cos_a) = half_angle_rad.min(std::f64::consts::PI).sin_cos();
        for i in from {
            let s = &seen[i as usize];
            // The sphere meets the cone when the angle between the axis and its centre is at
            // most the half-angle plus its angular radius β = asin(r/d): cos θ ≥ cos(α + β).
            let meets = s.always
                || half_angle_rad + s.beta >= std::f64::consts::PI
                || dot(s.v, axis) >= s.d * (cos_a * s.cos_b - sin_a * s.sin_b) - 1e-12;
            // And its box is not wholly outside one side of the bundle's pyramid.
            let outside = || match (pyramid, &s.corners) {
                (Some(planes), Some(corners)) => planes.iter().any(|n| corners.iter().all(|c| dot(*c, *n) > 0.0)),
                _ => false,
            };
            if meets && !outside() {
                out.push(i);
            }
        }
    }

    /// Distance along the unit direction `dir` from `origin` (the origin `s` was seen from) to
    /// geom `s`, if it is hit no farther than `limit_m`.
    #[inline(always)]
    fn hit(&self, s: &Seen, origin: &[f64; 3], dir: &[f64; 3], limit_m: f64, stats: &mut RayStats) -> Option<f64> {
        // By reference: the rays stay where they are (copies made per test stalled on
        // store forwarding).
        let dir_v = *dir;
        if s.r2.is_finite() {
            // Bounding sphere first, cheaper than the exact test: missed, or entered beyond
            // the nearest hit so far (with a margin for rounding: a sphere geom is its own
            // bounding sphere).
            stats.sphere_tests += 1;
            let t = dot(s.v, dir_v);
            let perp2 = s.d * s.d - t * t;
            // Entered beyond the limit: t − √(r² − perp²) > limit, without the square root.
            let beyond = t - (limit_m + 1e-9);
            if perp2 > s.r2 || (t < 0.0 && t * t > s.r2) || (beyond > 0.0 && beyond * beyond > s.r2 - perp2) {
                return None;
            }
        }
        stats.exact_tests += 1;
        let d = match s.kind {
            Kind::Primitive(shape) => shape.hit(s.local_origin, to_local(&s.mat, dir_v)),
            Kind::Mesh | Kind::Hfield => self.hit_mujoco(s, origin, dir),
        };
        (d >= 0.0).then_some(d)
    }

    /// MuJoCo's intersection of a mesh or height field geom (−1: none). Out of line, so the
    /// primitives' hot path keeps the ray in registers rather than in memory for the call.
    #[cold]
    #[inline(never)]
    fn hit_mujoco(&self, s: &Seen, origin: &[f64; 3], dir: &[f64; 3]) -> f64 {
        let id = self.geoms[s.k as usize].id as c_int;
        // mj_rayMesh and mj_rayHfield take the same arguments.
        let cast = match s.kind {
            Kind::Primitive(_) => return -1.0,
            Kind::Mesh => sys::mj_rayMesh,
            Kind::Hfield => sys::mj_rayHfield,
        };
        // SAFETY: the geom is a mesh (or height field, matched to its function) of this live
        // model; the call only reads the model and the (borrowed, unmodified) data and raises
        // only for a geom of the other kind; origin and dir hold 3 values each; the normal is
        // optional (null).
        unsafe { cast(self.model.as_ptr(), self.data.raw(), id, origin.as_ptr(), dir.as_ptr(), std::ptr::null_mut()) }
    }

    /// The nearest hit of the ray from `origin` along the unit vector `dir` within
    /// `max_dist_m`.
    pub fn cast(&self, origin: [f64; 3], dir: [f64; 3], max_dist_m: f64) -> Option<RayHit> {
        let seen = self.seen_from(origin, max_dist_m, 0.0);
        let mut candidates = Vec::new();
        Self::cull(&seen, 0..seen.len() as u32, &[dir], false, &mut candidates);
        self.nearest(&seen, &origin, &dir, max_dist_m, 0.0, &candidates, None, &mut RayStats::default()).map(|(h, _)| h)
    }

    /// The nearest hit among `candidates` (indices in `seen`, nearest-first), trying `hint`
    /// first (the geom the previous ray of the bundle hit: neighbouring rays mostly hit the
    /// same geom, and its distance then skips every candidate known to be farther). The answer
    /// does not depend on the hint. A geom whose hit is nearer than `clip_m` is clipped (not
    /// seen along this ray). Returns the hit and its index in `seen`.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn nearest(
        &self,
        seen: &[Seen],
        origin: &[f64; 3],
        dir: &[f64; 3],
        max_dist_m: f64,
        clip_m: f64,
        candidates: &[u32],
        hint: Option<u32>,
        stats: &mut RayStats,
    ) -> Option<(RayHit, u32)> {
        // Counted locally: kept in registers in the hot loop.
        let mut st = RayStats::default();
        let mut best: Option<(RayHit, u32)> = None;
        if let Some(i) = hint {
            let s = &seen[i as usize];
            if let Some(d) = self.hit(s, origin, dir, max_dist_m, &mut st)
                && d <= max_dist_m
                && d >= clip_m
            {
                best = Some((RayHit { dist_m: d, geom: self.geoms[s.k as usize].id }, i));
            }
        }
        for &i in candidates {
            let s = &seen[i as usize];
            let limit = best.map_or(max_dist_m, |b| b.0.dist_m);
            if s.near > limit {
                break;
            }
            if Some(i) == hint {
                continue;
            }
            if let Some(d) = self.hit(s, origin, dir, limit, &mut st)
                && d <= limit
                && d >= clip_m
            {
                let id = self.geoms[s.k as usize].id;
                if best.is_none_or(|(b, _)| d < b.dist_m || (d == b.dist_m && id < b.geom)) {
                    best = Some((RayHit { dist_m: d, geom: id }, i));
                }
            }
        }
        *stats += st;
        best
    }

    /// Casts the rays from `origin` along the unit vectors `dirs` of a sensor's frame turned
    /// into the world by `world_from_sensor` (row-major rotation), writing each nearest hit
    /// within `max_dist_m` into `out` (same length). Rays are turned a group at a time (no
    /// per-frame array of world directions). Consecutive rays are taken in bundles of
    /// `bundle` and culled together, and runs of 16 bundles as a group before that, so rays
    /// close in direction should be next to each other (an image tile, 4×4 tiles, a stretch
    /// of a scan). Groups run in parallel on the current rayon pool when `parallel`; the
    /// result does not depend on it. Returns what the cast cost.
    ///
    /// `clip_m` clips what is near, as a camera's near plane does (a sensor inside its own
    /// housing sees out of it): along ray `i` a geom whose nearest hit is nearer than
    /// `clip_m[i]` is not seen, and the ray goes on to what lies behind. Empty: nothing is
    /// clipped; one value: the same for every ray; else one per ray.
    ///
    /// # Errors
    /// [`Error::Size`] when `out` and `dirs` differ in length, or `clip_m` has another length
    /// than 0, 1 or theirs.
    #[allow(clippy::too_many_arguments)]
    pub fn cast_bundles(
        &self,
        origin: [f64; 3],
        world_from_sensor: &[f64; 9],
        dirs: &[[f64; 3]],
        bundle: usize,
        max_dist_m: f64,
        clip_m: &[f64],
        parallel: bool,
        out: &mut [Option<RayHit>],
    ) -> Result<RayStats> {
        if out.len() != dirs.len() {
            return Err(Error::Size { what: "ray output length", expected: dirs.len(), got: out.len() });
        }
        if clip_m.len() > 1 && clip_m.len() != dirs.len() {
            return Err(Error::Size { what: "ray clip distances", expected: dirs.len(), got: clip_m.len() });
        }
        let bundle = bundle.max(1);
        let clip_at = |i: usize| match clip_m.len() {
            0 => 0.0,
            1 => clip_m[0],
            _ => clip_m[i],
        };
        let min_clip = clip_m.iter().copied().fold(f64::INFINITY, f64::min);
        let seen = self.seen_from(origin, max_dist_m, if min_clip.is_finite() { min_clip.max(0.0) } else { 0.0 });
        // Bundles are culled in groups first (an image's 4×4 tiles), then each bundle from
        // its group's candidates: most geoms are dropped once per group, not once per bundle.
        let group = bundle * GROUP_BUNDLES;
        let m = world_from_sensor;
        let run = |(first, (dirs_sensor, out)): GroupChunk<'_>, scratch: &mut Scratch| {
            let Scratch { in_group, candidates, dirs } = scratch;
            dirs.clear();
            dirs.extend(dirs_sensor.iter().map(|d| {
                [
                    m[0] * d[0] + m[1] * d[1] + m[2] * d[2],
                    m[3] * d[0] + m[4] * d[1] + m[5] * d[2],
                    m[6] * d[0] + m[7] * d[1] + m[8] * d[2],
                ]
            }));
            let dirs = &dirs[..];
            let mut stats = RayStats { rays: dirs.len() as u64, ..RayStats::default() };
            // The group by its cone only: the pyramid costs a pass over the rays, and pays off
            // on the bundles' smaller ones.
            Self::cull(&seen, 0..seen.len() as u32, dirs, false, in_group);
            for (b, (dirs, out)) in dirs.chunks(bundle).zip(out.chunks_mut(bundle)).enumerate() {
                Self::cull(&seen, in_group.iter().copied(), dirs, true, candidates);
                let mut hint = None;
                for (r, (d, o)) in dirs.iter().zip(out.iter_mut()).enumerate() {
                    let clip = clip_at(first + b * bundle + r);
                    let best = self.nearest(&seen, &origin, d, max_dist_m, clip, candidates, hint, &mut stats);
                    hint = best.map(|(_, k)| k).or(hint);
                    *o = best.map(|(h, _)| h);
                }
            }
            stats
        };
        let stats = if parallel {
            use rayon::prelude::*;
            dirs.par_chunks(group)
                .zip(out.par_chunks_mut(group))
                .enumerate()
                .map_init(Scratch::default, |c, (k, chunk)| run((k * group, chunk), c))
                .reduce(RayStats::default, |mut a, b| {
                    a += b;
                    a
                })
        } else {
            let mut scratch = Scratch::default();
            let mut stats = RayStats::default();
            for (k, chunk) in dirs.chunks(group).zip(out.chunks_mut(group)).enumerate() {
                stats += run((k * group, chunk), &mut scratch);
            }
            stats
        };
        Ok(stats)
    }
}

/// One group of a cast: the index of its first ray, its rays (sensor frame) and their hits.
type GroupChunk<'a> = (usize, (&'a [[f64; 3]], &'a mut [Option<RayHit>]));

/// Per-thread lists of one group's cast: its candidates, a bundle's, its rays in the world.
#[derive(Default)]
struct Scratch {
    in_group: Vec<u32>,
    candidates: Vec<u32>,
    dirs: Vec<[f64; 3]>,
}

/// Bundles culled together as a group before each is culled on its own (see
/// [`RayScene::cast_bundles`]).
const GROUP_BUNDLES: usize = 16;

/// `geoms` (in id order) without any primitive that has the same shape, pose and size as an
/// earlier one (a world's collision and visual geoms often coincide): a ray hits both at the
/// same distance, and the lower id wins the tie, so the answer is unchanged.
fn without_twins(geoms: Vec<SceneGeom>) -> Vec<SceneGeom> {
    let mut kept: Vec<SceneGeom> = Vec::with_capacity(geoms.len());
    for g in geoms {
        let twin = matches!(g.kind, Kind::Primitive(_))
            && kept.iter().any(|k| k.kind == g.kind && k.pos == g.pos && k.mat == g.mat);
        if !twin {
            kept.push(g);
        }
    }
    kept
}

/// Whether every corner of `g`'s bounding box (MuJoCo's `geom_aabb`) is nearer to `origin`
/// than `radius_m`: the geom lies wholly inside the sphere whose geometry is clipped (a camera's
/// own head mesh, whose bounding sphere is larger).
fn box_within(g: &SceneGeom, origin: [f64; 3], radius_m: f64) -> bool {
    let [cx, cy, cz, hx, hy, hz] = g.aabb;
    let r2 = radius_m * radius_m;
    (0..8).all(|c| {
        let l = [
            cx + if c & 1 == 0 { -hx } else { hx },
            cy + if c & 2 == 0 { -hy } else { hy },
            cz + if c & 4 == 0 { -hz } else { hz },
        ];
        let m = &g.mat;
        let w = [
            g.pos[0] + m[0] * l[0] + m[1] * l[1] + m[2] * l[2] - origin[0],
            g.pos[1] + m[3] * l[0] + m[4] * l[1] + m[5] * l[2] - origin[1],
            g.pos[2] + m[6] * l[0] + m[7] * l[1] + m[8] * l[2] - origin[2],
        ];
        dot(w, w) < r2
    })
}

/// A box that holds the geom, in its frame: its centre and half-sizes; `None` for an infinite
/// plane.
fn box_half(g: &SceneGeom) -> Option<([f64; 3], [f64; 3])> {
    let at_centre = |h: [f64; 3]| Some(([0.0; 3], h));
    match g.kind {
        Kind::Primitive(Shape::Plane { half }) => {
            if half[0] > 0.0 && half[1] > 0.0 {
                at_centre([half[0], half[1], 0.0])
            } else {
                None
            }
        }
        Kind::Primitive(Shape::Sphere { radius }) => at_centre([radius; 3]),
        Kind::Primitive(Shape::Capsule { radius, half_len }) => at_centre([radius, radius, half_len + radius]),
        Kind::Primitive(Shape::Ellipsoid { inv_sq }) => at_centre(inv_sq.map(|s| 1.0 / s.sqrt())),
        Kind::Primitive(Shape::Cylinder { radius, half_len }) => at_centre([radius, radius, half_len]),
        Kind::Primitive(Shape::Box { half }) => at_centre(half),
        // MuJoCo's bounding box of the mesh or height field (tighter than the bounding sphere's
        // cube for long or flat meshes: a torso, a thigh), when it has one.
        Kind::Mesh | Kind::Hfield => {
            let [cx, cy, cz, hx, hy, hz] = g.aabb;
            if hx > 0.0 && hy > 0.0 && hz > 0.0 && [cx, cy, cz, hx, hy, hz].iter().all(|x| x.is_finite()) {
                Some(([cx, cy, cz], [hx, hy, hz]))
            } else {
                g.rbound.is_finite().then_some(([0.0; 3], [g.rbound; 3]))
            }
        }
    }
}

/// The four side planes (outward normals through the origin) of a pyramid about `axis` that
/// holds every ray of `dirs` (`axis` and `half_angle_rad` from [`bundle_cone`]), a little
/// wider for rounding; `None` for a bundle too wide for one (half-angle ≥ 60°). A geom whose
/// box lies wholly outside one plane can't be hit by the bundle: a tighter test than the
/// cone's for long or flat geoms.
fn bundle_pyramid(dirs: &[[f64; 3]], axis: [f64; 3], half_angle_rad: f64) -> Option<[[f64; 3]; 4]> {
    if half_angle_rad >= std::f64::consts::FRAC_PI_3 {
        return None;
    }
    // u, w: a basis of the plane across the axis.
    let pick = if axis[0].abs() < 0.6 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let u = {
        let c = dot(pick, axis);
        let x = [pick[0] - c * axis[0], pick[1] - c * axis[1], pick[2] - c * axis[2]];
        let n = dot(x, x).sqrt();
        x.map(|e| e / n)
    };
    let w = [axis[1] * u[2] - axis[2] * u[1], axis[2] * u[0] - axis[0] * u[2], axis[0] * u[1] - axis[1] * u[0]];
    let (mut x_lo, mut x_hi, mut y_lo, mut y_hi) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
    for d in dirs {
        // Within the cone the ray points forward along the axis (cos ≥ 0.5).
        let inv_z = 1.0 / dot(*d, axis);
        let (x, y) = (dot(*d, u) * inv_z, dot(*d, w) * inv_z);
        x_lo = x_lo.min(x);
        x_hi = x_hi.max(x);
        y_lo = y_lo.min(y);
        y_hi = y_hi.max(y);
    }
    let m = 1e-9;
    let (x_lo, x_hi, y_lo, y_hi) = (x_lo - m, x_hi + m, y_lo - m, y_hi + m);
    // p·u ≤ x_hi p·a, i.e. (u − x_hi a)·p ≤ 0; and so on.
    let plane = |s: f64, e: [f64; 3], k: f64| std::array::from_fn(|i| s * e[i] - s * k * axis[i]);
    Some([plane(1.0, u, x_hi), plane(-1.0, u, x_lo), plane(1.0, w, y_hi), plane(-1.0, w, y_lo)])
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

    /// Copies what ray casting reads (geom, camera and site poses, time) from `other`, a
    /// state of the same model, so readings can be taken from this copy on another thread.
    ///
    /// # Errors
    /// [`Error::Size`] when `other` belongs to a model of another layout.
    pub fn copy_poses_from(&mut self, other: &Data) -> Result<()> {
        super::ModelLayout::of(self.model()).require_same(&super::ModelLayout::of(other.model()))?;
        self.geom_xpos_mut().copy_from_slice(other.geom_xpos());
        self.geom_xmat_mut().copy_from_slice(other.geom_xmat());
        self.site_xpos_mut().copy_from_slice(other.site_xpos());
        self.site_xmat_mut().copy_from_slice(other.site_xmat());
        let n = self.model().raw().ncam as usize;
        let (p, m) = (other.cam_xpos().as_ptr(), other.cam_xmat().as_ptr());
        let (dp, dm) = (self.raw().cam_xpos as *mut [f64; 3], self.raw().cam_xmat as *mut [f64; 9]);
        // SAFETY: both states have ncam camera rows (same layout, checked above); the source is
        // borrowed shared and the destination exclusively through &mut self; they are distinct
        // allocations.
        unsafe {
            std::ptr::copy_nonoverlapping(p, dp, n);
            std::ptr::copy_nonoverlapping(m, dm, n);
        }
        self.set_time_secs(other.time_secs());
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    /// A scene of every primitive, a mesh and a floor, with some geoms of a body that is
    /// excluded, one invisible geom, and a box twice (as a world's collision and visual geoms).
    const SCENE: &str = r#"<mujoco><asset><mesh name="tet" vertex="0 0 0 0.3 0 0 0 0.3 0 0 0 0.3"/></asset>
      <worldbody><geom type="plane" size="5 5 0.1"/>
        <geom type="box" pos="1 0 0.3" size="0.1 0.2 0.3" euler="0 0 20"/>
        <geom type="box" pos="1 0 0.3" size="0.1 0.2 0.3" euler="0 0 20" group="1"/>
        <geom type="sphere" pos="1 0.8 0.4" size="0.15"/>
        <geom type="capsule" pos="1 -0.8 0.4" size="0.05 0.2" euler="30 0 0"/>
        <geom type="cylinder" pos="1.5 0.4 0.5" size="0.1 0.2"/>
        <geom type="ellipsoid" pos="1.5 -0.4 0.5" size="0.1 0.2 0.15"/>
        <geom type="mesh" mesh="tet" pos="0.8 0.3 0.6"/>
        <geom type="sphere" pos="0.6 0 0.5" size="0.05" rgba="1 1 1 0"/>
        <body name="robot" pos="0 0 0.5"><freejoint/><geom type="sphere" size="0.1"/></body>
      </worldbody></mujoco>"#;

    /// MuJoCo's own intersection of one ray with one primitive (−1: none).
    fn mujoco_ray_geom(ty: u32, pos: [f64; 3], mat: [f64; 9], size: [f64; 3], pnt: [f64; 3], vec: [f64; 3]) -> f64 {
        // SAFETY: every pointer is to an array of the length mju_rayGeom reads (3, 9, 3, 3, 3);
        // the type is a primitive it handles; the normal is optional (null).
        unsafe {
            sys::mju_rayGeom(
                pos.as_ptr(),
                mat.as_ptr(),
                size.as_ptr(),
                pnt.as_ptr(),
                vec.as_ptr(),
                ty as c_int,
                std::ptr::null_mut(),
            )
        }
    }

    #[test]
    fn primitives_match_mju_ray_geom() {
        use nalgebra::{UnitQuaternion, Vector3};
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(13);
        let types = [
            ("plane", sys::mjtGeom_mjGEOM_PLANE),
            ("sphere", sys::mjtGeom_mjGEOM_SPHERE),
            ("capsule", sys::mjtGeom_mjGEOM_CAPSULE),
            ("ellipsoid", sys::mjtGeom_mjGEOM_ELLIPSOID),
            ("cylinder", sys::mjtGeom_mjGEOM_CYLINDER),
            ("box", sys::mjtGeom_mjGEOM_BOX),
        ];
        for (name, ty) in types {
            let (mut hits, mut inside_hits, mut worst) = (0, 0, 0.0f64);
            for k in 0..20_000 {
                let pos = [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)];
                let q = UnitQuaternion::from_euler_angles(
                    rng.random_range(-3.2..3.2),
                    rng.random_range(-1.6..1.6),
                    rng.random_range(-3.2..3.2),
                );
                let m = q.to_rotation_matrix();
                let mat: [f64; 9] = std::array::from_fn(|i| m[(i / 3, i % 3)]);
                // Planes: a finite rectangle half the time, infinite otherwise.
                let size: [f64; 3] = if ty == sys::mjtGeom_mjGEOM_PLANE && k % 2 == 0 {
                    [0.0, 0.0, 0.1]
                } else {
                    std::array::from_fn(|_| rng.random_range(0.05..0.5))
                };
                // Origins near and inside the geom; directions at it (most hit) or anywhere,
                // not unit length, as MuJoCo allows.
                // Every fifth origin lies within 2 cm of the centre: inside every solid (sizes
                // ≥ 5 cm), so its ray must hit where it leaves.
                let from_inside = k % 5 == 1 && ty != sys::mjtGeom_mjGEOM_PLANE;
                let spread = if from_inside { 0.02 } else { 1.5 };
                let pnt: [f64; 3] = std::array::from_fn(|i| pos[i] + rng.random_range(-spread..spread));
                let target = Vector3::from(pos) + Vector3::from_fn(|_, _| rng.random_range(-0.4..0.4));
                let mut dir = if k % 4 == 0 {
                    Vector3::from_fn(|_, _| rng.random_range(-1.0..1.0))
                } else {
                    target - Vector3::from(pnt)
                };
                dir *= rng.random_range(0.3..2.0);
                let vec = [dir.x, dir.y, dir.z];
                let expected = mujoco_ray_geom(ty, pos, mat, size, pnt, vec);
                let shape = Shape::of(ty, size).unwrap();
                let got = shape.hit(to_local(&mat, sub(pnt, pos)), to_local(&mat, vec));
                assert_eq!(got >= 0.0, expected >= 0.0, "{name} ray {k}: ours {got}, MuJoCo {expected}");
                if expected >= 0.0 {
                    worst = worst.max((got - expected).abs());
                    hits += 1;
                    inside_hits += usize::from(from_inside);
                } else {
                    assert!(!from_inside, "{name} ray {k} from inside missed");
                }
            }
            assert!(worst < 1e-9, "{name}: worst difference {worst} m");
            // Planes are seen from their front only: about half the origins are behind.
            assert!(hits > 4_000, "{name}: only {hits} of 20000 rays hit");
            if ty != sys::mjtGeom_mjGEOM_PLANE {
                assert_eq!(inside_hits, 4_000, "{name}: rays from inside that hit");
            }
        }
    }

    const IDENTITY: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

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
        let filter = RayFilter { groups: [true; 6], exclude_bodies: model.subtree(robot), ..RayFilter::default() };
        let scene = RayScene::new(&data, &filter);
        let mut out = vec![None; dirs.len()];
        scene.cast_bundles(origin, &IDENTITY, &dirs, 16, 50.0, &[], true, &mut out).unwrap();
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
        // Every visible geom but the invisible one, the robot's and the box's twin (geom 2: the
        // lower id wins a tie, in MuJoCo as here) was hit by some ray.
        assert_eq!(hits.into_iter().collect::<Vec<_>>(), vec![0, 1, 3, 4, 5, 6, 7]);
        assert_eq!(scene.len(), 7, "the box's twin is left out of the scene");
        // Serial and parallel casts agree bit for bit.
        let mut serial = vec![None; dirs.len()];
        scene.cast_bundles(origin, &IDENTITY, &dirs, 7, 50.0, &[], false, &mut serial).unwrap();
        assert_eq!(serial, out);
    }
}
