//! Output-error model simulation and its exact sensitivities: the outputs of
//! `x⁺ = Ad x + Bd u`, `y = C x` (exact ZOH discretisation of `ẋ = A(θ) x + B(θ) u`) and
//! their derivatives with respect to the free entries of `A`, `B` and the initial states.
//!
//! The derivative of `(Ad, Bd)` with respect to one entry is the Fréchet derivative of
//! the matrix exponential, read off the upper-right block of
//! `exp([[M, E], [0, M]])` with `M = [[A, B], [0, 0]]·h` and `E` the unit change of that
//! entry times `h` (Van Loan, IEEE TAC 23(3), 1978; Najfeld & Havel, Adv. Appl. Math.
//! 16, 1995). Sensitivities then follow the discrete recursion
//! `s⁺ = Ad s + dAd x + dBd u`, exactly consistent with the simulation.

// Index loops over small state vectors read like the equations they implement.
#![allow(clippy::needless_range_loop)]

use nalgebra::{DMatrix, DVector};
use sysid_core::integrate::DEFAULT_BLOW_UP;
use sysid_core::{Experiment, LinearModel, discretize_zoh};

use crate::error::Result;
use crate::free_params::{FreeParameter, StateMatrix};

/// `(Ad, Bd)` of `(A, B)` over a step `h`.
pub(crate) fn zoh(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    h: f64,
) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    let mut blocks = discretize_zoh(a, &[b], h)?;
    let bd = blocks.pop().unwrap_or_else(|| DMatrix::zeros(a.nrows(), 0));
    let ad = blocks.pop().unwrap_or_else(|| DMatrix::zeros(0, 0));
    Ok((ad, bd))
}

/// Derivatives `(∂Ad/∂θ, ∂Bd/∂θ)` with respect to one free entry, by the block-exponential
/// Fréchet derivative.
pub(crate) fn zoh_derivative(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    h: f64,
    p: &FreeParameter,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let (n, m) = (a.nrows(), b.ncols());
    let s = n + m;
    let mut big = DMatrix::zeros(2 * s, 2 * s);
    for block in [0, s] {
        big.view_mut((block, block), (n, n)).copy_from(&(a * h));
        big.view_mut((block, block + n), (n, m)).copy_from(&(b * h));
    }
    let col = match p.matrix {
        StateMatrix::A => p.col,
        StateMatrix::B => n + p.col,
    };
    big[(p.row, s + col)] = h;
    let ex = big.exp();
    let d_ad = ex.view((0, s), (n, n)).into_owned();
    let d_bd = ex.view((0, s + n), (n, m)).into_owned();
    (d_ad, d_bd)
}

/// `(step bits, Ad, Bd, [(∂Ad/∂θ_j, ∂Bd/∂θ_j)])` of one sample step.
type Discretised = (
    u64,
    DMatrix<f64>,
    DMatrix<f64>,
    Vec<(DMatrix<f64>, DMatrix<f64>)>,
);

/// How the initial states enter the parameter vector.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum X0Layout {
    /// Fixed per experiment (not estimated).
    Fixed(Vec<DVector<f64>>),
    /// Estimated: `n` parameters per experiment after the model's free entries.
    Estimated,
}

/// The output-error least-squares problem over all experiments of a dataset.
pub(crate) struct OeProblem<'a> {
    pub base: &'a LinearModel,
    pub free: &'a [FreeParameter],
    pub experiments: &'a [Experiment],
    pub x0: X0Layout,
}

/// Residuals `ŷ − y` over every measured sample (NaN skipped), stacked by experiment,
/// then sample, then channel, and optionally their Jacobian.
pub(crate) struct Evaluated {
    pub residuals: DVector<f64>,
    pub jacobian: Option<DMatrix<f64>>,
}

impl OeProblem<'_> {
    /// Number of parameters (free entries, then initial states if estimated).
    pub fn n_params(&self) -> usize {
        let x0 = match self.x0 {
            X0Layout::Fixed(_) => 0,
            X0Layout::Estimated => self.base.n_states() * self.experiments.len(),
        };
        self.free.len() + x0
    }

    /// Number of measured (non-missing) output samples.
    pub fn n_residuals(&self) -> usize {
        self.experiments
            .iter()
            .map(|e| e.outputs().iter().filter(|v| !v.is_nan()).count())
            .sum()
    }

    /// `A(θ)` and `B(θ)` for the free-entry part of `θ`.
    pub fn matrices(&self, theta: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
        let mut a = self.base.a().clone();
        let mut b = self.base.b().clone();
        for (p, v) in self.free.iter().zip(theta) {
            match p.matrix {
                StateMatrix::A => a[(p.row, p.col)] = *v,
                StateMatrix::B => b[(p.row, p.col)] = *v,
            }
        }
        (a, b)
    }

    /// Initial state of experiment `e` under `θ`.
    pub fn x0(&self, theta: &[f64], e: usize) -> DVector<f64> {
        let n = self.base.n_states();
        match &self.x0 {
            X0Layout::Fixed(v) => v[e].clone(),
            X0Layout::Estimated => {
                let start = self.free.len() + e * n;
                DVector::from_column_slice(&theta[start..start + n])
            }
        }
    }

    /// Residuals (and the Jacobian when asked) at `θ`; `Ok(None)` when a simulation
    /// diverges (the cost is then +∞).
    pub fn evaluate(&self, theta: &[f64], jacobian: bool) -> Result<Option<Evaluated>> {
        let n = self.base.n_states();
        let c = self.base.c();
        let (a, b) = self.matrices(theta);
        let n_par = self.n_params();
        let n_res = self.n_residuals();
        let mut r = DVector::zeros(n_res);
        let mut jac = jacobian.then(|| DMatrix::zeros(n_res, n_par));
        let mut row = 0;
        // Discretisations are shared by experiments with the same step.
        let mut cache: Vec<Discretised> = Vec::new();
        for (e, exp) in self.experiments.iter().enumerate() {
            let h = exp.dt();
            let idx = match cache.iter().position(|c| c.0 == h.to_bits()) {
                Some(i) => i,
                None => {
                    let (ad, bd) = zoh(&a, &b, h)?;
                    let ders = if jacobian {
                        self.free
                            .iter()
                            .map(|p| zoh_derivative(&a, &b, h, p))
                            .collect()
                    } else {
                        Vec::new()
                    };
                    cache.push((h.to_bits(), ad, bd, ders));
                    cache.len() - 1
                }
            };
            let (_, ad, bd, ders) = &cache[idx];
            let x0 = self.x0(theta, e);
            let Some(states) = simulate_states(ad, bd, x0.as_slice(), exp.inputs()) else {
                return Ok(None);
            };
            let yhat = c * &states;
            let first_row = row;
            for k in 0..exp.len() {
                for (i, y) in exp.output(k).iter().enumerate() {
                    if !y.is_nan() {
                        r[row] = yhat[(i, k)] - y;
                        row += 1;
                    }
                }
            }
            if let Some(jac) = jac.as_mut() {
                let mut col_buf = DMatrix::zeros(c.nrows(), exp.len());
                // Free entries of A and B.
                for (j, (d_ad, d_bd)) in ders.iter().enumerate() {
                    let mut s = DVector::zeros(n);
                    let mut sens = DMatrix::zeros(n, exp.len());
                    for k in 1..exp.len() {
                        let u = DVector::from_column_slice(exp.input(k - 1));
                        let x = states.column(k - 1);
                        s = ad * &s + d_ad * x + d_bd * u;
                        sens.set_column(k, &s);
                    }
                    col_buf.copy_from(&(c * sens));
                    write_column(jac, first_row, j, &col_buf, exp);
                }
                // Initial state of this experiment: ∂x_k/∂x0 = Ad^k.
                if matches!(self.x0, X0Layout::Estimated) {
                    let mut phi = DMatrix::<f64>::identity(n, n);
                    let mut blocks: Vec<DMatrix<f64>> = Vec::with_capacity(exp.len());
                    for _ in 0..exp.len() {
                        blocks.push(c * &phi);
                        phi = ad * phi;
                    }
                    for i in 0..n {
                        for k in 0..exp.len() {
                            for o in 0..c.nrows() {
                                col_buf[(o, k)] = blocks[k][(o, i)];
                            }
                        }
                        write_column(jac, first_row, self.free.len() + e * n + i, &col_buf, exp);
                    }
                }
            }
        }
        Ok(Some(Evaluated {
            residuals: r,
            jacobian: jac,
        }))
    }
}

/// Copy `values` (`p × N`) into Jacobian column `col`, skipping missing measurements in
/// the same order as the residuals.
fn write_column(
    jac: &mut DMatrix<f64>,
    first_row: usize,
    col: usize,
    values: &DMatrix<f64>,
    exp: &Experiment,
) {
    let mut row = first_row;
    for k in 0..exp.len() {
        for (i, y) in exp.output(k).iter().enumerate() {
            if !y.is_nan() {
                jac[(row, col)] = values[(i, k)];
                row += 1;
            }
        }
    }
}

/// States `n × N` of `x⁺ = Ad x + Bd u` from `x0`; `None` when a state leaves
/// `sysid_core`'s blow-up bound or becomes non-finite.
pub(crate) fn simulate_states(
    ad: &DMatrix<f64>,
    bd: &DMatrix<f64>,
    x0: &[f64],
    inputs: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let n = ad.nrows();
    let len = inputs.ncols();
    let mut out = DMatrix::zeros(n, len);
    if len == 0 {
        return Some(out);
    }
    let mut x = DVector::from_column_slice(x0);
    out.set_column(0, &x);
    for k in 1..len {
        x = ad * &x + bd * inputs.column(k - 1);
        if x.iter()
            .any(|v| !v.is_finite() || v.abs() > DEFAULT_BLOW_UP)
        {
            return None;
        }
        out.set_column(k, &x);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::free_params::FreeParameter;

    /// Fréchet derivative against central differences of the ZOH blocks; the step
    /// `1e-5` balances truncation (~h²·‖d³/dθ³‖ ≈ 1e-10) and round-off (~ε/h ≈ 1e-11).
    #[test]
    fn zoh_derivative_matches_central_differences() {
        let a = DMatrix::from_row_slice(3, 3, &[0.0, 1.0, 0.0, -2.0, -0.3, 0.5, 0.1, 0.0, -1.0]);
        let b = DMatrix::from_row_slice(3, 2, &[0.0, 1.0, 1.0, 0.0, 0.5, -0.2]);
        let h = 0.07;
        for name in ["A[1,0]", "A[2,2]", "A[0,2]", "B[1,0]", "B[2,1]"] {
            let p = FreeParameter::parse(name).unwrap();
            let (d_ad, d_bd) = zoh_derivative(&a, &b, h, &p);
            let eps = 1e-5;
            let shifted = |delta: f64| {
                let (mut a2, mut b2) = (a.clone(), b.clone());
                match p.matrix {
                    StateMatrix::A => a2[(p.row, p.col)] += delta,
                    StateMatrix::B => b2[(p.row, p.col)] += delta,
                }
                zoh(&a2, &b2, h).unwrap()
            };
            let (ap, bp) = shifted(eps);
            let (am, bm) = shifted(-eps);
            let fa = (ap - am) / (2.0 * eps);
            let fb = (bp - bm) / (2.0 * eps);
            assert!((fa - d_ad).amax() < 1e-9, "{name}");
            assert!((fb - d_bd).amax() < 1e-9, "{name}");
        }
    }
}
