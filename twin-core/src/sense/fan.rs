//! The ray setup depth cameras and LiDARs share: a fixed fan of unit rays in the sensor's
//! frame, turned into the world at each reading (a group of rays at a time) and cast by bundles ([`RayScene`]) on the
//! calling thread, rayon's global pool or a pool of its own; and the seeded noise stream of
//! reading `k`; and the options both kinds take ([`RayOptions`]), checked once.

use crate::error::{Error, Result};
use crate::mj::{Data, RayFilter, RayHit, RayScene, RayStats};
use nalgebra::{Rotation3, Vector3};
use rand::SeedableRng;

/// What every ray sensor (a [`super::DepthCamera`], a [`super::Lidar`]) is given besides its
/// pattern of rays: range limits, noise, rate, threads and the geoms it sees. The defaults are a
/// LiDAR's; [`super::DepthCameraOptions::default`] changes `min_range_m` and `rate_hz`.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct RayOptions {
    /// Nearest range measured, metres, the near clip as in Gazebo: a LiDAR's minimum range
    /// along the beam (`<range><min>`), a depth camera's in depth, as a renderer's near plane
    /// (`<clip><near>`): nearer geometry is not seen and what lies behind it is measured, so a
    /// sensor inside its own housing or head sees out of it. (default: 0.1)
    #[default(0.1)]
    pub min_range_m: f64,
    /// Farthest range measured, metres; farther returns read `+Inf` in a scan, NaN in a depth
    /// image. (default: 10.0)
    #[default(10.0)]
    pub max_range_m: f64,
    /// Standard deviation of the Gaussian noise added to each valid return, metres (0: none).
    /// (default: 0.0)
    pub noise_std_m: f64,
    /// Seed of the noise; reading `k` (frame or scan) draws from stream `k` of it, so a run is
    /// reproducible. (default: 0)
    pub seed: u64,
    /// Readings per second when the sensor is published on a schedule, Hz. (default: 10.0)
    #[default(10.0)]
    pub rate_hz: f64,
    /// Threads casting rays: 0 uses rayon's global pool, 1 casts on the calling thread, more
    /// builds a pool of that many for this sensor. The reading is the same for any count.
    /// (default: 0)
    pub threads: usize,
    /// Which geoms the rays see. (default: [`RayFilter::default`]: groups 0–2, i.e. MJCF geoms
    /// and URDF visuals)
    pub filter: RayFilter,
}

impl RayOptions {
    /// Checks the range limits and the noise of the sensor named in errors as `what`.
    ///
    /// # Errors
    /// [`Error::OutOfRange`] for a range that is not 0 ≤ min < max (both finite) or a negative
    /// or non-finite noise.
    pub(crate) fn check(&self, what: &str) -> Result<()> {
        let (lo, hi) = (self.min_range_m, self.max_range_m);
        if !(lo >= 0.0 && hi > lo && hi.is_finite()) {
            return Err(Error::OutOfRange {
                what: what.to_string(),
                message: format!("range {lo} … {hi} m: give 0 ≤ min < max, both finite"),
            });
        }
        if !(self.noise_std_m >= 0.0 && self.noise_std_m.is_finite()) {
            return Err(Error::OutOfRange {
                what: what.to_string(),
                message: format!("range noise {} m: give a standard deviation ≥ 0", self.noise_std_m),
            });
        }
        Ok(())
    }
}

/// A sensor's rays: unit directions in its frame, ordered so that each run of `bundle`
/// consecutive rays is close in direction (an image tile, a stretch of a ring).
pub(crate) struct RayFan {
    dirs_sensor: Vec<[f64; 3]>,
    bundle: usize,
    /// 0: rayon's global pool; 1: the calling thread; more: `pool`.
    threads: usize,
    pool: Option<rayon::ThreadPool>,
    hits: Vec<Option<RayHit>>,
    stats: RayStats,
}

impl std::fmt::Debug for RayFan {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RayFan")
            .field("rays", &self.dirs_sensor.len())
            .field("bundle", &self.bundle)
            .field("threads", &self.threads)
            .finish()
    }
}

impl RayFan {
    /// Rays along `dirs_sensor` (unit vectors), culled `bundle` at a time, cast on `threads`
    /// threads (0: rayon's global pool; 1: the calling thread; more: a pool of that many,
    /// named in errors as `what`).
    ///
    /// # Errors
    /// [`Error::Options`] when the thread pool can't be built.
    pub(crate) fn new(dirs_sensor: Vec<Vector3<f64>>, bundle: usize, threads: usize, what: &str) -> Result<RayFan> {
        let pool = match threads {
            0 | 1 => None,
            n => Some(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build()
                    .map_err(|e| Error::Options(format!("{what}: can't start {n} ray threads: {e}")))?,
            ),
        };
        Ok(RayFan {
            dirs_sensor: dirs_sensor.iter().map(|d| [d.x, d.y, d.z]).collect(),
            bundle,
            threads,
            pool,
            hits: Vec::new(),
            stats: RayStats::default(),
        })
    }

    /// Casts every ray from `origin` with the sensor turned by `world_from_sensor`, against
    /// the geoms of `data` (its last forward pass) that `filter` lets through, up to
    /// `max_dist_m`, clipping what is nearer than `clip_m` along each ray (as
    /// [`RayScene::cast_bundles`]): the nearest hit of each ray, in the fan's order. The
    /// result is the same for any thread count.
    ///
    /// # Errors
    /// None in practice (the output always has the fan's length); passed on from
    /// [`RayScene::cast_bundles`].
    pub(crate) fn cast(
        &mut self,
        data: &Data,
        filter: &RayFilter,
        origin: [f64; 3],
        world_from_sensor: &Rotation3<f64>,
        max_dist_m: f64,
        clip_m: &[f64],
    ) -> Result<&[Option<RayHit>]> {
        self.hits.clear();
        self.hits.resize(self.dirs_sensor.len(), None);
        let scene = RayScene::new(data, filter);
        let m = world_from_sensor.matrix();
        let rot: [f64; 9] = std::array::from_fn(|i| m[(i / 3, i % 3)]);
        let (dirs, hits, bundle) = (&self.dirs_sensor, &mut self.hits, self.bundle);
        let cast = |parallel, hits: &mut [Option<RayHit>]| {
            scene.cast_bundles(origin, &rot, dirs, bundle, max_dist_m, clip_m, parallel, hits)
        };
        self.stats = match (&self.pool, self.threads) {
            (Some(pool), _) => pool.install(|| cast(true, hits))?,
            (None, 1) => cast(false, hits)?,
            (None, _) => cast(true, hits)?,
        };
        Ok(&self.hits)
    }

    /// What the last [`RayFan::cast`] cost (rays, bounding-sphere and exact geom tests).
    pub(crate) fn last_stats(&self) -> RayStats {
        self.stats
    }
}

/// The noise generator of reading `k` of a sensor seeded `seed`: stream `k` of the seed, so a
/// reading's noise depends neither on the thread count nor on earlier readings' ray counts.
pub(crate) fn noise_rng(seed: u64, k: u64) -> rand_chacha::ChaCha8Rng {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(k);
    rng
}
