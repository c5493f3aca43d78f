//! The ray setup depth cameras and LiDARs share: a fixed fan of unit rays in the sensor's
//! frame, turned into the world at each reading (a group of rays at a time) and cast by bundles ([`RayScene`]) on the
//! calling thread, rayon's global pool or a pool of its own; and the seeded noise stream of
//! reading `k`.

use crate::error::{Error, Result};
use crate::mj::{Data, RayFilter, RayHit, RayScene, RayStats};
use nalgebra::{Rotation3, Vector3};
use rand::SeedableRng;

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
