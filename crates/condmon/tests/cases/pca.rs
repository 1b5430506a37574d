//! PCA against an independent SVD of the centred data, exact reconstruction with all
//! components, and the algebraic identities of T² and Q on training data.

use condmon::{ComponentSelection, Pca};
use nalgebra::DMatrix;
use rand_distr::{Distribution, StandardNormal};

use crate::common::rng;

/// `n × p` data with correlated columns and very different variances (seeded).
fn correlated_data(n: usize, p: usize, seed: u64) -> DMatrix<f64> {
    let mut r = rng(seed);
    let z: DMatrix<f64> = DMatrix::from_fn(n, p, |_, _| StandardNormal.sample(&mut r));
    // Mixing matrix with decaying column scales: distinct, well-separated eigenvalues.
    let mix = DMatrix::from_fn(p, p, |i, j| {
        let scale = 3.0f64.powi(-(j as i32));
        scale
            * if i == j {
                1.0
            } else {
                0.3 * ((i + 2 * j) as f64).sin()
            }
    });
    let mut x = z * mix.transpose();
    for (j, mut col) in x.column_iter_mut().enumerate() {
        col.add_scalar_mut(10.0 * j as f64 - 7.0);
    }
    x
}

/// Eigenvalues of the sample covariance from the SVD of the centred data: sᵢ²/(n − 1),
/// descending. (nalgebra's SVD is a bidiagonalisation path, independent of the
/// SymmetricEigen used by `Pca`.)
fn svd_variances(x: &DMatrix<f64>) -> (Vec<f64>, DMatrix<f64>) {
    let n = x.nrows();
    let mut c = x.clone();
    for mut col in c.column_iter_mut() {
        let m = col.mean();
        col.add_scalar_mut(-m);
    }
    let svd = c.svd(false, true);
    let mut pairs: Vec<(f64, usize)> = svd
        .singular_values
        .iter()
        .enumerate()
        .map(|(i, s)| (s * s / (n - 1) as f64, i))
        .collect();
    pairs.sort_by(|a, b| b.0.total_cmp(&a.0));
    let vt = svd.v_t.expect("requested V");
    let dirs = DMatrix::from_fn(x.ncols(), pairs.len(), |r, k| vt[(pairs[k].1, r)]);
    (pairs.into_iter().map(|p| p.0).collect(), dirs)
}

#[test]
fn explained_variance_matches_svd() {
    let x = correlated_data(60, 5, 21);
    let pca = Pca::fit(&x, ComponentSelection::All).unwrap();
    let (var, dirs) = svd_variances(&x);
    let total: f64 = var.iter().sum();
    // Two backward-stable decompositions of the same matrix: eigenvalues agree to
    // ≈ ε·λ_max·p; 1e-12 relative to λ_max leaves three orders of margin.
    let lmax = var[0];
    for (a, b) in pca.explained_variance().iter().zip(&var) {
        assert!((a - b).abs() < 1e-12 * lmax, "{a} vs {b}");
    }
    for (a, b) in pca.explained_variance_ratio().iter().zip(&var) {
        assert!((a - b / total).abs() < 1e-12);
    }
    // Directions agree up to sign (eigenvalues are separated by factors ≈ 9, so the
    // eigenvector perturbation bound ε·λ_max/gap is ≈ 1e-15).
    let loadings = pca.loadings();
    for k in 0..5 {
        let dot = loadings.column(k).dot(&dirs.column(k)).abs();
        assert!((dot - 1.0).abs() < 1e-10, "component {k}: |cos| = {dot}");
    }
    // Component counts by cumulative variance, computed from the SVD values.
    for fraction in [0.5, 0.9, 0.95, 0.999, 1.0] {
        let mut acc = 0.0;
        let expected = var
            .iter()
            .position(|v| {
                acc += v / total;
                acc >= fraction - 1e-12
            })
            .unwrap()
            + 1;
        let p = Pca::fit(&x, ComponentSelection::VarianceFraction(fraction)).unwrap();
        assert_eq!(p.n_components(), expected, "fraction {fraction}");
        assert_eq!(p.transform(&x).unwrap().ncols(), expected);
    }
}

#[test]
fn reconstruction_with_all_components_is_exact() {
    let x = correlated_data(40, 6, 22);
    let pca = Pca::fit(&x, ComponentSelection::All).unwrap();
    let back = pca.inverse_transform(&pca.transform(&x).unwrap()).unwrap();
    // Orthogonal round trip: error ≈ ε·p·max|x| (max|x| ≈ 50): 1e-12 is generous.
    let err = (back - &x).amax();
    assert!(err < 1e-12 * x.amax(), "{err}");
    // Q is zero with every component.
    assert!(
        pca.q_statistic(&x)
            .unwrap()
            .iter()
            .all(|q| *q < 1e-20 * x.norm_squared())
    );
}

#[test]
fn t_squared_and_q_identities_on_training_data() {
    let (n, k) = (50, 2);
    let x = correlated_data(n, 4, 23);
    let pca = Pca::fit(&x, ComponentSelection::Fixed(k)).unwrap();
    // Σᵢ tᵢⱼ² = (n − 1)·λⱼ for each kept component, so mean T² = k(n − 1)/n.
    let t2 = pca.t_squared(&x).unwrap();
    let mean_t2 = t2.iter().sum::<f64>() / n as f64;
    assert!((mean_t2 - k as f64 * (n - 1) as f64 / n as f64).abs() < 1e-10);
    // Pythagoras: ‖x − μ‖² = ‖scores‖² + Q.
    let scores = pca.transform(&x).unwrap();
    let q = pca.q_statistic(&x).unwrap();
    for (i, qi) in q.iter().enumerate() {
        let centred = x.row(i).transpose() - pca.mean();
        let lhs = centred.norm_squared();
        let rhs = scores.row(i).norm_squared() + qi;
        assert!((lhs - rhs).abs() < 1e-10 * lhs.max(1.0));
    }
}

#[test]
fn more_features_than_samples() {
    // n = 6, p = 10: rank ≤ 5, trailing eigenvalues vanish (clamped at 0, never negative).
    let x = correlated_data(6, 10, 24);
    let pca = Pca::fit(&x, ComponentSelection::VarianceFraction(0.95)).unwrap();
    let ev = pca.explained_variance();
    assert!(ev.iter().all(|v| *v >= 0.0));
    assert!(ev[5..].iter().all(|v| *v < 1e-10 * ev[0]));
    assert!(pca.n_components() <= 5);
    let all = Pca::fit(&x, ComponentSelection::All).unwrap();
    let back = all.inverse_transform(&all.transform(&x).unwrap()).unwrap();
    assert!((back - &x).amax() < 1e-12 * x.amax());
}
