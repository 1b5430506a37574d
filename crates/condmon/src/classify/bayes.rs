//! Gaussian naive Bayes through linfa-bayes (`GaussianNb`): per-class, per-feature normal
//! densities, class-frequency priors, posteriors from linfa's log-probabilities.

use linfa::prelude::*;
use linfa_bayes::{GaussianNb, NaiveBayes};
use nalgebra::DMatrix;
use ndarray::Array1;
use serde::{Deserialize, Serialize};

use super::{Classifier, ClassifierModel, Predictions, ScoreKind, argmax_lowest};
use crate::data::{check_labelled, check_query, to_array2};
use crate::error::{CondmonError, Result};

/// Gaussian naive Bayes settings.
///
/// linfa estimates each class's feature variances by maximum likelihood (divisor `n_k`)
/// and adds `var_smoothing × (largest variance of any feature over all training rows)` to
/// every one, so that a feature constant within a class does not give a zero variance.
/// Priors are the training class frequencies.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NaiveBayesConfig {
    /// Variance smoothing (default 1e-9, linfa's and scikit-learn's default). Must be
    /// positive and finite.
    pub var_smoothing: f64,
}

impl Default for NaiveBayesConfig {
    fn default() -> Self {
        Self {
            var_smoothing: 1e-9,
        }
    }
}

impl Classifier for NaiveBayesConfig {
    type Model = NaiveBayesModel;

    /// Errors: non-positive smoothing, bad data, all features constant.
    fn fit(&self, x: &DMatrix<f64>, labels: &[usize]) -> Result<NaiveBayesModel> {
        if !(self.var_smoothing > 0.0 && self.var_smoothing.is_finite()) {
            return Err(CondmonError::InvalidConfig {
                field: "NaiveBayesConfig::var_smoothing",
                value: self.var_smoothing,
                reason: "must be positive and finite",
            });
        }
        let classes = check_labelled(x, labels)?;
        let constant = x
            .column_iter()
            .all(|c| c.iter().all(|v| v.to_bits() == c[0].to_bits()));
        if constant {
            return Err(CondmonError::ZeroVariance {
                what: "naive Bayes",
            });
        }
        let ds = Dataset::new(to_array2(x), Array1::from(labels.to_vec()));
        let model = GaussianNb::params()
            .var_smoothing(self.var_smoothing)
            .fit(&ds)?;
        Ok(NaiveBayesModel {
            model,
            classes,
            n_features: x.ncols(),
        })
    }
}

/// A fitted Gaussian naive Bayes model.
#[derive(Debug, Clone, PartialEq)]
pub struct NaiveBayesModel {
    model: GaussianNb<f64, usize>,
    classes: Vec<usize>,
    n_features: usize,
}

impl ClassifierModel for NaiveBayesModel {
    fn classes(&self) -> &[usize] {
        &self.classes
    }
    fn n_features(&self) -> usize {
        self.n_features
    }

    fn predict(&self, x: &DMatrix<f64>) -> Result<Predictions> {
        check_query("naive Bayes test features", x, self.n_features)?;
        let a = to_array2(x);
        // linfa returns columns in sorted label order, the same order as `classes`.
        let (log_proba, order) = self.model.predict_log_proba(a.view());
        let mut scores = DMatrix::zeros(x.nrows(), self.classes.len());
        for (col, label) in order.iter().enumerate() {
            let Ok(k) = self.classes.binary_search(label) else {
                continue;
            };
            for i in 0..x.nrows() {
                scores[(i, k)] = log_proba[[i, col]];
            }
        }
        let mut labels = Vec::with_capacity(x.nrows());
        for mut row in scores.row_iter_mut() {
            labels.push(self.classes[argmax_lowest(row.iter().copied())]);
            row.apply(|v| *v = v.exp());
            let s = row.sum();
            row /= s;
        }
        Ok(Predictions {
            classes: self.classes.clone(),
            labels,
            scores,
            kind: ScoreKind::Posterior,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn posteriors_match_hand_computed_densities() {
        // Feature 0: class 0 {0, 2} (μ 1, ML var 1), class 1 {4, 6, 8} (μ 6, var 8/3).
        // Feature 1: class 0 {1, 3} (μ 2, var 1), class 1 {0, 0, 3} (μ 1, var 2).
        // Smoothing 1e-12 × max overall variance changes nothing at 1e-10.
        let x = DMatrix::from_row_slice(5, 2, &[0.0, 1.0, 2.0, 3.0, 4.0, 0.0, 6.0, 0.0, 8.0, 3.0]);
        let m = NaiveBayesConfig {
            var_smoothing: 1e-12,
        }
        .fit(&x, &[3, 3, 8, 8, 8])
        .unwrap();
        let q = DMatrix::from_row_slice(1, 2, &[3.5, 1.5]);
        let p = m.predict(&q).unwrap();
        let g = |x: f64, mu: f64, v: f64| (-(x - mu).powi(2) / (2.0 * v)).exp() / v.sqrt();
        let a = 0.4 * g(3.5, 1.0, 1.0) * g(1.5, 2.0, 1.0);
        let b = 0.6 * g(3.5, 6.0, 8.0 / 3.0) * g(1.5, 1.0, 2.0);
        assert!((p.scores[(0, 1)] - b / (a + b)).abs() < 1e-10);
        assert_eq!(p.labels, vec![if b > a { 8 } else { 3 }]);
    }

    #[test]
    fn bad_inputs() {
        let x = DMatrix::from_element(4, 2, 1.0);
        assert!(matches!(
            NaiveBayesConfig::default().fit(&x, &[0, 0, 1, 1]),
            Err(CondmonError::ZeroVariance { .. })
        ));
        assert!(matches!(
            NaiveBayesConfig { var_smoothing: 0.0 }.fit(&x, &[0, 0, 1, 1]),
            Err(CondmonError::InvalidConfig { .. })
        ));
    }
}
