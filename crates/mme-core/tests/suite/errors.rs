//! Every configuration and data error is a typed error naming what is wrong.

use mme_core::{
    AutoWeight, MmeConfig, MmeError, NoiseSpec, NonlinearModel, StartTrajectory, WeightShape,
    WeightSpec, estimate, estimate_nonlinear,
};
use nalgebra::DMatrix;
use sysid_core::{Dataset, Experiment, LinearModel, ModelNames};

use super::common::{dataset, linear};

fn model() -> LinearModel {
    linear(
        &[0.0, 1.0, -2.0, -0.3],
        &[0.0, 1.0],
        &[1.0, 0.0],
        &[0.0, 1.0],
        2,
        (&["x", "v"], &["u"], &["x"], &["d"]),
    )
}

fn data(inputs: &[&str], outputs: &[&str], len: usize) -> Dataset {
    let u = DMatrix::from_fn(inputs.len(), len, |_, k| (k as f64 * 0.1).sin());
    let y = DMatrix::from_fn(outputs.len(), len, |_, k| (k as f64 * 0.1).cos());
    dataset(
        inputs,
        outputs,
        vec![Experiment::new(0.0, 0.1, u, y).unwrap()],
    )
}

fn given(w: WeightSpec, r: Vec<f64>) -> MmeConfig {
    MmeConfig {
        w,
        noise_variance: NoiseSpec::Given(r),
        ..MmeConfig::default()
    }
}

#[test]
fn non_positive_variance_names_the_channel() {
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let r = estimate(
            &model(),
            &data(&["u"], &["x"], 50),
            &given(WeightSpec::Scalar(1.0), vec![bad]),
        );
        assert!(
            matches!(r, Err(MmeError::NonPositiveVariance { ref channel, .. }) if channel == "x"),
            "{r:?}"
        );
    }
}

#[test]
fn w_not_positive_definite_names_the_matrix() {
    let d = data(&["u"], &["x"], 50);
    let cases = [
        WeightSpec::Matrix(DMatrix::from_element(1, 1, -1.0)),
        WeightSpec::Diagonal(vec![0.0]),
        WeightSpec::Auto(AutoWeight {
            shape: WeightShape::Matrix(DMatrix::from_element(1, 1, 0.0)),
            ..AutoWeight::default()
        }),
    ];
    for w in cases {
        let r = estimate(&model(), &d, &given(w, vec![0.1]));
        assert!(
            matches!(r, Err(MmeError::NotPositiveDefinite { .. })),
            "{r:?}"
        );
    }
}

#[test]
fn unknown_channels_are_named() {
    let r = estimate(
        &model(),
        &data(&["u"], &["position"], 50),
        &given(WeightSpec::Scalar(1.0), vec![0.1]),
    );
    assert!(
        matches!(r, Err(MmeError::UnknownChannel { kind: "output", ref name }) if name == "x"),
        "{r:?}"
    );
    let r = estimate(
        &model(),
        &data(&["force"], &["x"], 50),
        &given(WeightSpec::Scalar(1.0), vec![0.1]),
    );
    assert!(
        matches!(r, Err(MmeError::UnknownChannel { kind: "input", ref name }) if name == "u"),
        "{r:?}"
    );
}

#[test]
fn dimension_mismatches_are_typed() {
    let d = data(&["u"], &["x"], 50);
    let r = estimate(
        &model(),
        &d,
        &given(WeightSpec::Matrix(DMatrix::identity(2, 2)), vec![0.1]),
    );
    assert!(
        matches!(
            r,
            Err(MmeError::Dimension {
                what: "W",
                rows: 2,
                expected_rows: 1,
                ..
            })
        ),
        "{r:?}"
    );
    let r = estimate(
        &model(),
        &d,
        &given(WeightSpec::Scalar(1.0), vec![0.1, 0.2]),
    );
    assert!(
        matches!(
            r,
            Err(MmeError::Dimension {
                what: "noise variance",
                rows: 2,
                expected_rows: 1,
                ..
            })
        ),
        "{r:?}"
    );
    let nl = NonlinearModel::new(
        model(),
        DMatrix::from_element(1, 3, 1.0),
        model().e().clone(),
        names(),
    );
    assert!(
        matches!(nl, Err(MmeError::Dimension { what: "C", .. })),
        "{:?}",
        nl.err()
    );
    let nl =
        NonlinearModel::new(model(), model().c().clone(), model().e().clone(), names()).unwrap();
    let config = MmeConfig {
        start: StartTrajectory::Given(vec![vec![1.0]]),
        ..given(WeightSpec::Scalar(1.0), vec![0.1])
    };
    let r = estimate_nonlinear(&nl, &d, &config);
    assert!(
        matches!(
            r,
            Err(MmeError::Dimension {
                what: "initial state",
                ..
            })
        ),
        "{r:?}"
    );
}

fn names() -> ModelNames {
    let v = |s: &[&str]| s.iter().map(|x| x.to_string()).collect();
    ModelNames {
        states: v(&["x", "v"]),
        inputs: v(&["u"]),
        outputs: v(&["x"]),
        corrections: v(&["d"]),
    }
}

#[test]
fn invalid_settings_and_data_are_typed() {
    let d = data(&["u"], &["x"], 50);
    let config = MmeConfig {
        substeps: Some(0),
        ..given(WeightSpec::Scalar(1.0), vec![0.1])
    };
    assert!(matches!(
        estimate(&model(), &d, &config),
        Err(MmeError::InvalidSetting {
            name: "substeps",
            ..
        })
    ));
    let auto = WeightSpec::Auto(AutoWeight {
        initial: -1.0,
        ..AutoWeight::default()
    });
    assert!(matches!(
        estimate(&model(), &d, &given(auto, vec![0.1])),
        Err(MmeError::InvalidSetting {
            name: "initial",
            ..
        })
    ));
    let short = data(&["u"], &["x"], 1);
    assert!(matches!(
        estimate(&model(), &short, &given(WeightSpec::Scalar(1.0), vec![0.1])),
        Err(MmeError::TooFewSamples {
            experiment: 0,
            found: 1,
            needed: 2
        })
    ));
    let empty = dataset(&["u"], &["x"], vec![]);
    assert!(matches!(
        estimate(&model(), &empty, &given(WeightSpec::Scalar(1.0), vec![0.1])),
        Err(MmeError::NoExperiments)
    ));
}

#[test]
fn unobservable_initial_state_is_reported() {
    // Two decoupled modes, only the first measured: the second's initial value is free.
    let m = linear(
        &[-1.0, 0.0, 0.0, -2.0],
        &[1.0, 1.0],
        &[1.0, 0.0],
        &[1.0, 0.0],
        2,
        (&["a", "b"], &["u"], &["x"], &["d"]),
    );
    let r = estimate(
        &m,
        &data(&["u"], &["x"], 50),
        &given(WeightSpec::Scalar(1.0), vec![0.1]),
    );
    assert!(
        matches!(
            r,
            Err(MmeError::NotObservable {
                experiment: 0,
                pivot: 1,
                ..
            })
        ),
        "{r:?}"
    );
}
