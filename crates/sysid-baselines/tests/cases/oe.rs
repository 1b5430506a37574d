//! Output-error fits against known parameters: exact recovery without noise, calibrated
//! ±1σ with noise, stability verdicts, and k-step prediction with the exact model.

use nalgebra::DMatrix;
use sysid_baselines::{
    InitialStateTreatment, OeConfig, OeModel, Stability, StabilityVerdict, X0Policy, fit_oe,
};
use sysid_core::{Model, Termination};

use crate::common::{TRUE_A10, TRUE_A11, TRUE_B10, TRUE_X0, oscillator, oscillator_data};

fn free() -> Vec<String> {
    vec!["A[1,0]".into(), "A[1,1]".into(), "B[1,0]".into()]
}

/// From a start 20–50 % off, the noise-free fit recovers every parameter and the initial
/// state. The data come from an adaptive integrator at rtol 1e-12, so the data–model
/// mismatch is ~1e-12 and the parameters are determined far better than 1e-6.
#[test]
fn recovers_noise_free_parameters_from_a_perturbed_start() {
    let data = oscillator_data(0.0, 0);
    let start = oscillator(-3.0, -0.6, 1.6);
    let fit = fit_oe(
        &start,
        &data,
        &OeConfig {
            free: free(),
            ..OeConfig::default()
        },
    )
    .unwrap();
    assert_eq!(fit.report.termination, Some(Termination::Converged));
    let truth = [TRUE_A10, TRUE_A11, TRUE_B10];
    for (p, t) in fit.parameters.iter().zip(truth) {
        assert!((p.value - t).abs() < 1e-6, "{}: {} vs {t}", p.name, p.value);
    }
    for (x, t) in fit.initial_states[0].iter().zip(TRUE_X0) {
        assert!((x.value - t).abs() < 1e-6, "{}: {} vs {t}", x.name, x.value);
    }
    assert_eq!(fit.stability.verdict, StabilityVerdict::Stable);
    assert!(fit.sse < 1e-16, "{}", fit.sse);
    // The fitted model reproduces the data in free run.
    let a = fit.model.model.a();
    assert!((a[(1, 0)] - TRUE_A10).abs() < 1e-6 && (a[(0, 1)] - 1.0).abs() < 1e-15);
}

/// With white measurement noise (σ = 0.02, about 4 % of the output's spread) the
/// reported σ is calibrated: over 40 noise realisations each estimate lies within
/// ±2σ̂ of the truth in about 95 % of them (Binomial(40, 0.954): mean 38.2, s.d. 1.3; we
/// require ≥ 34, 3 s.d. below), and the spread of the estimates matches the mean σ̂
/// (the sample s.d. of 40 draws has a relative s.d. of 1/√78 = 0.11; allow ±35 %).
#[test]
fn noisy_estimates_lie_within_two_sigma() {
    let truth = [TRUE_A10, TRUE_A11, TRUE_B10];
    let start = oscillator(-3.5, -0.3, 2.3);
    let runs = 40;
    let mut within = [0usize; 3];
    let mut values: Vec<[f64; 3]> = Vec::new();
    let mut sigmas = [0.0; 3];
    for seed in 0..runs {
        let data = oscillator_data(0.02, 1000 + seed);
        let fit = fit_oe(
            &start,
            &data,
            &OeConfig {
                free: free(),
                ..OeConfig::default()
            },
        )
        .unwrap();
        let mut v = [0.0; 3];
        for (i, p) in fit.parameters.iter().enumerate() {
            if (p.value - truth[i]).abs() <= 2.0 * p.std {
                within[i] += 1;
            }
            v[i] = p.value;
            sigmas[i] += p.std / runs as f64;
        }
        values.push(v);
        // σ² estimates the noise variance.
        assert!((fit.residual_variance / 4e-4 - 1.0).abs() < 0.2);
    }
    for i in 0..3 {
        assert!(
            within[i] >= 34,
            "parameter {i}: {} of {runs} within 2σ",
            within[i]
        );
        let mean = values.iter().map(|v| v[i]).sum::<f64>() / runs as f64;
        let sd =
            (values.iter().map(|v| (v[i] - mean).powi(2)).sum::<f64>() / (runs - 1) as f64).sqrt();
        let ratio = sd / sigmas[i];
        assert!(
            (0.65..1.35).contains(&ratio),
            "parameter {i}: spread {sd} vs σ̂ {}",
            sigmas[i]
        );
    }
}

/// Known initial state, free `B` only: the fit is a linear least-squares problem that
/// the trust region solves at once.
#[test]
fn given_initial_state_is_used() {
    let data = oscillator_data(0.0, 0);
    let start = oscillator(TRUE_A10, TRUE_A11, 1.0);
    let config = OeConfig {
        free: vec!["B[1,0]".into()],
        initial_state: InitialStateTreatment::Given(vec![TRUE_X0.to_vec()]),
        ..OeConfig::default()
    };
    let fit = fit_oe(&start, &data, &config).unwrap();
    assert!((fit.parameters[0].value - TRUE_B10).abs() < 1e-8);
    // Fixed initial states carry no uncertainty.
    assert_eq!(fit.initial_states[0][0].std.to_bits(), 0.0_f64.to_bits());
    assert_eq!(fit.covariance.nrows(), 1);
}

#[test]
fn stability_verdicts() {
    let stable = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]);
    let s = Stability::of(&stable);
    assert_eq!(s.verdict, StabilityVerdict::Stable);
    // Eigenvalues −0.2 ± i·√(4 − 0.04).
    for (re, im) in &s.eigenvalues {
        assert!((re + 0.2).abs() < 1e-12 && (im.abs() - 3.96_f64.sqrt()).abs() < 1e-12);
    }
    let integrator = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 0.0, -1.0]);
    assert_eq!(
        Stability::of(&integrator).verdict,
        StabilityVerdict::Marginal
    );
    let unstable = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, 4.0, 0.0]);
    assert_eq!(Stability::of(&unstable).verdict, StabilityVerdict::Unstable);
}

/// With the true model and noise-free data, free run from the estimated initial state
/// and k-step prediction from windows of past data both reproduce the measurements, and
/// skip exactly the samples they consume.
#[test]
fn exact_model_simulates_and_predicts_the_data() {
    let data = oscillator_data(0.0, 0);
    let exp = &data.experiments()[0];
    let model = OeModel::new(oscillator(TRUE_A10, TRUE_A11, TRUE_B10));
    assert_eq!(model.initial_state, X0Policy::FromData);
    let sim = model.simulate(exp).unwrap();
    assert_eq!(sim.initial_samples, model.observer_window);
    let pred = model.predict(exp, 5).unwrap();
    assert_eq!(pred.initial_samples, model.observer_window + 4);
    assert!(pred.outputs[(0, pred.initial_samples - 1)].is_nan());
    for (p, start) in [(&sim, sim.initial_samples), (&pred, pred.initial_samples)] {
        for k in start..exp.len() {
            // Integrator mismatch ~1e-12 grows by at most the model's gain.
            assert!(
                (p.outputs[(0, k)] - exp.outputs()[(0, k)]).abs() < 1e-9,
                "sample {k}"
            );
        }
    }
}
