//! Bad input gives typed errors that say where: one class only, fewer samples than folds,
//! non-finite features, dimension mismatches, invalid configuration, a fold whose training
//! part loses a class.

use condmon::{
    Classifier, ClassifierModel, ClassifierSpec, ComponentSelection, CondmonError, CvConfig,
    CvScheme, Pca, Preprocessing, Standardiser, cross_validate, error_table,
};
use nalgebra::DMatrix;

fn data() -> (DMatrix<f64>, Vec<usize>) {
    let x = DMatrix::from_fn(8, 2, |i, j| {
        (i * 3 + j * 5) as f64 % 7.0 + if i < 4 { 0.0 } else { 10.0 }
    });
    (x, vec![0, 0, 0, 0, 1, 1, 1, 1])
}

#[test]
fn every_classifier_rejects_bad_training_data() {
    let (x, y) = data();
    for spec in ClassifierSpec::thesis_set() {
        assert!(
            matches!(
                spec.fit(&x, &[2; 8]),
                Err(CondmonError::TooFewClasses { found: 1, .. })
            ),
            "{}",
            spec.label()
        );
        let mut bad = x.clone();
        bad[(5, 1)] = f64::NAN;
        assert!(matches!(
            spec.fit(&bad, &y),
            Err(CondmonError::NonFinite {
                sample: 5,
                feature: 1,
                ..
            })
        ));
        assert!(matches!(
            spec.fit(&x, &y[..7]),
            Err(CondmonError::Length {
                found: 7,
                expected: 8,
                ..
            })
        ));
        // Prediction: wrong width, then a non-finite entry.
        let model = spec.fit(&x, &y).unwrap();
        assert!(matches!(
            model.predict(&DMatrix::zeros(2, 3)),
            Err(CondmonError::Shape {
                cols: 3,
                expected_cols: 2,
                ..
            })
        ));
        let mut q = DMatrix::zeros(2, 2);
        q[(1, 0)] = f64::INFINITY;
        assert!(matches!(
            model.predict(&q),
            Err(CondmonError::NonFinite {
                sample: 1,
                feature: 0,
                ..
            })
        ));
    }
}

#[test]
fn cross_validation_rejects_bad_setups() {
    let (x, y) = data();
    let clf = ClassifierSpec::thesis_set().remove(0);
    let pre = Preprocessing::default();
    let kfold = |folds| CvConfig {
        scheme: CvScheme::KFold { folds, seed: 0 },
        ..CvConfig::default()
    };
    assert!(matches!(
        cross_validate(&x, &y, &pre, &clf, &kfold(9)),
        Err(CondmonError::TooFewSamples {
            found: 8,
            needed: 9,
            ..
        })
    ));
    assert!(matches!(
        cross_validate(&x, &y, &pre, &clf, &kfold(1)),
        Err(CondmonError::InvalidConfig { .. })
    ));
    assert!(matches!(
        cross_validate(&x, &[1; 8], &pre, &clf, &kfold(2)),
        Err(CondmonError::TooFewClasses { found: 1, .. })
    ));
    let bad_level = CvConfig {
        confidence: 1.2,
        ..CvConfig::default()
    };
    assert!(matches!(
        cross_validate(&x, &y, &pre, &clf, &bad_level),
        Err(CondmonError::InvalidConfig {
            field: "CvConfig::confidence",
            ..
        })
    ));
    // Leave-one-out with a single sample of class 1: leaving it out (fold 7) leaves one
    // class in training. The error names the fold.
    let lonely = [0, 0, 0, 0, 0, 0, 0, 1];
    let loo = CvConfig {
        scheme: CvScheme::LeaveOneOut,
        ..CvConfig::default()
    };
    match cross_validate(&x, &lonely, &pre, &clf, &loo) {
        Err(CondmonError::Fold { fold: 7, source }) => {
            assert!(matches!(
                *source,
                CondmonError::TooFewClasses { found: 1, .. }
            ))
        }
        other => panic!("expected fold error, got {other:?}"),
    }
    assert!(matches!(
        error_table(&x, &y, &[], &[pre], &CvConfig::default()),
        Err(CondmonError::Length { .. })
    ));
}

#[test]
fn transforms_reject_bad_data() {
    let (x, _) = data();
    let mut bad = x.clone();
    bad[(0, 0)] = f64::NAN;
    assert!(matches!(
        Standardiser::fit(&bad),
        Err(CondmonError::NonFinite {
            sample: 0,
            feature: 0,
            ..
        })
    ));
    assert!(matches!(
        Pca::fit(&bad, ComponentSelection::All),
        Err(CondmonError::NonFinite { .. })
    ));
    let pca = Pca::fit(&x, ComponentSelection::Fixed(1)).unwrap();
    assert!(matches!(
        pca.transform(&DMatrix::zeros(1, 3)),
        Err(CondmonError::Shape { .. })
    ));
    assert!(matches!(
        pca.inverse_transform(&DMatrix::zeros(1, 2)),
        Err(CondmonError::Shape { .. })
    ));
}
