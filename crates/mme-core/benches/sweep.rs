//! Sweep throughput (samples per second) of the linear MME estimator for N = 10³…10⁶
//! samples, n = 2 and n = 4 states, one sub-step, fixed W and R. Inputs are built outside
//! the timed closure from a fixed seed.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use mme_core::{MmeConfig, NoiseSpec, WeightSpec, estimate};
use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use sysid_core::{Channel, Dataset, Experiment, LinearModel};

fn model(n: usize) -> LinearModel {
    if n == 2 {
        LinearModel::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -2.0, -0.3]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        )
        .expect("valid model")
    } else {
        LinearModel::new(
            DMatrix::from_row_slice(
                4,
                4,
                &[
                    0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, -2.0, 1.0, -0.1, 0.0, 1.0, -1.5, 0.0,
                    -0.2,
                ],
            ),
            DMatrix::from_row_slice(4, 1, &[0.0, 0.0, 1.0, 0.0]),
            DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0]),
            DMatrix::from_row_slice(4, 2, &[0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0]),
        )
        .expect("valid model")
    }
}

fn data(model: &LinearModel, len: usize) -> Dataset {
    let p = model.n_outputs();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let normal = Normal::new(0.0, 0.1).expect("valid sigma");
    let y = DMatrix::from_fn(p, len, |i, k| {
        (k as f64 * 0.01 * (i + 1) as f64).sin() + normal.sample(&mut rng)
    });
    let u = DMatrix::from_fn(1, len, |_, k| (k as f64 * 0.003).cos());
    let exp = Experiment::new(0.0, 0.01, u, y).expect("valid experiment");
    let outputs = model
        .output_names()
        .iter()
        .map(|n| Channel::new(n.clone()))
        .collect();
    Dataset::new(vec![Channel::new("u1")], outputs, vec![exp]).expect("valid dataset")
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("sweep");
    for n in [2usize, 4] {
        let m = model(n);
        let config = MmeConfig {
            w: WeightSpec::Scalar(1.0),
            noise_variance: NoiseSpec::Given(vec![0.01; m.n_outputs()]),
            substeps: Some(1),
            ..MmeConfig::default()
        };
        for len in [1_000usize, 10_000, 100_000, 1_000_000] {
            let d = data(&m, len);
            group.throughput(Throughput::Elements(len as u64));
            if len >= 100_000 {
                group.sample_size(10);
            }
            group.bench_with_input(BenchmarkId::new(format!("n{n}"), len), &d, |b, d| {
                b.iter(|| black_box(estimate(&m, d, &config).expect("sweep succeeds")))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
