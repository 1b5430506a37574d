//! Criterion bench: Levenberg–Marquardt training of a 2-5-1 network on 1000 samples for a
//! fixed number of epochs (no early stopping, no goal, so every iteration does the same
//! work), with `trainlm` and with the accelerated two-phase schedule.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use nalgebra::DMatrix;
use nn::{Acceleration, Damping, LmConfig, Mlp, ValidationSplit, train_lm};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

fn bench_lm(c: &mut Criterion) {
    let n = 1000;
    let epochs = 20;
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let x = DMatrix::<f64>::from_fn(2, n, |_, _| rng.random_range(-2.0..2.0));
    let t = DMatrix::from_fn(1, n, |_, k| (x[(0, k)]).sin() * (0.5 * x[(1, k)]).cos());
    let net = Mlp::for_data(&x, &t, &[5], 7).expect("valid data");
    let config = LmConfig {
        max_epochs: epochs,
        validation: ValidationSplit::None,
        min_gradient: 0.0,
        ..LmConfig::default()
    };
    // `trainlm`, and the two-phase schedule with geodesic acceleration (10 plain epochs,
    // then 10 with the correction's extra pass per trial step).
    let accelerated = LmConfig {
        damping: Damping::TrainlmThenGainRatio,
        acceleration: Acceleration::Geodesic,
        ..config
    };
    let mut group = c.benchmark_group("lm");
    for (name, config) in [("2-5-1", config), ("2-5-1-accelerated", accelerated)] {
        group.bench_with_input(
            BenchmarkId::new(name, format!("{n}x{epochs}epochs")),
            &(&x, &t),
            |b, (x, t)| {
                b.iter(|| {
                    let mut trained = net.clone();
                    let report = train_lm(&mut trained, x, t, &config, None).expect("valid");
                    black_box(report.train_mse)
                })
            },
        );
    }
    group.finish();
}

/// Issue 5's grid: 3 inputs, 1 output, N = 2,000 and 20,000 samples, H = 1…10 hidden
/// units, 20 LM epochs each (time per network at a fixed amount of work). The head-to-head
/// with MINPACK's LM from scipy on the same data and initial weights, to the same training
/// MSE, is `examples/lm_vs_scipy.rs` + `benches/scipy_lm.py` (see the crate README).
fn bench_lm_grid(c: &mut Criterion) {
    let mut group = c.benchmark_group("lm_grid");
    group.sample_size(10);
    for n in [2_000usize, 20_000] {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let x = DMatrix::<f64>::from_fn(3, n, |_, _| rng.random_range(-2.0..2.0));
        let t = DMatrix::from_fn(1, n, |_, k| {
            (x[(0, k)]).sin() * (0.5 * x[(1, k)]).cos() + 0.3 * x[(2, k)].tanh()
        });
        for h in 1usize..=10 {
            let net = Mlp::for_data(&x, &t, &[h], 11).expect("valid data");
            let config = LmConfig {
                max_epochs: 20,
                validation: ValidationSplit::None,
                min_gradient: 0.0,
                ..LmConfig::default()
            };
            group.bench_with_input(
                BenchmarkId::new(format!("N{n}"), format!("H{h}")),
                &(x.clone(), t.clone()),
                |b, (x, t)| {
                    b.iter(|| {
                        let mut trained = net.clone();
                        let report = train_lm(&mut trained, x, t, &config, None).expect("valid");
                        black_box(report.train_mse)
                    })
                },
            );
        }
    }
    group.finish();
}

criterion_group!(benches, bench_lm, bench_lm_grid);
criterion_main!(benches);
