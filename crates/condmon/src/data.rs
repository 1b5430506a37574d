//! Validation of labelled feature matrices (rows = samples, columns = features), the class
//! list, row selection, and the hand-written nalgebra ↔ ndarray bridge.

use nalgebra::DMatrix;
use ndarray::Array2;

use crate::error::{CondmonError, Result};

/// Check every entry of `x` is finite; the error names the first bad sample and feature.
pub(crate) fn check_finite(matrix: &'static str, x: &DMatrix<f64>) -> Result<()> {
    for sample in 0..x.nrows() {
        for feature in 0..x.ncols() {
            if !x[(sample, feature)].is_finite() {
                return Err(CondmonError::NonFinite {
                    matrix,
                    sample,
                    feature,
                });
            }
        }
    }
    Ok(())
}

/// Check `x` has `expected_cols` columns and at least one row, and is finite.
pub(crate) fn check_query(
    matrix: &'static str,
    x: &DMatrix<f64>,
    expected_cols: usize,
) -> Result<()> {
    if x.ncols() != expected_cols {
        return Err(CondmonError::Shape {
            matrix,
            rows: x.nrows(),
            cols: x.ncols(),
            expected_rows: x.nrows(),
            expected_cols,
        });
    }
    check_finite(matrix, x)
}

/// Check an unlabelled training matrix: at least `min_rows` rows, at least one column,
/// finite entries.
pub(crate) fn check_training(
    matrix: &'static str,
    x: &DMatrix<f64>,
    min_rows: usize,
) -> Result<()> {
    if x.ncols() == 0 {
        return Err(CondmonError::TooFewSamples {
            what: "features (columns)",
            found: 0,
            needed: 1,
        });
    }
    if x.nrows() < min_rows {
        return Err(CondmonError::TooFewSamples {
            what: matrix,
            found: x.nrows(),
            needed: min_rows,
        });
    }
    check_finite(matrix, x)
}

/// Sorted distinct labels.
pub(crate) fn classes_of(labels: &[usize]) -> Vec<usize> {
    let mut classes = labels.to_vec();
    classes.sort_unstable();
    classes.dedup();
    classes
}

/// Validate a labelled training set and return its sorted classes: one label per row,
/// at least one feature, finite entries, at least two classes.
pub(crate) fn check_labelled(x: &DMatrix<f64>, labels: &[usize]) -> Result<Vec<usize>> {
    if labels.len() != x.nrows() {
        return Err(CondmonError::Length {
            what: "training labels (one per feature row)",
            found: labels.len(),
            expected: x.nrows(),
        });
    }
    check_training("training features", x, 2)?;
    let classes = classes_of(labels);
    if classes.len() < 2 {
        return Err(CondmonError::TooFewClasses {
            what: "training labels",
            found: classes.len(),
        });
    }
    Ok(classes)
}

/// Rows `rows` of `x`, in that order.
pub(crate) fn select_rows(x: &DMatrix<f64>, rows: &[usize]) -> DMatrix<f64> {
    DMatrix::from_fn(rows.len(), x.ncols(), |i, j| x[(rows[i], j)])
}

/// nalgebra (column-major) → ndarray (row-major), same row/column meaning.
pub(crate) fn to_array2(x: &DMatrix<f64>) -> Array2<f64> {
    Array2::from_shape_fn((x.nrows(), x.ncols()), |(i, j)| x[(i, j)])
}

/// ndarray → nalgebra, same row/column meaning (only the tests need this direction).
#[cfg(test)]
pub(crate) fn from_array2(a: &Array2<f64>) -> DMatrix<f64> {
    DMatrix::from_fn(a.nrows(), a.ncols(), |i, j| a[[i, j]])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_round_trip_and_keep_orientation() {
        let x = DMatrix::from_row_slice(2, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let a = to_array2(&x);
        assert_eq!(a.shape(), &[2, 3]);
        // An exact copy.
        assert_eq!(a[[1, 0]].to_bits(), 4.0f64.to_bits());
        assert_eq!(from_array2(&a), x);
    }

    #[test]
    fn labelled_checks() {
        let x = DMatrix::from_row_slice(3, 1, &[0.0, 1.0, f64::NAN]);
        assert!(matches!(
            check_labelled(&x, &[0, 1, 1]),
            Err(CondmonError::NonFinite {
                sample: 2,
                feature: 0,
                ..
            })
        ));
        let x = DMatrix::from_row_slice(3, 1, &[0.0, 1.0, 2.0]);
        assert!(matches!(
            check_labelled(&x, &[4, 4, 4]),
            Err(CondmonError::TooFewClasses { found: 1, .. })
        ));
        assert!(matches!(
            check_labelled(&x, &[0, 1]),
            Err(CondmonError::Length {
                found: 2,
                expected: 3,
                ..
            })
        ));
        assert_eq!(check_labelled(&x, &[7, 2, 7]).unwrap(), vec![2, 7]);
    }
}
