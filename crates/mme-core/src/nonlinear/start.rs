//! The starting trajectory of the nonlinear estimator ([`StartTrajectory`](crate::StartTrajectory)):
//! from the data (the minimum-norm state reproducing the observed outputs at each sample,
//! linear between samples, `d = 0`) or the open-loop rollout of the model from given
//! initial states.

use nalgebra::DMatrix;
use sysid_core::Dynamics;

use super::{NonlinearRun, Traj};
use crate::error::{MmeError, Result};

impl<F: Dynamics> NonlinearRun<'_, F> {
    /// Minimum-norm state reproducing the observed outputs at sample `k` (0 if none).
    pub(super) fn data_states(&self, e: usize, k: usize) -> Vec<f64> {
        let exp = &self.data.experiments()[e];
        let n = self.model.dynamics.n_states();
        let rows: Vec<usize> = (0..self.binding.outputs.len())
            .filter(|&i| !exp.outputs()[(self.binding.outputs[i], k)].is_nan())
            .collect();
        if rows.is_empty() {
            return vec![0.0; n];
        }
        let c = DMatrix::from_fn(rows.len(), n, |r, j| self.model.c[(rows[r], j)]);
        let y = nalgebra::DVector::from_iterator(
            rows.len(),
            rows.iter()
                .map(|&i| exp.outputs()[(self.binding.outputs[i], k)]),
        );
        match c.pseudo_inverse(1e-12) {
            Ok(pinv) => (pinv * y).iter().copied().collect(),
            Err(_) => vec![0.0; n],
        }
    }

    /// Data-based start: `C⁺ỹ` at samples (previous value where nothing is observed),
    /// linear between samples, `d = 0`.
    pub(super) fn data_trajectory(&self, e: usize) -> Traj {
        let g = self.grids[e];
        let n = self.model.dynamics.n_states();
        let exp = &self.data.experiments()[e];
        let mut at: Vec<Vec<f64>> = Vec::with_capacity(g.samples);
        for k in 0..g.samples {
            let any = self
                .binding
                .outputs
                .iter()
                .any(|&row| !exp.outputs()[(row, k)].is_nan());
            let v = if any || k == 0 {
                self.data_states(e, k)
            } else {
                at[k - 1].clone()
            };
            at.push(v);
        }
        let mut x = vec![0.0; n * (g.steps + 1)];
        for j in 0..=g.steps {
            let k = (j / g.substeps).min(g.samples - 1);
            let frac = (j - k * g.substeps) as f64 / g.substeps as f64;
            let next = (k + 1).min(g.samples - 1);
            for i in 0..n {
                x[j * n + i] = at[k][i] + frac * (at[next][i] - at[k][i]);
            }
        }
        Traj {
            x,
            d: vec![0.0; self.model.e.ncols() * g.steps],
            consistent: false,
        }
    }

    pub(super) fn open_loop(&mut self, e: usize, x0: &[f64]) -> Result<Traj> {
        let g = self.grids[e];
        let (n, q) = (self.model.dynamics.n_states(), self.model.e.ncols());
        let mut x = vec![0.0; n * (g.steps + 1)];
        x[..n].copy_from_slice(x0);
        let zero = vec![0.0; q];
        let mut cur = x0.to_vec();
        for j in 0..g.steps {
            let (ua, ub) = self.interval_inputs(e, j);
            let t = g.t0 + j as f64 * g.h;
            self.rk.step(
                &self.model.dynamics,
                &self.model.e,
                t,
                g.h,
                &mut cur,
                &g.stage_input(j, &ua, &ub),
                &zero,
            );
            if let Some(state) = cur
                .iter()
                .position(|v| !v.is_finite() || v.abs() > self.opts.blow_up)
            {
                return Err(MmeError::Diverged {
                    experiment: e,
                    time: t + g.h,
                    state,
                });
            }
            x[(j + 1) * n..(j + 2) * n].copy_from_slice(&cur);
        }
        Ok(Traj {
            x,
            d: vec![0.0; q * g.steps],
            consistent: true,
        })
    }
}
