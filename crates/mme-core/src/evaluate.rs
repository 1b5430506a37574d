//! The common face of the linear and nonlinear solvers: "solve at this `W` and `R`", as
//! used by the automatic `W` search and the noise-variance likelihood.

use nalgebra::DMatrix;

use crate::error::Result;
use crate::sweep::LogDet;

/// What one solve at a given `(W, R)` returns, summed over experiments.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Summary {
    /// Sum of squared residuals per model output.
    pub sse: Vec<f64>,
    /// Observed samples per model output.
    pub count: Vec<usize>,
    /// `Σ h dᵀWd`.
    pub correction_cost: f64,
    /// `J`.
    pub cost: f64,
    /// `Σ log det S_j` of the (last) sweep.
    pub logdet_s: f64,
    /// `Σ_experiments log det P_0`.
    pub logdet_p0: f64,
}

impl Summary {
    /// Residual mean square per channel (`sse/count`; NaN for a channel never observed).
    pub fn residual_variance(&self) -> Vec<f64> {
        self.sse
            .iter()
            .zip(&self.count)
            .map(|(s, &c)| if c > 0 { s / c as f64 } else { f64::NAN })
            .collect()
    }

    /// The covariance-constraint ratio `Σ_i sse_i/R_i / Σ_i n_i`.
    pub fn ratio(&self, inv_r: &[f64]) -> f64 {
        let total: usize = self.count.iter().sum();
        let weighted: f64 = self.sse.iter().zip(inv_r).map(|(s, w)| s * w).sum();
        if total == 0 {
            f64::NAN
        } else {
            weighted / total as f64
        }
    }
}

/// A solver of the MME problem at a given `W` and `R`.
pub(crate) trait Solve {
    /// States `n`.
    fn n_states(&self) -> usize;
    /// Corrections `q`.
    fn n_corrections(&self) -> usize;
    /// Per experiment: number of correction pieces and the sub-step `h`.
    fn pieces(&self) -> Vec<(usize, f64)>;
    /// Switch the initial-state prior (if the configuration has one) on or off for the
    /// following solves; the noise-variance likelihood runs with it off.
    fn use_prior(&mut self, on: bool);
    /// Solve with weight `w` and `1/R_i` = `inv_r`.
    fn solve(&mut self, w: &DMatrix<f64>, inv_r: &[f64], logdet: LogDet) -> Result<Summary>;
}
