//! The simulation side of trajectory refinement: shooting windows simulated free-run by
//! RK4 with the network in the loop (inputs held or interpolated between samples as each
//! record's experiment says), their scaled residuals, the fit of a window's start state,
//! and the forward-difference Jacobian over weights and start states.

use nalgebra::DMatrix;
use rayon::prelude::*;
use sysid_core::{
    Dynamics, InterSample, LeastSquaresProblem, LmSettings, Termination, levenberg_marquardt,
};

use super::{HybridParts, ShootingRecord};
use crate::mlp::{Mlp, Workspace};

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
    pub(super) parts: &'a HybridParts<'a, F>,
    pub(super) records: &'a [ShootingRecord<'a>],
    pub(super) inv_scale: Vec<f64>,
    pub(super) substeps: usize,
    pub(super) blow_up: f64,
}

/// Per-thread buffers for [`Shooter::residuals`].
pub(super) struct Buffers {
    x: Vec<f64>,
    tmp: Vec<f64>,
    k: [Vec<f64>; 4],
    xu: Vec<f64>,
    d: Vec<f64>,
    ws: Workspace,
    /// Interpolated inputs at the start, middle and end of an RK4 step (first-order hold).
    u: [Vec<f64>; 3],
}

impl Buffers {
    pub(super) fn new(n: usize, m: usize, q: usize) -> Self {
        Self {
            x: vec![0.0; n],
            tmp: vec![0.0; n],
            k: std::array::from_fn(|_| vec![0.0; n]),
            xu: vec![0.0; n + m],
            d: vec![0.0; q],
            ws: Workspace::new(),
            u: std::array::from_fn(|_| vec![0.0; m]),
        }
    }
}

/// The input over one RK4 step.
#[derive(Clone, Copy)]
enum StepInput<'u> {
    /// Held at the sample's value (zero-order hold): every stage reads this slice.
    Held(&'u [f64]),
    /// Linear from `ua` (this sample) to `ub` (the next): the step's start, middle and end
    /// lie at fractions `s` of the sample interval.
    Ramp {
        ua: &'u [f64],
        ub: &'u [f64],
        s: [f64; 3],
    },
}

impl<F: Dynamics> Shooter<'_, F> {
    /// `dx = f(x, u) + E·NN([x; u])` at `x` and input `u`.
    fn rhs(&self, net: &Mlp, x: &[f64], u: &[f64], dx: &mut [f64], b: &mut BufRest<'_>) {
        self.parts.base.rhs(0.0, x, u, dx);
        let n = x.len();
        b.xu[..n].copy_from_slice(x);
        b.xu[n..].copy_from_slice(u);
        // Lengths are checked once in `refine_on_trajectories`.
        if net.forward(b.xu, b.d, b.ws).is_err() {
            dx.fill(f64::NAN);
            return;
        }
        let e = self.parts.e;
        for (j, dj) in b.d.iter().enumerate() {
            for (i, dxi) in dx.iter_mut().enumerate() {
                *dxi += e[(i, j)] * dj;
            }
        }
    }

    /// Simulate window `w` from state `x0` and write its scaled residuals (`p` per sample
    /// after the start; 0 where the output is not observed) into `r`. False when the
    /// simulation diverges.
    pub(super) fn window_residuals(
        &self,
        net: &Mlp,
        w: &Window,
        x0: &[f64],
        r: &mut [f64],
        b: &mut Buffers,
    ) -> bool {
        let c = self.parts.c;
        let p = c.nrows();
        let exp = self.records[w.record].experiment;
        let h = exp.dt() / self.substeps as f64;
        let steps = self.substeps as f64;
        b.x.copy_from_slice(x0);
        for (k, rk) in (w.start..w.end).zip(r.chunks_exact_mut(p)) {
            let ua = exp.input(k);
            for j in 0..self.substeps {
                let input = match exp.intersample() {
                    InterSample::Zoh => StepInput::Held(ua),
                    // Windows end at most at the last sample, so `k + 1` exists.
                    InterSample::Foh => StepInput::Ramp {
                        ua,
                        ub: exp.input(k + 1),
                        s: [
                            j as f64 / steps,
                            (j as f64 + 0.5) / steps,
                            (j + 1) as f64 / steps,
                        ],
                    },
                };
                self.rk4(net, h, input, b);
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
        net: &Mlp,
        windows: &[Window],
        starts: &[f64],
        r: &mut [f64],
        b: &mut Buffers,
    ) -> std::result::Result<(), usize> {
        let n = b.x.len();
        let p = self.parts.c.nrows();
        let mut row = 0;
        for (wi, w) in windows.iter().enumerate() {
            let len = (w.end - w.start) * p;
            let x0 = &starts[wi * n..(wi + 1) * n];
            if !self.window_residuals(net, w, x0, &mut r[row..row + len], b) {
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
        net: &Mlp,
        w: &Window,
        x0: &[f64],
        x_scale: &[f64],
        b: &mut Buffers,
        fitted: &mut [f64],
    ) -> f64 {
        let mut problem = StartFit {
            shooter: self,
            net,
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

    /// One classical RK4 step of size `h` on `b.x`; stage 1 reads the input at the step's
    /// start, stages 2 and 3 at its middle, stage 4 at its end.
    fn rk4(&self, net: &Mlp, h: f64, input: StepInput<'_>, b: &mut Buffers) {
        let Buffers {
            x,
            tmp,
            k,
            xu,
            d,
            ws,
            u,
        } = b;
        let (u_start, u_mid, u_end): (&[f64], &[f64], &[f64]) = match input {
            StepInput::Held(v) => (v, v, v),
            StepInput::Ramp { ua, ub, s } => {
                for (buf, si) in u.iter_mut().zip(s) {
                    for ((o, a), z) in buf.iter_mut().zip(ua).zip(ub) {
                        *o = a + si * (z - a);
                    }
                }
                let [u0, u1, u2] = u;
                (u0.as_slice(), u1.as_slice(), u2.as_slice())
            }
        };
        let mut rest = BufRest { xu, d, ws };
        let [k1, k2, k3, k4] = k;
        self.rhs(net, x, u_start, k1, &mut rest);
        for ((t, xi), ki) in tmp.iter_mut().zip(x.iter()).zip(k1.iter()) {
            *t = xi + 0.5 * h * ki;
        }
        self.rhs(net, tmp, u_mid, k2, &mut rest);
        for ((t, xi), ki) in tmp.iter_mut().zip(x.iter()).zip(k2.iter()) {
            *t = xi + 0.5 * h * ki;
        }
        self.rhs(net, tmp, u_mid, k3, &mut rest);
        for ((t, xi), ki) in tmp.iter_mut().zip(x.iter()).zip(k3.iter()) {
            *t = xi + h * ki;
        }
        self.rhs(net, tmp, u_end, k4, &mut rest);
        for (i, xi) in x.iter_mut().enumerate() {
            *xi += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
}

/// The start state of one window as a least-squares problem, the weights fixed.
struct StartFit<'s, 'a, F> {
    shooter: &'s Shooter<'a, F>,
    net: &'s Mlp,
    window: &'s Window,
    x_scale: &'s [f64],
    bufs: &'s mut Buffers,
}

impl<F: Dynamics> LeastSquaresProblem for StartFit<'_, '_, F> {
    type Error = std::convert::Infallible;

    fn residual_count(&self) -> usize {
        (self.window.end - self.window.start) * self.shooter.parts.c.nrows()
    }

    fn residuals(&mut self, x0: &[f64], r: &mut [f64]) -> Result<bool, Self::Error> {
        Ok(self
            .shooter
            .window_residuals(self.net, self.window, x0, r, self.bufs))
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
                self.net,
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

/// The network buffers of [`Buffers`], borrowed apart from the state buffers.
struct BufRest<'b> {
    xu: &'b mut [f64],
    d: &'b mut [f64],
    ws: &'b mut Workspace,
}

/// The current point of the training problem, for the Jacobian.
pub(super) struct Linearisation<'s, 'a, F> {
    pub(super) shooter: &'s Shooter<'a, F>,
    pub(super) net: &'s Mlp,
    pub(super) windows: &'s [Window],
    pub(super) starts: &'s [f64],
    pub(super) theta: &'s [f64],
    pub(super) x_scale: &'s [f64],
    pub(super) dims: (usize, usize, usize),
}

impl<F: Dynamics> Linearisation<'_, '_, F> {
    /// Column `j` of `jac` = `(r(θ + h_j e_j) − r(θ))/h_j`, `h_j = √ε·max(1, |θ_j|)`.
    /// Weight columns simulate every window; a start-state column only its own window
    /// (the other rows are zero). Columns are computed in parallel, each with its own
    /// network copy and buffers, so the result does not depend on the thread count. A
    /// perturbed simulation that diverges leaves a zero column.
    pub(super) fn jacobian(&self, r0: &[f64], jac: &mut DMatrix<f64>) {
        let (n, m, q) = self.dims;
        let nw = self.net.n_weights();
        let p = self.shooter.parts.c.nrows();
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
                || (self.net.clone(), Buffers::new(n, m, q), vec![0.0; n]),
                |(pert, bufs, x0), (j, col)| {
                    let tj = self.theta[j];
                    let h = sqrt_eps * tj.abs().max(1.0);
                    // The step actually taken, after rounding of θ_j + h.
                    let h = (tj + h) - tj;
                    if j < nw {
                        pert.weights_mut().copy_from_slice(self.net.weights());
                        pert.weights_mut()[j] = tj + h;
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
                        let ok = self.shooter.window_residuals(self.net, w, x0, seg, bufs);
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
