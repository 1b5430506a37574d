//! The starting trajectory of the nonlinear estimator ([`StartTrajectory`](crate::StartTrajectory)):
//! from the data (the minimum-norm state reproducing the observed outputs at each sample,
//! linear between samples, `d = 0`) or the open-loop rollout of the model from given
//! initial states; and the fitted start that replaces the data-based one when that gives
//! no finite rollout.

use nalgebra::DMatrix;
use sysid_core::{Dynamics, Experiment, InitialStateFit, Integrator, fit_initial_state};

use super::{NonlinearRun, Traj};
use crate::error::{MmeError, Result};

/// Samples from the start of an experiment over which the fitted start's initial state
/// is fitted (clipped to the experiment's length).
pub(super) const FIT_WINDOW: usize = 200;

impl<F: Dynamics> NonlinearRun<'_, F> {
    /// Minimum-norm state reproducing the observed outputs at sample `k` (0 if none).
    pub(super) fn data_states(&self, e: usize, k: usize) -> Vec<f64> {
        let exp = &self.data.experiments()[e];
        let n = self.model.dynamics.n_states();
        let rows: Vec<usize> = (0..self.binding.outputs.len())
            .filter(|&i| !exp.outputs()[(self.binding.outputs[i], k)].is_nan())
            .collect();
        // With an initial-state prior, the directions the outputs leave open take the
        // prior's means (states without a prior: 0) instead of 0.
        let prior_mean = self
            .prior
            .as_ref()
            .map(|p| nalgebra::DVector::from_column_slice(&p.mean));
        if rows.is_empty() {
            return prior_mean.map_or_else(|| vec![0.0; n], |m| m.iter().copied().collect());
        }
        let c = DMatrix::from_fn(rows.len(), n, |r, j| self.model.c[(rows[r], j)]);
        let y = nalgebra::DVector::from_iterator(
            rows.len(),
            rows.iter()
                .map(|&i| exp.outputs()[(self.binding.outputs[i], k)]),
        );
        match (c.clone().pseudo_inverse(1e-12), prior_mean) {
            (Ok(pinv), None) => (pinv * y).iter().copied().collect(),
            (Ok(pinv), Some(m)) => {
                let open = &m - &pinv * (&c * &m);
                (pinv * y + open).iter().copied().collect()
            }
            (Err(_), None) => vec![0.0; n],
            (Err(_), Some(m)) => m.iter().copied().collect(),
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

    /// The fitted start, which replaces the data-based start when that gives no finite
    /// rollout: the measured directions from the data, the directions the outputs do not
    /// determine from the model's open-loop run,
    /// `x_j = x_data,j + (I − C⁺C)·x_sim,j` (`x_data` the data-based start, which lies in
    /// the row space of `C`; `x_sim` the run with `d = 0` on the estimator's RK4 grid),
    /// `d = 0`. The run starts from the initial state whose free run best fits the
    /// outputs over the first [`FIT_WINDOW`] samples ([`fit_initial_state`], from
    /// `C⁺ỹ_0`). The data-based start puts such a direction at 0, where a term like a
    /// tank's `√|h|` has no usable slope; the run puts it where the model's own dynamics
    /// and the first outputs place it. Deterministic; not a rollout (the first
    /// Gauss–Newton step is taken in full, as from the data-based start).
    pub(super) fn fitted_trajectory(&mut self, e: usize) -> Result<Traj> {
        let g = self.grids[e];
        let (n, m) = (
            self.model.dynamics.n_states(),
            self.model.dynamics.n_inputs(),
        );
        let p = self.binding.outputs.len();
        let exp = &self.data.experiments()[e];
        // The first samples as the model sees them (its inputs and outputs, in its order).
        let len = FIT_WINDOW.min(g.samples);
        let inputs = DMatrix::from_fn(m, len, |r, k| exp.inputs()[(self.binding.inputs[r], k)]);
        let outputs = DMatrix::from_fn(p, len, |r, k| exp.outputs()[(self.binding.outputs[r], k)]);
        let first = Experiment::new(g.t0, exp.dt(), inputs, outputs)?.with_intersample(g.hold);
        let fit = InitialStateFit {
            window: len,
            integrator: Integrator::Rk4 {
                substeps: g.substeps,
            },
            blow_up: self.opts.blow_up,
            ..InitialStateFit::default()
        };
        let guess = self.data_states(e, 0);
        let x0 = fit_initial_state(&self.model.dynamics, &self.model.c, &first, &guess, &fit)?;
        let sim = self.open_loop(e, &x0)?;
        let mut traj = self.data_trajectory(e);
        let c = &self.model.c;
        let null = match c.clone().pseudo_inverse(1e-12) {
            Ok(pinv) => DMatrix::identity(n, n) - pinv * c,
            Err(_) => DMatrix::identity(n, n),
        };
        for (x, s) in traj.x.chunks_exact_mut(n).zip(sim.x.chunks_exact(n)) {
            for (r, xr) in x.iter_mut().enumerate() {
                *xr += (0..n).map(|k| null[(r, k)] * s[k]).sum::<f64>();
            }
        }
        Ok(traj)
    }

    pub(super) fn open_loop(&mut self, e: usize, x0: &[f64]) -> Result<Traj> {
        let g = self.grids[e];
        let (n, q) = (self.model.dynamics.n_states(), self.model.e.ncols());
        let mut x = vec![0.0; n * (g.steps + 1)];
        x[..n].copy_from_slice(x0);
        let zero = vec![0.0; q];
        let mut cur = x0.to_vec();
        for j in 0..g.steps {
            let (ua, ub) = g.interval(&self.bound[e], j);
            let t = g.t0 + j as f64 * g.h;
            self.rk.step(
                &self.model.dynamics,
                &self.model.e,
                t,
                g.h,
                &mut cur,
                &g.stage_input(j, ua, ub),
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
