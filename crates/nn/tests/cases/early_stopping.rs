//! Validation early stopping on a deliberately over-fitting case.

use nn::{LmConfig, Mlp, StopReason, ValidationSplit, split_indices, train_lm};

use crate::common::{add_noise, uniform_inputs};

#[test]
fn stops_on_validation_and_returns_best_weights() {
    // 40 noisy samples of sin(2x) (σ = 0.3) and a 1-15-1 network (46 weights for 30
    // training samples): the training error keeps falling by fitting the noise, so the
    // validation error must turn up and stop training.
    let x = uniform_inputs(1, 40, -2.0, 2.0, 21);
    let t = add_noise(&x.map(|v| (2.0 * v).sin()), 0.3, 22);
    let split = ValidationSplit::Random {
        fraction: 0.25,
        seed: 4,
    };
    let config = LmConfig {
        validation: split,
        max_fail: 6,
        max_epochs: 500,
        ..LmConfig::default()
    };
    let mut net = Mlp::for_data(&x, &t, &[15], 8).unwrap();
    let report = train_lm(&mut net, &x, &t, &config, None).unwrap();

    assert_eq!(report.termination, StopReason::ValidationStop, "{report:?}");
    assert_eq!((report.n_train, report.n_val), (30, 10));
    assert_eq!(report.val_history.len(), report.epochs + 1);
    let min = report
        .val_history
        .iter()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let val = report.val_mse.unwrap();
    assert_eq!(val.to_bits(), min.to_bits());
    assert_eq!(
        report.val_history[report.best_epoch].to_bits(),
        val.to_bits()
    );
    // It stopped exactly max_fail epochs after the best one (no later improvement).
    assert_eq!(report.epochs, report.best_epoch + 6);
    // The *returned* weights are the best-validation ones: recompute their validation
    // and training MSE from scratch on the same split.
    let (tr, va) = split_indices(40, &split).unwrap();
    let cols = |idx: &[usize], m: &nalgebra::DMatrix<f64>| m.select_columns(idx);
    let val_now = net
        .mse(&cols(&va, &x), &cols(&va, &t), config.error_space)
        .unwrap();
    let train_now = net
        .mse(&cols(&tr, &x), &cols(&tr, &t), config.error_space)
        .unwrap();
    // Same sums in a different loop: equal to round-off of an O(0.1) number.
    assert!((val_now - val).abs() < 1e-14, "{val_now} vs {val}");
    assert!((train_now - report.train_mse).abs() < 1e-14);
    // And the final (over-fitted) epoch trains better but validates worse.
    assert!(report.train_history[report.epochs] < report.train_mse);
    assert!(report.val_history[report.epochs] > val);
}
