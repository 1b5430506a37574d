//! Fixtures shared by the crate's unit tests.

use nalgebra::DMatrix;
use sysid_core::{LinearModel, ModelNames, TermModel, TermSpec};

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

/// Oscillator `ẋ = v`, `v̇ = −4x − 0.2v + u` (x measured, v corrected) with `terms`
/// (effect, term, coefficient) in `v`'s equation.
pub(crate) fn oscillator(terms: &[(&str, &str, f64)]) -> TermModel {
    let names = ModelNames {
        states: vec!["x".into(), "v".into()],
        inputs: vec!["u".into()],
        outputs: vec!["x".into()],
        corrections: vec!["v".into()],
    };
    let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.2]);
    let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
    let c = DMatrix::from_row_slice(1, 2, &[1.0, 0.0]);
    let e = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
    let linear = LinearModel::with_names(a, b, c, e, names).unwrap_or_else(|e| panic!("{e}"));
    TermModel::from_specs(
        linear,
        terms.iter().map(|&(effect, term, coefficient)| TermSpec {
            state: "v",
            into: None,
            effect,
            term,
            coefficient,
        }),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}
