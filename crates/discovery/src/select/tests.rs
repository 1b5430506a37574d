//! Unit tests of stepwise selection against brute-force least squares and known
//! structure.

use super::*;

/// Deterministic pseudo-random numbers in [-0.5, 0.5) (64-bit LCG, top bits).
fn noise(seed: u64, n: usize) -> Vec<f64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect()
}

fn design(y: Vec<f64>, columns: Vec<Vec<f64>>) -> Design {
    let n = y.len();
    Design {
        y,
        columns,
        segments: vec![n],
    }
}

/// y = 2 x − 0.5 x³ + small white noise: the two true columns are chosen out of
/// {1, x, x³, sin 3x, x²}, and the coefficients equal an independent normal-equation
/// solve on the true columns (brute force) to 1e-10.
#[test]
fn recovers_the_true_columns_and_matches_least_squares() {
    let n = 400;
    let x: Vec<f64> = (0..n)
        .map(|k| -2.0 + 4.0 * k as f64 / (n - 1) as f64)
        .collect();
    let e = noise(1, n);
    let y: Vec<f64> = x
        .iter()
        .zip(&e)
        .map(|(x, e)| 2.0 * x - 0.5 * x.powi(3) + 0.01 * e)
        .collect();
    let cols = vec![
        vec![1.0; n],
        x.clone(),
        x.iter().map(|v| v.powi(3)).collect(),
        x.iter().map(|v| (3.0 * v).sin()).collect(),
        x.iter().map(|v| v * v).collect(),
    ];
    let sel = select(
        &design(y.clone(), cols.clone()),
        &SelectionConfig::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let chosen: Vec<usize> = sel.terms.iter().map(|t| t.candidate).collect();
    assert_eq!(chosen, vec![1, 2], "{sel:?}");
    // Brute-force 2×2 normal equations.
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
    let (a11, a12, a22) = (
        dot(&cols[1], &cols[1]),
        dot(&cols[1], &cols[2]),
        dot(&cols[2], &cols[2]),
    );
    let (b1, b2) = (dot(&cols[1], &y), dot(&cols[2], &y));
    let det = a11 * a22 - a12 * a12;
    let want = [(a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det];
    for (t, w) in sel.terms.iter().zip(want) {
        assert!((t.coefficient - w).abs() < 1e-10 * w.abs().max(1.0));
        assert!(t.ci95[0] <= t.coefficient && t.coefficient <= t.ci95[1]);
    }
    let total: f64 = sel.terms.iter().map(|t| t.share).sum();
    assert!((total - sel.r2).abs() < 1e-9, "Pratt shares add up to R²");
}

/// Pure white noise against 10 unrelated smooth columns: nothing enters (the
/// Bonferroni-split level keeps the family-wise false-entry rate near α = 1 %).
#[test]
fn noise_selects_nothing() {
    let n = 500;
    let y = noise(7, n);
    let cols: Vec<Vec<f64>> = (1..=10)
        .map(|f| (0..n).map(|k| (0.01 * f as f64 * k as f64).sin()).collect())
        .collect();
    let sel =
        select(&design(y, cols), &SelectionConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    assert!(sel.terms.is_empty(), "{:?}", sel.terms);
    assert!(sel.r2.abs() < 1e-12);
}

/// A greedy start cannot lock in {1, h}: y = −0.03·sqrt(h) + 0.06·h over
/// h ∈ [0.16, 0.36] is fitted almost as well by a constant and h, but the exchange
/// step reaches the true pair and the constant is not selected.
#[test]
fn exchange_reaches_the_curved_pair() {
    let n = 2000;
    let h: Vec<f64> = (0..n)
        .map(|k| 0.26 + 0.1 * (0.013 * k as f64).sin())
        .collect();
    let e = noise(3, n);
    let y: Vec<f64> = h
        .iter()
        .zip(&e)
        .map(|(h, e)| -0.03 * h.sqrt() + 0.06 * h + 1e-6 * e)
        .collect();
    let cols = vec![
        vec![1.0; n],
        h.clone(),
        h.iter().map(|v| v.sqrt()).collect(),
    ];
    let sel =
        select(&design(y, cols), &SelectionConfig::default()).unwrap_or_else(|e| panic!("{e}"));
    let chosen: Vec<usize> = sel.terms.iter().map(|t| t.candidate).collect();
    assert_eq!(chosen, vec![1, 2], "{:?}", sel.steps);
    assert!((sel.terms[1].coefficient + 0.03).abs() < 1e-4);
}

#[test]
fn screening_and_validation() {
    let n = 50;
    let x: Vec<f64> = (0..n).map(|k| k as f64).collect();
    let mut bad = x.clone();
    bad[7] = f64::NAN;
    let cols = vec![
        x.clone(),
        vec![0.0; n],
        bad,
        x.iter().map(|v| -3.0 * v).collect(),
    ];
    let sel = select(&design(x.clone(), cols), &SelectionConfig::default())
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        sel.screened,
        vec![
            (1, Screened::Zero),
            (2, Screened::NonFinite { sample: 7 }),
            (3, Screened::Duplicate { of: 0 })
        ]
    );
    assert_eq!(sel.terms[0].aliases, vec![3]);
    let cfg = SelectionConfig {
        alpha: 1.5,
        ..SelectionConfig::default()
    };
    assert!(matches!(
        select(&design(x.clone(), vec![]), &cfg),
        Err(DiscoveryError::InvalidConfig { field: "alpha", .. })
    ));
    let mut d = design(x, vec![vec![1.0; 3]]);
    assert!(matches!(
        select(&d, &SelectionConfig::default()),
        Err(DiscoveryError::Length { .. })
    ));
    d.columns.clear();
    d.segments = vec![10];
    assert!(matches!(
        select(&d, &SelectionConfig::default()),
        Err(DiscoveryError::Length { .. })
    ));
}
