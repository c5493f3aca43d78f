//! The random numbers of sysid's synthetic data (logs with known truth for tests, benches and
//! `twin excite --synthetic`): one seeded generator, uniform and Gaussian draws.
//!
//! The stream is the workspace's one generator, `rand_chacha`'s ChaCha8 (as twin-core's engine
//! and randomize's episodes), seeded with `seed_from_u64`; Gaussian draws are `rand_distr`'s
//! `StandardNormal`, as the engine's sensor noise.

use rand::{Rng as _, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Deterministic pseudo-random numbers (ChaCha8), uniform and Gaussian.
#[derive(Debug, Clone)]
pub struct Rng(ChaCha8Rng);

impl Rng {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Rng {
        Rng(ChaCha8Rng::seed_from_u64(seed))
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0.random::<f64>()
    }
    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        self.0.sample(StandardNormal)
    }
}
