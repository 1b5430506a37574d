//! Output-error model simulation and its exact sensitivities: the outputs of
//! `x⁺ = Ad x + Bd u` (inputs held, exact ZOH) or `x⁺ = Ad x + Bd u + Γ₂ Δu` (inputs
//! linear between samples, exact FOH), `y = C x`, of `ẋ = A(θ) x + B(θ) u` — each
//! experiment as its [`sysid_core::InterSample`] says — and their derivatives with
//! respect to the free entries of `A`, `B` and the initial states.
//!
//! The derivatives of `(Ad, Bd, Γ₂)` with respect to one entry are Fréchet derivatives of
//! block matrix exponentials ([`crate::discrete`]). Sensitivities then follow the
//! discrete recursion `s⁺ = Ad s + dAd x + dBd u (+ dΓ₂ Δu)`, exactly consistent with
//! the simulation.

// Index loops over small state vectors read like the equations they implement.
#![allow(clippy::needless_range_loop)]

use nalgebra::{DMatrix, DVector};
use sysid_core::integrate::DEFAULT_BLOW_UP;
use sysid_core::{Experiment, InterSample, LinearModel};

use crate::discrete::{SampleStep, StepDerivative};
use crate::error::Result;
use crate::free_params::{FreeParameter, StateMatrix};

/// `(step bits, inter-sample behaviour, step, [∂step/∂θ_j])` of one sample period.
type Discretised = (u64, InterSample, SampleStep, Vec<StepDerivative>);

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
        // Discretisations are shared by experiments with the same step and hold.
        let mut cache: Vec<Discretised> = Vec::new();
        for (e, exp) in self.experiments.iter().enumerate() {
            let h = exp.dt();
            let hold = exp.intersample();
            let idx = match cache.iter().position(|c| c.0 == h.to_bits() && c.1 == hold) {
                Some(i) => i,
                None => {
                    let step = SampleStep::new(&a, &b, h, hold)?;
                    let ders = if jacobian {
                        self.free
                            .iter()
                            .map(|p| StepDerivative::new(&a, &b, h, hold, p))
                            .collect()
                    } else {
                        Vec::new()
                    };
                    cache.push((h.to_bits(), hold, step, ders));
                    cache.len() - 1
                }
            };
            let (_, _, step, ders) = &cache[idx];
            let ad = &step.ad;
            let x0 = self.x0(theta, e);
            let Some(states) = simulate_states(step, x0.as_slice(), exp.inputs()) else {
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
                // Buffers of this experiment, allocated once; the per-sample loops below
                // only multiply into them.
                let inputs = exp.inputs();
                let mut col_buf = DMatrix::zeros(c.nrows(), exp.len());
                let mut s = DVector::zeros(n);
                let mut s_next = DVector::zeros(n);
                let mut sens = DMatrix::zeros(n, exp.len());
                // Free entries of A and B.
                for (j, der) in ders.iter().enumerate() {
                    let (d_ad, d_bd) = (&der.d_ad, &der.d_bd);
                    s.fill(0.0);
                    sens.column_mut(0).fill(0.0);
                    for k in 1..exp.len() {
                        s_next.gemv(1.0, ad, &s, 0.0);
                        s_next.gemv(1.0, d_ad, &states.column(k - 1), 1.0);
                        s_next.gemv(1.0, d_bd, &inputs.column(k - 1), 1.0);
                        if let Some(d_ramp) = &der.d_ramp {
                            s_next.gemv(1.0, d_ramp, &inputs.column(k), 1.0);
                            s_next.gemv(-1.0, d_ramp, &inputs.column(k - 1), 1.0);
                        }
                        std::mem::swap(&mut s, &mut s_next);
                        sens.set_column(k, &s);
                    }
                    col_buf.gemm(1.0, c, &sens, 0.0);
                    write_column(jac, first_row, j, &col_buf, exp);
                }
                // Initial state of this experiment: ∂x_k/∂x0 = Ad^k, one state's column
                // of C·Ad^k at a time (n passes over the record, no per-sample matrices).
                if matches!(self.x0, X0Layout::Estimated) {
                    for i in 0..n {
                        s.fill(0.0);
                        s[i] = 1.0;
                        for k in 0..exp.len() {
                            col_buf.column_mut(k).gemv(1.0, c, &s, 0.0);
                            s_next.gemv(1.0, ad, &s, 0.0);
                            std::mem::swap(&mut s, &mut s_next);
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

/// States `n × N` of `step` (`x⁺ = Ad x + Bd u`, plus `Γ₂ Δu` for linear inputs) from
/// `x0`; `None` when a state leaves `sysid_core`'s blow-up bound or becomes non-finite.
pub(crate) fn simulate_states(
    step: &SampleStep,
    x0: &[f64],
    inputs: &DMatrix<f64>,
) -> Option<DMatrix<f64>> {
    let n = step.ad.nrows();
    let len = inputs.ncols();
    let mut out = DMatrix::zeros(n, len);
    if len == 0 {
        return Some(out);
    }
    let mut x = DVector::from_column_slice(x0);
    let mut next = DVector::zeros(n);
    out.set_column(0, &x);
    for k in 1..len {
        step.advance_into(&x, inputs, k - 1, &mut next);
        std::mem::swap(&mut x, &mut next);
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
    use crate::discrete::zoh;
    use sysid_core::ModelNames;

    fn oscillator() -> LinearModel {
        LinearModel::with_names(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.4]),
            DMatrix::from_row_slice(2, 1, &[0.0, 2.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::zeros(2, 0),
            ModelNames::numbered(2, 1, 1, 0),
        )
        .unwrap()
    }

    /// Two records of 60 samples at different steps, a smooth input.
    fn experiments(hold: InterSample) -> Vec<Experiment> {
        [0.1, 0.25]
            .iter()
            .map(|&dt| {
                let len = 60;
                let u = DMatrix::from_fn(1, len, |_, k| {
                    let t = k as f64 * dt;
                    (1.3 * t).sin() + 0.5 * (3.1 * t).cos()
                });
                let y = DMatrix::from_fn(1, len, |_, k| (0.7 * k as f64 * dt).sin());
                Experiment::new(0.0, dt, u, y)
                    .unwrap()
                    .with_intersample(hold)
            })
            .collect()
    }

    /// The analytic Jacobian (free entries by the sensitivity recursion, initial states by
    /// `C Ad^k`) against central differences of the residuals, for held and linear inputs.
    /// Step 1e-6 on parameters of size ~1 over 60 samples: truncation ~1e-12·‖∂³r‖,
    /// round-off ~ε·‖r‖/1e-6 ≈ 1e-9; the Jacobian's entries are O(1), so 1e-7 is ample.
    #[test]
    fn jacobian_matches_central_differences_for_both_holds() {
        let base = oscillator();
        let free: Vec<FreeParameter> = ["A[1,0]", "A[1,1]", "B[1,0]", "A[0,1]"]
            .iter()
            .map(|n| FreeParameter::parse(n).unwrap())
            .collect();
        for hold in [InterSample::Zoh, InterSample::Foh] {
            let exps = experiments(hold);
            let problem = OeProblem {
                base: &base,
                free: &free,
                experiments: &exps,
                x0: X0Layout::Estimated,
            };
            let theta = [-3.5, -0.3, 1.7, 0.9, 0.3, -0.2, 0.1, 0.4];
            let at = |t: &[f64], jac: bool| problem.evaluate(t, jac).unwrap().unwrap();
            let exact = at(&theta, true).jacobian.unwrap();
            let eps = 1e-6;
            for j in 0..theta.len() {
                let (mut plus, mut minus) = (theta, theta);
                plus[j] += eps;
                minus[j] -= eps;
                let fd = (at(&plus, false).residuals - at(&minus, false).residuals) / (2.0 * eps);
                let err = (fd - exact.column(j)).amax();
                assert!(err < 1e-7, "{hold:?}, parameter {j}: {err:e}");
            }
        }
    }

    /// Held inputs: the simulation is bit for bit the original ZOH recursion
    /// `x⁺ = Ad x + Bd u_k` with `(Ad, Bd)` from `discretize_zoh`.
    #[test]
    fn held_simulation_is_the_zoh_recursion_bit_for_bit() {
        let base = oscillator();
        let exp = &experiments(InterSample::Zoh)[0];
        let (ad, bd) = zoh(base.a(), base.b(), exp.dt()).unwrap();
        let step = SampleStep::new(base.a(), base.b(), exp.dt(), InterSample::Zoh).unwrap();
        let states = simulate_states(&step, &[0.3, -0.1], exp.inputs()).unwrap();
        let mut x = DVector::from_column_slice(&[0.3, -0.1]);
        for k in 1..exp.len() {
            x = &ad * &x + &bd * exp.inputs().column(k - 1);
            for i in 0..2 {
                assert_eq!(states[(i, k)].to_bits(), x[i].to_bits(), "sample {k}");
            }
        }
    }
}
