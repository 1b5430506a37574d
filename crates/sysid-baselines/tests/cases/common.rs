//! Shared fixtures: a damped two-state oscillator simulated independently of the
//! output-error code (adaptive Dormand–Prince, tight tolerances), and seeded noise.

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sysid_core::integrate::DEFAULT_BLOW_UP;
use sysid_core::{
    Channel, Dataset, DpOptions, Experiment, Integrator, LinearModel, ModelNames, simulate,
};

/// True oscillator `ẍ = −4x − 0.4ẋ + 2u`, position measured.
pub const TRUE_A10: f64 = -4.0;
pub const TRUE_A11: f64 = -0.4;
pub const TRUE_B10: f64 = 2.0;
pub const TRUE_X0: [f64; 2] = [0.5, -0.2];

pub fn oscillator(a10: f64, a11: f64, b10: f64) -> LinearModel {
    LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, a10, a11]),
        DMatrix::from_row_slice(2, 1, &[0.0, b10]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(2, 0),
        ModelNames {
            states: vec!["x".into(), "v".into()],
            inputs: vec!["u".into()],
            outputs: vec!["x".into()],
            corrections: vec![],
        },
    )
    .unwrap()
}

/// A deterministic, broadband-enough input: two sines and a slow square wave.
pub fn input(len: usize, dt: f64) -> DMatrix<f64> {
    DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * dt;
        (1.3 * t).sin() + 0.5 * (3.7 * t).sin() + 0.3 * (0.4 * t).sin().signum()
    })
}

/// Noise-free outputs of `model` from `x0`, integrated with Dormand–Prince at
/// rtol 1e-12 (inputs held between samples, as the exact ZOH assumes).
pub fn simulate_outputs(
    model: &LinearModel,
    x0: &[f64],
    dt: f64,
    u: &DMatrix<f64>,
) -> DMatrix<f64> {
    let method = Integrator::DormandPrince(DpOptions {
        rtol: 1e-12,
        atol: 1e-14,
        h_min: 1e-14,
        max_steps: 1_000_000,
    });
    let states = simulate(model, x0, 0.0, dt, u, &method, DEFAULT_BLOW_UP).unwrap();
    model.c() * states
}

pub fn add_noise(y: &mut DMatrix<f64>, sigma: f64, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, sigma).unwrap();
    for v in y.iter_mut() {
        *v += normal.sample(&mut rng);
    }
}

pub fn dataset(u: DMatrix<f64>, y: DMatrix<f64>, dt: f64) -> Dataset {
    Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("x")],
        vec![Experiment::new(0.0, dt, u, y).unwrap()],
    )
    .unwrap()
}

/// The oscillator's data set: 1000 samples at 50 Hz.
pub fn oscillator_data(noise_sigma: f64, seed: u64) -> Dataset {
    let dt = 0.02;
    let u = input(1000, dt);
    let truth = oscillator(TRUE_A10, TRUE_A11, TRUE_B10);
    let mut y = simulate_outputs(&truth, &TRUE_X0, dt, &u);
    if noise_sigma > 0.0 {
        add_noise(&mut y, noise_sigma, seed);
    }
    dataset(u, y, dt)
}

/// Standard-normal white noise.
pub fn white(len: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    (0..len).map(|_| normal.sample(&mut rng)).collect()
}

/// The input, output and sample interval of a record of the independent generator
/// (`fixtures/discovery_suite/cases/<name>/<file>`, scipy, not this workspace's code).
pub fn read_case(name: &str, file: &str) -> (Vec<f64>, Vec<f64>, f64) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/discovery_suite/cases")
        .join(name)
        .join(file);
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |n: &str| header.iter().position(|h| *h == n).unwrap();
    let (ct, cu, cy) = (col("t"), col("u"), col("y"));
    let (mut t, mut u, mut y) = (Vec::new(), Vec::new(), Vec::new());
    for l in lines {
        let f: Vec<f64> = l.split(',').map(|v| v.parse().unwrap()).collect();
        t.push(f[ct]);
        u.push(f[cu]);
        y.push(f[cy]);
    }
    (u, y, t[1] - t[0])
}

/// One experiment from one input and one output series (channels `u`, `y`; the NARX
/// term names carry them).
pub fn series(u: &[f64], y: &[f64], dt: f64) -> Dataset {
    let n = u.len();
    let e = Experiment::new(
        0.0,
        dt,
        DMatrix::from_row_slice(1, n, u),
        DMatrix::from_row_slice(1, n, y),
    )
    .unwrap();
    Dataset::new(vec![Channel::new("u")], vec![Channel::new("y")], vec![e]).unwrap()
}

/// A NARX model's free-run RMSE over a one-experiment record after its delay window
/// (`y` the record's measured output).
pub fn free_run_rmse<M: sysid_core::Model>(model: &M, data: &Dataset, y: &[f64]) -> f64
where
    M::Error: std::fmt::Debug,
{
    let sim = model.simulate(&data.experiments()[0]).unwrap();
    let s = sim.initial_samples;
    ((s..y.len())
        .map(|k| (sim.outputs[(0, k)] - y[k]).powi(2))
        .sum::<f64>()
        / (y.len() - s) as f64)
        .sqrt()
}
