//! Bad input gives typed errors naming what is wrong.

use nalgebra::DMatrix;
use sysid_baselines::{
    BaselineError, NarxConfig, NarxOrders, OeConfig, OeModel, SuggestionConfig, evaluate, fit_narx,
    fit_oe, suggest_lags,
};
use sysid_core::{Channel, Dataset, Experiment, Horizon, LinearModel, Model};

use crate::common::{dataset, input, oscillator, oscillator_data};

#[test]
fn lags_larger_than_the_data() {
    let short = dataset(input(12, 0.1), DMatrix::from_element(1, 12, 0.3), 0.1);
    let config = SuggestionConfig {
        max_lag: 20,
        ..SuggestionConfig::default()
    };
    assert!(matches!(
        suggest_lags(&short, &config),
        Err(BaselineError::LagsExceedData {
            needed: 22,
            available: 12,
            ..
        })
    ));
    let narx = NarxConfig {
        orders: NarxOrders::symmetric(15),
        ..NarxConfig::default()
    };
    assert!(matches!(
        fit_narx(&short, &narx),
        Err(BaselineError::LagsExceedData {
            needed: 16,
            available: 12,
            experiment: 0,
            ..
        })
    ));
    let oe = OeModel::new(oscillator(-4.0, -0.4, 2.0));
    assert!(matches!(
        oe.predict(&short.experiments()[0], 5),
        Err(BaselineError::LagsExceedData { .. })
    ));
    assert!(matches!(
        oe.predict(&short.experiments()[0], 0),
        Err(BaselineError::InvalidConfig { field: "k", .. })
    ));
}

#[test]
fn bad_free_parameter_names() {
    let data = oscillator_data(0.0, 0);
    let start = oscillator(-3.0, -0.6, 1.6);
    let fit = |names: &[&str]| {
        fit_oe(
            &start,
            &data,
            &OeConfig {
                free: names.iter().map(|s| s.to_string()).collect(),
                ..OeConfig::default()
            },
        )
    };
    assert!(matches!(
        fit(&["A[2,0]"]),
        Err(BaselineError::ParameterIndex {
            matrix: "A",
            rows: 2,
            cols: 2,
            ..
        })
    ));
    assert!(matches!(
        fit(&["B[1,1]"]),
        Err(BaselineError::ParameterIndex {
            matrix: "B",
            rows: 2,
            cols: 1,
            ..
        })
    ));
    assert!(matches!(
        fit(&["theta"]),
        Err(BaselineError::BadParameterName { .. })
    ));
    assert!(matches!(
        fit(&["A[1,0]", "A[ 1, 0 ]"]),
        Err(BaselineError::DuplicateParameter { .. })
    ));
}

#[test]
fn dimension_and_channel_mismatches() {
    let data = oscillator_data(0.0, 0);
    let start = oscillator(-3.0, -0.6, 1.6);
    let config = OeConfig {
        free: vec!["A[1,0]".into()],
        ..OeConfig::default()
    };
    // Two inputs in the data, one in the model.
    let exp = &data.experiments()[0];
    let two = Dataset::new(
        vec![Channel::new("u"), Channel::new("w")],
        vec![Channel::new("x")],
        vec![
            Experiment::new(
                0.0,
                exp.dt(),
                DMatrix::from_fn(2, exp.len(), |_, k| exp.inputs()[(0, k)]),
                exp.outputs().clone(),
            )
            .unwrap(),
        ],
    )
    .unwrap();
    assert!(matches!(
        fit_oe(&start, &two, &config),
        Err(BaselineError::Dimension {
            found: 2,
            expected: 1,
            ..
        })
    ));
    // Same shape, different output name.
    let renamed = Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("theta")],
        vec![exp.clone()],
    )
    .unwrap();
    assert!(matches!(
        fit_oe(&start, &renamed, &config),
        Err(BaselineError::ChannelMismatch { kind: "output", .. })
    ));
    assert!(matches!(
        evaluate(&OeModel::new(start.clone()), &renamed, Horizon::FreeRun),
        Err(BaselineError::UnknownOutput { .. })
    ));
    // A model simulated on an experiment of the wrong width.
    assert!(matches!(
        OeModel::new(start).simulate(&two.experiments()[0]),
        Err(BaselineError::Dimension { .. })
    ));
    let narx = fit_narx(
        &data,
        &NarxConfig {
            network: sysid_baselines::NetworkChoice::Hidden {
                units: 1,
                restarts: 1,
            },
            lm: nn::LmConfig {
                max_epochs: 2,
                ..NarxConfig::default().lm
            },
            ..NarxConfig::default()
        },
    )
    .unwrap();
    assert!(matches!(
        narx.model.simulate(&two.experiments()[0]),
        Err(BaselineError::Dimension {
            found: 2,
            expected: 1,
            ..
        })
    ));
}

/// A second state that is neither driven nor measured leaves its parameter without any
/// effect on the outputs: the Jacobian column is zero.
#[test]
fn unidentifiable_parameter_is_named() {
    let data = oscillator_data(0.0, 0);
    let decoupled = LinearModel::with_names(
        DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, -2.0]),
        DMatrix::from_row_slice(2, 1, &[1.0, 0.0]),
        DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        DMatrix::zeros(2, 0),
        sysid_core::ModelNames {
            states: vec!["x".into(), "v".into()],
            inputs: vec!["u".into()],
            outputs: vec!["x".into()],
            corrections: vec![],
        },
    )
    .unwrap();
    let config = OeConfig {
        free: vec!["A[0,0]".into(), "A[1,1]".into()],
        initial_state: sysid_baselines::InitialStateTreatment::Zero,
        ..OeConfig::default()
    };
    match fit_oe(&decoupled, &data, &config) {
        Err(BaselineError::Unidentifiable { name, .. }) => assert_eq!(name, "A[1,1]"),
        other => panic!("expected Unidentifiable, got {other:?}"),
    }
}
