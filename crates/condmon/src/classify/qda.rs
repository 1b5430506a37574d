//! Quadratic discriminant analysis: Gaussian classes with their own covariances,
//! regularised toward the pooled covariance (Friedman's RDA, JASA 84(405), 1989), priors,
//! and log-posteriors through per-class Cholesky factors.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::covariance::{Factor, diagonal_target, regularised_factor, scatter};
use super::lda::{Pooled, pooled_covariance};
use super::{Classifier, ClassifierModel, Predictions, Priors, Shrinkage, posteriors_from_log};
use crate::data::{check_labelled, check_query};
use crate::error::Result;

/// QDA settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QdaConfig {
    /// Class priors (default: training frequencies).
    pub priors: Priors,
    /// Weight α of the per-class covariance blend `(1 − α)·S_k + α·Σ_pooled` (α = 1 is
    /// LDA with pooled covariance). Default [`Shrinkage::Auto`]: α = 0 unless a class
    /// covariance is singular, as it is whenever a class has no more samples than
    /// features; a class with a single sample has `S_k = 0` and needs α > 0.
    ///
    /// `Auto` only restores numerical conditioning: with few samples per class it picks a
    /// small α, so each class density is very narrow off the span of its own training
    /// deviations and the posteriors are overconfident (classification then behaves like
    /// "nearest class subspace"). With few samples per class (e.g. the thesis's 8
    /// networks per class and 13 weights) prefer a fixed α such as 0.5, or PCA first.
    pub regularisation: Shrinkage,
    /// Shrinkage of the pooled covariance toward its diagonal, as in
    /// [`LdaConfig::shrinkage`](super::LdaConfig::shrinkage) (default
    /// [`Shrinkage::Auto`]).
    pub pooled_shrinkage: Shrinkage,
}

impl Default for QdaConfig {
    fn default() -> Self {
        Self {
            priors: Priors::Empirical,
            regularisation: Shrinkage::Auto,
            pooled_shrinkage: Shrinkage::Auto,
        }
    }
}

impl Classifier for QdaConfig {
    type Model = QdaModel;

    /// Errors: invalid shrinkage weights, bad data, `n ≤ K`, a covariance still singular
    /// after regularisation, all features constant.
    fn fit(&self, x: &DMatrix<f64>, labels: &[usize]) -> Result<QdaModel> {
        self.regularisation.validate("QdaConfig::regularisation")?;
        self.pooled_shrinkage
            .validate("QdaConfig::pooled_shrinkage")?;
        let classes = check_labelled(x, labels)?;
        let Pooled {
            cov: pooled,
            means,
            counts,
        } = pooled_covariance(x, labels, &classes)?;
        let target = diagonal_target(&pooled, "QDA pooled covariance")?;
        let pooled =
            regularised_factor(&pooled, &target, self.pooled_shrinkage, "pooled", None)?.sigma;
        let mut factors = Vec::with_capacity(classes.len());
        for ((&class, mean), &count) in classes.iter().zip(&means).zip(&counts) {
            let mut s = scatter(x, labels, class, mean);
            if count > 1 {
                s /= (count - 1) as f64;
            }
            factors.push(regularised_factor(
                &s,
                &pooled,
                self.regularisation,
                "class",
                Some(class),
            )?);
        }
        Ok(QdaModel {
            log_priors: self.priors.log_priors(&counts),
            classes,
            means,
            factors,
        })
    }
}

/// A fitted QDA model.
#[derive(Debug, Clone, PartialEq)]
pub struct QdaModel {
    classes: Vec<usize>,
    means: Vec<DVector<f64>>,
    log_priors: Vec<f64>,
    factors: Vec<Factor>,
}

impl QdaModel {
    /// Class means, in class order.
    pub fn means(&self) -> &[DVector<f64>] {
        &self.means
    }

    /// The (regularised) covariance of each class, in class order.
    pub fn covariances(&self) -> Vec<&DMatrix<f64>> {
        self.factors.iter().map(|f| &f.sigma).collect()
    }

    /// Blend weight α used for each class, in class order.
    pub fn regularisation(&self) -> Vec<f64> {
        self.factors.iter().map(|f| f.lambda).collect()
    }

    /// Unnormalised log-posteriors
    /// `−½ (x − μ_k)ᵀ Σ_k⁻¹ (x − μ_k) − ½ ln det Σ_k + ln π_k`, `n × K`.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    pub fn log_scores(&self, x: &DMatrix<f64>) -> Result<DMatrix<f64>> {
        check_query("QDA test features", x, self.n_features())?;
        let mut out = DMatrix::zeros(x.nrows(), self.classes.len());
        for (k, ((mean, &lp), f)) in self
            .means
            .iter()
            .zip(&self.log_priors)
            .zip(&self.factors)
            .enumerate()
        {
            let d2 = f.mahalanobis_sq(x, mean, "class", Some(self.classes[k]))?;
            for (i, d2) in d2.into_iter().enumerate() {
                out[(i, k)] = lp - 0.5 * (d2 + f.log_det);
            }
        }
        Ok(out)
    }
}

impl ClassifierModel for QdaModel {
    fn classes(&self) -> &[usize] {
        &self.classes
    }
    fn n_features(&self) -> usize {
        self.means.first().map_or(0, |m| m.len())
    }
    fn predict(&self, x: &DMatrix<f64>) -> Result<Predictions> {
        Ok(posteriors_from_log(&self.log_scores(x)?, &self.classes))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::CondmonError;

    #[test]
    fn one_dimensional_log_scores_match_gaussian_densities() {
        // Class 0: {−1, 1} → μ 0, s² 2. Class 1: {2, 4, 6} → μ 4, s² 4. Priors 2/5, 3/5.
        let x = DMatrix::from_column_slice(5, 1, &[-1.0, 1.0, 2.0, 4.0, 6.0]);
        let m = QdaConfig::default().fit(&x, &[0, 0, 1, 1, 1]).unwrap();
        assert_eq!(m.regularisation(), vec![0.0, 0.0]);
        let q = DMatrix::from_column_slice(2, 1, &[0.3, 2.9]);
        let p = m.predict(&q).unwrap();
        let dens = |x: f64, mu: f64, v: f64| (-(x - mu).powi(2) / (2.0 * v)).exp() / v.sqrt();
        for (i, xv) in [0.3, 2.9].into_iter().enumerate() {
            let a = 0.4 * dens(xv, 0.0, 2.0);
            let b = 0.6 * dens(xv, 4.0, 4.0);
            assert!((p.scores[(i, 1)] - b / (a + b)).abs() < 1e-14);
        }
    }

    #[test]
    fn single_sample_class_needs_regularisation() {
        let x = DMatrix::from_column_slice(4, 1, &[0.0, 1.0, 2.0, 9.0]);
        let labels = [0, 0, 0, 1];
        let strict = QdaConfig {
            regularisation: Shrinkage::None,
            ..QdaConfig::default()
        };
        assert!(matches!(
            strict.fit(&x, &labels),
            Err(CondmonError::SingularCovariance { class: Some(1), .. })
        ));
        let m = QdaConfig::default().fit(&x, &labels).unwrap();
        // S₁ = 0, so the blend (1 − α)·0 + α·Σ is well conditioned at the first α > 0.
        assert_eq!(m.regularisation(), vec![0.0, 1e-6]);
    }
}
