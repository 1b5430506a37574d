//! Principal component analysis on the sample covariance (nalgebra `SymmetricEigen`): true
//! explained variances, the component count chosen by [`ComponentSelection`], scores,
//! reconstruction, and the Hotelling T² and Q (squared prediction error) statistics.
//!
//! Written here instead of using linfa-reduction, whose `explained_variance()` divides by
//! the number of kept components instead of `n − 1` and whose ratios are relative to the
//! kept components only (see `notes/crates.md` §4).

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::data::{check_query, check_training};
use crate::error::{CondmonError, Result};

/// Slack on the cumulative explained-variance test, so that a fraction of exactly 1.0 (or
/// a threshold hit exactly by the data) is not missed through round-off of the eigenvalue
/// sum (relative round-off there is a few ε·p ≪ 1e-12).
pub const CUMULATIVE_SLACK: f64 = 1e-12;

/// How many principal components to keep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum ComponentSelection {
    /// The fewest leading components whose cumulative explained-variance ratio reaches this
    /// fraction (in (0, 1]; the thesis uses 0.90 and 0.95, §6.1 step V).
    VarianceFraction(f64),
    /// Exactly this many components (1 ≤ k ≤ number of features).
    Fixed(usize),
    /// Every component (a rotation; reconstruction is exact).
    All,
}

impl ComponentSelection {
    /// Check the selection is usable with `p` features.
    pub fn validate(&self, p: usize) -> Result<()> {
        match *self {
            Self::VarianceFraction(d) if !(d > 0.0 && d <= 1.0) => {
                Err(CondmonError::InvalidConfig {
                    field: "ComponentSelection::VarianceFraction",
                    value: d,
                    reason: "fraction must be in (0, 1]",
                })
            }
            Self::Fixed(k) if k == 0 || k > p => Err(CondmonError::InvalidConfig {
                field: "ComponentSelection::Fixed",
                value: k as f64,
                reason: "must be between 1 and the number of features",
            }),
            _ => Ok(()),
        }
    }
}

/// A fitted PCA: training mean, all eigenpairs of the sample covariance (descending), and
/// the number of kept components.
///
/// Eigenvectors are signed so that the entry of largest magnitude is positive (first such
/// entry on ties), which makes the scores deterministic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Pca {
    mean: DVector<f64>,
    /// `p × p`, column `i` = i-th principal direction.
    eigenvectors: DMatrix<f64>,
    /// Variance along each direction (divisor `n − 1`), descending, clamped at 0.
    eigenvalues: DVector<f64>,
    n_components: usize,
}

impl Pca {
    /// Fit to `x` (`n × p`, rows = samples). Centres, but does not scale: standardise
    /// first if features have different units.
    ///
    /// Errors: invalid selection, fewer than two rows, no columns, a non-finite entry, all
    /// features constant.
    pub fn fit(x: &DMatrix<f64>, selection: ComponentSelection) -> Result<Self> {
        check_training("PCA training features", x, 2)?;
        let p = x.ncols();
        selection.validate(p)?;
        let n = x.nrows() as f64;
        let mean = DVector::from_fn(p, |j, _| x.column(j).sum() / n);
        let mut centred = x.clone();
        for (j, mut col) in centred.column_iter_mut().enumerate() {
            col.add_scalar_mut(-mean[j]);
        }
        let cov = (centred.transpose() * &centred) / (n - 1.0);
        let eig = SymmetricEigen::new(cov);
        let mut order: Vec<usize> = (0..p).collect();
        order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
        let eigenvalues = DVector::from_fn(p, |i, _| eig.eigenvalues[order[i]].max(0.0));
        let mut eigenvectors = DMatrix::from_fn(p, p, |r, c| eig.eigenvectors[(r, order[c])]);
        for mut col in eigenvectors.column_iter_mut() {
            let mut pivot = 0;
            for r in 1..p {
                if col[r].abs() > col[pivot].abs() {
                    pivot = r;
                }
            }
            if col[pivot] < 0.0 {
                col.neg_mut();
            }
        }
        let total = eigenvalues.sum();
        if total <= 0.0 {
            return Err(CondmonError::ZeroVariance { what: "PCA" });
        }
        let n_components = match selection {
            ComponentSelection::All => p,
            ComponentSelection::Fixed(k) => k,
            ComponentSelection::VarianceFraction(d) => {
                let mut cumulative = 0.0;
                let mut k = p;
                for (i, l) in eigenvalues.iter().enumerate() {
                    cumulative += l / total;
                    if cumulative >= d - CUMULATIVE_SLACK {
                        k = i + 1;
                        break;
                    }
                }
                k
            }
        };
        Ok(Self {
            mean,
            eigenvectors,
            eigenvalues,
            n_components,
        })
    }

    /// Number of input features `p`.
    pub fn n_features(&self) -> usize {
        self.mean.len()
    }

    /// Number of kept components `k`.
    pub fn n_components(&self) -> usize {
        self.n_components
    }

    /// Training mean.
    pub fn mean(&self) -> &DVector<f64> {
        &self.mean
    }

    /// Kept principal directions, `p × k` (columns are orthonormal).
    pub fn loadings(&self) -> DMatrix<f64> {
        self.eigenvectors.columns(0, self.n_components).into_owned()
    }

    /// Every principal direction, `p × p`, kept ones first.
    pub fn all_directions(&self) -> &DMatrix<f64> {
        &self.eigenvectors
    }

    /// Variance along every principal direction (all `p`, descending): the eigenvalues of
    /// the sample covariance with divisor `n − 1`.
    pub fn explained_variance(&self) -> &[f64] {
        self.eigenvalues.as_slice()
    }

    /// Share of the total variance along every direction (all `p`; sums to 1).
    pub fn explained_variance_ratio(&self) -> Vec<f64> {
        let total = self.eigenvalues.sum();
        self.eigenvalues.iter().map(|l| l / total).collect()
    }

    /// Cumulative share of the total variance of the first `1, 2, …, p` components.
    pub fn cumulative_ratio(&self) -> Vec<f64> {
        let mut acc = 0.0;
        self.explained_variance_ratio()
            .into_iter()
            .map(|r| {
                acc += r;
                acc
            })
            .collect()
    }

    /// Scores on the kept components: `(x − mean) · loadings`, `n × k`.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn transform(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_query("features to project", x, self.n_features())?;
        Ok(self.centre(x) * self.eigenvectors.columns(0, self.n_components))
    }

    /// Map scores (`n × k`) back to feature space: `scores · loadingsᵀ + mean`.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn inverse_transform(&self, scores: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_query("PCA scores", scores, self.n_components)?;
        let mut x = scores * self.eigenvectors.columns(0, self.n_components).transpose();
        for (j, mut col) in x.column_iter_mut().enumerate() {
            col.add_scalar_mut(self.mean[j]);
        }
        Ok(x)
    }

    /// Hotelling's T² of each row on the kept components, `Σᵢ tᵢ² / λᵢ`. A component with
    /// zero variance contributes nothing (its scores are 0 on the training data).
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn t_squared(&self, x: &DMatrix<f64>) -> Result<Vec<f64>> {
        let t = self.transform(x)?;
        Ok(t.row_iter()
            .map(|row| {
                row.iter()
                    .zip(self.eigenvalues.iter())
                    .filter(|(_, l)| **l > 0.0)
                    .map(|(s, l)| s * s / l)
                    .sum()
            })
            .collect())
    }

    /// Q statistic (squared prediction error) of each row: squared distance between the
    /// centred row and its projection on the kept components.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn q_statistic(&self, x: &DMatrix<f64>) -> Result<Vec<f64>> {
        check_query("features to project", x, self.n_features())?;
        let c = self.centre(x);
        let p = self.eigenvectors.columns(0, self.n_components);
        let residual = &c - (&c * p) * p.transpose();
        Ok(residual.row_iter().map(|r| r.norm_squared()).collect())
    }

    fn centre(&self, x: &DMatrix<f64>) -> DMatrix<f64> {
        let mut c = x.clone();
        for (j, mut col) in c.column_iter_mut().enumerate() {
            col.add_scalar_mut(-self.mean[j]);
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_aligned_data_has_known_eigenpairs() {
        // Points (±2, 0) and (0, ±1): covariance diag(8/3, 2/3), directions e₁ then e₂.
        let x = DMatrix::from_row_slice(4, 2, &[2.0, 0.0, -2.0, 0.0, 0.0, 1.0, 0.0, -1.0]);
        let pca = Pca::fit(&x, ComponentSelection::VarianceFraction(0.8)).unwrap();
        let ev = pca.explained_variance();
        assert!((ev[0] - 8.0 / 3.0).abs() < 1e-14 && (ev[1] - 2.0 / 3.0).abs() < 1e-14);
        // 8/3 ÷ 10/3 = 0.8 exactly: the slack lets the threshold be met by one component.
        assert_eq!(pca.n_components(), 1);
        assert!((pca.loadings()[(0, 0)] - 1.0).abs() < 1e-14);
        // Q of (0, 1) with one component is 1; T² of (2, 0) is 4 / (8/3) = 1.5.
        let q = pca
            .q_statistic(&DMatrix::from_row_slice(1, 2, &[0.0, 1.0]))
            .unwrap();
        assert!((q[0] - 1.0).abs() < 1e-14);
        let t2 = pca
            .t_squared(&DMatrix::from_row_slice(1, 2, &[2.0, 0.0]))
            .unwrap();
        assert!((t2[0] - 1.5).abs() < 1e-14);
    }

    #[test]
    fn selection_is_validated() {
        let x = DMatrix::from_row_slice(3, 2, &[1.0, 2.0, 3.0, 5.0, 4.0, 4.0]);
        for bad in [
            ComponentSelection::VarianceFraction(0.0),
            ComponentSelection::VarianceFraction(1.5),
            ComponentSelection::VarianceFraction(f64::NAN),
            ComponentSelection::Fixed(0),
            ComponentSelection::Fixed(3),
        ] {
            assert!(matches!(
                Pca::fit(&x, bad),
                Err(CondmonError::InvalidConfig { .. })
            ));
        }
        let constant = DMatrix::from_element(3, 2, 1.0);
        assert!(matches!(
            Pca::fit(&constant, ComponentSelection::All),
            Err(CondmonError::ZeroVariance { .. })
        ));
    }
}
