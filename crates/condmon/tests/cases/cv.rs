//! Cross-validation: stratified, deterministic folds; leave-one-out against a
//! hand-computed result; preprocessing fitted per fold; error tables consistent with
//! single runs and serialisable.

use condmon::{
    ClassifierSpec, CvConfig, CvScheme, ErrorTable, FeatureScaling, KnnConfig, LdaConfig,
    Preprocessing, QdaConfig, Reduction, TrainedPipeline, cross_validate, error_table, folds_for,
    stratified_folds,
};
use nalgebra::DMatrix;

use crate::common::{Gauss, rng, two_classes};

#[test]
fn folds_are_stratified_partitions_and_deterministic() {
    // Classes of 17, 9 and 4 samples with non-contiguous labels, interleaved by the
    // permutation i ↦ 7i mod 30.
    let labels: Vec<usize> = (0..30)
        .map(|i| match (7 * i) % 30 {
            0..17 => 3,
            17..26 => 7,
            _ => 11,
        })
        .collect();
    let count = |c: usize| labels.iter().filter(|&&l| l == c).count();
    let sizes = [(3, count(3)), (7, count(7)), (11, count(11))];
    assert_eq!(sizes.map(|s| s.1), [17, 9, 4]);
    for k in [2, 3, 5, 7] {
        let folds = stratified_folds(&labels, k, 42).unwrap();
        assert_eq!(folds.len(), k);
        // A partition of 0..30.
        let mut all: Vec<usize> = folds.iter().flatten().copied().collect();
        all.sort_unstable();
        assert_eq!(all, (0..30).collect::<Vec<_>>());
        // Per class and fold: ⌊n_c/k⌋ or ⌈n_c/k⌉ (within ±1 of each other).
        for &(c, n_c) in &sizes {
            for f in &folds {
                let in_fold = f.iter().filter(|&&i| labels[i] == c).count();
                assert!(
                    in_fold == n_c / k || in_fold == n_c.div_ceil(k),
                    "k {k} class {c}"
                );
            }
        }
        // Fold sizes differ by at most one.
        let min = folds.iter().map(Vec::len).min().unwrap();
        let max = folds.iter().map(Vec::len).max().unwrap();
        assert!(max - min <= 1);
        // Same seed, same folds; some other seed, different folds.
        assert_eq!(stratified_folds(&labels, k, 42).unwrap(), folds);
        assert!((0..5).any(|s| stratified_folds(&labels, k, 100 + s).unwrap() != folds));
    }
}

#[test]
fn leave_one_out_matches_hand_computation() {
    // 1-D, 1-NN, no scaling. Leaving each point out, its nearest other point is:
    //   0.0 → 0.9 (class 0, right)    0.9 → 0.0 (class 0, right)
    //   2.0 → 0.9 (class 0, wrong)    3.2 → 4.0 (class 1, wrong)
    //   4.0 → 3.2 (class 0, wrong)    6.5 → 4.0 (class 1, right)
    let x = DMatrix::from_column_slice(6, 1, &[0.0, 0.9, 2.0, 3.2, 4.0, 6.5]);
    let labels = [0, 0, 1, 0, 1, 1];
    let config = CvConfig {
        scheme: CvScheme::LeaveOneOut,
        ..CvConfig::default()
    };
    let knn = KnnConfig { k: 1 };
    for scaling in [FeatureScaling::None, FeatureScaling::Standardise] {
        // Standardising a single feature is a monotone affine map: same neighbours.
        let pre = Preprocessing {
            scaling,
            reduction: Reduction::None,
        };
        let r = cross_validate(&x, &labels, &pre, &knn, &config).unwrap();
        assert_eq!(r.predictions, vec![0, 0, 0, 1, 0, 1]);
        assert_eq!(r.errors, 3);
        assert!((r.error_percent() - 50.0).abs() < 1e-12);
        assert_eq!(r.confusion.counts, vec![vec![2, 1], vec![2, 1]]);
        assert_eq!(r.features_per_fold, vec![1; 6]);
    }
    assert_eq!(folds_for(&labels, CvScheme::LeaveOneOut).unwrap().len(), 6);
}

fn gaussian_set(seed: u64) -> (DMatrix<f64>, Vec<usize>) {
    let c0 = Gauss::new(
        &[0.0, 0.0, 0.0],
        &[1.0, 0.3, 0.0, 0.3, 1.0, 0.2, 0.0, 0.2, 2.0],
    );
    let c1 = Gauss::new(
        &[1.0, 0.5, -0.5],
        &[1.5, 0.0, 0.1, 0.0, 1.0, 0.0, 0.1, 0.0, 1.0],
    );
    let (mut x, y) = two_classes(&mut rng(seed), 30, &c0, &c1);
    // Put the features on very different scales, as raw network weights are.
    for (j, s) in [1.0, 100.0, 0.01].into_iter().enumerate() {
        x.column_mut(j).scale_mut(s);
    }
    (x, y)
}

#[test]
fn preprocessing_is_fitted_on_training_folds_only() {
    // The k-fold result equals an explicit loop that fits the pipeline on the other folds'
    // rows only (the definition of leak-free cross-validation), fold by fold.
    let (x, y) = gaussian_set(41);
    let config = CvConfig {
        scheme: CvScheme::KFold { folds: 4, seed: 9 },
        ..CvConfig::default()
    };
    let pre = Preprocessing::pca_fraction(0.9);
    let clf = ClassifierSpec::Knn(KnnConfig { k: 3 });
    let r = cross_validate(&x, &y, &pre, &clf, &config).unwrap();
    let folds = folds_for(&y, config.scheme).unwrap();
    let mut expected = vec![usize::MAX; y.len()];
    for (f, test) in folds.iter().enumerate() {
        let train: Vec<usize> = (0..y.len()).filter(|i| !test.contains(i)).collect();
        let xt = DMatrix::from_fn(train.len(), 3, |i, j| x[(train[i], j)]);
        let yt: Vec<usize> = train.iter().map(|&i| y[i]).collect();
        let pipe = TrainedPipeline::fit(&pre, &clf, &xt, &yt).unwrap();
        let pca = pipe.preprocessing.pca.as_ref().unwrap();
        assert_eq!(r.features_per_fold[f], pca.n_components());
        let xs = DMatrix::from_fn(test.len(), 3, |i, j| x[(test[i], j)]);
        for (&i, &l) in test.iter().zip(&pipe.predict(&xs).unwrap().labels) {
            expected[i] = l;
        }
    }
    assert_eq!(r.predictions, expected);
    // Deterministic under the seed.
    assert_eq!(cross_validate(&x, &y, &pre, &clf, &config).unwrap(), r);
}

#[test]
fn error_table_matches_single_runs_and_round_trips() {
    let (x, y) = gaussian_set(42);
    let classifiers = vec![
        ClassifierSpec::Lda(LdaConfig::default()),
        ClassifierSpec::Qda(QdaConfig::default()),
        ClassifierSpec::Knn(KnnConfig { k: 5 }),
    ];
    let columns = [Preprocessing::default(), Preprocessing::pca_fraction(0.95)];
    let config = CvConfig {
        scheme: CvScheme::KFold { folds: 5, seed: 3 },
        confidence: 0.9,
    };
    let table = error_table(&x, &y, &classifiers, &columns, &config).unwrap();
    assert_eq!(table.rows.len(), 3);
    assert_eq!(table.columns, vec!["no PCA", "after PCA (95 % variance)"]);
    for (r, clf) in classifiers.iter().enumerate() {
        for (c, pre) in columns.iter().enumerate() {
            let single = cross_validate(&x, &y, pre, clf, &config).unwrap();
            let cell = table.cell(r, c).unwrap();
            assert_eq!(cell, &single);
            assert!(
                cell.interval.lower <= cell.error_rate && cell.error_rate <= cell.interval.upper
            );
            assert!((table.percentages()[(r, c)] - 100.0 * single.error_rate).abs() < 1e-12);
        }
    }
    let json = serde_json::to_string(&table).unwrap();
    let back: ErrorTable = serde_json::from_str(&json).unwrap();
    assert_eq!(back, table);
}
