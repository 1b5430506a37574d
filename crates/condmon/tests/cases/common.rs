//! Shared helpers: seeded Gaussian classes, true Gaussian log-densities, Φ.

use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use statrs::distribution::{ContinuousCDF, Normal};

/// A seeded generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// A Gaussian class: mean and covariance.
#[derive(Clone)]
pub struct Gauss {
    pub mean: DVector<f64>,
    pub cov: DMatrix<f64>,
}

impl Gauss {
    pub fn new(mean: &[f64], cov_rows: &[f64]) -> Self {
        let p = mean.len();
        Self {
            mean: DVector::from_column_slice(mean),
            cov: DMatrix::from_row_slice(p, p, cov_rows),
        }
    }

    /// `n` samples as rows: μ + L z with Σ = L Lᵀ.
    pub fn sample(&self, rng: &mut ChaCha8Rng, n: usize) -> DMatrix<f64> {
        let p = self.mean.len();
        let l = self
            .cov
            .clone()
            .cholesky()
            .expect("test covariance is SPD")
            .l();
        let mut x = DMatrix::zeros(n, p);
        for i in 0..n {
            let z = DVector::from_fn(p, |_, _| StandardNormal.sample(rng));
            let s = &self.mean + &l * z;
            x.set_row(i, &s.transpose());
        }
        x
    }

    /// Log-density at `x` (explicit inverse and determinant: a different code path from
    /// the crate's Cholesky discriminants).
    pub fn log_density(&self, x: &[f64]) -> f64 {
        let p = self.mean.len() as f64;
        let inv = self.cov.clone().try_inverse().expect("SPD");
        let d = DVector::from_column_slice(x) - &self.mean;
        let m = (d.transpose() * inv * &d)[(0, 0)];
        -0.5 * (m + self.cov.determinant().ln() + p * (2.0 * std::f64::consts::PI).ln())
    }
}

/// `n` samples from each class, stacked, with labels 0 and 1.
pub fn two_classes(
    rng: &mut ChaCha8Rng,
    n: usize,
    c0: &Gauss,
    c1: &Gauss,
) -> (DMatrix<f64>, Vec<usize>) {
    let a = c0.sample(rng, n);
    let b = c1.sample(rng, n);
    let mut x = DMatrix::zeros(2 * n, a.ncols());
    x.rows_mut(0, n).copy_from(&a);
    x.rows_mut(n, n).copy_from(&b);
    let labels = (0..2 * n).map(|i| usize::from(i >= n)).collect();
    (x, labels)
}

/// Standard normal CDF.
pub fn phi(x: f64) -> f64 {
    Normal::new(0.0, 1.0).expect("unit normal").cdf(x)
}

/// Fraction of disagreements.
pub fn error_rate(predicted: &[usize], truth: &[usize]) -> f64 {
    let wrong = predicted.iter().zip(truth).filter(|(a, b)| a != b).count();
    wrong as f64 / truth.len() as f64
}

/// Error of the true Bayes rule (equal priors) on the same test set.
pub fn bayes_rule_error(x: &DMatrix<f64>, truth: &[usize], c0: &Gauss, c1: &Gauss) -> f64 {
    let pred: Vec<usize> = (0..x.nrows())
        .map(|i| {
            let row: Vec<f64> = x.row(i).iter().copied().collect();
            usize::from(c1.log_density(&row) > c0.log_density(&row))
        })
        .collect();
    error_rate(&pred, truth)
}
