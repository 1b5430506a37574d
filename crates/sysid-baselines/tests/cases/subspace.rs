//! Subspace identification (PO-MOESP) and the linear state-space baseline against known
//! discrete systems: exact recovery of the eigenvalues and of the transfer function
//! (Markov parameters, checked by brute force against the truth's impulse response) from
//! noise-free data; the held-out order choice and the refinement with noise; an integrator
//! with an input bias; input validation.

use approx::assert_relative_eq;
use nalgebra::{DMatrix, DVector};
use sysid_baselines::{
    BaselineError, DiscreteStateSpace, LinearSsConfig, Section, fit_linear_ss, moesp,
};
use sysid_core::{Channel, Dataset, Experiment, Model};

use crate::common::{add_noise, white};

/// Fourth-order truth: poles 0.9 e^{±0.3i} and 0.6 e^{±1.2i}, a feedthrough.
fn truth() -> DiscreteStateSpace {
    let block = |r: f64, w: f64| {
        let (c, s) = (r * w.cos(), r * w.sin());
        [c, s, -s, c]
    };
    let (b1, b2) = (block(0.9, 0.3), block(0.6, 1.2));
    let mut a = DMatrix::zeros(4, 4);
    for (o, b) in [(0, b1), (2, b2)] {
        a[(o, o)] = b[0];
        a[(o, o + 1)] = b[1];
        a[(o + 1, o)] = b[2];
        a[(o + 1, o + 1)] = b[3];
    }
    DiscreteStateSpace {
        a,
        b: DMatrix::from_column_slice(4, 1, &[1.0, 0.5, -0.7, 0.3]),
        c: DMatrix::from_row_slice(1, 4, &[0.4, -0.2, 0.6, 0.9]),
        d: DMatrix::from_element(1, 1, 0.25),
    }
}

fn sorted_eigs(mut e: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    e.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.total_cmp(&y.1)));
    e
}

fn record(len: usize, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
    let u = DMatrix::from_row_slice(1, len, &white(len, seed));
    let x0 = DVector::from_column_slice(&[0.3, -0.1, 0.2, 0.05]);
    let y = truth().simulate(&u, &x0);
    (u, y)
}

fn dataset(u: DMatrix<f64>, y: DMatrix<f64>) -> Dataset {
    Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("y")],
        vec![Experiment::new(0.0, 1.0, u, y).unwrap()],
    )
    .unwrap()
}

/// Noise-free data: four singular values stand out (the fifth is round-off), and the
/// order-4 realisation has the truth's eigenvalues and its impulse response (Markov
/// parameters D, CB, CAB, … up to lag 40, compared by brute force).
#[test]
fn moesp_recovers_a_known_system_exactly() {
    let (u, y) = record(1500, 11);
    let mo = moesp(&u, &y, 8).unwrap();
    let sv = mo.singular_values();
    assert!(sv[3] / sv[0] > 1e-3, "{sv:?}");
    assert!(sv[4] / sv[0] < 1e-10, "{sv:?}");
    let (model, _x0) = mo.realise(4, &u, &y).unwrap();
    let (found, expected) = (
        sorted_eigs(model.eigenvalues()),
        sorted_eigs(truth().eigenvalues()),
    );
    for (f, e) in found.iter().zip(&expected) {
        assert_relative_eq!(f.0, e.0, epsilon = 1e-9);
        assert_relative_eq!(f.1, e.1, epsilon = 1e-9);
    }
    let (mf, mt) = (model.markov(40), truth().markov(40));
    for (k, (f, t)) in mf.iter().zip(&mt).enumerate() {
        assert!((f[(0, 0)] - t[(0, 0)]).abs() < 1e-9, "lag {k}: {f} vs {t}");
    }
    // Brute force: the impulse response by simulating both models.
    let mut pulse = DMatrix::zeros(1, 40);
    pulse[(0, 0)] = 1.0;
    let zero = DVector::zeros(4);
    let (yf, yt) = (
        model.simulate(&pulse, &zero),
        truth().simulate(&pulse, &zero),
    );
    for k in 0..40 {
        assert!((yf[(0, k)] - yt[(0, k)]).abs() < 1e-9, "sample {k}");
    }
}

/// The baseline on noise-free data with the order fixed: the refined parallel-section
/// model has the truth's poles and reproduces a new record after its window exactly.
#[test]
fn baseline_reproduces_noise_free_system() {
    let (u, y) = record(1200, 12);
    let cfg = LinearSsConfig {
        order: Some(4),
        window: 20,
        ..LinearSsConfig::default()
    };
    let fit = fit_linear_ss(&dataset(u, y), &cfg).unwrap();
    assert_eq!(fit.order, 4);
    assert_eq!(fit.final_refinement_failure, None);
    assert!(fit.training_rmse < 1e-8, "{}", fit.training_rmse);
    let found = sorted_eigs(fit.model.poles());
    let expected = sorted_eigs(truth().eigenvalues());
    for (f, e) in found.iter().zip(&expected) {
        assert_relative_eq!(f.0, e.0, epsilon = 1e-7);
        assert_relative_eq!(f.1, e.1, epsilon = 1e-7);
    }
    let (u2, y2) = record(500, 13);
    let p = fit
        .model
        .simulate(&dataset(u2, y2.clone()).experiments()[0])
        .unwrap();
    assert_eq!(p.initial_samples, 20);
    for k in 20..500 {
        assert!((p.outputs[(0, k)] - y2[(0, k)]).abs() < 1e-7, "sample {k}");
    }
}

/// With measurement noise the held-out choice lands on the true order, and the refined
/// model's held-out error is at the noise level.
#[test]
fn held_out_choice_finds_the_order() {
    let (u, mut y) = record(3000, 14);
    add_noise(&mut y, 0.01, 15);
    let fit = fit_linear_ss(&dataset(u, y), &LinearSsConfig::default()).unwrap();
    assert_eq!(fit.order, 4, "{:?}", fit.candidates);
    // A normal record: the whole-record refinement succeeded.
    assert_eq!(fit.final_refinement_failure, None);
    let best = fit.candidates[3].refined_rmse.unwrap();
    assert!(best < 0.0115, "{best}");
    assert!(fit.candidates[2].refined_rmse.unwrap() > 1.5 * best);
}

/// An integrator behind a first-order lag driven by a biased input (the EMPS structure:
/// position from force with an offset): the refinement recovers the poles and the bias.
#[test]
fn integrator_with_input_bias() {
    let len = 4000;
    // A slow square wave plus noise as input, the plant sees u − 0.3.
    let w = white(len, 16);
    let u: Vec<f64> = (0..len)
        .map(|k| if (k / 400) % 2 == 0 { 1.0 } else { -1.0 } + 0.2 * w[k])
        .collect();
    let (mut v, mut q) = (0.0, 0.0);
    let mut y = Vec::with_capacity(len);
    for &uk in &u {
        y.push(q);
        q += 0.01 * v;
        v = 0.98 * v + 0.05 * (uk - 0.3);
    }
    let data = dataset(
        DMatrix::from_row_slice(1, len, &u),
        DMatrix::from_row_slice(1, len, &y),
    );
    let cfg = LinearSsConfig {
        order: Some(2),
        window: 20,
        ..LinearSsConfig::default()
    };
    let fit = fit_linear_ss(&data, &cfg).unwrap();
    let poles = sorted_eigs(fit.model.poles());
    assert_relative_eq!(poles[0].0, 0.98, epsilon = 1e-6);
    assert_relative_eq!(poles[1].0, 1.0, epsilon = 1e-6);
    assert_relative_eq!(fit.model.input_offset, 0.3, epsilon = 1e-6);
    assert!(matches!(fit.model.sections[0], Section::Second { .. }));
    // The same with the integrator held at z = 1.
    let held = LinearSsConfig {
        integrator: true,
        ..cfg.clone()
    };
    let fit_i = fit_linear_ss(&data, &held).unwrap();
    assert!(matches!(
        fit_i.model.sections[0],
        Section::Integrating { .. }
    ));
    let poles_i = sorted_eigs(fit_i.model.poles());
    assert_relative_eq!(poles_i[0].0, 0.98, epsilon = 1e-6);
    assert_eq!(poles_i[1], (1.0, 0.0));
    assert_relative_eq!(fit_i.model.input_offset, 0.3, epsilon = 1e-6);
    assert!(fit.training_rmse < 1e-8 * y.iter().map(|v| v.abs()).fold(0.0, f64::max));
}

#[test]
fn invalid_inputs_are_typed_errors() {
    let (u, y) = record(300, 17);
    let data = dataset(u.clone(), y.clone());
    let bad = LinearSsConfig {
        validation_fraction: 0.9,
        ..LinearSsConfig::default()
    };
    assert!(matches!(
        fit_linear_ss(&data, &bad),
        Err(BaselineError::InvalidConfig {
            field: "validation_fraction",
            ..
        })
    ));
    let mimo = Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("y"), Channel::new("z")],
        vec![Experiment::new(0.0, 1.0, u.clone(), DMatrix::zeros(2, 300)).unwrap()],
    )
    .unwrap();
    assert!(matches!(
        fit_linear_ss(&mimo, &LinearSsConfig::default()),
        Err(BaselineError::Dimension { .. })
    ));
    assert!(matches!(
        moesp(
            &u.columns(0, 30).into_owned(),
            &y.columns(0, 30).into_owned(),
            8
        ),
        Err(BaselineError::TooFewRows { .. })
    ));
    let mut holes = y.clone();
    holes[(0, 100)] = f64::NAN;
    assert!(matches!(
        fit_linear_ss(&dataset(u, holes), &LinearSsConfig::default()),
        Err(BaselineError::NoInitialWindow { window: 100, .. })
    ));
}

/// Free-run RMSE of `model` on samples `from..` of `data`'s record (state fitted to the
/// first `window` of them, the error after them), through the public simulation.
fn rmse_on(model: &sysid_baselines::LinearSsModel, data: &Dataset, from: usize) -> f64 {
    let e = &data.experiments()[0];
    let part = Experiment::new(
        0.0,
        1.0,
        e.inputs().columns(from, e.len() - from).into_owned(),
        e.outputs().columns(from, e.len() - from).into_owned(),
    )
    .unwrap();
    let p = model.simulate(&part).unwrap();
    let w = p.initial_samples;
    let y = part.outputs();
    let sse: f64 = (w..part.len())
        .map(|k| (p.outputs[(0, k)] - y[(0, k)]).powi(2))
        .sum();
    (sse / (part.len() - w) as f64).sqrt()
}

/// The record on which the whole-record refinement fails: `msd_cubic`'s training record at
/// 20 Hz, seed 2 (201 samples; `mmenn compare` fits it with a 25-sample window). The
/// chosen order (2) is refined and scored in the held-out stage, but on the whole record
/// a numerator is not identifiable at that start. The fit keeps the held-out stage's
/// model and says why: the model returned is the one the held-out RMSE scored (its RMSE on
/// the held-out quarter is the chosen candidate's, to the bit), its training RMSE is its
/// own on the whole record, and without the input bias (which this record does not
/// need) the whole-record refinement succeeds, so the flag is unset.
/// Measured: order 2, held-out RMSE 1.6838, kept model's whole-record RMSE 1.4912;
/// "parameter 'section 0 b1' is not identifiable from the data (… ratio 4.4e-9)".
#[test]
fn failed_whole_record_refinement_keeps_the_held_out_stage_model() {
    let data = plants::simulate_system(&plants::SimulationRequest {
        system: "msd_cubic".into(),
        recipe: plants::Recipe::Train,
        seed: 2,
        fs: Some(20.0),
        ..Default::default()
    })
    .unwrap()
    .data;
    assert_eq!(data.experiments()[0].len(), 201);
    let cfg = LinearSsConfig {
        window: 25,
        ..LinearSsConfig::default()
    };
    assert!(cfg.fit_input_offset);
    let fit = fit_linear_ss(&data, &cfg).unwrap();
    let why = fit
        .final_refinement_failure
        .as_deref()
        .unwrap_or_else(|| panic!("the whole-record refinement succeeded: {fit:?}"));
    assert!(why.contains("not identifiable"), "{why}");
    assert_eq!(fit.order, 2, "{:?}", fit.candidates);
    let chosen = fit
        .candidates
        .iter()
        .find(|c| c.order == fit.order)
        .unwrap();
    // The held-out quarter starts at round(0.75 · 201) = 151.
    assert_eq!(
        rmse_on(&fit.model, &data, 151).to_bits(),
        chosen.refined_rmse.unwrap().to_bits(),
        "the model returned is the one scored on the held-out quarter"
    );
    assert_eq!(
        rmse_on(&fit.model, &data, 0).to_bits(),
        fit.training_rmse.to_bits()
    );
    // A fixed order skips the choice but not the stages: the same held-out model.
    let fixed = fit_linear_ss(
        &data,
        &LinearSsConfig {
            order: Some(2),
            ..cfg.clone()
        },
    )
    .unwrap();
    assert_eq!(fixed.model, fit.model);
    assert_eq!(fixed.final_refinement_failure, fit.final_refinement_failure);
    // Without the input bias the whole-record refinement of this record succeeds: the
    // flag is unset and the model is no longer the held-out stage's.
    let plain = fit_linear_ss(
        &data,
        &LinearSsConfig {
            fit_input_offset: false,
            ..cfg
        },
    )
    .unwrap();
    assert_eq!(plain.final_refinement_failure, None);
    let held = plain
        .candidates
        .iter()
        .find(|c| c.order == plain.order)
        .unwrap();
    assert_ne!(
        rmse_on(&plain.model, &data, 151).to_bits(),
        held.refined_rmse.unwrap().to_bits()
    );
}
