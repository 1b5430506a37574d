//! Wall time of one output-error fit on a long record: a lightly damped oscillator
//! (`ẍ = −4x − 0.4ẋ + 2u`) driven by a seeded random held input, `N` samples at 0.05 s,
//! fitted from a start 20 % off in every free entry (A[1,0], A[1,1], B[1,0]) with the
//! initial state estimated. Prints N, iterations, the fitted entries and the seconds.
//!
//! `cargo run --release -p sysid-baselines --example oe_speed -- [N]` (default 200 000).
#![allow(clippy::print_stdout)]

use std::time::Instant;

use nalgebra::DMatrix;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use sysid_baselines::{OeConfig, fit_oe};
use sysid_core::{Channel, Dataset, Experiment, LinearModel, ModelNames};

fn oscillator(k: f64, c: f64, b: f64) -> LinearModel {
    LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -k, -c]),
        DMatrix::from_row_slice(2, 1, &[0.0, b]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(2, 0),
        ModelNames::numbered(2, 1, 1, 0),
    )
    .expect("valid oscillator")
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(200_000);
    let dt = 0.05;
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut level = 0.0;
    let u = DMatrix::from_fn(1, n, |_, k| {
        if k % 20 == 0 {
            level = rng.random_range(-1.0..1.0);
        }
        level
    });
    // The truth's output: the exact held-input recursion of the true model (RK4 with 50
    // sub-steps; error far below the noise it stands in for).
    let (ks, cs, bs) = (4.0, 0.4, 2.0);
    let mut x = [0.0f64, 0.0];
    let h = dt / 50.0;
    let f = |x: [f64; 2], u: f64| [x[1], -ks * x[0] - cs * x[1] + bs * u];
    let mut y = DMatrix::zeros(1, n);
    for k in 0..n {
        y[(0, k)] = x[0] + 1e-3 * rng.random_range(-1.0..1.0);
        for _ in 0..50 {
            let uk = u[(0, k)];
            let k1 = f(x, uk);
            let k2 = f([x[0] + h / 2.0 * k1[0], x[1] + h / 2.0 * k1[1]], uk);
            let k3 = f([x[0] + h / 2.0 * k2[0], x[1] + h / 2.0 * k2[1]], uk);
            let k4 = f([x[0] + h * k3[0], x[1] + h * k3[1]], uk);
            x[0] += h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]);
            x[1] += h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]);
        }
    }
    let data = Dataset::new(
        vec![Channel::new("u1")],
        vec![Channel::new("y1")],
        vec![Experiment::new(0.0, dt, u, y).expect("valid record")],
    )
    .expect("valid dataset");
    let start = oscillator(0.8 * ks, 1.2 * cs, 0.8 * bs);
    let config = OeConfig {
        free: vec!["A[1,0]".into(), "A[1,1]".into(), "B[1,0]".into()],
        ..OeConfig::default()
    };
    let clock = Instant::now();
    let fit = fit_oe(&start, &data, &config).expect("fit");
    let secs = clock.elapsed().as_secs_f64();
    let values: Vec<String> = fit
        .parameters
        .iter()
        .map(|p| format!("{} = {:.6}", p.name, p.value))
        .collect();
    println!(
        "N = {n}: {} iterations, {}, {secs:.3} s",
        fit.report.iterations.len(),
        values.join(", ")
    );
}
