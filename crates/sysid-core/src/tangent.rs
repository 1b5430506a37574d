//! The one RK4 step of the workspace with its tangents: a classical RK4 step of
//! `ẋ = f(t, x, u; p)` over inputs held or linear between samples ([`StepInput`]), which
//! can also carry a tangent matrix `S = ∂x/∂z` (`n × r`, the sensitivity of the state to
//! `r` quantities: initial states, parameters, a held correction) through the step
//! exactly — the derivative of the discrete RK4 map, not of the flow, so `S` is the exact
//! derivative of the simulated trajectory.
//!
//! With `ξ_1 = x`, `ξ_s = x + c_s h k_{s−1}` (`c = ½, ½, 1`), `k_s = f(t + c_s h, ξ_s)`:
//! `∂ξ_s = S + c_s h ∂k_{s−1}`, `∂k_s = A(ξ_s)·∂ξ_s + F_p(ξ_s)` with `A = ∂f/∂x` (the
//! [`Dynamics`] Jacobian) and `F_p` the derivative of `f` along the tangent's directions
//! held fixed in `x` (the [`TangentSource`] hook: `∂f/∂θ` for parameters, `E` for a held
//! correction `E d`, nothing for initial states), and `S⁺ = S + h/6 Σ w_s ∂k_s`
//! (`w = 1, 2, 2, 1`).
//!
//! Used by sysid-core's fixed-step simulation, mme-core's linearisation (`S = [I | 0]`,
//! `F_p = [0 | E]` give `[Φ | Γ]`), discovery's forward sensitivities and nn's shooting
//! windows.

use nalgebra::DMatrix;

use crate::dataset::InterSample;
use crate::dynamics::Dynamics;

/// The input over one RK4 step.
#[derive(Debug, Clone, Copy)]
pub enum StepInput<'u> {
    /// Held at `u` for every stage (zero-order hold).
    Held(&'u [f64]),
    /// Linear between two samples (first-order hold): at a stage `c·h` into the step,
    /// `u = ua + (from + c·per)·(ub − ua)`, where `from` is the fraction of the sample
    /// interval at the step's start and `per = h/dt` the fraction one step spans.
    Ramp {
        /// Input at the interval's first sample.
        ua: &'u [f64],
        /// Input at the interval's last sample.
        ub: &'u [f64],
        /// Interval fraction at the step's start.
        from: f64,
        /// Interval fraction per step.
        per: f64,
    },
}

impl StepInput<'_> {
    /// The input at stage offset `c` (fraction of the step), computed into `buf` when it
    /// is interpolated.
    pub fn at<'a>(&'a self, c: f64, buf: &'a mut [f64]) -> &'a [f64] {
        match *self {
            StepInput::Held(u) => u,
            StepInput::Ramp { ua, ub, from, per } => {
                let f = from + c * per;
                for ((b, a), z) in buf.iter_mut().zip(ua).zip(ub) {
                    *b = a + f * (z - a);
                }
                &buf[..ua.len()]
            }
        }
    }

    /// The input of sub-step `j` of `substeps` across a sample interval over which it
    /// runs linearly from `ua` to `ub` (see also
    /// [`InterSample::step_input`](InterSample::step_input)).
    pub fn ramp<'u>(ua: &'u [f64], ub: &'u [f64], j: usize, substeps: usize) -> StepInput<'u> {
        StepInput::Ramp {
            ua,
            ub,
            from: j as f64 / substeps as f64,
            per: 1.0 / substeps as f64,
        }
    }
}

// `InterSample` is the dataset's word; its RK4 input lives with the step.
impl InterSample {
    /// The input over RK4 sub-step `j` of `substeps` across the sample interval from
    /// input `ua` to `ub` (`ub` is read only for a first-order hold).
    pub fn step_input<'u>(
        self,
        ua: &'u [f64],
        ub: &'u [f64],
        j: usize,
        substeps: usize,
    ) -> StepInput<'u> {
        match self {
            InterSample::Zoh => StepInput::Held(ua),
            InterSample::Foh => StepInput::ramp(ua, ub, j, substeps),
        }
    }
}

/// The part of the right-hand side's derivative along the tangent's directions that is
/// not through `x`: `F_p(t, x, u)` (`n × r`), added to `A·∂ξ` at every stage.
pub trait TangentSource {
    /// Write `F_p` at `(t, x, u)` into `out` (`n × r`, zeroed by the caller).
    fn add_to(&self, t: f64, x: &[f64], u: &[f64], out: &mut DMatrix<f64>);

    /// Write `A = ∂f/∂x` at `(t, x, u)` into `a` and return true, for a source that knows
    /// it more cheaply than [`Dynamics::jacobians`] (which also forms `∂f/∂u`, unused
    /// here); by default false, and the step asks the dynamics.
    fn state_jacobian(&self, _t: f64, _x: &[f64], _u: &[f64], _a: &mut DMatrix<f64>) -> bool {
        false
    }
}

const STAGE_C: [f64; 4] = [0.0, 0.5, 0.5, 1.0];
const WEIGHT: [f64; 4] = [1.0, 2.0, 2.0, 1.0];

/// Buffers of the RK4 step (no allocation per step).
#[derive(Debug, Clone)]
pub struct Rk4 {
    u: Vec<f64>,
    k: [Vec<f64>; 4],
    xi: Vec<f64>,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    /// Tangents: `∂ξ` of the current stage, `∂k` of every stage, `F_p`.
    dxi: DMatrix<f64>,
    dk: [DMatrix<f64>; 4],
    fp: DMatrix<f64>,
}

impl Rk4 {
    /// Buffers for `n` states, `m` inputs and `r` tangent directions.
    pub fn new(n: usize, m: usize, r: usize) -> Self {
        Self {
            u: vec![0.0; m],
            k: std::array::from_fn(|_| vec![0.0; n]),
            xi: vec![0.0; n],
            a: DMatrix::zeros(n, n),
            b: DMatrix::zeros(n, m),
            dxi: DMatrix::zeros(n, r),
            dk: std::array::from_fn(|_| DMatrix::zeros(n, r)),
            fp: DMatrix::zeros(n, r),
        }
    }

    /// Room for an interpolated input (allocates only the first time a longer one comes).
    fn fit_input(&mut self, input: &StepInput<'_>) {
        if let StepInput::Ramp { ua, .. } = input
            && self.u.len() < ua.len()
        {
            self.u.resize(ua.len(), 0.0);
        }
    }

    fn stage_point(&mut self, s: usize, c: f64, x: &[f64]) {
        if s == 0 {
            self.xi.copy_from_slice(x);
        } else {
            for ((xi, xv), kv) in self.xi.iter_mut().zip(x).zip(&self.k[s - 1]) {
                *xi = xv + c * kv;
            }
        }
    }

    /// `x ← x⁺` for one step of length `h` from time `t`.
    pub fn step<F: Dynamics + ?Sized>(
        &mut self,
        f: &F,
        t: f64,
        h: f64,
        x: &mut [f64],
        input: &StepInput<'_>,
    ) {
        self.fit_input(input);
        for (s, &cs) in STAGE_C.iter().enumerate() {
            self.stage_point(s, cs * h, x);
            f.rhs(
                t + cs * h,
                &self.xi,
                input.at(cs, &mut self.u),
                &mut self.k[s],
            );
        }
        for (i, xi) in x.iter_mut().enumerate() {
            *xi +=
                h / 6.0 * (self.k[0][i] + 2.0 * self.k[1][i] + 2.0 * self.k[2][i] + self.k[3][i]);
        }
    }

    /// `x ← x⁺` and `s ← ∂x⁺/∂z` (`n × r`) for one step, the tangent's direct source
    /// `source` (module doc).
    #[allow(clippy::too_many_arguments)]
    pub fn step_with_tangents<F: Dynamics + ?Sized, T: TangentSource + ?Sized>(
        &mut self,
        f: &F,
        source: &T,
        t: f64,
        h: f64,
        x: &mut [f64],
        s: &mut DMatrix<f64>,
        input: &StepInput<'_>,
    ) {
        self.fit_input(input);
        for (st, &cs) in STAGE_C.iter().enumerate() {
            let c = cs * h;
            self.stage_point(st, c, x);
            let ts = t + c;
            let us = input.at(cs, &mut self.u);
            f.rhs(ts, &self.xi, us, &mut self.k[st]);
            if !source.state_jacobian(ts, &self.xi, us, &mut self.a) {
                f.jacobians(ts, &self.xi, us, &mut self.a, &mut self.b);
            }
            self.fp.fill(0.0);
            source.add_to(ts, &self.xi, us, &mut self.fp);
            // ∂ξ = S + c ∂k_{s−1}.
            self.dxi.copy_from(s);
            if st > 0 {
                add_scaled(&mut self.dxi, c, &self.dk[st - 1]);
            }
            let dk = &mut self.dk[st];
            dk.copy_from(&self.fp);
            dk.gemm(1.0, &self.a, &self.dxi, 1.0);
        }
        for (i, xi) in x.iter_mut().enumerate() {
            *xi +=
                h / 6.0 * (self.k[0][i] + 2.0 * self.k[1][i] + 2.0 * self.k[2][i] + self.k[3][i]);
        }
        for (st, w) in WEIGHT.iter().enumerate() {
            add_scaled(s, h / 6.0 * w, &self.dk[st]);
        }
    }
}

/// `y ← y + a·x` for matrices of one shape.
fn add_scaled(y: &mut DMatrix<f64>, a: f64, x: &DMatrix<f64>) {
    for (yi, xi) in y.as_mut_slice().iter_mut().zip(x.as_slice()) {
        *yi += a * xi;
    }
}
