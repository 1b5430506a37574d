//! Evaluation (metrics skip initial samples, horizons never mix) and residual analysis.

use sysid_baselines::{
    BaselineError, EvaluationTable, OeModel, ResidualConfig, evaluate, residual_analysis,
};
use sysid_core::{Confidence, Horizon, Model, channel_metrics};

use crate::common::{TRUE_A10, TRUE_A11, TRUE_B10, oscillator, oscillator_data};

#[test]
fn table_refuses_rows_of_another_horizon() {
    let data = oscillator_data(0.01, 5);
    let model = OeModel::new(oscillator(TRUE_A10, TRUE_A11, TRUE_B10));
    let free = evaluate(&model, &data, Horizon::FreeRun).unwrap();
    let one = evaluate(&model, &data, Horizon::Steps(1)).unwrap();
    let five = evaluate(&model, &data, Horizon::Steps(5)).unwrap();
    assert_eq!(one.horizon, Horizon::Steps(1));

    let mut table = EvaluationTable::new("Table 5-1", Horizon::FreeRun);
    table.push("linear OE", free.clone()).unwrap();
    let err = table.push("linear OE, 1-step", one.clone()).unwrap_err();
    assert!(matches!(
        err,
        BaselineError::MixedHorizon {
            expected: Horizon::FreeRun,
            found: Horizon::Steps(1),
            ..
        }
    ));
    assert_eq!(table.rows().len(), 1);

    let mut steps = EvaluationTable::new("1-step", Horizon::Steps(1));
    steps.push("a", one).unwrap();
    assert!(matches!(
        steps.push("b", five),
        Err(BaselineError::MixedHorizon { .. })
    ));
    assert!(matches!(
        steps.push("c", free),
        Err(BaselineError::MixedHorizon { .. })
    ));
    // The horizon is part of the serialised table.
    let json = serde_json::to_string(&table).unwrap();
    assert!(json.contains("\"horizon\":\"free_run\""), "{json}");
}

/// The metrics are those of `channel_metrics` on the samples after the prediction's
/// initial ones.
#[test]
fn evaluation_skips_initial_samples() {
    let data = oscillator_data(0.01, 6);
    let model = OeModel::new(oscillator(TRUE_A10, TRUE_A11, TRUE_B10));
    let ev = evaluate(&model, &data, Horizon::Steps(3)).unwrap();
    let exp = &data.experiments()[0];
    let pred = model.predict(exp, 3).unwrap();
    let skip = model.observer_window + 2;
    assert_eq!(pred.initial_samples, skip);
    assert_eq!(ev.initial_samples, skip);
    let y: Vec<f64> = exp.outputs().row(0).iter().skip(skip).copied().collect();
    let p: Vec<f64> = pred.outputs.row(0).iter().skip(skip).copied().collect();
    let by_hand = channel_metrics(&y, &p).unwrap();
    assert_eq!(ev.channels[0].metrics, by_hand);
    assert_eq!(ev.channels[0].metrics.samples, exp.len() - skip);
}

/// The true model leaves white residuals (the noise): few residual-ACF lags outside the
/// 99 % band (25 lags at 1 % each: mean 0.25, P(X > 3) < 0.02 %). A model with the
/// wrong stiffness leaves a structured residual, correlated far outside the band.
#[test]
fn residuals_of_true_and_wrong_models() {
    let data = oscillator_data(0.01, 8);
    let config = ResidualConfig::default();
    let good = OeModel::new(oscillator(TRUE_A10, TRUE_A11, TRUE_B10));
    let ra = residual_analysis(&good, &data, 0, Horizon::FreeRun, &config).unwrap();
    assert_eq!(ra.horizon, Horizon::FreeRun);
    let ch = &ra.channels[0];
    assert_eq!(ch.autocorrelation.lags.len(), 26);
    assert_eq!(ch.cross[0].correlogram.lags.len(), 51);
    assert!(ch.acf_outside_99.len() <= 3, "{:?}", ch.acf_outside_99);
    assert!(
        ch.xcf_outside_99[0].len() <= 3,
        "{:?}",
        ch.xcf_outside_99[0]
    );
    // Residual RMS ≈ noise σ (the free run starts from a state fitted to 20 samples).
    assert!((ch.rms / 0.01 - 1.0).abs() < 0.15, "{}", ch.rms);

    let bad = OeModel::new(oscillator(-3.0, TRUE_A11, TRUE_B10));
    let rb = residual_analysis(&bad, &data, 0, Horizon::FreeRun, &config).unwrap();
    let ch = &rb.channels[0];
    assert!(ch.acf_outside_99.len() >= 20, "{:?}", ch.acf_outside_99);
    assert!(ch.autocorrelation.values[1] > ch.autocorrelation.bound(Confidence::P99));
    // Round trip through JSON keeps the horizon and bands.
    let back: sysid_baselines::ResidualAnalysis =
        serde_json::from_str(&serde_json::to_string(&rb).unwrap()).unwrap();
    assert_eq!(back, rb);
}
