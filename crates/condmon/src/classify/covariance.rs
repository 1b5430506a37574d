//! Covariance estimates shared by LDA and QDA: class means, scatter matrices, the
//! [`Shrinkage`] rule for singular matrices, and the Cholesky factor used for
//! Mahalanobis distances and log-determinants.

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::error::{CondmonError, Result};

/// Weights tried, in order, by [`Shrinkage::Auto`]: the first for which the regularised
/// matrix passes [`MIN_EIGEN_RATIO`] is used.
pub const AUTO_SHRINKAGE_LADDER: [f64; 10] =
    [0.0, 1e-6, 1e-4, 1e-3, 1e-2, 0.05, 0.1, 0.25, 0.5, 1.0];

/// Smallest accepted ratio of the smallest to the largest eigenvalue of a covariance
/// before it is factored. At 1e-10 the Cholesky solves keep about six significant
/// digits (relative error ≈ ε / ratio), plenty to rank class log-densities.
pub const MIN_EIGEN_RATIO: f64 = 1e-10;

/// Floor on the diagonal of a shrinkage target, relative to the mean diagonal entry. Only
/// a constant feature (zero variance) reaches it; it keeps the target positive definite.
pub const DIAGONAL_FLOOR_RTOL: f64 = 1e-6;

/// Regularisation of a covariance estimate `S` toward a target `T`:
/// `Σ(λ) = (1 − λ)·S + λ·T`, `λ ∈ [0, 1]`.
///
/// For LDA (and QDA's pooled matrix) `T` is the diagonal of `S` (each entry floored at
/// [`DIAGONAL_FLOOR_RTOL`] × the mean diagonal), i.e. shrinkage toward independent
/// features with the same variances. For QDA's per-class matrices `T` is the regularised
/// pooled covariance (Friedman's regularised discriminant analysis, JASA 1989).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Shrinkage {
    /// λ = 0: the sample estimate as is; a singular matrix is an error.
    None,
    /// A fixed λ in [0, 1].
    Fixed(f64),
    /// The smallest λ on [`AUTO_SHRINKAGE_LADDER`] that makes the matrix well conditioned
    /// (eigenvalue ratio ≥ [`MIN_EIGEN_RATIO`]). A numerical safeguard, not a
    /// statistically tuned amount: non-singular data keep λ = 0.
    Auto,
}

impl Shrinkage {
    /// Check a fixed weight is in [0, 1].
    pub fn validate(&self, field: &'static str) -> Result<()> {
        match *self {
            Self::Fixed(l) if !(0.0..=1.0).contains(&l) => Err(CondmonError::InvalidConfig {
                field,
                value: l,
                reason: "shrinkage weight must be in [0, 1]",
            }),
            _ => Ok(()),
        }
    }

    fn candidates(&self) -> &[f64] {
        match self {
            Self::None => &[0.0],
            Self::Fixed(l) => std::slice::from_ref(l),
            Self::Auto => &AUTO_SHRINKAGE_LADDER,
        }
    }
}

/// A positive-definite covariance ready for discriminants: its lower Cholesky factor,
/// `ln det Σ`, and the shrinkage weight that produced it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Factor {
    pub(crate) l: DMatrix<f64>,
    pub(crate) log_det: f64,
    pub(crate) lambda: f64,
    pub(crate) sigma: DMatrix<f64>,
}

impl Factor {
    /// Squared Mahalanobis distance of each row of `x` to `mean`: ‖L⁻¹(x − μ)‖².
    pub(crate) fn mahalanobis_sq(
        &self,
        x: &DMatrix<f64>,
        mean: &DVector<f64>,
        what: &'static str,
        class: Option<usize>,
    ) -> Result<Vec<f64>> {
        let d = DMatrix::from_fn(x.ncols(), x.nrows(), |j, i| x[(i, j)] - mean[j]);
        let z = self
            .l
            .solve_lower_triangular(&d)
            .ok_or(CondmonError::SingularCovariance {
                what,
                class,
                ratio: 0.0,
                regularisation: self.lambda,
            })?;
        Ok(z.column_iter().map(|c| c.norm_squared()).collect())
    }
}

/// Class means (`K × p`, rows in class order) and class counts.
pub(crate) fn class_means(
    x: &DMatrix<f64>,
    labels: &[usize],
    classes: &[usize],
) -> (Vec<DVector<f64>>, Vec<usize>) {
    let p = x.ncols();
    let mut sums = vec![DVector::zeros(p); classes.len()];
    let mut counts = vec![0usize; classes.len()];
    for (i, label) in labels.iter().enumerate() {
        if let Ok(k) = classes.binary_search(label) {
            sums[k] += x.row(i).transpose();
            counts[k] += 1;
        }
    }
    for (s, &c) in sums.iter_mut().zip(&counts) {
        if c > 0 {
            *s /= c as f64;
        }
    }
    (sums, counts)
}

/// Scatter matrix `Σ_{i ∈ class} (xᵢ − μ)(xᵢ − μ)ᵀ` of the rows of one class.
pub(crate) fn scatter(
    x: &DMatrix<f64>,
    labels: &[usize],
    class: usize,
    mean: &DVector<f64>,
) -> DMatrix<f64> {
    let p = x.ncols();
    let mut s = DMatrix::zeros(p, p);
    for (i, &label) in labels.iter().enumerate() {
        if label == class {
            let d = x.row(i).transpose() - mean;
            s.ger(1.0, &d, &d, 1.0);
        }
    }
    s
}

/// Diagonal shrinkage target of `s`: its diagonal, floored (see [`DIAGONAL_FLOOR_RTOL`]).
pub(crate) fn diagonal_target(s: &DMatrix<f64>, what: &'static str) -> Result<DMatrix<f64>> {
    let p = s.nrows();
    let mean_diag = s.diagonal().sum() / p as f64;
    if mean_diag <= 0.0 || !mean_diag.is_finite() {
        return Err(CondmonError::ZeroVariance { what });
    }
    let floor = DIAGONAL_FLOOR_RTOL * mean_diag;
    Ok(DMatrix::from_diagonal(&s.diagonal().map(|v| v.max(floor))))
}

/// Regularise `s` toward `target` under `shrinkage` and factor it.
pub(crate) fn regularised_factor(
    s: &DMatrix<f64>,
    target: &DMatrix<f64>,
    shrinkage: Shrinkage,
    what: &'static str,
    class: Option<usize>,
) -> Result<Factor> {
    let mut last_ratio = 0.0;
    let mut last_lambda = 0.0;
    for &lambda in shrinkage.candidates() {
        let sigma = s * (1.0 - lambda) + target * lambda;
        let eig = SymmetricEigen::new(sigma.clone());
        let max = eig.eigenvalues.max();
        let min = eig.eigenvalues.min();
        let ratio = if max > 0.0 { min / max } else { 0.0 };
        last_ratio = ratio;
        last_lambda = lambda;
        if ratio.is_nan() || ratio < MIN_EIGEN_RATIO {
            continue;
        }
        if let Some(chol) = sigma.clone().cholesky() {
            let l = chol.l();
            let log_det = 2.0 * l.diagonal().iter().map(|v| v.ln()).sum::<f64>();
            return Ok(Factor {
                l,
                log_det,
                lambda,
                sigma,
            });
        }
    }
    Err(CondmonError::SingularCovariance {
        what,
        class,
        ratio: last_ratio,
        regularisation: last_lambda,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mahalanobis_matches_explicit_inverse() {
        let s = DMatrix::from_row_slice(2, 2, &[2.0, 0.6, 0.6, 1.0]);
        let target = diagonal_target(&s, "test").unwrap();
        let f = regularised_factor(&s, &target, Shrinkage::None, "test", None).unwrap();
        let inv = s.clone().try_inverse().unwrap();
        let mu = DVector::from_vec(vec![0.5, -1.0]);
        let x = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, -3.0, 0.25]);
        let d2 = f.mahalanobis_sq(&x, &mu, "test", None).unwrap();
        for (i, d2) in d2.iter().enumerate() {
            let d = x.row(i).transpose() - &mu;
            let expected = (d.transpose() * &inv * &d)[(0, 0)];
            // Both are O(10) values from 2×2 solves: round-off ≈ 1e-15 relative.
            assert!((d2 - expected).abs() < 1e-12 * expected.max(1.0));
        }
        assert!((f.log_det - (2.0 - 0.36f64).ln()).abs() < 1e-14);
    }

    #[test]
    fn singular_matrix_needs_shrinkage() {
        // Rank one: [1 1; 1 1].
        let s = DMatrix::from_element(2, 2, 1.0);
        let target = diagonal_target(&s, "test").unwrap();
        assert!(matches!(
            regularised_factor(&s, &target, Shrinkage::None, "pooled", None),
            Err(CondmonError::SingularCovariance { .. })
        ));
        let f = regularised_factor(&s, &target, Shrinkage::Auto, "pooled", None).unwrap();
        // Eigenvalues of (1−λ)[1 1;1 1] + λI are 2 − λ and λ: the ratio passes 1e-10 first
        // at λ = 1e-6 on the ladder.
        assert!((f.lambda - 1e-6).abs() < 1e-20);
        assert!(Shrinkage::Fixed(1.5).validate("x").is_err());
    }
}
