//! The validation check of a round judged by the report's rule (`crate::validation`).

use super::*;
use sysid_core::{LinearModel, ModelNames};

/// Samples of the validation record and of its initial-state window.
const LEN: usize = 1000;
const WINDOW: usize = 200;
const DT: f64 = 0.1;
/// Measurement noise variance of `x`.
const NOISE: f64 = 1e-4;

/// `ẋ = a·x + u`, `ż = λ·z` (`x` measured and corrected, `z` unmeasured) with `terms`
/// (effect, term, coefficient) in `x`'s equation.
fn model(a: f64, lambda: f64, terms: &[(&str, &str, f64)]) -> TermModel {
    let names = ModelNames {
        states: vec!["x".into(), "z".into()],
        inputs: vec!["u".into()],
        outputs: vec!["x".into()],
        corrections: vec!["x".into()],
    };
    let linear = LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, &[a, 0.0, 0.0, lambda]),
        DMatrix::from_row_slice(2, 1, &[1.0, 0.0]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::from_row_slice(2, 1, &[1.0, 0.0]),
        names,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    TermModel::from_specs(
        linear,
        terms
            .iter()
            .map(|&(effect, term, coefficient)| ("x", effect, term, coefficient)),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// A validation record of `ẋ = −x + u` from `x(0) = 0.5`, with noise of variance
/// [`NOISE`].
fn validation_record() -> Dataset {
    let truth = model(-1.0, 0.0, &[]);
    let u = DMatrix::from_fn(1, LEN, |_, k| {
        let t = k as f64 * DT;
        (0.31 * t).sin() + 0.5 * (1.7 * t).sin() + if (k / 70) % 2 == 0 { 0.4 } else { -0.4 }
    });
    let blank = Experiment::new(0.0, DT, u.clone(), DMatrix::zeros(1, LEN))
        .unwrap_or_else(|e| panic!("{e}"));
    let xs = free_run_states(&truth, &[0.5, 0.0], &blank).unwrap_or_else(|e| panic!("{e}"));
    let y = truth.linear().c() * xs + crate::judge::gaussian_noise(&[NOISE], LEN, 7, 0);
    Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("x")],
        vec![Experiment::new(0.0, DT, u, y).unwrap_or_else(|e| panic!("{e}"))],
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// The model before the round (`x`'s rate constant off, `z` fed nowhere) and the
/// augmented one: the round's terms put the rate constant right and couple the unstable
/// unmeasured `z` (`ż = λ·z`) into `x`.
fn before_and_after(lambda: f64) -> (TermModel, TermModel) {
    let current = model(-0.6, lambda, &[]);
    let augmented = model(
        -0.6,
        lambda,
        &[
            ("linear_stiffness", "x", -0.4),
            ("linear_coupling", "z", 1.0),
        ],
    );
    (current, augmented)
}

/// The old check's cost: initial state fitted by free-run error over the whole record.
fn whole_record_cost(model: &TermModel, data: &Dataset, start: &[Vec<f64>]) -> f64 {
    let config = CalibrationConfig {
        weights: OutputWeights::NoiseVariance(vec![NOISE]),
        ..RefineConfig::default().calibration
    };
    crate::augment::fit_initial_states(model, data, &[start], &config)
        .map(|fit| fit.cost_after)
        .unwrap_or(f64::INFINITY)
}

/// The window rule's run of `model` on `data` (panics when it fails).
fn window_run(model: &TermModel, data: &Dataset) -> crate::validation::ValidationRun {
    crate::validation::validation_run(model, model.linear(), data, WINDOW, &[NOISE], false)
        .unwrap_or_else(|e| panic!("{e}"))
}

/// The round's terms make the model right from the state the whole record tunes: fitted
/// over every sample, `z(0)` lands on the unstable mode's null manifold and the free-run
/// cost falls from about 2e3 to the noise level (the old check accepted the round). From
/// the state the first 200 samples determine — the report's rule — `z` grows as e^{0.2 t}
/// and the free run explodes (fit 43.6 % → about −1.4e5 %): the check rejects it.
#[test]
fn a_whole_record_state_hid_an_exploding_validation_run_the_window_rule_rejects() {
    let data = validation_record();
    let (current, augmented) = before_and_after(0.2);
    let start = vec![vec![0.5, 0.0]];
    let (hidden_before, hidden_after) = (
        whole_record_cost(&current, &data, &start),
        whole_record_cost(&augmented, &data, &start),
    );
    assert!(
        hidden_after < 2.0 && hidden_after < 1e-2 * hidden_before,
        "the whole-record state should hide the divergence: {hidden_before:.4e} → {hidden_after:.4e}"
    );
    let (before, after) = (window_run(&current, &data), window_run(&augmented, &data));
    assert!(
        after.cost > 1e3 * before.cost,
        "{:.4e} → {:.4e}",
        before.cost,
        after.cost
    );
    assert!(
        after.records[0].fit_percent("x") < -1000.0,
        "{}",
        after.fit_summary()
    );
    let why = validation_rejection(&current, &augmented, &data, WINDOW, &[NOISE])
        .unwrap_or_else(|| panic!("accepted: {}", after.fit_summary()));
    assert!(
        why.contains("did not fall") && why.contains("first 200 samples"),
        "{why}"
    );
}

/// Not exploding, only worse than the model it augments under the window rule (fit
/// 43.6 % → 34.9 %), although the whole record's state again takes the cost to the noise
/// level: rejected.
#[test]
fn a_validation_run_worse_than_the_model_it_augments_is_rejected() {
    let data = validation_record();
    let (current, augmented) = before_and_after(0.1);
    let start = vec![vec![0.5, 0.0]];
    let hidden = whole_record_cost(&augmented, &data, &start);
    assert!(
        hidden < whole_record_cost(&current, &data, &start),
        "{hidden:.4e}"
    );
    let why = validation_rejection(&current, &augmented, &data, WINDOW, &[NOISE]);
    assert!(why.is_some_and(|w| w.contains("did not fall")));
}

/// A free run that blows up from the window's state is a rejection naming the validation
/// record and the failure, with no cost printed for the diverged model.
#[test]
fn a_diverged_validation_run_is_a_rejection_naming_the_record_not_a_cost() {
    let data = validation_record();
    let (current, augmented) = before_and_after(0.5);
    match crate::validation::validation_run(
        &augmented,
        augmented.linear(),
        &data,
        WINDOW,
        &[NOISE],
        false,
    ) {
        Err(DiscoveryError::ValidationRun {
            record: 0,
            window: WINDOW,
            source: sysid_core::CoreError::Diverged { .. },
        }) => {}
        other => panic!("expected a diverged run of record 0, got {other:?}"),
    }
    let why = validation_rejection(&current, &augmented, &data, WINDOW, &[NOISE])
        .unwrap_or_else(|| panic!("a diverged run was accepted"));
    assert!(
        why.contains("validation record 0") && why.contains("diverge") && !why.contains("→"),
        "{why}"
    );
}

/// The positive control: the round's right term alone (the rate constant) passes, and
/// the truth's cost under the rule is at the noise level.
#[test]
fn a_round_that_improves_the_validation_run_passes() {
    let data = validation_record();
    let (current, _) = before_and_after(0.2);
    let right = model(-0.6, 0.2, &[("linear_stiffness", "x", -0.4)]);
    assert_eq!(
        validation_rejection(&current, &right, &data, WINDOW, &[NOISE]),
        None
    );
    let cost = window_run(&right, &data).cost;
    assert!((0.7..1.3).contains(&cost), "{cost}");
}

/// The rule's noise variances must match the outputs: an error, not a cost.
#[test]
fn noise_variances_of_the_wrong_length_are_an_error() {
    let data = validation_record();
    let (current, _) = before_and_after(0.2);
    let got =
        crate::validation::validation_run(&current, current.linear(), &data, WINDOW, &[], false);
    assert!(matches!(got, Err(DiscoveryError::Length { .. })), "{got:?}");
}

/// The roles a user gives reach the free-run search's candidates: two tanks read in volts
/// are `Other` by their unit, so no level law is a candidate; with `[roles]` making them
/// levels, the orifice outflow of each is (the regression's proposals take the same
/// overrides through `DiscoveryConfig::roles`).
#[test]
fn given_roles_open_the_level_laws_to_the_search() {
    let names = ModelNames {
        states: vec!["h1".into(), "h2".into()],
        inputs: vec!["u".into()],
        outputs: vec!["y".into()],
        corrections: vec!["h1".into(), "h2".into()],
    };
    let linear = LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, &[-0.02, 0.0, 0.02, -0.015]),
        DMatrix::from_row_slice(2, 1, &[0.03, 0.0]),
        DMatrix::from_row_slice(1, 2, &[0.0, 1.0]),
        DMatrix::identity(2, 2),
        names,
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let model = TermModel::from_specs(linear, std::iter::empty::<(&str, &str, &str, f64)>())
        .unwrap_or_else(|e| panic!("{e}"));
    let units: BTreeMap<String, String> = ["h1", "h2", "u", "y"]
        .iter()
        .map(|n| (n.to_string(), "V".to_string()))
        .collect();
    let len = 400;
    let states = DMatrix::from_fn(2, len, |i, k| {
        5.0 + (i as f64 + 1.0) * (0.01 * k as f64).sin()
    });
    let inputs = DMatrix::from_fn(1, len, |_, k| 3.0 + (0.03 * k as f64).sin());
    let samples =
        Samples::new(states, inputs, DMatrix::zeros(2, len)).unwrap_or_else(|e| panic!("{e}"));
    let orifices = |roles: &[(String, Role)]| -> Vec<String> {
        let (candidates, _) =
            steps::round_candidates(&model, &units, roles, std::slice::from_ref(&samples), &[])
                .unwrap_or_else(|e| panic!("{e}"));
        candidates
            .iter()
            .filter(|c| c.effect == "orifice_outflow")
            .map(|c| format!("{}: {}", c.state, c.term))
            .collect()
    };
    assert!(orifices(&[]).is_empty(), "{:?}", orifices(&[]));
    let levels = [
        ("h1".to_string(), Role::Level),
        ("h2".to_string(), Role::Level),
    ];
    let with = orifices(&levels);
    assert!(
        with.iter()
            .any(|c| c.starts_with("h1: ") && c.contains("sqrt(abs(h1))")),
        "{with:?}"
    );
    assert!(
        with.iter()
            .any(|c| c.starts_with("h2: ") && c.contains("sqrt(abs(h2))")),
        "{with:?}"
    );
    // A role for a state the model lacks is an error naming it.
    let bad = [("h3".to_string(), Role::Level)];
    assert!(steps::round_candidates(&model, &units, &bad, &[samples], &[]).is_err());
}
