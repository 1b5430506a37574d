//! Fixtures shared by the crate's unit tests.

use nalgebra::DMatrix;
use sysid_core::{LinearModel, ModelNames};

/// `ẋ = a·x + b·u`, `x` measured and corrected (names `x`, `u`).
pub(crate) fn scalar_model(a: f64, b: f64) -> LinearModel {
    let names = ModelNames {
        states: vec!["x".into()],
        inputs: vec!["u".into()],
        outputs: vec!["x".into()],
        corrections: vec!["x".into()],
    };
    let one = |v: f64| DMatrix::from_element(1, 1, v);
    LinearModel::with_names(one(a), one(b), one(1.0), one(1.0), names)
        .unwrap_or_else(|e| panic!("{e}"))
}
