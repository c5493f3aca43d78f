//! The ray setup depth cameras and LiDARs share: a fixed fan of unit rays in the sensor's
//! frame, turned into the world at each reading and cast by bundles ([`RayScene`]) on the
//! calling thread, rayon's global pool or a pool of its own; and the seeded noise stream of
//! reading `k`.

use crate::error::{Error, Result};
use crate::mj::{Data, RayFilter, RayHit, RayScene, RayStats};
use nalgebra::{Rotation3, Vector3};
use rand::SeedableRng;

/// A sensor's rays: unit directions in its frame, ordered so that each run of `bundle`
/// consecutive rays is close in direction (an image tile, a stretch of a ring).
pub(crate) struct RayFan {
    dirs_sensor: Vec<Vector3<f64>>,
    bundle: usize,
    /// 0: rayon's global pool; 1: the calling thread; more: `pool`.
    threads: usize,
    pool: Option<rayon::ThreadPool>,
    dirs_world: Vec<[f64; 3]>,
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
            dirs_sensor,
            bundle,
            threads,
            pool,
            dirs_world: Vec::new(),
            hits: Vec::new(),
            stats: RayStats::default(),
        })
    }

    /// Casts every ray from `origin` with the sensor turned by `world_from_sensor`, against
    /// the geoms of `data` (its last forward pass) that `filter` lets through, up to
    /// `max_dist_m`: the nearest hit of each ray, in the fan's order. The result is the same
    /// for any thread count.
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
    ) -> Result<&[Option<RayHit>]> {
        self.dirs_world.clear();
        self.dirs_world.extend(self.dirs_sensor.iter().map(|r| {
            let d = world_from_sensor * r;
            [d.x, d.y, d.z]
        }));
        self.hits.clear();
        self.hits.resize(self.dirs_world.len(), None);
        let scene = RayScene::new(data, filter);
        let (dirs, hits, bundle) = (&self.dirs_world, &mut self.hits, self.bundle);
        self.stats = match (&self.pool, self.threads) {
            (Some(pool), _) => pool.install(|| scene.cast_bundles(origin, dirs, bundle, max_dist_m, true, hits))?,
            (None, 1) => scene.cast_bundles(origin, dirs, bundle, max_dist_m, false, hits)?,
            (None, _) => scene.cast_bundles(origin, dirs, bundle, max_dist_m, true, hits)?,
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
