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
    /// Read from a grid of the interval (band-limited input, [`InterSample::Bl`]): the
    /// `per_interval + 1` points of `m` values each span the sample interval evenly; the
    /// input is linear between them. `from` and `per` as for [`StepInput::Ramp`].
    Grid {
        /// The interval's grid points, `(per_interval + 1)·m` values.
        points: &'u [f64],
        /// Grid steps per sample interval.
        per_interval: usize,
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
            StepInput::Grid {
                points,
                per_interval,
                from,
                per,
            } => grid_point(points, per_interval, from + c * per, buf),
        }
    }

    /// Number of input channels an interpolated step writes (0 for a held one, which
    /// writes none).
    pub fn interpolated_width(&self) -> usize {
        match *self {
            StepInput::Held(_) => 0,
            StepInput::Ramp { ua, .. } => ua.len(),
            StepInput::Grid {
                points,
                per_interval,
                ..
            } => points.len() / (per_interval + 1),
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

/// The input at interval fraction `f` (clamped to `[0, 1]`) of an interval's grid
/// (`per_interval + 1` points of `m` values; linear between points), written into `buf`.
pub(crate) fn grid_point<'a>(
    points: &[f64],
    per_interval: usize,
    f: f64,
    buf: &'a mut [f64],
) -> &'a [f64] {
    let m = points.len() / (per_interval + 1);
    let s = (f * per_interval as f64).clamp(0.0, per_interval as f64);
    let i = (s.floor() as usize).min(per_interval - 1);
    let w = s - i as f64;
    let (a, z) = (
        &points[i * m..(i + 1) * m],
        &points[(i + 1) * m..(i + 2) * m],
    );
    for ((b, a), z) in buf.iter_mut().zip(a).zip(z) {
        *b = a + w * (z - a);
    }
    &buf[..m]
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
            // Two samples cannot carry the band-limited reading: it needs the record
            // ([`crate::Experiment::step_input`]); from two samples it is linear.
            InterSample::Foh | InterSample::Bl => StepInput::ramp(ua, ub, j, substeps),
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

/// A right-hand side that evaluates `f`, `A = ∂f/∂x` and `F_p` at one stage point in one
/// call, for dynamics whose three share work (a term evaluated once serves `f` and its
/// column of `F_p`). Used by [`Rk4::step_with_stage_tangents`].
pub trait StageTangents {
    /// At `(t, x, u)`: write `f` into `k`, `A` into `a` (`n × n`), and add `F_p` into
    /// `fp` (`n × r`, zeroed by the caller).
    fn stage(
        &self,
        t: f64,
        x: &[f64],
        u: &[f64],
        k: &mut [f64],
        a: &mut DMatrix<f64>,
        fp: &mut DMatrix<f64>,
    );
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
    /// Tangents: one column of `∂ξ` of the current stage, `∂k` of every stage, `F_p`.
    dxi: Vec<f64>,
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
            dxi: vec![0.0; n],
            dk: std::array::from_fn(|_| DMatrix::zeros(n, r)),
            fp: DMatrix::zeros(n, r),
        }
    }

    /// Room for an interpolated input (allocates only the first time a longer one comes).
    fn fit_input(&mut self, input: &StepInput<'_>) {
        let width = input.interpolated_width();
        if self.u.len() < width {
            self.u.resize(width, 0.0);
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
        self.advance_state(h, x);
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
        self.tangent_step(t, h, x, s, input, |ts, xi, us, k, a, b, fp| {
            f.rhs(ts, xi, us, k);
            if !source.state_jacobian(ts, xi, us, a) {
                f.jacobians(ts, xi, us, a, b);
            }
            source.add_to(ts, xi, us, fp);
        });
    }

    /// [`Rk4::step_with_tangents`] for dynamics that give `f`, `A` and `F_p` together
    /// ([`StageTangents`]); the same arithmetic otherwise.
    pub fn step_with_stage_tangents<F: StageTangents + ?Sized>(
        &mut self,
        f: &F,
        t: f64,
        h: f64,
        x: &mut [f64],
        s: &mut DMatrix<f64>,
        input: &StepInput<'_>,
    ) {
        self.tangent_step(t, h, x, s, input, |ts, xi, us, k, a, _, fp| {
            f.stage(ts, xi, us, k, a, fp);
        });
    }

    /// The step with tangents, `eval(t, ξ, u, k, A, B, F_p)` filling a stage's `k`, `A`
    /// and `F_p` (`F_p` arrives zeroed; `B` is scratch).
    ///
    /// The tangent products are written out over the column-major storage ([`stage_tangent`]).
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn tangent_step(
        &mut self,
        t: f64,
        h: f64,
        x: &mut [f64],
        s: &mut DMatrix<f64>,
        input: &StepInput<'_>,
        mut eval: impl FnMut(
            f64,
            &[f64],
            &[f64],
            &mut [f64],
            &mut DMatrix<f64>,
            &mut DMatrix<f64>,
            &mut DMatrix<f64>,
        ),
    ) {
        self.fit_input(input);
        let n = s.nrows();
        assert_eq!(
            s.shape(),
            self.fp.shape(),
            "tangent shape differs from the buffers"
        );
        for (st, &cs) in STAGE_C.iter().enumerate() {
            let c = cs * h;
            self.stage_point(st, c, x);
            let ts = t + c;
            let us = input.at(cs, &mut self.u);
            self.fp.fill(0.0);
            eval(
                ts,
                &self.xi,
                us,
                &mut self.k[st],
                &mut self.a,
                &mut self.b,
                &mut self.fp,
            );
            // ∂k_s = F_p + A·∂ξ_s with ∂ξ_s = S + c ∂k_{s−1}.
            let (done, rest) = self.dk.split_at_mut(st);
            let prev = done.last().map(|m| (c, m.as_slice()));
            let (a, fp, sv, dk) = (
                self.a.as_slice(),
                self.fp.as_slice(),
                s.as_slice(),
                rest[0].as_mut_slice(),
            );
            match n {
                0 => {}
                1 => stage_tangent::<1>(a, fp, sv, prev, dk),
                2 => stage_tangent::<2>(a, fp, sv, prev, dk),
                3 => stage_tangent::<3>(a, fp, sv, prev, dk),
                4 => stage_tangent::<4>(a, fp, sv, prev, dk),
                5 => stage_tangent::<5>(a, fp, sv, prev, dk),
                6 => stage_tangent::<6>(a, fp, sv, prev, dk),
                _ => stage_tangent_dyn(n, a, fp, sv, prev, &mut self.dxi, dk),
            }
        }
        self.advance_state(h, x);
        // S⁺ = S + h/6 Σ w_s ∂k_s, the stages added in order.
        let w = WEIGHT.map(|w| h / 6.0 * w);
        let [d0, d1, d2, d3] = &self.dk;
        for ((((sv, a0), a1), a2), a3) in s
            .as_mut_slice()
            .iter_mut()
            .zip(d0.as_slice())
            .zip(d1.as_slice())
            .zip(d2.as_slice())
            .zip(d3.as_slice())
        {
            *sv = *sv + w[0] * a0 + w[1] * a1 + w[2] * a2 + w[3] * a3;
        }
    }

    /// `x ← x + h/6 (k_1 + 2 k_2 + 2 k_3 + k_4)`.
    fn advance_state(&self, h: f64, x: &mut [f64]) {
        for (i, xi) in x.iter_mut().enumerate() {
            *xi +=
                h / 6.0 * (self.k[0][i] + 2.0 * self.k[1][i] + 2.0 * self.k[2][i] + self.k[3][i]);
        }
    }
}

/// `∂k = F_p + A·(S + c ∂k_prev)` (`∂k_prev` term only when `prev = Some((c, ∂k_prev))`)
/// for `N` states, over column-major `n × r` slices, with `A` held in registers.
///
/// For these small shapes (a few states, tens of columns) nalgebra's general `gemm`
/// spends more in dispatch and per-column views than in arithmetic, and a loop over a
/// run-time `n` keeps the accumulators in memory. Every element accumulates in the order
/// `gemm` uses for matrices of at most 5 rows (`F_p`, then `A_{i0}·∂ξ_0`, `A_{i1}·∂ξ_1`,
/// …), so the results are the same to the last bit there.
#[inline(always)]
fn stage_tangent<const N: usize>(
    a: &[f64],
    fp: &[f64],
    s: &[f64],
    prev: Option<(f64, &[f64])>,
    dk: &mut [f64],
) {
    let a: [[f64; N]; N] = std::array::from_fn(|l| std::array::from_fn(|i| a[l * N + i]));
    let column = |acc: &mut [f64; N], d: &[f64; N]| {
        for l in 0..N {
            for i in 0..N {
                acc[i] += a[l][i] * d[l];
            }
        }
    };
    let cols = dk
        .chunks_exact_mut(N)
        .zip(fp.chunks_exact(N))
        .zip(s.chunks_exact(N));
    match prev {
        None => {
            for ((out, f), sc) in cols {
                let d: [f64; N] = std::array::from_fn(|l| sc[l]);
                let mut acc: [f64; N] = std::array::from_fn(|i| f[i]);
                column(&mut acc, &d);
                out.copy_from_slice(&acc);
            }
        }
        Some((c, p)) => {
            for (((out, f), sc), pc) in cols.zip(p.chunks_exact(N)) {
                let d: [f64; N] = std::array::from_fn(|l| sc[l] + c * pc[l]);
                let mut acc: [f64; N] = std::array::from_fn(|i| f[i]);
                column(&mut acc, &d);
                out.copy_from_slice(&acc);
            }
        }
    }
}

/// [`stage_tangent`] for any number of states `n`, `dxi` (length `n`) as scratch.
fn stage_tangent_dyn(
    n: usize,
    a: &[f64],
    fp: &[f64],
    s: &[f64],
    prev: Option<(f64, &[f64])>,
    dxi: &mut [f64],
    dk: &mut [f64],
) {
    for (j, ((out, f), sc)) in dk
        .chunks_exact_mut(n)
        .zip(fp.chunks_exact(n))
        .zip(s.chunks_exact(n))
        .enumerate()
    {
        match prev {
            None => dxi.copy_from_slice(sc),
            Some((c, p)) => {
                for ((d, sv), pv) in dxi.iter_mut().zip(sc).zip(&p[j * n..(j + 1) * n]) {
                    *d = sv + c * pv;
                }
            }
        }
        out.copy_from_slice(f);
        for (l, &d) in dxi.iter().enumerate() {
            for (o, &av) in out.iter_mut().zip(&a[l * n..(l + 1) * n]) {
                *o += av * d;
            }
        }
    }
}
