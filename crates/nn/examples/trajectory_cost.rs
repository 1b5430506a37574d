//! CPU cost of [`train_on_trajectories`] (multiple shooting of the hybrid model), for
//! before/after measurements of the shooting code: a noise-free record of a teacher
//! hybrid model (damped oscillator `ẍ = −x − 0.2ẋ + u` plus a 3-3-1 network correction,
//! 2,000 samples at 0.05 s, RK4 with 16 sub-steps), a student network (the teacher's
//! weights perturbed by ±0.3, `ChaCha8Rng` seed 1) trained for 10 accepted steps on
//! windows of 40 samples. Prints the process CPU time (all threads) of each of `REPEATS`
//! runs, their minimum, and the training-objective history in full precision, so that two
//! builds can be compared for speed and for identical results.
//!
//! Run: `RAYON_NUM_THREADS=1 cargo run --release -p nn --example trajectory_cost`.

#![allow(clippy::print_stdout)]

use nalgebra::DMatrix;
use nn::{
    Architecture, Mlp, NetCorrection, ShootingRecord, TrajectoryConfig, train_on_trajectories,
};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use sysid_core::{CorrectedModel, Experiment, Integrator, LinearModel};

/// Runs; the reported time is the minimum.
const REPEATS: usize = 5;

/// CPU time of the process (all threads), s.
fn cpu_seconds() -> f64 {
    let t = rustix::time::clock_gettime(rustix::time::ClockId::ProcessCPUTime);
    t.tv_sec as f64 + 1e-9 * t.tv_nsec as f64
}

fn assumed() -> LinearModel {
    LinearModel::new(
        DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -1.0, -0.2]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
    )
    .expect("shapes fit")
}

fn teacher() -> Mlp {
    let mut net = Mlp::new(&Architecture::single(3, 3, 1), 21).expect("architecture");
    let mut w = net.weights().to_vec();
    for v in &mut w[12..] {
        *v *= 0.5;
    }
    net.set_weights(&w).expect("weights");
    net
}

fn main() {
    let (n, dt) = (2000, 0.05);
    let lin = assumed();
    let mut truth = CorrectedModel::new(
        lin.clone(),
        NetCorrection::new(teacher(), 2).expect("split"),
        lin.e().clone(),
        lin.c().clone(),
        vec!["x".into()],
    )
    .expect("shapes fit");
    truth.integrator = Integrator::Rk4 { substeps: 16 };
    let u = DMatrix::from_fn(1, n, |_, k| {
        let t = k as f64 * dt;
        1.5 * (0.7 * t).sin() + 0.8 * (1.9 * t).sin()
    });
    let xs = truth
        .simulate_states(&[0.5, 0.0], 0.0, dt, &u)
        .expect("teacher simulates");
    let exp = Experiment::new(0.0, dt, u, lin.c() * &xs).expect("record");
    let records = [ShootingRecord {
        experiment: &exp,
        states: &xs,
    }];
    let config = TrajectoryConfig {
        window: 40,
        max_iterations: 10,
        ..TrajectoryConfig::default()
    };
    let mut student = teacher();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let w: Vec<f64> = student
        .weights()
        .iter()
        .map(|v| v + rng.random_range(-0.3..0.3))
        .collect();
    student.set_weights(&w).expect("weights");

    let mut times = Vec::new();
    let mut history = Vec::new();
    for _ in 0..REPEATS {
        let mut model = CorrectedModel::new(
            lin.clone(),
            NetCorrection::new(student.clone(), 2).expect("split"),
            lin.e().clone(),
            lin.c().clone(),
            vec!["x".into()],
        )
        .expect("shapes fit");
        let start = cpu_seconds();
        let report =
            train_on_trajectories(&mut model, &records, &[], &config, None).expect("training runs");
        times.push(cpu_seconds() - start);
        history = report.train_history;
    }
    let min = times.iter().copied().fold(f64::INFINITY, f64::min);
    println!("cpu_s per run: {times:.3?}");
    println!("cpu_s min: {min:.3}");
    let history: Vec<String> = history.iter().map(|v| format!("{v:e}")).collect();
    println!("train_history: {}", history.join(" "));
}
