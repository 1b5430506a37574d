//! The classifier vocabulary: the [`Classifier`] / [`ClassifierModel`] traits (config →
//! fitted model → predictions with posteriors or vote shares), [`Predictions`],
//! [`Priors`], and [`ClassifierSpec`], the closed set used by error tables.

pub mod bayes;
pub mod covariance;
pub mod knn;
pub mod lda;
pub mod qda;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::error::Result;

pub use bayes::{NaiveBayesConfig, NaiveBayesModel};
pub use covariance::Shrinkage;
pub use knn::{KnnConfig, KnnModel};
pub use lda::{LdaConfig, LdaModel};
pub use qda::{QdaConfig, QdaModel};

/// What the per-class scores of a [`Predictions`] mean.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ScoreKind {
    /// Posterior class probabilities under the model (rows sum to 1).
    Posterior,
    /// Share of the neighbour set voting for each class (rows sum to 1).
    VoteShare,
}

/// Predicted labels and per-class scores for a batch of samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Predictions {
    /// Classes known to the model, sorted; the column order of `scores`.
    pub classes: Vec<usize>,
    /// Predicted label of each sample.
    pub labels: Vec<usize>,
    /// `n × K` scores (posteriors or vote shares, see `kind`).
    pub scores: DMatrix<f64>,
    /// Meaning of `scores`.
    pub kind: ScoreKind,
}

/// Class prior probabilities for the discriminant classifiers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Priors {
    /// Class frequencies in the training data (MATLAB `classify`'s default).
    #[default]
    Empirical,
    /// Equal priors 1/K.
    Uniform,
}

impl Priors {
    /// Natural-log priors for class counts `counts`.
    pub(crate) fn log_priors(&self, counts: &[usize]) -> Vec<f64> {
        let k = counts.len() as f64;
        let n: usize = counts.iter().sum();
        counts
            .iter()
            .map(|&c| match self {
                Self::Empirical => (c as f64 / n as f64).ln(),
                Self::Uniform => -k.ln(),
            })
            .collect()
    }
}

/// A classifier configuration that can be fitted to labelled features.
///
/// `x` is `n × p` (rows = samples); `labels[i]` is the class of row `i`. Labels are
/// arbitrary `usize` values; at least two distinct ones are needed.
pub trait Classifier {
    /// The fitted model.
    type Model: ClassifierModel;
    /// Validate the configuration and the data, then fit.
    fn fit(&self, x: &DMatrix<f64>, labels: &[usize]) -> Result<Self::Model>;
}

/// A fitted classifier.
pub trait ClassifierModel {
    /// Classes seen in training, sorted.
    fn classes(&self) -> &[usize];
    /// Number of features expected by [`ClassifierModel::predict`].
    fn n_features(&self) -> usize;
    /// Labels and per-class scores of the rows of `x`.
    ///
    /// Errors: wrong number of columns, a non-finite entry.
    fn predict(&self, x: &DMatrix<f64>) -> Result<Predictions>;
}

/// Index of the largest score in a row; exact ties go to the lowest class label (the
/// first column, since classes are sorted).
pub(crate) fn argmax_lowest(row: impl Iterator<Item = f64>) -> usize {
    let mut best = 0;
    let mut best_v = f64::NEG_INFINITY;
    for (j, v) in row.enumerate() {
        if v > best_v {
            best = j;
            best_v = v;
        }
    }
    best
}

/// Turn `n × K` log-scores into posteriors (log-sum-exp per row) and labels.
pub(crate) fn posteriors_from_log(log_scores: &DMatrix<f64>, classes: &[usize]) -> Predictions {
    let mut scores = log_scores.clone();
    let mut labels = Vec::with_capacity(scores.nrows());
    for mut row in scores.row_iter_mut() {
        let best = argmax_lowest(row.iter().copied());
        let m = row[best];
        row.apply(|v| *v = (*v - m).exp());
        let s = row.sum();
        row /= s;
        labels.push(classes[best]);
    }
    Predictions {
        classes: classes.to_vec(),
        labels,
        scores,
        kind: ScoreKind::Posterior,
    }
}

/// The four classifiers of thesis ch. 6, as one closed set (used by error tables).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum ClassifierSpec {
    /// Linear discriminant analysis.
    Lda(LdaConfig),
    /// Quadratic discriminant analysis.
    Qda(QdaConfig),
    /// k nearest neighbours.
    Knn(KnnConfig),
    /// Gaussian naive Bayes.
    NaiveBayes(NaiveBayesConfig),
}

impl ClassifierSpec {
    /// The thesis's four rows (Tables 6-2…6-5) with default settings.
    pub fn thesis_set() -> Vec<ClassifierSpec> {
        vec![
            Self::Lda(LdaConfig::default()),
            Self::Qda(QdaConfig::default()),
            Self::Knn(KnnConfig::default()),
            Self::NaiveBayes(NaiveBayesConfig::default()),
        ]
    }

    /// Row label as in the thesis tables (k-NN shows its k).
    pub fn label(&self) -> String {
        match self {
            Self::Lda(_) => "Linear Discriminant".to_owned(),
            Self::Qda(_) => "Quadratic Discriminant".to_owned(),
            Self::Knn(c) => format!("k-NN (k = {})", c.k),
            Self::NaiveBayes(_) => "Naive Bayes".to_owned(),
        }
    }
}

/// A model fitted from a [`ClassifierSpec`].
#[derive(Debug, Clone)]
pub enum TrainedModel {
    /// See [`LdaModel`].
    Lda(LdaModel),
    /// See [`QdaModel`].
    Qda(QdaModel),
    /// See [`KnnModel`].
    Knn(KnnModel),
    /// See [`NaiveBayesModel`].
    NaiveBayes(NaiveBayesModel),
}

impl Classifier for ClassifierSpec {
    type Model = TrainedModel;
    fn fit(&self, x: &DMatrix<f64>, labels: &[usize]) -> Result<TrainedModel> {
        Ok(match self {
            Self::Lda(c) => TrainedModel::Lda(c.fit(x, labels)?),
            Self::Qda(c) => TrainedModel::Qda(c.fit(x, labels)?),
            Self::Knn(c) => TrainedModel::Knn(c.fit(x, labels)?),
            Self::NaiveBayes(c) => TrainedModel::NaiveBayes(c.fit(x, labels)?),
        })
    }
}

impl ClassifierModel for TrainedModel {
    fn classes(&self) -> &[usize] {
        match self {
            Self::Lda(m) => m.classes(),
            Self::Qda(m) => m.classes(),
            Self::Knn(m) => m.classes(),
            Self::NaiveBayes(m) => m.classes(),
        }
    }
    fn n_features(&self) -> usize {
        match self {
            Self::Lda(m) => m.n_features(),
            Self::Qda(m) => m.n_features(),
            Self::Knn(m) => m.n_features(),
            Self::NaiveBayes(m) => m.n_features(),
        }
    }
    fn predict(&self, x: &DMatrix<f64>) -> Result<Predictions> {
        match self {
            Self::Lda(m) => m.predict(x),
            Self::Qda(m) => m.predict(x),
            Self::Knn(m) => m.predict(x),
            Self::NaiveBayes(m) => m.predict(x),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_sum_exp_posteriors() {
        // log-scores (0, ln 3) → posteriors (1/4, 3/4); large offsets must not overflow.
        let l = DMatrix::from_row_slice(2, 2, &[0.0, 3f64.ln(), 1000.0, 1000.0 + 3f64.ln()]);
        let p = posteriors_from_log(&l, &[4, 9]);
        // Row 1 stores 1000 + ln 3, which carries an absolute error up to ε·1000 ≈ 1e-13.
        for (r, tol) in [(0, 1e-15), (1, 1e-12)] {
            assert!((p.scores[(r, 0)] - 0.25).abs() < tol);
            assert!((p.scores[(r, 1)] - 0.75).abs() < tol);
            assert_eq!(p.labels[r], 9);
        }
        // Exact tie: lowest label.
        let tie = DMatrix::from_row_slice(1, 2, &[-1.0, -1.0]);
        assert_eq!(posteriors_from_log(&tie, &[4, 9]).labels, vec![4]);
    }
}
