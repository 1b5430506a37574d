//! The simulation side of trajectory training: shooting windows of the hybrid model
//! (sysid-core's `CorrectedModel` with the network as its correction) simulated free-run
//! by sysid-core's RK4 step (inputs held or interpolated between samples as each record's
//! experiment says), their scaled residuals, the fit of a window's start state,
//! and the forward-difference Jacobian over weights and start states.

use nalgebra::DMatrix;
use rayon::prelude::*;
use sysid_core::tangent::Rk4;
use sysid_core::{
    CorrectedModel, Dynamics, LeastSquaresProblem, LmSettings, Termination, levenberg_marquardt,
};

use super::ShootingRecord;
use crate::correction::NetCorrection;

/// Levenberg–Marquardt iterations when fitting a window's start state.
const START_FIT_ITERATIONS: usize = 20;

/// A window: record, first sample, last sample (inclusive).
#[derive(Debug, Clone, Copy)]
pub(super) struct Window {
    pub(super) record: usize,
    pub(super) start: usize,
    pub(super) end: usize,
}

/// Everything a simulation of a set of windows needs, shared read-only across threads.
pub(super) struct Shooter<'a, F> {
    /// The hybrid model being trained (its network as given: working copies with trial
    /// weights come from [`Shooter::model`]).
    pub(super) hybrid: &'a CorrectedModel<F, NetCorrection>,
    pub(super) records: &'a [ShootingRecord<'a>],
    pub(super) inv_scale: Vec<f64>,
    pub(super) substeps: usize,
    pub(super) blow_up: f64,
}

/// Per-thread buffers for [`Shooter::residuals`].
pub(super) struct Buffers {
    x: Vec<f64>,
    rk: Rk4,
}

impl Buffers {
    pub(super) fn new(n: usize, m: usize, _q: usize) -> Self {
        Self {
            x: vec![0.0; n],
            rk: Rk4::new(n, m, 0),
        }
    }
}

/// A working copy of the hybrid model `ẋ = f(x, u) + E·NN([x; u])`: the base dynamics
/// borrowed, the network owned, so trial weights are written into it in place.
pub(super) type Hybrid<'m, F> = CorrectedModel<&'m F, NetCorrection>;

impl<'a, F: Dynamics> Shooter<'a, F> {
    /// A working copy of the model being trained (one per thread or problem).
    pub(super) fn model(&self) -> Hybrid<'a, F> {
        self.hybrid.with_borrowed_base()
    }

    /// Simulate window `w` of `model` from state `x0` by sysid-core's RK4 step (inputs
    /// held or linear between samples as the record says) and write its scaled residuals
    /// (`p` per sample after the start; 0 where the output is not observed) into `r`.
    /// False when the simulation diverges.
    pub(super) fn window_residuals(
        &self,
        model: &Hybrid<'_, F>,
        w: &Window,
        x0: &[f64],
        r: &mut [f64],
        b: &mut Buffers,
    ) -> bool {
        let c = self.hybrid.c();
        let p = c.nrows();
        let exp = self.records[w.record].experiment;
        let h = exp.dt() / self.substeps as f64;
        b.x.copy_from_slice(x0);
        for (k, rk) in (w.start..w.end).zip(r.chunks_exact_mut(p)) {
            // Windows end at most at the last sample, so `k + 1` exists.
            let t = exp.t0() + k as f64 * exp.dt();
            for j in 0..self.substeps {
                let input = exp.step_input(k, j, self.substeps);
                b.rk.step(model, t + j as f64 * h, h, &mut b.x, &input);
            }
            // NaN counts as diverged too.
            if !b.x.iter().all(|v| v.abs() <= self.blow_up) {
                return false;
            }
            let y = exp.output(k + 1);
            for (o, ro) in rk.iter_mut().enumerate() {
                let sim: f64 = b.x.iter().enumerate().map(|(i, x)| c[(o, i)] * x).sum();
                *ro = if y[o].is_nan() {
                    0.0
                } else {
                    (y[o] - sim) * self.inv_scale[o]
                };
            }
        }
        true
    }

    /// Residuals of every window, window `i` started from `starts[i·n..(i+1)·n]`, into
    /// `r`. Returns the index of the first window that diverged, if any.
    pub(super) fn residuals(
        &self,
        model: &Hybrid<'_, F>,
        windows: &[Window],
        starts: &[f64],
        r: &mut [f64],
        b: &mut Buffers,
    ) -> std::result::Result<(), usize> {
        let n = b.x.len();
        let p = self.hybrid.c().nrows();
        let mut row = 0;
        for (wi, w) in windows.iter().enumerate() {
            let len = (w.end - w.start) * p;
            let x0 = &starts[wi * n..(wi + 1) * n];
            if !self.window_residuals(model, w, x0, &mut r[row..row + len], b) {
                return Err(wi);
            }
            row += len;
        }
        Ok(())
    }

    /// Held-out objective of one window: the sum of squared residuals minimised over its
    /// start state (the workspace's Levenberg–Marquardt in the start state with the
    /// weights fixed, from `x0`, forward differences of step `√ε` in units of `x_scale`),
    /// so held-out windows are judged like training windows, whose starts are free. The
    /// fitted start is written into `fitted`. Infinite when the window diverges from `x0`.
    pub(super) fn fitted_window_sse(
        &self,
        model: &Hybrid<'_, F>,
        w: &Window,
        x0: &[f64],
        x_scale: &[f64],
        b: &mut Buffers,
        fitted: &mut [f64],
    ) -> f64 {
        let mut problem = StartFit {
            shooter: self,
            model,
            window: w,
            x_scale,
            bufs: b,
        };
        let settings = LmSettings {
            max_iterations: START_FIT_ITERATIONS,
            mu_max: 1e10,
            ftol: 1e-10,
            ..LmSettings::default()
        };
        let Ok(solution) = levenberg_marquardt(&mut problem, x0, &settings);
        if solution.report.termination == Termination::Diverged {
            fitted.copy_from_slice(x0);
            return f64::INFINITY;
        }
        fitted.copy_from_slice(&solution.theta);
        solution.report.final_cost()
    }
}

/// The start state of one window as a least-squares problem, the weights fixed.
struct StartFit<'s, 'a, F> {
    shooter: &'s Shooter<'a, F>,
    model: &'s Hybrid<'a, F>,
    window: &'s Window,
    x_scale: &'s [f64],
    bufs: &'s mut Buffers,
}

impl<F: Dynamics> LeastSquaresProblem for StartFit<'_, '_, F> {
    type Error = std::convert::Infallible;

    fn residual_count(&self) -> usize {
        (self.window.end - self.window.start) * self.shooter.hybrid.c().nrows()
    }

    fn residuals(&mut self, x0: &[f64], r: &mut [f64]) -> Result<bool, Self::Error> {
        Ok(self
            .shooter
            .window_residuals(self.model, self.window, x0, r, self.bufs))
    }

    /// Forward differences, step `√ε·σ_j`; a diverging perturbed window gives a zero
    /// column.
    fn jacobian(
        &mut self,
        x0: &[f64],
        r: &[f64],
        jac: &mut DMatrix<f64>,
    ) -> Result<(), Self::Error> {
        let mut xp = x0.to_vec();
        for (j, s) in self.x_scale.iter().enumerate() {
            let h = f64::EPSILON.sqrt() * s;
            xp[j] = x0[j] + h;
            let mut col = jac.column_mut(j);
            let ok = self.shooter.window_residuals(
                self.model,
                self.window,
                &xp,
                col.as_mut_slice(),
                self.bufs,
            );
            finish_column(col.as_mut_slice(), r, h, ok);
            xp[j] = x0[j];
        }
        Ok(())
    }
}

/// The current point of the training problem, for the Jacobian.
pub(super) struct Linearisation<'s, 'a, F> {
    pub(super) shooter: &'s Shooter<'a, F>,
    /// The model at the current weights.
    pub(super) model: &'s Hybrid<'a, F>,
    pub(super) windows: &'s [Window],
    pub(super) starts: &'s [f64],
    pub(super) theta: &'s [f64],
    pub(super) x_scale: &'s [f64],
    pub(super) dims: (usize, usize, usize),
}

impl<F: Dynamics> Linearisation<'_, '_, F> {
    /// Column `j` of `jac` = `(r(θ + h_j e_j) − r(θ))/h_j`, `h_j = √ε·max(1, |θ_j|)`.
    /// Weight columns simulate every window; a start-state column only its own window
    /// (the other rows are zero). Columns are computed in parallel, each worker with its
    /// own model copy and buffers, so the result does not depend on the thread count. A
    /// perturbed simulation that diverges leaves a zero column.
    pub(super) fn jacobian(&self, r0: &[f64], jac: &mut DMatrix<f64>) {
        let (n, m, q) = self.dims;
        let weights = self.model.correction().network().weights();
        let nw = weights.len();
        let p = self.shooter.hybrid.c().nrows();
        let offsets: Vec<usize> = self
            .windows
            .iter()
            .scan(0, |acc, w| {
                let o = *acc;
                *acc += (w.end - w.start) * p;
                Some(o)
            })
            .collect();
        let sqrt_eps = f64::EPSILON.sqrt();
        // Columns of a DMatrix are contiguous.
        jac.as_mut_slice()
            .par_chunks_mut(r0.len().max(1))
            .enumerate()
            .for_each_init(
                || (self.shooter.model(), Buffers::new(n, m, q), vec![0.0; n]),
                |(pert, bufs, x0), (j, col)| {
                    let tj = self.theta[j];
                    let h = sqrt_eps * tj.abs().max(1.0);
                    // The step actually taken, after rounding of θ_j + h.
                    let h = (tj + h) - tj;
                    if j < nw {
                        let w = pert.correction_mut().weights_mut();
                        w.copy_from_slice(weights);
                        w[j] = tj + h;
                        let ok = self
                            .shooter
                            .residuals(pert, self.windows, self.starts, col, bufs)
                            .is_ok();
                        finish_column(col, r0, h, ok);
                    } else {
                        let (wi, i) = ((j - nw) / n, (j - nw) % n);
                        x0.copy_from_slice(&self.starts[wi * n..(wi + 1) * n]);
                        let hx = h * self.x_scale[i];
                        x0[i] += hx;
                        let w = &self.windows[wi];
                        let (a, b) = (offsets[wi], offsets[wi] + (w.end - w.start) * p);
                        col[..a].fill(0.0);
                        col[b..].fill(0.0);
                        let seg = &mut col[a..b];
                        let ok = self.shooter.window_residuals(self.model, w, x0, seg, bufs);
                        finish_column(seg, &r0[a..b], h, ok);
                    }
                },
            );
    }
}

/// Turn perturbed residuals into a difference quotient (or zeros after divergence).
fn finish_column(col: &mut [f64], r0: &[f64], h: f64, ok: bool) {
    if ok {
        for (c, r) in col.iter_mut().zip(r0) {
            *c = (*c - r) / h;
        }
    } else {
        col.fill(0.0);
    }
}
