//! Terrain: the ground a scenario's robot walks on, built as MuJoCo geometry.
//!
//! A scenario's `[terrain]` table ([`TerrainOptions`]) names a kind and its parameters; the
//! generator ([`TerrainOptions::build`]) turns them, deterministically from `seed`, into a
//! [`TerrainGeometry`]: one heightfield (rough ground, slopes) and static boxes (steps, stairs,
//! obstacles, the platforms between gaps). [`TerrainGeometry::to_mjcf`] writes them as MJCF
//! (`<hfield>` asset, `hfield` and `box` geoms named `twin_terrain*`) that is composed with the
//! converted robot over its floor plane (z = 0); [`TerrainGeometry::height_at`] is the ground's
//! height anywhere, which seats the robot on the ground at reset (never inside it).
//!
//! The terrain lies along a path from the origin in direction `direction_deg` (0: the robot's
//! forward axis, world +x); the robot starts at the origin on flat ground and the terrain begins
//! `start_m` ahead. `difficulty` in [0, 1] scales the kind from flat (0) to its parameters
//! as written (1): the amplitude of rough ground, the angle of a slope, the height of a step,
//! the rise of stairs, the height of obstacles, the width of gaps.
//!
//! ```toml
//! [terrain]
//! kind = "rough"          # flat | rough | slope | steps | stairs | obstacles | gaps
//! difficulty = 1.0        # 0: flat … 1: the parameters below (default 1)
//! seed = 0                # rough ground and obstacles are drawn from it (default 0)
//! amplitude_m = 0.01      # rough: heights within ±amplitude around the mean, m
//! wavelength_m = 0.4      # rough: distance between independent heights, m
//! ```
//!
//! Every kind's keys, with defaults, are on [`TerrainOptions`]'s fields.

use crate::mj::{Data, GeomType, Model, ObjType};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::fmt::Write as _;

/// Kinds of terrain (`kind = "…"`).
pub const KINDS: [&str; 7] = ["flat", "rough", "slope", "steps", "stairs", "obstacles", "gaps"];

/// The `[terrain]` table of a scenario. Keys that don't belong to the `kind` are errors.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize, smart_default::SmartDefault)]
#[serde(deny_unknown_fields)]
pub struct TerrainOptions {
    /// One of [`KINDS`]; a scenario's table must name it (`TerrainOptions::default()`: `flat`).
    #[default("flat")]
    pub kind: String,
    /// From flat (0) to the parameters as written (1) (default: 1).
    #[serde(default = "one")]
    #[default(1.0)]
    pub difficulty: f64,
    /// Seed of rough ground and obstacles (default: 0).
    #[serde(default)]
    pub seed: u64,
    /// Distance from the robot's start (the origin) to where the terrain begins, m (default:
    /// 1.0; rough ground fades in over the half metre before it).
    pub start_m: Option<f64>,
    /// Heading of the path, degrees from world +x, counter-clockwise (default: 0).
    pub direction_deg: Option<f64>,
    /// Width of the terrain across the path, m (default: 3).
    pub width_m: Option<f64>,
    /// Rough ground, obstacles: length of the terrain along the path, m (default: 8).
    pub length_m: Option<f64>,
    /// Rough ground, slope: heightfield cell size, m (default: 0.05).
    pub cell_m: Option<f64>,
    /// Rough ground: heights within ±amplitude of the mean at difficulty 1, m (default: 0.05).
    pub amplitude_m: Option<f64>,
    /// Rough ground: distance between the independent random heights (smoothly interpolated
    /// between), m (default: 0.4).
    pub wavelength_m: Option<f64>,
    /// Slope: angle of the ramps at difficulty 1, degrees (default: 15).
    pub slope_deg: Option<f64>,
    /// Slope: length of the up ramp and of the down ramp, m, horizontal (default: 2).
    pub ramp_m: Option<f64>,
    /// Slope: length of the top between the ramps, m (default: 1).
    pub plateau_m: Option<f64>,
    /// Steps: height of the step up (and down again) at difficulty 1, m (default: 0.1);
    /// obstacles: height of the boxes at difficulty 1, m (default: 0.1).
    pub height_m: Option<f64>,
    /// Steps: length of the raised part, m (default: 1).
    pub depth_m: Option<f64>,
    /// Stairs: rise of each stair at difficulty 1, m (default: 0.12).
    pub rise_m: Option<f64>,
    /// Stairs: run (tread length) of each stair, m (default: 0.3).
    pub run_m: Option<f64>,
    /// Stairs: stairs up (and as many down) (default: 4); gaps: number of gaps (default: 3).
    pub count: Option<u32>,
    /// Stairs: length of the top landing, m (default: 1).
    pub landing_m: Option<f64>,
    /// Obstacles: smallest side of a box's footprint, m (default: 0.05).
    pub size_min_m: Option<f64>,
    /// Obstacles: largest side of a box's footprint, m (default: 0.2).
    pub size_max_m: Option<f64>,
    /// Obstacles: boxes per metre of path (default: 0.5).
    pub density_per_m: Option<f64>,
    /// Gaps: width of each gap at difficulty 1, m (default: 0.3).
    pub gap_m: Option<f64>,
    /// Gaps: length of the platforms between gaps, m (default: 1).
    pub platform_m: Option<f64>,
    /// Gaps: height of the walking surface above the bottom of the gaps, m (default: 0.3).
    pub pit_depth_m: Option<f64>,
}

fn one() -> f64 {
    1.0
}

/// Which optional keys each kind reads.
fn keys_of(kind: &str) -> &'static [&'static str] {
    match kind {
        "rough" => &["length_m", "cell_m", "amplitude_m", "wavelength_m"],
        "slope" => &["cell_m", "slope_deg", "ramp_m", "plateau_m"],
        "steps" => &["height_m", "depth_m"],
        "stairs" => &["rise_m", "run_m", "count", "landing_m"],
        "obstacles" => &["length_m", "height_m", "size_min_m", "size_max_m", "density_per_m"],
        "gaps" => &["gap_m", "count", "platform_m", "pit_depth_m"],
        _ => &[],
    }
}

/// A box of the terrain, static, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TerrainBox {
    /// Centre, m.
    pub center_m: [f64; 3],
    /// Half sizes along its own axes, m.
    pub half_m: [f64; 3],
    /// Rotation about z, radians.
    pub yaw_rad: f64,
}

/// A heightfield of the terrain: a grid of heights in the path frame (the one heightfield type,
/// shared with Gazebo worlds' `<heightmap>`s).
pub use twin_convert::hfield::Heightfield;

/// The terrain as geometry (see the [module docs](self)).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TerrainGeometry {
    /// Height of the floor plane, m: 0, or below it for ground that goes below the start's
    /// level (rough ground: −amplitude).
    pub floor_z_m: f64,
    /// The heightfield, if the kind has one.
    pub hfield: Option<Heightfield>,
    /// Static boxes.
    pub boxes: Vec<TerrainBox>,
}

/// Height of a box at difficulty 0 (a box of no height is not a box), m.
pub const MIN_BOX_M: f64 = 1e-6;

/// Name prefix of the terrain's geoms (and of its heightfield asset).
pub const GEOM_PREFIX: &str = "twin_terrain";

/// A float for MJCF (shortest round-trip form).
fn num(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    format!("{v}")
}

fn smooth(t: f64) -> f64 {
    let t = t.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

impl TerrainOptions {
    fn get(&self, v: Option<f64>, default: f64) -> f64 {
        v.unwrap_or(default)
    }

    /// Start of the terrain along the path, m.
    pub fn start(&self) -> f64 {
        self.get(self.start_m, 1.0)
    }

    /// Checks values and that every key set belongs to the kind; the error is (key, message).
    ///
    /// # Errors
    /// The first bad key and what is wrong with it.
    pub fn validate(&self) -> std::result::Result<(), (&'static str, String)> {
        if !KINDS.contains(&self.kind.as_str()) {
            return Err(("kind", format!("unknown terrain kind \"{}\" (available: {})", self.kind, KINDS.join(", "))));
        }
        if !(0.0..=1.0).contains(&self.difficulty) {
            return Err(("difficulty", format!("must be within [0, 1] (got {})", self.difficulty)));
        }
        let set: [(&'static str, bool); 21] = [
            ("length_m", self.length_m.is_some()),
            ("cell_m", self.cell_m.is_some()),
            ("amplitude_m", self.amplitude_m.is_some()),
            ("wavelength_m", self.wavelength_m.is_some()),
            ("slope_deg", self.slope_deg.is_some()),
            ("ramp_m", self.ramp_m.is_some()),
            ("plateau_m", self.plateau_m.is_some()),
            ("height_m", self.height_m.is_some()),
            ("depth_m", self.depth_m.is_some()),
            ("rise_m", self.rise_m.is_some()),
            ("run_m", self.run_m.is_some()),
            ("count", self.count.is_some()),
            ("landing_m", self.landing_m.is_some()),
            ("size_min_m", self.size_min_m.is_some()),
            ("size_max_m", self.size_max_m.is_some()),
            ("density_per_m", self.density_per_m.is_some()),
            ("gap_m", self.gap_m.is_some()),
            ("platform_m", self.platform_m.is_some()),
            ("pit_depth_m", self.pit_depth_m.is_some()),
            ("width_m", false),
            ("start_m", false),
        ];
        let own = keys_of(&self.kind);
        for (key, present) in set {
            if present && !own.contains(&key) {
                let users: Vec<&str> = KINDS.iter().copied().filter(|k| keys_of(k).contains(&key)).collect();
                return Err((
                    key,
                    format!(
                        "does not apply to kind \"{}\" (it belongs to {}); the keys of \"{}\": {}",
                        self.kind,
                        users.join(", "),
                        self.kind,
                        if own.is_empty() {
                            "none besides difficulty, seed, start_m, direction_deg, width_m".into()
                        } else {
                            own.join(", ")
                        }
                    ),
                ));
            }
        }
        crate::bounds::positive([
            ("width_m", self.width_m),
            ("length_m", self.length_m),
            ("cell_m", self.cell_m),
            ("wavelength_m", self.wavelength_m),
            ("ramp_m", self.ramp_m),
            ("depth_m", self.depth_m),
            ("run_m", self.run_m),
            ("landing_m", self.landing_m),
            ("size_min_m", self.size_min_m),
            ("size_max_m", self.size_max_m),
            ("platform_m", self.platform_m),
            ("pit_depth_m", self.pit_depth_m),
            ("density_per_m", self.density_per_m.filter(|d| *d != 0.0)),
            ("height_m", self.height_m),
        ])?;
        crate::bounds::non_negative([
            ("start_m", self.start_m),
            ("amplitude_m", self.amplitude_m),
            ("rise_m", self.rise_m),
            ("gap_m", self.gap_m),
            ("plateau_m", self.plateau_m),
        ])?;
        if let Some(d) = self.direction_deg
            && !d.is_finite()
        {
            return Err(("direction_deg", format!("must be a finite number of degrees (got {d})")));
        }
        if let Some(s) = self.slope_deg
            && !(0.0..60.0).contains(&s)
        {
            return Err(("slope_deg", format!("must be within [0, 60) degrees (got {s})")));
        }
        if self.get(self.size_min_m, 0.05) > self.get(self.size_max_m, 0.2) {
            return Err(("size_min_m", "must not exceed size_max_m".into()));
        }
        if let Some(c) = self.count
            && !(1..=100).contains(&c)
        {
            return Err(("count", format!("must be from 1 to 100 (got {c})")));
        }
        let cell = self.get(self.cell_m, 0.05);
        if cell < 0.005 {
            return Err((
                "cell_m",
                format!("must be at least 0.005 m (got {cell}): the heightfield would be too large"),
            ));
        }
        let cells = (self.extent_along().1 - self.extent_along().0) / cell * self.get(self.width_m, 3.0) / cell;
        if matches!(self.kind.as_str(), "rough" | "slope") && cells > 4.0e6 {
            return Err((
                "cell_m",
                format!(
                    "the heightfield would have {cells:.0} cells (at most 4 000 000): use a larger cell_m or a smaller terrain"
                ),
            ));
        }
        Ok(())
    }

    /// Heightfield extent along the path (from, to), m.
    fn extent_along(&self) -> (f64, f64) {
        let start = self.start();
        match self.kind.as_str() {
            "rough" => (-1.0, start + self.get(self.length_m, 8.0) + 0.5),
            "slope" => (start - 0.5, start + 2.0 * self.get(self.ramp_m, 2.0) + self.get(self.plateau_m, 1.0) + 0.5),
            _ => (0.0, 0.0),
        }
    }

    /// The terrain's height above the floor along the path frame at (u along, v across), for
    /// the kinds built as a heightfield; `lattice`: rough ground's random heights.
    fn hfield_height(&self, u: f64, v: f64, lattice: &Lattice) -> f64 {
        let d = self.difficulty;
        let start = self.start();
        match self.kind.as_str() {
            "rough" => {
                let a = d * self.get(self.amplitude_m, 0.05);
                // Heights within ±a of the start's level, faded in over the half metre before
                // the start (the floor plane goes down to −a, see `floor_z_m`).
                let fade = smooth((u - (start - 0.5)) / 0.5);
                fade * a * lattice.at(u, v)
            }
            "slope" => {
                let tan = (d * self.get(self.slope_deg, 15.0)).to_radians().tan();
                let ramp = self.get(self.ramp_m, 2.0);
                let top = start + ramp + self.get(self.plateau_m, 1.0);
                let up = (u - start).clamp(0.0, ramp);
                let down = (u - top).clamp(0.0, ramp);
                tan * (up - down)
            }
            _ => 0.0,
        }
    }

    /// Builds the terrain (deterministic for the options, seed included).
    pub fn build(&self) -> TerrainGeometry {
        let yaw = self.get(self.direction_deg, 0.0).to_radians();
        let (c, s) = (yaw.cos(), yaw.sin());
        let world = |u: f64, v: f64| [c * u - s * v, s * u + c * v];
        let width = self.get(self.width_m, 3.0);
        let start = self.start();
        let d = self.difficulty;
        let mut geometry = TerrainGeometry::default();
        // Every box is built at any difficulty (at least MIN_BOX_M high), so the terrain's
        // geoms are the same whatever the difficulty: only their sizes and places change.
        let slab = |u0: f64, u1: f64, top: f64, boxes: &mut Vec<TerrainBox>| {
            let top = top.max(MIN_BOX_M);
            if u1 > u0 {
                let p = world((u0 + u1) / 2.0, 0.0);
                boxes.push(TerrainBox {
                    center_m: [p[0], p[1], top / 2.0],
                    half_m: [(u1 - u0) / 2.0, width / 2.0, top / 2.0],
                    yaw_rad: yaw,
                });
            }
        };
        match self.kind.as_str() {
            "rough" | "slope" => {
                if self.kind == "rough" {
                    geometry.floor_z_m = -d * self.get(self.amplitude_m, 0.05);
                }
                let (u0, u1) = self.extent_along();
                let cell = self.get(self.cell_m, 0.05);
                let ncol = ((u1 - u0) / cell).round().max(1.0) as usize + 1;
                let nrow = (width / cell).round().max(1.0) as usize + 1;
                let lattice = Lattice::new(self.seed, self.get(self.wavelength_m, 0.4), u0, u1, width);
                let (hx, hy) = ((u1 - u0) / 2.0, width / 2.0);
                let mut heights = Vec::with_capacity(nrow * ncol);
                for i in 0..nrow {
                    let v = -hy + 2.0 * hy * i as f64 / (nrow - 1) as f64;
                    for j in 0..ncol {
                        let u = u0 + 2.0 * hx * j as f64 / (ncol - 1) as f64;
                        heights.push(self.hfield_height(u, v, &lattice));
                    }
                }
                geometry.hfield = Some(Heightfield {
                    center_m: world((u0 + u1) / 2.0, 0.0),
                    half_m: [hx, hy],
                    yaw_rad: yaw,
                    nrow,
                    ncol,
                    heights_m: heights,
                });
            }
            "steps" => {
                let h = d * self.get(self.height_m, 0.1);
                slab(start, start + self.get(self.depth_m, 1.0), h, &mut geometry.boxes);
            }
            "stairs" => {
                let rise = d * self.get(self.rise_m, 0.12);
                let run = self.get(self.run_m, 0.3);
                let n = self.count.unwrap_or(4);
                let end = start + 2.0 * f64::from(n) * run + self.get(self.landing_m, 1.0);
                for i in 0..n {
                    let k = f64::from(i);
                    slab(start + k * run, end - k * run, (k + 1.0) * rise, &mut geometry.boxes);
                }
            }
            "obstacles" => {
                let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
                let length = self.get(self.length_m, 8.0);
                let n = (self.get(self.density_per_m, 0.5) * length).round() as usize;
                let (lo, hi) = (self.get(self.size_min_m, 0.05), self.get(self.size_max_m, 0.2));
                let h = d * self.get(self.height_m, 0.1);
                for _ in 0..n {
                    // Every draw is made whatever the difficulty: the boxes stay where they are
                    // as it changes, only their height does.
                    let u = start + rng.random::<f64>() * length;
                    let v = (rng.random::<f64>() - 0.5) * width;
                    let (sx, sy) = (lo + rng.random::<f64>() * (hi - lo), lo + rng.random::<f64>() * (hi - lo));
                    let turn = rng.random::<f64>() * std::f64::consts::PI;
                    let (p, h) = (world(u, v), h.max(MIN_BOX_M));
                    geometry.boxes.push(TerrainBox {
                        center_m: [p[0], p[1], h / 2.0],
                        half_m: [sx / 2.0, sy / 2.0, h / 2.0],
                        yaw_rad: yaw + turn,
                    });
                }
            }
            "gaps" => {
                let pit = self.get(self.pit_depth_m, 0.3);
                let gap = d * self.get(self.gap_m, 0.3);
                let platform = self.get(self.platform_m, 1.0);
                let n = self.count.unwrap_or(3);
                // The start platform reaches back behind the robot; the last one runs on.
                let mut u = -2.0;
                let mut next = start;
                for _ in 0..n {
                    slab(u, next, pit, &mut geometry.boxes);
                    u = next + gap;
                    next = u + platform;
                }
                slab(u, u + 5.0, pit, &mut geometry.boxes);
            }
            _ => {}
        }
        geometry
    }
}

/// Rough ground's random heights in [−1, 1] on a lattice of spacing `wavelength`, smoothly
/// interpolated (C¹: smoothstep weights) in between.
struct Lattice {
    values: Vec<f64>,
    nu: usize,
    nv: usize,
    u0: f64,
    v0: f64,
    spacing: f64,
}

impl Lattice {
    fn new(seed: u64, spacing: f64, u0: f64, u1: f64, width: f64) -> Lattice {
        let nu = ((u1 - u0) / spacing).ceil() as usize + 2;
        let nv = (width / spacing).ceil() as usize + 2;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let values = (0..nu * nv).map(|_| rng.random::<f64>() * 2.0 - 1.0).collect();
        Lattice { values, nu, nv, u0, v0: -width / 2.0, spacing }
    }

    fn at(&self, u: f64, v: f64) -> f64 {
        let x = ((u - self.u0) / self.spacing).clamp(0.0, (self.nu - 1) as f64);
        let y = ((v - self.v0) / self.spacing).clamp(0.0, (self.nv - 1) as f64);
        let (i, j) = ((x.floor() as usize).min(self.nu - 2), (y.floor() as usize).min(self.nv - 2));
        let (tx, ty) = (smooth(x - i as f64), smooth(y - j as f64));
        let g = |a: usize, b: usize| self.values[b * self.nu + a];
        let bottom = g(i, j) * (1.0 - tx) + g(i + 1, j) * tx;
        let top = g(i, j + 1) * (1.0 - tx) + g(i + 1, j + 1) * tx;
        bottom * (1.0 - ty) + top * ty
    }
}

impl TerrainBox {
    /// Height of the box's top at world (x, y) if (x, y) is over it.
    pub fn top_at(&self, x: f64, y: f64) -> Option<f64> {
        let (c, s) = (self.yaw_rad.cos(), self.yaw_rad.sin());
        let (dx, dy) = (x - self.center_m[0], y - self.center_m[1]);
        let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
        (u.abs() <= self.half_m[0] && v.abs() <= self.half_m[1]).then_some(self.center_m[2] + self.half_m[2])
    }
}

impl TerrainGeometry {
    /// Whether the terrain adds nothing to the floor (no geometry, or none above
    /// [`MIN_BOX_M`]).
    pub fn is_flat(&self) -> bool {
        self.boxes.iter().all(|b| b.half_m[2] * 2.0 <= MIN_BOX_M)
            && self.hfield.as_ref().is_none_or(|h| h.range_m() == (0.0, 0.0))
    }

    /// Height of the ground (the floor at 0, the heightfield, the tops of boxes) at world
    /// (x, y), m.
    pub fn height_at(&self, x: f64, y: f64) -> f64 {
        let mut z: f64 = self.floor_z_m;
        if let Some(h) = self.hfield.as_ref().and_then(|h| h.height_at(x, y)) {
            z = z.max(h);
        }
        for b in &self.boxes {
            if let Some(t) = b.top_at(x, y) {
                z = z.max(t);
            }
        }
        z
    }

    /// The highest ground under a rectangle of half sizes `half_m` (x, y, world axes) centred at
    /// (x, y), sampled every 1 cm and at the corners, m.
    pub fn highest_under(&self, x: f64, y: f64, half_m: [f64; 2]) -> f64 {
        let n = |h: f64| ((2.0 * h / 0.01).ceil() as usize).max(1);
        let (nx, ny) = (n(half_m[0]), n(half_m[1]));
        let mut z = f64::NEG_INFINITY;
        for i in 0..=nx {
            for j in 0..=ny {
                let px = x - half_m[0] + 2.0 * half_m[0] * i as f64 / nx as f64;
                let py = y - half_m[1] + 2.0 * half_m[1] * j as f64 / ny as f64;
                z = z.max(self.height_at(px, py));
            }
        }
        z
    }

    /// MJCF for the terrain, to go inside `<mujoco>` next to a model with a floor plane:
    /// an `<asset>` with the heightfield and a `<worldbody>` with its geoms. The geoms collide
    /// as the converter's floor does (`contype`/`conaffinity` 1) with friction `friction`.
    pub fn to_mjcf(&self, friction: [f64; 3]) -> String {
        let mut x = String::new();
        let friction = friction.map(num).join(" ");
        let quat = |yaw: f64| format!("{} 0 0 {}", num((yaw / 2.0).cos()), num((yaw / 2.0).sin()));
        if let Some(h) = &self.hfield {
            let _ = write!(x, "<asset>\n  {}\n</asset>\n", h.hfield_element(GEOM_PREFIX));
        }
        x.push_str("<worldbody>\n");
        let rgba = "0.45 0.42 0.36 1";
        if let Some(h) = &self.hfield {
            let _ = writeln!(
                x,
                "  <geom name=\"{GEOM_PREFIX}_hfield\" type=\"hfield\" hfield=\"{GEOM_PREFIX}\" {} contype=\"1\" conaffinity=\"1\" friction=\"{friction}\" rgba=\"{rgba}\"/>",
                h.placement()
            );
        }
        for (i, b) in self.boxes.iter().enumerate() {
            let _ = writeln!(
                x,
                "  <geom name=\"{GEOM_PREFIX}_box{i}\" type=\"box\" pos=\"{} {} {}\" size=\"{} {} {}\" quat=\"{}\" contype=\"1\" conaffinity=\"1\" friction=\"{friction}\" rgba=\"{rgba}\"/>",
                num(b.center_m[0]),
                num(b.center_m[1]),
                num(b.center_m[2]),
                num(b.half_m[0]),
                num(b.half_m[1]),
                num(b.half_m[2]),
                quat(b.yaw_rad)
            );
        }
        x.push_str("</worldbody>\n");
        x
    }
}

/// Friction of the converter's floor plane, which the terrain's geoms share.
pub const FLOOR_FRICTION: [f64; 3] = [1.0, 0.005, 0.0001];

/// `model` (a converted robot with the terrain's MJCF, [`TerrainGeometry::to_mjcf`]) with the
/// terrain's geoms at the floor plane's contact priority (so that a contact with the terrain
/// takes the same friction a contact with the floor does), and the free joint's height in
/// keyframe `home` raised so that the lowest of the `feet` bodies' geoms rests on the highest
/// ground under them ([`seat_lift`]): the robot is seated on the terrain, never inside it.
/// Returns the model and the lift, m.
///
/// # Errors
/// [`crate::Error::InvalidEdit`] when the model holds none of the terrain's geoms (an MJCF model,
/// which the terrain is not composed with); MuJoCo's errors.
pub fn settle(model: &Model, geometry: &TerrainGeometry, feet: &[usize]) -> crate::Result<(Model, f64)> {
    let ours = terrain_geoms(model);
    if ours.is_empty() {
        return Err(crate::Error::Mj(twin_mj::Error::InvalidEdit(
            "the model holds no terrain geoms: terrain is composed with URDF robots (converted by twin); \
             for an MJCF model, add the terrain to its <worldbody> yourself"
                .into(),
        )));
    }
    let floor = model.id(ObjType::Geom, "floor");
    let priority = floor.map_or(0, |g| model.geom_priority()[g]);
    let mut edit = model.edit()?;
    for &g in &ours {
        edit.set_geom_priority(g, priority)?;
    }
    if let Some(g) = floor
        && geometry.floor_z_m != 0.0
    {
        let p = model.geom_pos()[g];
        edit.set_geom_pos(g, [p[0], p[1], geometry.floor_z_m])?;
    }
    let model = edit.finish()?;
    let (Some(free), Some(key)) = (model.free_joint(), model.id(ObjType::Key, "home")) else {
        return Ok((model, 0.0));
    };
    let home = model.key_qpos(key).map(<[f64]>::to_vec).unwrap_or_default();
    let lift = seat_lift(&model, &home, geometry, feet)?.max(0.0);
    if lift == 0.0 {
        return Ok((model, 0.0));
    }
    let mut edit = model.edit()?;
    edit.set_key_qpos(key, free.qpos_adr + 2, &[home[free.qpos_adr + 2] + lift])?;
    Ok((edit.finish()?, lift))
}

/// The terrain's geoms in `model` (named [`GEOM_PREFIX`]…), in model order.
fn terrain_geoms(model: &Model) -> Vec<usize> {
    (0..model.ngeom()).filter(|&g| model.name(ObjType::Geom, g).starts_with(GEOM_PREFIX)).collect()
}

/// How far the robot in pose `qpos` must rise (negative: sink) for the lowest point of its
/// `feet` bodies' collision geoms to rest on the highest ground under them (each geom's bounding
/// circle), m.
///
/// # Errors
/// MuJoCo's errors posing the model.
pub fn seat_lift(model: &Model, qpos: &[f64], geometry: &TerrainGeometry, feet: &[usize]) -> crate::Result<f64> {
    let shared = std::sync::Arc::new(model.try_clone()?);
    let mut data = Data::new(shared.clone())?;
    data.qpos_mut().copy_from_slice(qpos);
    data.forward()?;
    let mut lift = f64::NEG_INFINITY;
    for g in 0..shared.ngeom() {
        let body = shared.geom_bodyid()[g] as usize;
        if !feet.contains(&body) || (shared.geom_contype()[g] == 0 && shared.geom_conaffinity()[g] == 0) {
            continue;
        }
        let Some(lowest) = crate::robot::geom_lowest_z(&shared, &data, g) else { continue };
        let p = data.geom_xpos()[g];
        let r = shared.geom_rbound()[g];
        lift = lift.max(geometry.highest_under(p[0], p[1], [r, r]) - lowest);
    }
    Ok(if lift.is_finite() { lift } else { 0.0 })
}

impl TerrainGeometry {
    /// `model` (which holds a terrain of the same kind and structure: the same options but for
    /// seed and continuous values) with this terrain's heights and boxes instead: a new terrain
    /// per episode without compiling a model.
    ///
    /// # Errors
    /// [`crate::Error::InvalidEdit`] when the model's terrain has other geoms (another kind or
    /// box count, or no heightfield where this one has one).
    pub fn write_into(&self, model: &Model) -> crate::Result<Model> {
        let ours = terrain_geoms(model);
        let hfield_geom =
            ours.iter().copied().find(|&g| model.name(ObjType::Geom, g) == format!("{GEOM_PREFIX}_hfield"));
        let boxes: Vec<usize> = ours.iter().copied().filter(|&g| Some(g) != hfield_geom).collect();
        if boxes.len() != self.boxes.len() || hfield_geom.is_some() != self.hfield.is_some() {
            return Err(crate::Error::Mj(twin_mj::Error::InvalidEdit(format!(
                "the model's terrain has {} boxes{}, this one {}{}: not the same terrain kind",
                boxes.len(),
                if hfield_geom.is_some() { " and a heightfield" } else { "" },
                self.boxes.len(),
                if self.hfield.is_some() { " and a heightfield" } else { "" },
            ))));
        }
        let mut edit = model.edit()?;
        if let (Some(g), Some(h)) = (hfield_geom, &self.hfield) {
            let (lo, hi) = h.range_m();
            let range = hi - lo;
            let data: Vec<f32> =
                h.heights_m.iter().map(|v| if range > 0.0 { ((v - lo) / range) as f32 } else { 0.0 }).collect();
            let id = model.geom_dataid()[g].max(0) as usize;
            edit.set_hfield(id, if range > 0.0 { range } else { 1e-6 }, &data)?;
            edit.set_geom_pos(g, [h.center_m[0], h.center_m[1], lo])?;
        }
        for (&g, b) in boxes.iter().zip(&self.boxes) {
            let q = [(b.yaw_rad / 2.0).cos(), 0.0, 0.0, (b.yaw_rad / 2.0).sin()];
            edit.set_geom_box(g, b.center_m, q, b.half_m)?;
        }
        // No mj_setConst needed for static geometry, but `finish` is the only way out.
        Ok(edit.finish()?)
    }
}

/// The robot running into the terrain: a contact of one of its geoms with a terrain box more
/// than [`COLLISION_DEPTH_M`] below the box's top (its side, not its top: a stubbed toe, a
/// shin against an obstacle).
#[derive(Debug, Clone, PartialEq)]
pub struct Collision {
    /// Simulated time, s.
    pub time_secs: f64,
    /// The terrain geom.
    pub terrain_geom: String,
    /// The robot body that hit it.
    pub robot_body: String,
    /// Contact point, world frame, m.
    pub position_m: [f64; 3],
}

impl std::fmt::Display for Collision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ran into {} at {:.2} s (x {:.2} y {:.2} z {:.3} m)",
            self.robot_body,
            self.terrain_geom,
            self.time_secs,
            self.position_m[0],
            self.position_m[1],
            self.position_m[2]
        )
    }
}

/// How far below a box's top a contact with it counts as hitting its side, m.
pub const COLLISION_DEPTH_M: f64 = 0.005;

/// Watches a rollout for the robot's first [`Collision`] with the terrain (an observer of the
/// rollout engine; scenario checks name it when an episode fails).
#[derive(Debug, Clone, Default)]
pub struct Collisions {
    /// Terrain boxes: (id, top, m).
    terrain: Vec<(usize, f64)>,
    /// The first collision of the rollout.
    pub first: Option<Collision>,
}

impl Collisions {
    /// A watcher for `model`'s terrain boxes.
    pub fn new(model: &Model) -> Collisions {
        let terrain = terrain_geoms(model)
            .into_iter()
            .filter(|&g| model.geom_kind(g) == GeomType::Box)
            .map(|g| (g, model.geom_pos()[g][2] + model.geom_size()[g][2]))
            .collect();
        Collisions { terrain, first: None }
    }
}

impl crate::engine::Observer for Collisions {
    fn start(&mut self, model: &Model, _data: &Data) -> crate::Result<()> {
        // Boxes move between episodes (a new terrain per episode): their tops are re-read.
        *self = Collisions::new(model);
        Ok(())
    }

    fn observe(&mut self, step: &crate::engine::StepView<'_>) -> crate::Result<crate::engine::Flow> {
        if self.first.is_some() || self.terrain.is_empty() {
            return Ok(crate::engine::Flow::Continue);
        }
        let model = step.data.model();
        for (geoms, p) in step.data.contact_points() {
            let (Ok(a), Ok(b)) = (usize::try_from(geoms[0]), usize::try_from(geoms[1])) else { continue };
            let (ground, robot) = match (self.terrain.iter().find(|t| t.0 == a), self.terrain.iter().find(|t| t.0 == b))
            {
                (Some(t), None) => (t, b),
                (None, Some(t)) => (t, a),
                _ => continue,
            };
            let body = model.geom_bodyid()[robot] as usize;
            if p[2] < ground.1 - COLLISION_DEPTH_M {
                self.first = Some(Collision {
                    time_secs: step.sim_secs,
                    terrain_geom: model.name(ObjType::Geom, ground.0).to_string(),
                    robot_body: model.name(ObjType::Body, body).to_string(),
                    position_m: p,
                });
                break;
            }
        }
        Ok(crate::engine::Flow::Continue)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(kind: &str) -> TerrainOptions {
        TerrainOptions { kind: kind.into(), ..TerrainOptions::default() }
    }

    #[test]
    fn keys_of_other_kinds_are_refused() {
        let mut o = opts("rough");
        o.slope_deg = Some(5.0);
        let (key, m) = o.validate().unwrap_err();
        assert_eq!(key, "slope_deg");
        assert!(m.contains("slope") && m.contains("amplitude_m"), "{m}");
        let mut o = opts("rough");
        o.difficulty = 1.5;
        assert_eq!(o.validate().unwrap_err().0, "difficulty");
        assert_eq!(opts("lava").validate().unwrap_err().0, "kind");
    }

    #[test]
    fn rough_ground_is_bounded_seeded_and_flat_at_the_start() {
        let mut o = opts("rough");
        o.amplitude_m = Some(0.01);
        let g = o.build();
        let h = g.hfield.as_ref().unwrap();
        let (lo, hi) = h.range_m();
        assert!(lo >= -0.01 - 1e-12 && hi <= 0.01 + 1e-12 && hi - lo > 0.015, "{lo} {hi}");
        assert_eq!(g.floor_z_m, -0.01);
        // The start pad (up to start − 0.5 m) is at the start's level.
        for x in [-0.5, 0.0, 0.3, 0.5] {
            assert_eq!(g.height_at(x, 0.05), 0.0, "{x}");
        }
        assert_eq!(g, o.build());
        o.seed = 1;
        assert_ne!(g, o.build());
        o.difficulty = 0.0;
        assert!(o.build().is_flat());
    }

    #[test]
    fn slope_rises_and_falls_at_its_angle() {
        let mut o = opts("slope");
        o.slope_deg = Some(5.0);
        let g = o.build();
        let tan = 5f64.to_radians().tan();
        assert!((g.height_at(2.0, 0.0) - tan).abs() < 1e-9);
        assert!((g.height_at(3.5, 0.3) - 2.0 * tan).abs() < 1e-9);
        assert!((g.height_at(5.5, -0.2) - 0.5 * tan).abs() < 1e-9);
        assert_eq!(g.height_at(0.2, 0.0), 0.0);
        // Turned by 90°: the same profile along +y.
        o.direction_deg = Some(90.0);
        assert!((o.build().height_at(0.0, 2.0) - tan).abs() < 1e-9);
    }

    #[test]
    fn boxes_of_steps_stairs_and_gaps() {
        let mut o = opts("steps");
        o.height_m = Some(0.03);
        o.difficulty = 0.5;
        let g = o.build();
        assert_eq!(g.height_at(1.5, 0.0), 0.015);
        assert_eq!(g.height_at(2.1, 0.0), 0.0);
        o.difficulty = 0.0;
        assert!(o.build().is_flat() && o.build().boxes.len() == 1);
        let g = opts("stairs").build();
        assert_eq!(g.boxes.len(), 4);
        assert!((g.height_at(1.0 + 3.0 * 0.3 + 0.1, 0.0) - 0.48).abs() < 1e-12);
        let g = opts("gaps").build();
        assert_eq!(g.height_at(0.0, 0.0), 0.3);
        assert_eq!(g.height_at(1.1, 0.0), 0.0);
        assert_eq!(g.height_at(1.4, 0.0), 0.3);
        let g = opts("obstacles").build();
        assert_eq!(g.boxes.len(), 4);
        assert!(g.boxes.iter().all(|b| b.center_m[0] >= 1.0 && b.half_m[2] == 0.05));
    }
}
