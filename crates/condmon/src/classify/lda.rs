//! Linear discriminant analysis: Gaussian classes with one pooled covariance, priors, and
//! log-posteriors through a Cholesky factor (Hastie, Tibshirani & Friedman, *Elements of
//! Statistical Learning*, §4.3).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::covariance::{Factor, class_means, diagonal_target, regularised_factor, scatter};
use super::{Classifier, ClassifierModel, Predictions, Priors, Shrinkage, posteriors_from_log};
use crate::data::{check_labelled, check_query};
use crate::error::{CondmonError, Result};

/// LDA settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LdaConfig {
    /// Class priors (default: training frequencies).
    pub priors: Priors,
    /// Shrinkage of the pooled covariance toward its diagonal (default
    /// [`Shrinkage::Auto`]: none unless the pooled covariance is singular, as it is
    /// whenever there are more features than `n − K`).
    pub shrinkage: Shrinkage,
}

impl Default for LdaConfig {
    fn default() -> Self {
        Self {
            priors: Priors::Empirical,
            shrinkage: Shrinkage::Auto,
        }
    }
}

/// Class means and counts with the pooled within-class covariance.
pub(crate) struct Pooled {
    /// `Σ_k Σ_{i∈k} (xᵢ − μ_k)(xᵢ − μ_k)ᵀ / (n − K)`.
    pub(crate) cov: DMatrix<f64>,
    /// Class means, in class order.
    pub(crate) means: Vec<DVector<f64>>,
    /// Class counts, in class order.
    pub(crate) counts: Vec<usize>,
}

/// Pooled within-class covariance, class means and counts. Needs `n > K`.
pub(crate) fn pooled_covariance(
    x: &DMatrix<f64>,
    labels: &[usize],
    classes: &[usize],
) -> Result<Pooled> {
    let n = x.nrows();
    let k = classes.len();
    if n <= k {
        return Err(CondmonError::TooFewSamples {
            what: "pooled covariance (samples must exceed classes)",
            found: n,
            needed: k + 1,
        });
    }
    let (means, counts) = class_means(x, labels, classes);
    let mut pooled = DMatrix::zeros(x.ncols(), x.ncols());
    for (class, mean) in classes.iter().zip(&means) {
        pooled += scatter(x, labels, *class, mean);
    }
    pooled /= (n - k) as f64;
    Ok(Pooled {
        cov: pooled,
        means,
        counts,
    })
}

impl Classifier for LdaConfig {
    type Model = LdaModel;

    /// Errors: invalid shrinkage, bad data (see [`crate`] docs), `n ≤ K`, a pooled
    /// covariance still singular after shrinkage, all features constant.
    fn fit(&self, x: &DMatrix<f64>, labels: &[usize]) -> Result<LdaModel> {
        self.shrinkage.validate("LdaConfig::shrinkage")?;
        let classes = check_labelled(x, labels)?;
        let Pooled {
            cov: pooled,
            means,
            counts,
        } = pooled_covariance(x, labels, &classes)?;
        let target = diagonal_target(&pooled, "LDA pooled covariance")?;
        let factor = regularised_factor(&pooled, &target, self.shrinkage, "pooled", None)?;
        Ok(LdaModel {
            log_priors: self.priors.log_priors(&counts),
            classes,
            means,
            factor,
        })
    }
}

/// A fitted LDA model.
#[derive(Debug, Clone, PartialEq)]
pub struct LdaModel {
    classes: Vec<usize>,
    means: Vec<DVector<f64>>,
    log_priors: Vec<f64>,
    factor: Factor,
}

impl LdaModel {
    /// Class means, in class order.
    pub fn means(&self) -> &[DVector<f64>] {
        &self.means
    }

    /// The (regularised) pooled covariance used.
    pub fn covariance(&self) -> &DMatrix<f64> {
        &self.factor.sigma
    }

    /// Shrinkage weight λ actually used.
    pub fn shrinkage(&self) -> f64 {
        self.factor.lambda
    }

    /// Unnormalised log-posteriors `−½ (x − μ_k)ᵀ Σ⁻¹ (x − μ_k) + ln π_k` (terms common
    /// to all classes dropped), `n × K`.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn log_scores(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_query("LDA test features", x, self.n_features())?;
        let mut out = DMatrix::zeros(x.nrows(), self.classes.len());
        for (k, (mean, &lp)) in self.means.iter().zip(&self.log_priors).enumerate() {
            let d2 = self.factor.mahalanobis_sq(x, mean, "pooled", None)?;
            for (i, d2) in d2.into_iter().enumerate() {
                out[(i, k)] = lp - 0.5 * d2;
            }
        }
        Ok(out)
    }
}

impl ClassifierModel for LdaModel {
    fn classes(&self) -> &[usize] {
        &self.classes
    }
    fn n_features(&self) -> usize {
        self.factor.l.nrows()
    }
    fn predict(&self, x: &DMatrix<f64>) -> Result<Predictions> {
        Ok(posteriors_from_log(&self.log_scores(x)?, &self.classes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_dimensional_posterior_is_the_logistic_formula() {
        // Class 0 at {−1, 0, 1} (mean 0), class 1 at {2, 3, 4} (mean 3); pooled variance
        // (2 + 2)/(6 − 2) = 1. Posterior of class 1: 1/(1 + exp(−(x·3 − 4.5))).
        let x = DMatrix::from_column_slice(6, 1, &[-1.0, 0.0, 1.0, 2.0, 3.0, 4.0]);
        let m = LdaConfig::default().fit(&x, &[0, 0, 0, 1, 1, 1]).unwrap();
        assert!((m.covariance()[(0, 0)] - 1.0).abs() < 1e-15);
        assert!(m.shrinkage().abs() < f64::MIN_POSITIVE);
        let q = DMatrix::from_column_slice(3, 1, &[0.5, 1.5, 2.2]);
        let p = m.predict(&q).unwrap();
        for (i, xv) in [0.5, 1.5, 2.2].into_iter().enumerate() {
            let expected = 1.0 / (1.0 + (-(3.0 * xv - 4.5f64)).exp());
            assert!((p.scores[(i, 1)] - expected).abs() < 1e-14);
        }
        // x = 1.5 is exactly on the boundary: the tie goes to the lower label.
        assert_eq!(p.labels, vec![0, 0, 1]);
    }

    #[test]
    fn singular_pooled_covariance() {
        // Second feature duplicates the first: rank-one pooled covariance.
        let x = DMatrix::from_row_slice(
            6,
            2,
            &[-1.0, -1.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 4.0],
        );
        let labels = [0, 0, 0, 1, 1, 1];
        let strict = LdaConfig {
            shrinkage: Shrinkage::None,
            ..LdaConfig::default()
        };
        assert!(matches!(
            strict.fit(&x, &labels),
            Err(CondmonError::SingularCovariance { .. })
        ));
        let m = LdaConfig::default().fit(&x, &labels).unwrap();
        assert!(m.shrinkage() > 0.0);
        let p = m
            .predict(&DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 3.0, 3.0]))
            .unwrap();
        assert_eq!(p.labels, vec![0, 1]);
    }
}
