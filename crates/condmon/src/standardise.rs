//! Feature standardisation (z-scores) fitted on training rows only, applied to any rows.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::data::{check_query, check_training};
use crate::error::Result;

/// A feature whose sample standard deviation is at most this fraction of
/// `max(1, |mean|)` counts as constant: it is centred but not divided (scale 1).
///
/// Dividing by a spread at round-off level would turn noise into O(1) features. 1e-12
/// leaves four orders of margin above double-precision round-off of a mean.
pub const CONSTANT_FEATURE_RTOL: f64 = 1e-12;

/// Per-feature affine map `z = (x − mean) / scale`, fitted to training rows.
///
/// `scale` is the sample standard deviation (divisor `n − 1`), or 1 for a constant
/// feature (see [`CONSTANT_FEATURE_RTOL`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Standardiser {
    mean: DVector<f64>,
    scale: DVector<f64>,
}

impl Standardiser {
    /// Fit to `x` (`n × p`, rows = samples).
    ///
    /// Errors: fewer than two rows, no columns, a non-finite entry.
    pub fn fit(x: &DMatrix<f64>) -> Result<Self> {
        check_training("standardiser training features", x, 2)?;
        let n = x.nrows() as f64;
        let mean = DVector::from_fn(x.ncols(), |j, _| x.column(j).sum() / n);
        let scale = DVector::from_fn(x.ncols(), |j, _| {
            let m = mean[j];
            let ss: f64 = x.column(j).iter().map(|v| (v - m) * (v - m)).sum();
            let sd = (ss / (n - 1.0)).sqrt();
            if sd <= CONSTANT_FEATURE_RTOL * m.abs().max(1.0) {
                1.0
            } else {
                sd
            }
        });
        Ok(Self { mean, scale })
    }

    /// Number of features.
    pub fn n_features(&self) -> usize {
        self.mean.len()
    }

    /// Training means.
    pub fn mean(&self) -> &DVector<f64> {
        &self.mean
    }

    /// Divisors (standard deviations, 1 for constant features).
    pub fn scale(&self) -> &DVector<f64> {
        &self.scale
    }

    /// Standardise the rows of `x`.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn transform(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_query("features to standardise", x, self.n_features())?;
        Ok(DMatrix::from_fn(x.nrows(), x.ncols(), |i, j| {
            (x[(i, j)] - self.mean[j]) / self.scale[j]
        }))
    }

    /// Map standardised rows back to original units.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn inverse_transform(&self, z: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_query("standardised features", z, self.n_features())?;
        Ok(DMatrix::from_fn(z.nrows(), z.ncols(), |i, j| {
            z[(i, j)] * self.scale[j] + self.mean[j]
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::CondmonError;

    #[test]
    fn hand_computed_scores_and_constant_feature() {
        // Column 0: 1, 2, 3 → mean 2, sd 1 → −1, 0, 1. Column 1 constant 5 → 0, 0, 0.
        let x = DMatrix::from_row_slice(3, 2, &[1.0, 5.0, 2.0, 5.0, 3.0, 5.0]);
        let s = Standardiser::fit(&x).unwrap();
        let z = s.transform(&x).unwrap();
        let expected = DMatrix::from_row_slice(3, 2, &[-1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        // Exact small integers: only round-off of a 3-term mean.
        assert!((z - expected).amax() < 1e-15);
        let back = s.inverse_transform(&s.transform(&x).unwrap()).unwrap();
        assert!((back - x).amax() < 1e-14);
    }

    #[test]
    fn bad_inputs() {
        let x = DMatrix::from_row_slice(1, 2, &[1.0, 2.0]);
        assert!(matches!(
            Standardiser::fit(&x),
            Err(CondmonError::TooFewSamples { found: 1, .. })
        ));
        let x = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 3.0, 4.0]);
        let s = Standardiser::fit(&x).unwrap();
        assert!(matches!(
            s.transform(&DMatrix::zeros(1, 3)),
            Err(CondmonError::Shape {
                cols: 3,
                expected_cols: 2,
                ..
            })
        ));
    }
}
