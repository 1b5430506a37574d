//! Helpers: datasets, seeded noise, small truth systems.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sysid_core::{Channel, Dataset, Dynamics, Experiment, LinearModel, ModelNames};

/// A dataset with the given channel names.
pub fn dataset(inputs: &[&str], outputs: &[&str], experiments: Vec<Experiment>) -> Dataset {
    Dataset::new(
        inputs.iter().map(|n| Channel::new(*n)).collect(),
        outputs.iter().map(|n| Channel::new(*n)).collect(),
        experiments,
    )
    .unwrap()
}

/// `len` samples of N(0, σ²) from a seeded ChaCha8 stream.
pub fn gaussian(seed: u64, len: usize, sigma: f64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).unwrap();
    (0..len).map(|_| normal.sample(&mut rng)).collect()
}

/// A linear model with names.
pub fn linear(
    a: &[f64],
    b: &[f64],
    c: &[f64],
    e: &[f64],
    n: usize,
    names: (&[&str], &[&str], &[&str], &[&str]),
) -> LinearModel {
    let (m, p, q) = (names.1.len(), names.2.len(), names.3.len());
    let v = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    LinearModel::with_names(
        DMatrix::from_row_slice(n, n, a),
        DMatrix::from_row_slice(n, m, b),
        DMatrix::from_row_slice(p, n, c),
        DMatrix::from_row_slice(n, q, e),
        ModelNames {
            states: v(names.0),
            inputs: v(names.1),
            outputs: v(names.2),
            corrections: v(names.3),
        },
    )
    .unwrap()
}

/// Coefficient of determination of `est` against `truth` (1 − SSE/SST).
pub fn r2(truth: &[f64], est: &[f64]) -> f64 {
    let mean = truth.iter().sum::<f64>() / truth.len() as f64;
    let sse: f64 = truth.iter().zip(est).map(|(t, e)| (t - e).powi(2)).sum();
    let sst: f64 = truth.iter().map(|t| (t - mean).powi(2)).sum();
    1.0 - sse / sst
}

/// Cubic mass–spring–damper `m ẍ + c ẋ + k(x + x³) = u` (thesis §2.5), m = 1, c = 0.1,
/// k = 0.5.
pub struct CubicMsd;

impl CubicMsd {
    pub const M: f64 = 1.0;
    pub const C: f64 = 0.1;
    pub const K: f64 = 0.5;
    /// The truth correction relative to the assumed model `ẍ = −(k/m)x + u/m`.
    pub fn correction(x: f64, v: f64) -> f64 {
        -(Self::K / Self::M) * x * x * x - (Self::C / Self::M) * v
    }
}

impl Dynamics for CubicMsd {
    fn n_states(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        dx[0] = x[1];
        dx[1] = (u[0] - Self::C * x[1] - Self::K * (x[0] + x[0].powi(3))) / Self::M;
    }
}

/// Thesis §2.5 data: `u = sin t`, `x(0) = (5, 0)`, position sampled every 0.01 s with
/// N(0, `noise_var`) noise. Returns the dataset (input `u`, output `x`) and the true
/// states (`2 × len`).
pub fn msd_data(len: usize, noise_var: f64, seed: u64) -> (Dataset, DMatrix<f64>) {
    let dt = 0.01;
    let u = DMatrix::from_fn(1, len, |_, k| (k as f64 * dt).sin());
    // RK4 with 10 sub-steps per sample: local error ~(ωh)⁵/120 ≈ 1e-12 at ω ≈ 4 rad/s.
    let truth = sysid_core::simulate(
        &CubicMsd,
        &[5.0, 0.0],
        0.0,
        dt,
        &u,
        &sysid_core::Integrator::Rk4 { substeps: 10 },
        1e9,
    )
    .unwrap();
    let v = gaussian(seed, len, noise_var.sqrt());
    let y = DMatrix::from_fn(1, len, |_, k| truth[(0, k)] + v[k]);
    (
        dataset(
            &["u"],
            &["x"],
            vec![Experiment::new(0.0, dt, u, y).unwrap()],
        ),
        truth,
    )
}

/// The thesis's assumed model for the cubic MSD: `ẋ1 = x2`, `ẋ2 = −(k/m)x1 + u/m + d`.
pub fn msd_assumed() -> LinearModel {
    let k_m = CubicMsd::K / CubicMsd::M;
    linear(
        &[0.0, 1.0, -k_m, 0.0],
        &[0.0, 1.0 / CubicMsd::M],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x"], &["d"]),
    )
}

/// Row `i` of a matrix as a vector.
pub fn row(m: &DMatrix<f64>, i: usize) -> Vec<f64> {
    m.row(i).iter().copied().collect()
}

/// A record whose inputs are linear between samples: MME told so (`d_foh`, d̂ RMS)
/// leaves d̂ below 1e-6 of the `forcing` RMS, and told the inputs are held (`d_zoh`)
/// needs a correction at least 1e4 times larger and above a tenth of the forcing.
pub fn assert_hold_margins(d_foh: f64, d_zoh: f64, forcing: f64) {
    assert!(
        d_foh < 1e-6 * forcing,
        "Foh d̂ RMS {d_foh} vs forcing {forcing}"
    );
    assert!(d_zoh > 1e4 * d_foh, "Zoh d̂ RMS {d_zoh} vs Foh {d_foh}");
    assert!(
        d_zoh > 0.1 * forcing,
        "Zoh d̂ RMS {d_zoh} vs forcing {forcing}"
    );
}
