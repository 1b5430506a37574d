//! Regression update of the assumed model from d̂ on a system whose truth is linear.

use mme_core::{MmeConfig, NoiseSpec, UpdateConfig, estimate, update_model};
use nalgebra::DMatrix;
use sysid_core::{Experiment, Integrator, LinearModel, simulate};

use super::common::{dataset, gaussian, linear, row};

fn oscillator(k: f64, c: f64, b: f64) -> LinearModel {
    linear(
        &[0.0, 1.0, -k, -c],
        &[0.0, b],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x"], &["d"]),
    )
}

#[test]
fn update_recovers_the_true_rows_and_improves_free_run() {
    let truth_model = oscillator(2.0, 0.4, 1.5);
    let assumed = oscillator(1.0, 0.0, 1.0);
    let (dt, len, sigma) = (0.01, 3001, 0.01);
    // Multi-sine input so that x, v and u are not collinear.
    let u = DMatrix::from_fn(1, len, |_, k| {
        let t = k as f64 * dt;
        (0.7 * t).sin() + 0.6 * (2.3 * t).sin() + 0.4 * (4.1 * t + 1.0).cos()
    });
    let x0 = [0.5, 0.0];
    let truth = simulate(
        &truth_model,
        &x0,
        0.0,
        dt,
        &u,
        &Integrator::Rk4 { substeps: 4 },
        1e9,
    )
    .unwrap();
    let v = gaussian(77, len, sigma);
    let y = DMatrix::from_fn(1, len, |_, k| truth[(0, k)] + v[k]);
    let data = dataset(
        &["u"],
        &["x"],
        vec![Experiment::new(0.0, dt, u.clone(), y).unwrap()],
    );
    let config = MmeConfig {
        noise_variance: NoiseSpec::Given(vec![sigma * sigma]),
        substeps: Some(1),
        ..MmeConfig::default()
    };
    let est = estimate(&assumed, &data, &config).unwrap();
    let up = update_model(&assumed, &data, &est, &UpdateConfig::default()).unwrap();
    let reg = &up.regressions[0];
    // True rows: A[1,:] = (−2, −0.4), B[1,0] = 1.5; each within 3 effective σ.
    let want = [
        (up.model.a()[(1, 0)], -2.0, 0),
        (up.model.a()[(1, 1)], -0.4, 1),
        (up.model.b()[(1, 0)], 1.5, 2),
    ];
    for (got, truth, c) in want {
        let s = reg.coefficients[c].sigma_effective;
        assert!(
            (got - truth).abs() <= 3.0 * s,
            "{}: {got} vs {truth} ± 3·{s}",
            reg.coefficients[c].regressor
        );
        // The naive σ is optimistic: autocorrelated residuals inflate it.
        assert!(reg.coefficients[c].sigma < s);
    }
    // The row E does not reach stays exactly as it was (E's first row is 0).
    assert!(
        (up.model.a()[(0, 1)] - 1.0).abs() < f64::EPSILON
            && up.model.a()[(0, 0)].abs() < f64::EPSILON
    );
    assert!(up.model.b()[(0, 0)].abs() < f64::EPSILON);
    // Free run from the true initial state: the updated model tracks the truth far better.
    let err = |m: &LinearModel| {
        let x = simulate(m, &x0, 0.0, dt, &u, &Integrator::Rk4 { substeps: 4 }, 1e9).unwrap();
        let e: Vec<f64> = row(&x, 0)
            .iter()
            .zip(row(&truth, 0))
            .map(|(a, b)| a - b)
            .collect();
        (e.iter().map(|v| v * v).sum::<f64>() / len as f64).sqrt()
    };
    let (before, after) = (err(&assumed), err(&up.model));
    assert!(after < 0.1 * before, "free-run RMS {before} → {after}");
}
