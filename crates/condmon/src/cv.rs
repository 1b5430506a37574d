//! Cross-validated error estimates: stratified k-fold (seeded, ChaCha8) and leave-one-out
//! folds, out-of-fold predictions with preprocessing refitted on each training part,
//! confusion matrices, and the Wilson score interval on the error rate.

use nalgebra::DMatrix;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};

use crate::classify::{Classifier, ClassifierModel};
use crate::data::{check_labelled, classes_of, select_rows};
use crate::error::{CondmonError, Result};
use crate::pipeline::{Preprocessing, TrainedPipeline};

/// How samples are split into folds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum CvScheme {
    /// Stratified k-fold: each class's samples are shuffled with
    /// `ChaCha8Rng::seed_from_u64(seed)` and dealt round-robin over the folds, so every
    /// fold holds ⌊n_c/k⌋ or ⌈n_c/k⌉ samples of each class c and fold sizes differ by at
    /// most one.
    KFold {
        /// Number of folds k (≥ 2, ≤ number of samples).
        folds: usize,
        /// Shuffling seed.
        seed: u64,
    },
    /// Leave-one-out: fold i holds sample i alone (no randomness).
    LeaveOneOut,
}

/// Cross-validation settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CvConfig {
    /// Fold scheme (default stratified 10-fold, seed 0).
    pub scheme: CvScheme,
    /// Confidence level of the error-rate interval, in (0, 1) (default 0.95).
    pub confidence: f64,
}

impl Default for CvConfig {
    fn default() -> Self {
        Self {
            scheme: CvScheme::KFold { folds: 10, seed: 0 },
            confidence: 0.95,
        }
    }
}

impl CvConfig {
    /// Check the confidence level.
    pub fn validate(&self) -> Result<()> {
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return Err(CondmonError::InvalidConfig {
                field: "CvConfig::confidence",
                value: self.confidence,
                reason: "must be in (0, 1)",
            });
        }
        Ok(())
    }
}

/// Stratified k-fold test sets (see [`CvScheme::KFold`]): `folds` sorted index lists that
/// partition `0..labels.len()`.
///
/// Errors: `folds < 2`, fewer samples than folds.
pub fn stratified_folds(labels: &[usize], folds: usize, seed: u64) -> Result<Vec<Vec<usize>>> {
    if folds < 2 {
        return Err(CondmonError::InvalidConfig {
            field: "CvScheme::KFold::folds",
            value: folds as f64,
            reason: "need at least 2 folds",
        });
    }
    if labels.len() < folds {
        return Err(CondmonError::TooFewSamples {
            what: "samples for k-fold cross-validation (one per fold)",
            found: labels.len(),
            needed: folds,
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = vec![Vec::new(); folds];
    let mut next = 0usize;
    for class in classes_of(labels) {
        let mut members: Vec<usize> = (0..labels.len()).filter(|&i| labels[i] == class).collect();
        // Fisher–Yates.
        for i in (1..members.len()).rev() {
            let j = rng.random_range(0..=i);
            members.swap(i, j);
        }
        for m in members {
            out[next % folds].push(m);
            next += 1;
        }
    }
    for f in &mut out {
        f.sort_unstable();
    }
    Ok(out)
}

/// Test-set index lists of `scheme` for `labels`.
///
/// Errors: see [`stratified_folds`]; leave-one-out needs at least two samples.
pub fn folds_for(labels: &[usize], scheme: CvScheme) -> Result<Vec<Vec<usize>>> {
    match scheme {
        CvScheme::KFold { folds, seed } => stratified_folds(labels, folds, seed),
        CvScheme::LeaveOneOut => {
            if labels.len() < 2 {
                return Err(CondmonError::TooFewSamples {
                    what: "samples for leave-one-out",
                    found: labels.len(),
                    needed: 2,
                });
            }
            Ok((0..labels.len()).map(|i| vec![i]).collect())
        }
    }
}

/// A two-sided confidence interval for a proportion.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Interval {
    /// Lower end.
    pub lower: f64,
    /// Upper end.
    pub upper: f64,
    /// Confidence level.
    pub level: f64,
}

/// Wilson score interval (Wilson, JASA 22, 1927) for `errors` out of `n`:
/// `(p̂ + z²/2n ± z·√(p̂(1−p̂)/n + z²/4n²)) / (1 + z²/n)` with `z = Φ⁻¹((1 + level)/2)`.
///
/// Chosen over the normal (Wald) interval because it stays inside [0, 1] and keeps near
/// nominal coverage at 0 errors and small n, which is the regime of these tables. Caveat:
/// cross-validated errors are not independent Bernoulli trials (the folds share training
/// data), so the interval describes test-set sampling only; it is the usual approximation.
///
/// Errors: `n = 0`, `errors > n`, level outside (0, 1).
pub fn wilson_interval(errors: usize, n: usize, level: f64) -> Result<Interval> {
    if n == 0 || errors > n {
        return Err(CondmonError::TooFewSamples {
            what: "trials for a proportion interval (n ≥ max(1, errors))",
            found: n,
            needed: errors.max(1),
        });
    }
    let invalid = CondmonError::InvalidConfig {
        field: "confidence level",
        value: level,
        reason: "must be in (0, 1)",
    };
    if !(level > 0.0 && level < 1.0) {
        return Err(invalid);
    }
    let z = Normal::new(0.0, 1.0)
        .map_err(|_| invalid)?
        .inverse_cdf(0.5 + level / 2.0);
    let nf = n as f64;
    let p = errors as f64 / nf;
    let z2 = z * z;
    let denom = 1.0 + z2 / nf;
    let centre = (p + z2 / (2.0 * nf)) / denom;
    let half = z / denom * (p * (1.0 - p) / nf + z2 / (4.0 * nf * nf)).sqrt();
    Ok(Interval {
        lower: (centre - half).max(0.0),
        upper: (centre + half).min(1.0),
        level,
    })
}

/// Counts of (true class, predicted class) pairs.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConfusionMatrix {
    /// Classes, sorted: the row and column order.
    pub classes: Vec<usize>,
    /// `counts[t][p]`: samples of class `classes[t]` predicted as `classes[p]`.
    pub counts: Vec<Vec<usize>>,
}

impl ConfusionMatrix {
    /// Tally `truth` against `predicted` (labels outside `classes` are ignored).
    pub fn new(classes: &[usize], truth: &[usize], predicted: &[usize]) -> Self {
        let mut counts = vec![vec![0; classes.len()]; classes.len()];
        for (t, p) in truth.iter().zip(predicted) {
            if let (Ok(t), Ok(p)) = (classes.binary_search(t), classes.binary_search(p)) {
                counts[t][p] += 1;
            }
        }
        Self {
            classes: classes.to_vec(),
            counts,
        }
    }

    /// Number of samples tallied.
    pub fn total(&self) -> usize {
        self.counts.iter().flatten().sum()
    }

    /// Number of misclassified samples (off-diagonal sum).
    pub fn errors(&self) -> usize {
        self.total()
            - (0..self.classes.len())
                .map(|i| self.counts[i][i])
                .sum::<usize>()
    }
}

/// Result of one cross-validation run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CvResult {
    /// Fold scheme used.
    pub scheme: CvScheme,
    /// Number of samples (each predicted once, out of fold).
    pub n: usize,
    /// Misclassified samples.
    pub errors: usize,
    /// `errors / n`.
    pub error_rate: f64,
    /// Wilson interval on the error rate.
    pub interval: Interval,
    /// Confusion matrix over all out-of-fold predictions.
    pub confusion: ConfusionMatrix,
    /// Out-of-fold predicted label of each sample.
    pub predictions: Vec<usize>,
    /// Number of features the classifier saw in each fold (differs from the input count
    /// after PCA; may differ between folds when PCA keeps a variance fraction).
    pub features_per_fold: Vec<usize>,
}

impl CvResult {
    /// Error rate in percent (the unit of thesis Tables 6-2…6-5).
    pub fn error_percent(&self) -> f64 {
        100.0 * self.error_rate
    }
}

/// Cross-validate `classifier` behind `preprocessing` on `x` (`n × p`, rows = samples).
///
/// For every fold, preprocessing (standardisation, PCA) and the classifier are fitted on
/// the other folds only, then the fold's samples are predicted.
///
/// Errors: bad data or configuration (checked first), or a fit failing inside a fold
/// ([`CondmonError::Fold`], e.g. a training part with a single class).
pub fn cross_validate<C: Classifier>(
    x: &DMatrix<f64>,
    labels: &[usize],
    preprocessing: &Preprocessing,
    classifier: &C,
    config: &CvConfig,
) -> Result<CvResult> {
    config.validate()?;
    let classes = check_labelled(x, labels)?;
    let folds = folds_for(labels, config.scheme)?;
    cross_validate_with_folds(
        x,
        labels,
        &classes,
        &folds,
        preprocessing,
        classifier,
        config,
    )
}

/// Cross-validation on precomputed folds (already validated data).
pub(crate) fn cross_validate_with_folds<C: Classifier>(
    x: &DMatrix<f64>,
    labels: &[usize],
    classes: &[usize],
    folds: &[Vec<usize>],
    preprocessing: &Preprocessing,
    classifier: &C,
    config: &CvConfig,
) -> Result<CvResult> {
    let n = labels.len();
    let mut predictions = vec![0usize; n];
    let mut features_per_fold = Vec::with_capacity(folds.len());
    let mut in_test = vec![false; n];
    for (f, test) in folds.iter().enumerate() {
        in_test.iter_mut().for_each(|t| *t = false);
        test.iter().for_each(|&i| in_test[i] = true);
        let train: Vec<usize> = (0..n).filter(|&i| !in_test[i]).collect();
        let train_labels: Vec<usize> = train.iter().map(|&i| labels[i]).collect();
        let wrap = |e| CondmonError::Fold {
            fold: f,
            source: Box::new(e),
        };
        let pipe = TrainedPipeline::fit(
            preprocessing,
            classifier,
            &select_rows(x, &train),
            &train_labels,
        )
        .map_err(wrap)?;
        features_per_fold.push(pipe.model.n_features());
        let pred = pipe.predict(&select_rows(x, test)).map_err(wrap)?;
        for (&i, &l) in test.iter().zip(&pred.labels) {
            predictions[i] = l;
        }
    }
    let confusion = ConfusionMatrix::new(classes, labels, &predictions);
    let errors = confusion.errors();
    Ok(CvResult {
        scheme: config.scheme,
        n,
        errors,
        error_rate: errors as f64 / n as f64,
        interval: wilson_interval(errors, n, config.confidence)?,
        confusion,
        predictions,
        features_per_fold,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_known_values() {
        // 0/10 at 95 %: upper = z²/(n + z²) with z = 1.959964 → 3.841459/13.841459.
        let i = wilson_interval(0, 10, 0.95).unwrap();
        assert!(i.lower.abs() < 1e-15);
        assert!((i.upper - 3.841_458_820_694_124 / 13.841_458_820_694_124).abs() < 1e-9);
        // 5/10 at 95 %: symmetric about 0.5, half-width z·√(0.025 + z²/400)/(1 + z²/10)
        // = 0.263357 (tabulated Wilson interval [0.2366, 0.7634]).
        let i = wilson_interval(5, 10, 0.95).unwrap();
        assert!((i.lower - 0.236_593).abs() < 1e-6 && (i.upper - 0.763_407).abs() < 1e-6);
        assert!(wilson_interval(3, 2, 0.95).is_err());
        assert!(wilson_interval(1, 2, 1.0).is_err());
    }

    #[test]
    fn confusion_counts() {
        let c = ConfusionMatrix::new(&[1, 2], &[1, 1, 2, 2, 2], &[1, 2, 2, 2, 1]);
        assert_eq!(c.counts, vec![vec![1, 1], vec![1, 2]]);
        assert_eq!((c.total(), c.errors()), (5, 2));
    }
}
