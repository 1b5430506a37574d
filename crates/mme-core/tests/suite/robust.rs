//! Issue 21: one wild sample (x = 20 in a ±5 signal with noise σ = 0.3) must not move `W`
//! by orders of magnitude. The plain covariance constraint collapses `W`; the Huber
//! estimate keeps it near the clean value, reports the sample, and agrees with an
//! independent check: the plain estimate with that sample marked missing.

use mme_core::{MmeConfig, NoiseSpec, RobustConfig, estimate, estimate_robust, screen_outliers};
use nalgebra::DMatrix;
use sysid_core::{Dataset, Experiment, LinearModel, MmeEstimate};

use super::common::{dataset, gaussian, linear};

const SIGMA: f64 = 0.3;
const WILD: usize = 400;

/// Assumed oscillator ω = 1 rad/s, position measured, correction in the velocity equation.
fn model() -> LinearModel {
    linear(
        &[0.0, 1.0, -1.0, -0.1],
        &[0.0, 1.0],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x"], &["d"]),
    )
}

/// 1000 samples at 0.02 s of a ±5 signal the model cannot follow exactly, noise σ = 0.3;
/// with `wild`, sample 400 reads 20; with `missing`, it is absent instead.
fn data(wild: bool, missing: bool) -> Dataset {
    let len = 1000;
    let noise = gaussian(5, len, SIGMA);
    let mut y = DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * 0.02;
        4.0 * (1.3 * t).sin() + (2.9 * t).cos() + noise[k]
    });
    if wild {
        y[(0, WILD)] = 20.0;
    }
    if missing {
        y[(0, WILD)] = f64::NAN;
    }
    let u = DMatrix::from_fn(1, len, |_, k| (0.5 * k as f64 * 0.02).sin());
    dataset(
        &["u"],
        &["x"],
        vec![Experiment::new(0.0, 0.02, u, y).unwrap()],
    )
}

fn config() -> MmeConfig {
    MmeConfig {
        noise_variance: NoiseSpec::Given(vec![SIGMA * SIGMA]),
        ..MmeConfig::default()
    }
}

fn w_of(e: &MmeEstimate) -> f64 {
    e.w[(0, 0)]
}

#[test]
fn one_wild_sample_cannot_move_w_under_the_robust_option() {
    let m = model();
    let clean = estimate(&m, &data(false, false), &config()).unwrap();
    let plain = estimate(&m, &data(true, false), &config()).unwrap();
    // The failure of the issue: the plain constraint collapses W by orders of magnitude.
    assert!(
        w_of(&plain) < 1e-2 * w_of(&clean),
        "plain {} clean {}",
        w_of(&plain),
        w_of(&clean)
    );

    let robust =
        estimate_robust(&m, &data(true, false), &config(), &RobustConfig::default()).unwrap();
    let w_rob = w_of(&robust.output.estimate);
    assert!(robust.converged, "{} passes", robust.passes);
    assert!(
        w_rob > w_of(&clean) / 3.0 && w_rob < w_of(&clean) * 3.0,
        "robust {w_rob} clean {}",
        w_of(&clean)
    );
    // The wild sample is reported first, about (20 − 4 sin(1.3·8) − cos(2.9·8))/0.3 σ out.
    let top = &robust.outliers[0];
    assert_eq!(
        (top.experiment, top.sample, top.channel.as_str()),
        (0, WILD, "x")
    );
    assert!(top.sigmas > 40.0, "{top:?}");
    assert!((top.time - WILD as f64 * 0.02).abs() < 1e-12);
    assert!(robust.outliers.len() <= 2, "{:?}", robust.outliers);

    // Independent check: the plain estimate with the sample marked missing.
    let gap = estimate(&m, &data(false, true), &config()).unwrap();
    let (xr, xg) = (
        &robust.output.estimate.experiments[0].states,
        &gap.experiments[0].states,
    );
    let worst = (0..xr.ncols())
        .map(|k| (xr[(0, k)] - xg[(0, k)]).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.5 * SIGMA, "largest position difference {worst}");

    // On clean data the robust option keeps W near the plain value (the κ(c) target).
    let robust_clean =
        estimate_robust(&m, &data(false, false), &config(), &RobustConfig::default()).unwrap();
    let ratio = w_of(&robust_clean.output.estimate) / w_of(&clean);
    assert!(ratio > 0.5 && ratio < 2.0, "ratio {ratio}");
    assert!(
        robust_clean.outliers.is_empty(),
        "{:?}",
        robust_clean.outliers
    );
}

#[test]
fn the_screen_finds_the_wild_sample_without_an_estimate() {
    let found = screen_outliers(
        &data(true, false),
        &["x".to_string()],
        &[SIGMA * SIGMA],
        8.0,
    )
    .unwrap();
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].sample, WILD);
}

/// A sine at 0.4 of the Nyquist frequency (2.5 samples per period): the cubic through
/// each sample's neighbours misses it by 2.2 × its value, thousands of noise σ. The screen
/// measures a sample against the record's robust spread of those misses when it is larger
/// than σ, so it flags the one wild sample and nothing else (in units of σ alone it
/// flagged 200 of the 1 000 clean samples, every local maximum of the misses).
#[test]
fn the_screen_finds_the_wild_sample_of_an_oscillation_near_nyquist() {
    let (n, sigma, wild) = (1000usize, 1e-3, 500usize);
    let noise = gaussian(77, n, sigma);
    let mut y: Vec<f64> = (0..n)
        .map(|k| (0.8 * std::f64::consts::PI * k as f64 + 0.3).sin() + noise[k])
        .collect();
    let screen = |y: &[f64]| {
        let exp = Experiment::new(
            0.0,
            0.01,
            DMatrix::zeros(1, n),
            DMatrix::from_row_slice(1, n, y),
        )
        .unwrap();
        screen_outliers(
            &dataset(&["u"], &["x"], vec![exp]),
            &["x".to_string()],
            &[sigma * sigma],
            8.0,
        )
        .unwrap()
    };
    let clean = screen(&y);
    assert!(
        clean.is_empty(),
        "{} flagged: {:?}",
        clean.len(),
        clean.first()
    );
    y[wild] += 40.0;
    let found = screen(&y);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].sample, wild);
}
