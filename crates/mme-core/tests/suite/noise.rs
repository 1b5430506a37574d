//! Noise variance estimated from the data (maximum restricted marginal likelihood) on the
//! cubic MSD, whose assumed model is wrong, and on a linear system driven by process
//! noise, whose stochastic model is exactly the one the likelihood assumes.

use mme_core::{MmeConfig, NoiseMethod, NoiseSpec, WeightSpec, estimate_with_report};
use nalgebra::DMatrix;
use sysid_core::Experiment;

use super::common::{dataset, gaussian, linear, msd_assumed, msd_data};

#[test]
fn noise_variance_of_the_cubic_msd_within_20_percent_at_two_levels() {
    for (noise_var, seed) in [(0.09, 41u64), (0.0025, 42)] {
        let (data, _) = msd_data(2001, noise_var, seed);
        let config = MmeConfig {
            noise_variance: NoiseSpec::Auto,
            ..MmeConfig::default()
        };
        let out = estimate_with_report(&msd_assumed(), &data, &config).unwrap();
        let report = &out.noise;
        assert_eq!(report.method, NoiseMethod::MarginalLikelihood);
        let ml = report.variance[0];
        let diff = report.difference_based[0];
        assert!((ml / noise_var - 1.0).abs() < 0.2, "ML {ml} vs {noise_var}");
        // The difference-based start is reported as a cross-check; second differences
        // of a signal moving ≲0.2 per sample leave it within a few per cent here.
        assert!(
            (diff / noise_var - 1.0).abs() < 0.2,
            "difference-based {diff} vs {noise_var}"
        );
        assert_eq!(out.estimate.noise_variance, report.variance);
    }
}

#[test]
fn noise_variances_of_two_channels_with_process_noise() {
    // Double integrator driven by white acceleration noise (intensity 4 per second):
    // exactly the stochastic model behind the likelihood, with W = 1/4 per unit time.
    // Position and velocity are both measured, with different noise variances.
    let model = linear(
        &[0.0, 1.0, 0.0, 0.0],
        &[0.0, 1.0],
        &[1.0, 0.0, 0.0, 1.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x", "v"], &["d"]),
    );
    let (len, dt) = (4000usize, 0.01);
    let w_acc = gaussian(50, len, (4.0_f64 / dt).sqrt());
    let mut x = [0.0_f64, 0.0];
    let mut states = DMatrix::zeros(2, len);
    for k in 0..len {
        states[(0, k)] = x[0];
        states[(1, k)] = x[1];
        let a = w_acc[k] + (0.5 * k as f64 * dt).sin();
        x = [x[0] + dt * x[1] + 0.5 * dt * dt * a, x[1] + dt * a];
    }
    let (r1, r2) = (0.01_f64, 0.04_f64);
    let v1 = gaussian(51, len, r1.sqrt());
    let v2 = gaussian(52, len, r2.sqrt());
    let y = DMatrix::from_fn(2, len, |i, k| {
        states[(i, k)] + if i == 0 { v1[k] } else { v2[k] }
    });
    let u = DMatrix::from_fn(1, len, |_, k| (0.5 * k as f64 * dt).sin());
    let data = dataset(
        &["u"],
        &["x", "v"],
        vec![Experiment::new(0.0, dt, u, y).unwrap()],
    );
    let config = MmeConfig {
        w: WeightSpec::Scalar(1.0),
        noise_variance: NoiseSpec::Auto,
        substeps: Some(1),
        ..MmeConfig::default()
    };
    let out = estimate_with_report(&model, &data, &config).unwrap();
    let v = &out.noise.variance;
    assert!(
        (v[0] / r1 - 1.0).abs() < 0.2 && (v[1] / r2 - 1.0).abs() < 0.2,
        "{v:?}"
    );
    // The likelihood's W scale is that of the simulated process noise (1/4), to within
    // the spread a 40 s record allows (a factor of 2 either way).
    let alpha = out.noise.likelihood_alpha.unwrap();
    assert!((0.125..0.5).contains(&alpha), "alpha {alpha}");
}
