//! Shared data generators (seeded).

use nalgebra::DMatrix;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};

/// `rows × n` inputs uniform in [lo, hi).
pub fn uniform_inputs(rows: usize, n: usize, lo: f64, hi: f64, seed: u64) -> DMatrix<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    DMatrix::from_fn(rows, n, |_, _| rng.random_range(lo..hi))
}

/// `n` evenly spaced points on [lo, hi] as a `1 × n` matrix.
pub fn grid(n: usize, lo: f64, hi: f64) -> DMatrix<f64> {
    DMatrix::from_fn(1, n, |_, k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
}

/// Add N(0, σ²) noise to every entry.
pub fn add_noise(m: &DMatrix<f64>, sigma: f64, seed: u64) -> DMatrix<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).expect("valid σ");
    m.map(|v| v + normal.sample(&mut rng))
}

/// Plain mean of squared differences, computed independently of the crate.
pub fn mse(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm_squared() / a.len() as f64
}

/// Run `f` on a rayon pool of `threads` threads.
pub fn with_threads<R: Send>(threads: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}
