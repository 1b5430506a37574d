//! Bad input gives typed errors naming what and where.

use nalgebra::DMatrix;
use nn::{
    Architecture, LmConfig, Mlp, NnError, SweepConfig, ValidationSplit, Workspace, sizing_sweep,
    train_lm,
};

#[test]
fn mismatched_dimensions() {
    let x = DMatrix::zeros(2, 10);
    let t = DMatrix::zeros(1, 9);
    assert_eq!(
        Mlp::for_data(&x, &t, &[3], 0).unwrap_err(),
        NnError::Shape {
            matrix: "targets",
            rows: 1,
            cols: 9,
            expected_rows: 1,
            expected_cols: 10
        }
    );
    let mut net = Mlp::new(&Architecture::single(3, 2, 1), 0).unwrap();
    let t = DMatrix::zeros(1, 10);
    assert_eq!(
        train_lm(&mut net, &x, &t, &LmConfig::default(), None).unwrap_err(),
        NnError::Shape {
            matrix: "inputs",
            rows: 2,
            cols: 10,
            expected_rows: 3,
            expected_cols: 10
        }
    );
    let mut y = [0.0; 1];
    assert_eq!(
        net.forward(&[1.0, 2.0], &mut y, &mut Workspace::new())
            .unwrap_err(),
        NnError::Length {
            what: "input sample",
            found: 2,
            expected: 3
        }
    );
    assert_eq!(
        net.set_weights(&[0.0; 3]).unwrap_err(),
        NnError::Length {
            what: "weight vector",
            found: 3,
            expected: 11
        }
    );
    assert!(matches!(
        net.input_jacobian(&[0.0]),
        Err(NnError::Length { .. })
    ));
}

#[test]
fn nan_in_training_data_names_channel_and_sample() {
    let x = DMatrix::from_fn(2, 20, |i, k| (i + k) as f64);
    let mut t = DMatrix::from_fn(1, 20, |_, k| k as f64);
    t[(0, 13)] = f64::NAN;
    let mut net = Mlp::new(&Architecture::single(2, 3, 1), 0).unwrap();
    let before = net.clone();
    assert_eq!(
        train_lm(&mut net, &x, &t, &LmConfig::default(), None).unwrap_err(),
        NnError::NonFinite {
            matrix: "targets",
            channel: 0,
            sample: 13
        }
    );
    assert_eq!(net, before, "network untouched on error");
    let mut x2 = x.clone();
    x2[(1, 4)] = f64::INFINITY;
    assert_eq!(
        Mlp::for_data(&x2, &t, &[3], 0).unwrap_err(),
        NnError::NonFinite {
            matrix: "inputs",
            channel: 1,
            sample: 4
        }
    );
}

#[test]
fn zero_samples_and_bad_config() {
    let x = DMatrix::zeros(2, 0);
    let t = DMatrix::zeros(1, 0);
    let mut net = Mlp::new(&Architecture::single(2, 3, 1), 0).unwrap();
    assert_eq!(
        train_lm(&mut net, &x, &t, &LmConfig::default(), None).unwrap_err(),
        NnError::TooFewSamples {
            what: "training data",
            found: 0,
            needed: 1
        }
    );
    let x = DMatrix::zeros(2, 5);
    let t = DMatrix::zeros(1, 5);
    let bad = LmConfig {
        mu_initial: -1.0,
        ..LmConfig::default()
    };
    assert!(matches!(
        train_lm(&mut net, &x, &t, &bad, None),
        Err(NnError::InvalidConfig {
            field: "mu_initial",
            ..
        })
    ));
    // 5 samples with a 5 % validation share leave no validation sample (round(0.25) = 0).
    let tiny = LmConfig {
        validation: ValidationSplit::Random {
            fraction: 0.05,
            seed: 0,
        },
        ..LmConfig::default()
    };
    assert!(matches!(
        train_lm(&mut net, &x, &t, &tiny, None),
        Err(NnError::TooFewSamples {
            what: "validation split",
            found: 5,
            ..
        })
    ));
    let sweep = SweepConfig {
        inits: 0,
        ..SweepConfig::default()
    };
    assert!(matches!(
        sizing_sweep(&x, &t, &x, &t, &sweep, None),
        Err(NnError::InvalidConfig { field: "inits", .. })
    ));
    let test_t = DMatrix::zeros(2, 5);
    assert!(matches!(
        sizing_sweep(&x, &t, &x, &test_t, &SweepConfig::default(), None),
        Err(NnError::Shape {
            matrix: "test targets",
            ..
        })
    ));
}
