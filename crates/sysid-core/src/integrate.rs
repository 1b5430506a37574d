//! ODE integrators for sampled-data simulation: fixed-step RK4 with sub-steps and
//! adaptive Dormand–Prince 5(4) with error control. Between samples inputs are held
//! (zero-order hold, the default) or interpolated linearly (first-order hold, for
//! band-limited inputs; [`InterSample`]), and every interval ends exactly on the next
//! sample time.
//!
//! Written here rather than taken from `ode_solvers` because sampled-data simulation needs
//! the input to change at each sample and steps to land exactly on sample times (its RK4
//! overshoots `t_end`; see `../shared/notes/crates.md`).

// Index loops over small state vectors read like the equations they implement.
#![allow(clippy::needless_range_loop)]

use nalgebra::DMatrix;

use crate::bandlimited::{BL_FACTOR, band_limited_grid};
use crate::dataset::{Experiment, InterSample};
use crate::dynamics::Dynamics;
use crate::error::{CoreError, Result};
use crate::tangent::{Rk4, StepInput};

/// How to integrate between samples.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Integrator {
    /// Classical fourth-order Runge–Kutta with `substeps` equal steps per sample interval.
    Rk4 {
        /// Steps per sample interval (≥ 1).
        substeps: usize,
    },
    /// Dormand–Prince 5(4) with local error control.
    DormandPrince(DpOptions),
}

impl Default for Integrator {
    fn default() -> Self {
        Integrator::DormandPrince(DpOptions::default())
    }
}

/// Options of the adaptive Dormand–Prince integrator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DpOptions {
    /// Relative tolerance on each state's local error.
    pub rtol: f64,
    /// Absolute tolerance on each state's local error.
    pub atol: f64,
    /// Smallest step allowed, s; a smaller one is [`CoreError::StepSizeUnderflow`].
    pub h_min: f64,
    /// Step budget per call of [`integrate_interval`].
    pub max_steps: usize,
}

impl Default for DpOptions {
    fn default() -> Self {
        Self {
            rtol: 1e-8,
            atol: 1e-10,
            h_min: 1e-12,
            max_steps: 100_000,
        }
    }
}

/// The input along one sample interval `[t_a, t_b]`.
trait InputPath {
    /// The input at `t`, written into `buf` when it has to be computed.
    fn at<'a>(&'a self, t: f64, buf: &'a mut [f64]) -> &'a [f64];
    /// The input over RK4 sub-step `j` of `substeps` across the interval.
    fn step(&self, j: usize, substeps: usize) -> StepInput<'_>;
}

/// Zero-order hold: `u_a` throughout.
struct Held<'u>(&'u [f64]);

impl InputPath for Held<'_> {
    fn at<'a>(&'a self, _t: f64, _buf: &'a mut [f64]) -> &'a [f64] {
        self.0
    }
    fn step(&self, _: usize, _: usize) -> StepInput<'_> {
        StepInput::Held(self.0)
    }
}

/// First-order hold: `u_a + (t − t_a)/(t_b − t_a)·(u_b − u_a)`.
struct Ramp<'u> {
    ta: f64,
    span: f64,
    ua: &'u [f64],
    ub: &'u [f64],
}

impl InputPath for Ramp<'_> {
    fn at<'a>(&'a self, t: f64, buf: &'a mut [f64]) -> &'a [f64] {
        let s = (t - self.ta) / self.span;
        for ((b, a), z) in buf.iter_mut().zip(self.ua).zip(self.ub) {
            *b = a + s * (z - a);
        }
        &buf[..self.ua.len()]
    }
    fn step(&self, j: usize, substeps: usize) -> StepInput<'_> {
        StepInput::ramp(self.ua, self.ub, j, substeps)
    }
}

/// Band-limited: linear between the points of the interval's grid
/// ([`crate::bandlimited`]).
struct GridPath<'u> {
    ta: f64,
    span: f64,
    points: &'u [f64],
    per_interval: usize,
}

impl GridPath<'_> {
    fn step_input(&self, from: f64, per: f64) -> StepInput<'_> {
        StepInput::Grid {
            points: self.points,
            per_interval: self.per_interval,
            from,
            per,
        }
    }
}

impl InputPath for GridPath<'_> {
    fn at<'a>(&'a self, t: f64, buf: &'a mut [f64]) -> &'a [f64] {
        let f = (t - self.ta) / self.span;
        crate::tangent::grid_point(self.points, self.per_interval, f, buf)
    }
    fn step(&self, j: usize, substeps: usize) -> StepInput<'_> {
        self.step_input(j as f64 / substeps as f64, 1.0 / substeps as f64)
    }
}

/// States beyond this magnitude count as a blown-up simulation.
pub const DEFAULT_BLOW_UP: f64 = 1e12;

/// Reusable buffers so integration does not allocate per step.
#[derive(Debug, Clone)]
pub struct Workspace {
    k: [Vec<f64>; 7],
    tmp: Vec<f64>,
    y5: Vec<f64>,
    /// Interpolated input (first-order hold); sized on first use.
    u: Vec<f64>,
    /// Last accepted adaptive step, carried between intervals.
    h_last: Option<f64>,
    /// The RK4 step's buffers.
    rk4: Rk4,
}

impl Workspace {
    /// Buffers for `n` states.
    pub fn new(n: usize) -> Self {
        Self {
            k: std::array::from_fn(|_| vec![0.0; n]),
            tmp: vec![0.0; n],
            y5: vec![0.0; n],
            u: Vec::new(),
            h_last: None,
            rk4: Rk4::new(n, 0, 0),
        }
    }
}

/// One classical RK4 step of size `h` from `(t, x)` with input `u` held; updates `x`.
pub fn rk4_step<D: Dynamics + ?Sized>(
    f: &D,
    t: f64,
    h: f64,
    x: &mut [f64],
    u: &[f64],
    ws: &mut Workspace,
) {
    ws.rk4.step(f, t, h, x, &StepInput::Held(u));
}

// Dormand–Prince 5(4) tableau (Dormand & Prince 1980; Hairer, Nørsett & Wanner, Solving
// ODEs I, Table 5.2).
const C: [f64; 7] = [0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];
const A: [[f64; 6]; 7] = [
    [0.0; 6],
    [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
    [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
    [
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
        0.0,
        0.0,
    ],
    [
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
        0.0,
    ],
    [
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];
/// Error weights: 5th-order minus embedded 4th-order weights.
const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

/// Integrate from `t0` to `t1` with `u` held constant, updating `x` in place.
pub fn integrate_interval<D: Dynamics + ?Sized>(
    f: &D,
    t0: f64,
    t1: f64,
    x: &mut [f64],
    u: &[f64],
    method: &Integrator,
    ws: &mut Workspace,
) -> Result<()> {
    interval_path(f, t0, t1, x, &Held(u), method, ws)
}

/// Integrate from sample `t0` (input `ua`) to the next sample `t1` (input `ub`) with the
/// input between them as `hold` says, updating `x` in place. With [`InterSample::Zoh`]
/// this is [`integrate_interval`] with `ua` (`ub` unused). Two samples cannot carry a
/// band-limited reading: [`InterSample::Bl`] is linear here (use
/// [`integrate_record_interval`], which reads the record's grid).
#[allow(clippy::too_many_arguments)]
pub fn integrate_sample<D: Dynamics + ?Sized>(
    f: &D,
    t0: f64,
    t1: f64,
    x: &mut [f64],
    ua: &[f64],
    ub: &[f64],
    hold: InterSample,
    method: &Integrator,
    ws: &mut Workspace,
) -> Result<()> {
    match hold {
        InterSample::Zoh => interval_path(f, t0, t1, x, &Held(ua), method, ws),
        InterSample::Foh | InterSample::Bl => {
            if ws.u.len() < ua.len() {
                ws.u.resize(ua.len(), 0.0);
            }
            let ramp = Ramp {
                ta: t0,
                span: t1 - t0,
                ua,
                ub,
            };
            interval_path(f, t0, t1, x, &ramp, method, ws)
        }
    }
}

/// Integrate interval `k → k + 1` of `exp` with its input between the samples as the
/// record says ([`Experiment::intersample`], the band-limited grid included), updating `x`.
pub fn integrate_record_interval<D: Dynamics + ?Sized>(
    f: &D,
    exp: &Experiment,
    k: usize,
    x: &mut [f64],
    method: &Integrator,
    ws: &mut Workspace,
) -> Result<()> {
    let (ta, tb) = (exp.time(k), exp.time(k + 1));
    match exp.band_limited_interval(k) {
        Some(points) if exp.intersample() == InterSample::Bl => {
            if ws.u.len() < exp.n_inputs() {
                ws.u.resize(exp.n_inputs(), 0.0);
            }
            let path = GridPath {
                ta,
                span: tb - ta,
                points,
                per_interval: BL_FACTOR,
            };
            interval_path(f, ta, tb, x, &path, method, ws)
        }
        _ => integrate_sample(
            f,
            ta,
            tb,
            x,
            exp.input(k),
            exp.input(k + 1),
            exp.intersample(),
            method,
            ws,
        ),
    }
}

fn interval_path<D: Dynamics + ?Sized, P: InputPath>(
    f: &D,
    t0: f64,
    t1: f64,
    x: &mut [f64],
    input: &P,
    method: &Integrator,
    ws: &mut Workspace,
) -> Result<()> {
    match method {
        Integrator::Rk4 { substeps } => {
            let s = (*substeps).max(1);
            let h = (t1 - t0) / s as f64;
            for j in 0..s {
                ws.rk4.step(f, t0 + j as f64 * h, h, x, &input.step(j, s));
            }
            Ok(())
        }
        Integrator::DormandPrince(opt) => dopri_interval(f, t0, t1, x, input, opt, ws),
    }
}

fn dopri_interval<D: Dynamics + ?Sized, P: InputPath>(
    f: &D,
    t0: f64,
    t1: f64,
    x: &mut [f64],
    input: &P,
    opt: &DpOptions,
    ws: &mut Workspace,
) -> Result<()> {
    let n = x.len();
    let span = t1 - t0;
    let mut t = t0;
    let mut h = ws.h_last.unwrap_or(span).min(span);
    // k[0] holds f(t, x) at the start of each step (first-same-as-last after the first).
    f.rhs(t, x, input.at(t, &mut ws.u), &mut ws.k[0]);
    let mut steps = 0usize;
    while t < t1 {
        if steps >= opt.max_steps {
            return Err(CoreError::TooManySteps {
                max_steps: opt.max_steps,
                t,
            });
        }
        steps += 1;
        let last = t + h >= t1 - 1e-14 * t1.abs().max(span);
        let h_step = if last { t1 - t } else { h };
        for s in 1..7 {
            for i in 0..n {
                let mut acc = x[i];
                for (j, a) in A[s].iter().enumerate().take(s) {
                    acc += h_step * a * ws.k[j][i];
                }
                ws.tmp[i] = acc;
            }
            let (head, tail) = ws.k.split_at_mut(s);
            let _ = head;
            let ts = t + C[s] * h_step;
            f.rhs(ts, &ws.tmp, input.at(ts, &mut ws.u), &mut tail[0]);
        }
        // tmp now holds the 5th-order solution (stage 7 point = A[6] weights).
        ws.y5.copy_from_slice(&ws.tmp);
        let mut err = 0.0;
        for i in 0..n {
            let mut e = 0.0;
            for (s, w) in E.iter().enumerate() {
                e += w * ws.k[s][i];
            }
            e *= h_step;
            let sc = opt.atol + opt.rtol * x[i].abs().max(ws.y5[i].abs());
            err += (e / sc) * (e / sc);
        }
        let err = (err / n.max(1) as f64).sqrt();
        if !err.is_finite() {
            let (state, value) = first_bad(&ws.y5);
            return Err(CoreError::Diverged {
                t: t + h_step,
                state,
                value,
            });
        }
        if err <= 1.0 {
            t = if last { t1 } else { t + h_step };
            x.copy_from_slice(&ws.y5);
            let (k0, rest) = ws.k.split_at_mut(1);
            k0[0].copy_from_slice(&rest[5]);
            let fac = if err == 0.0 {
                5.0
            } else {
                (0.9 * err.powf(-0.2)).clamp(0.2, 5.0)
            };
            if !last {
                h = h_step * fac;
                ws.h_last = Some(h);
            } else {
                // Keep the unclipped step for the next interval.
                ws.h_last = Some((h_step * fac).max(h));
            }
        } else {
            let fac = (0.9 * err.powf(-0.2)).clamp(0.2, 1.0);
            h = h_step * fac;
            if h < opt.h_min {
                return Err(CoreError::StepSizeUnderflow { t, h });
            }
        }
    }
    Ok(())
}

fn first_bad(x: &[f64]) -> (usize, f64) {
    x.iter()
        .enumerate()
        .find(|(_, v)| !v.is_finite())
        .map(|(i, v)| (i, *v))
        .unwrap_or((0, f64::NAN))
}

/// Free-run simulation on a uniform grid `t_k = t0 + k·dt`, `k = 0..N` (`N` = columns of
/// `inputs`, `m × N`), input `u_k` held on `[t_k, t_{k+1})`. Returns the states `n × N`
/// (column `k` is `x(t_k)`, column 0 is `x0`).
///
/// Errors with [`CoreError::Diverged`] when a state becomes non-finite or exceeds
/// `blow_up` in magnitude.
pub fn simulate<D: Dynamics + ?Sized>(
    f: &D,
    x0: &[f64],
    t0: f64,
    dt: f64,
    inputs: &DMatrix<f64>,
    method: &Integrator,
    blow_up: f64,
) -> Result<DMatrix<f64>> {
    simulate_with(f, x0, t0, dt, inputs, InterSample::Zoh, method, blow_up)
}

/// [`simulate`] with the input between samples as `hold` says.
///
/// For [`InterSample::Bl`] the band-limited grid of `inputs` is computed on every call
/// (the record's ends held); a record's own grid, computed once, is read by
/// [`simulate_experiment`].
#[allow(clippy::too_many_arguments)]
pub fn simulate_with<D: Dynamics + ?Sized>(
    f: &D,
    x0: &[f64],
    t0: f64,
    dt: f64,
    inputs: &DMatrix<f64>,
    hold: InterSample,
    method: &Integrator,
    blow_up: f64,
) -> Result<DMatrix<f64>> {
    CoreError::check_len("initial state", x0.len(), f.n_states())?;
    CoreError::check_len("input channels", inputs.nrows(), f.n_inputs())?;
    let grid = (hold == InterSample::Bl && inputs.ncols() > 0).then(|| band_limited_grid(inputs));
    let run = Run {
        t0,
        dt,
        inputs: inputs.as_slice(),
        m: inputs.nrows(),
        len: inputs.ncols(),
        hold,
        grid: grid.as_deref(),
    };
    run.simulate(f, x0, method, blow_up)
}

/// Free run over samples `range` of `exp` from `x0` (the state at sample `range.start`),
/// the input between samples as the record says: `n × range.len()` states, column `j` at
/// sample `range.start + j`.
///
/// A band-limited record is read through its own grid, computed once when the record was
/// made ([`Experiment::band_limited_grid`]): no per-call cost, and the samples beyond the
/// range shape the input near its ends as they do in the whole record, as the sensitivity
/// runs read it ([`Experiment::step_input`]). The same bits as [`simulate_with`] over the
/// record's inputs for the whole record.
///
/// Errors: a range beyond the record, a state of the wrong length, a channel-count
/// mismatch, a diverging run ([`CoreError::Diverged`]).
pub fn simulate_experiment<D: Dynamics + ?Sized>(
    f: &D,
    x0: &[f64],
    exp: &Experiment,
    range: std::ops::Range<usize>,
    method: &Integrator,
    blow_up: f64,
) -> Result<DMatrix<f64>> {
    if range.start > range.end || range.end > exp.len() {
        return Err(CoreError::Range {
            start: range.start,
            end: range.end,
            len: exp.len(),
        });
    }
    let m = exp.n_inputs();
    CoreError::check_len("initial state", x0.len(), f.n_states())?;
    CoreError::check_len("input channels", m, f.n_inputs())?;
    let inputs = &exp.inputs().as_slice()[range.start * m..range.end * m];
    // A record holds its grid exactly when it is read band-limited.
    let grid = exp
        .band_limited_grid()
        .filter(|_| !range.is_empty())
        .map(|g| &g[range.start * BL_FACTOR * m..((range.end - 1) * BL_FACTOR + 1) * m]);
    let run = Run {
        t0: exp.time(range.start),
        dt: exp.dt(),
        inputs,
        m,
        len: range.len(),
        hold: exp.intersample(),
        grid,
    };
    run.simulate(f, x0, method, blow_up)
}

/// One free run's inputs: `inputs` column-major (`m` per sample), and for a band-limited
/// reading its grid over the same samples.
struct Run<'a> {
    t0: f64,
    dt: f64,
    inputs: &'a [f64],
    m: usize,
    /// Samples (also with no input channels).
    len: usize,
    hold: InterSample,
    grid: Option<&'a [f64]>,
}

impl Run<'_> {
    fn simulate<D: Dynamics + ?Sized>(
        &self,
        f: &D,
        x0: &[f64],
        method: &Integrator,
        blow_up: f64,
    ) -> Result<DMatrix<f64>> {
        let n = f.n_states();
        let (t0, dt, m) = (self.t0, self.dt, self.m);
        if !(dt.is_finite() && dt > 0.0) {
            return Err(CoreError::BadSamplePeriod { dt });
        }
        let len = self.len;
        let mut out = DMatrix::zeros(n, len);
        if len == 0 {
            return Ok(out);
        }
        let mut x = x0.to_vec();
        let mut ws = Workspace::new(n);
        out.column_mut(0).copy_from_slice(&x);
        if self.grid.is_some() {
            ws.u.resize(m, 0.0);
        }
        for k in 1..len {
            let ua = &self.inputs[(k - 1) * m..k * m];
            let ub = &self.inputs[k * m..(k + 1) * m];
            let ta = t0 + (k - 1) as f64 * dt;
            let tb = t0 + k as f64 * dt;
            match self.grid {
                Some(g) => {
                    let first = (k - 1) * BL_FACTOR * m;
                    let path = GridPath {
                        ta,
                        span: tb - ta,
                        points: &g[first..first + (BL_FACTOR + 1) * m],
                        per_interval: BL_FACTOR,
                    };
                    interval_path(f, ta, tb, &mut x, &path, method, &mut ws)?;
                }
                None => integrate_sample(f, ta, tb, &mut x, ua, ub, self.hold, method, &mut ws)?,
            }
            if let Some((state, value)) = x
                .iter()
                .enumerate()
                .find(|(_, v)| !v.is_finite() || v.abs() > blow_up)
            {
                return Err(CoreError::Diverged {
                    t: tb,
                    state,
                    value: *value,
                });
            }
            out.column_mut(k).copy_from_slice(&x);
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ẋ = λ x + u (scalar), exact solution known.
    struct Decay(f64);
    impl Dynamics for Decay {
        fn n_states(&self) -> usize {
            1
        }
        fn n_inputs(&self) -> usize {
            1
        }
        fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
            dx[0] = self.0 * x[0] + u[0];
        }
    }

    /// Harmonic oscillator rotated: x'' = -x, exact solution cos/sin.
    struct Osc;
    impl Dynamics for Osc {
        fn n_states(&self) -> usize {
            2
        }
        fn n_inputs(&self) -> usize {
            0
        }
        fn rhs(&self, _t: f64, x: &[f64], _u: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -x[0];
        }
    }

    fn rk4_error(steps: usize) -> f64 {
        let mut x = [1.0, 0.0];
        let mut ws = Workspace::new(2);
        integrate_interval(
            &Osc,
            0.0,
            2.0,
            &mut x,
            &[],
            &Integrator::Rk4 { substeps: steps },
            &mut ws,
        )
        .unwrap();
        ((x[0] - 2.0_f64.cos()).powi(2) + (x[1] + 2.0_f64.sin()).powi(2)).sqrt()
    }

    #[test]
    fn rk4_is_fourth_order() {
        let e1 = rk4_error(20);
        let e2 = rk4_error(40);
        let order = (e1 / e2).log2();
        assert!((order - 4.0).abs() < 0.15, "observed order {order}");
    }

    #[test]
    fn dopri_meets_tolerance_and_lands_on_t1() {
        for rtol in [1e-4, 1e-7, 1e-10] {
            let opt = DpOptions {
                rtol,
                atol: rtol * 1e-2,
                ..DpOptions::default()
            };
            let mut x = [1.0];
            let mut ws = Workspace::new(1);
            integrate_interval(
                &Decay(-3.0),
                0.0,
                2.0,
                &mut x,
                &[1.0],
                &Integrator::DormandPrince(opt),
                &mut ws,
            )
            .unwrap();
            // x(t) = 1/3 + (1 - 1/3) e^{-3t}
            let exact = 1.0 / 3.0 + (2.0 / 3.0) * (-6.0_f64).exp();
            // Global error is at most a small multiple of the local tolerance here (stable problem).
            assert!(
                (x[0] - exact).abs() < 10.0 * rtol,
                "rtol {rtol}: err {}",
                (x[0] - exact).abs()
            );
        }
    }

    #[test]
    fn dopri_fixed_step_is_fifth_order() {
        // Disable error control (huge tolerance) so the step is the whole interval / k.
        let opt = DpOptions {
            rtol: 1e6,
            atol: 1e6,
            ..DpOptions::default()
        };
        let err = |k: usize| {
            let mut x = [1.0, 0.0];
            let mut ws = Workspace::new(2);
            let h = 2.0 / k as f64;
            for j in 0..k {
                ws.h_last = None;
                integrate_interval(
                    &Osc,
                    j as f64 * h,
                    (j + 1) as f64 * h,
                    &mut x,
                    &[],
                    &Integrator::DormandPrince(opt),
                    &mut ws,
                )
                .unwrap();
            }
            ((x[0] - 2.0_f64.cos()).powi(2) + (x[1] + 2.0_f64.sin()).powi(2)).sqrt()
        };
        let order = (err(10) / err(20)).log2();
        assert!((order - 5.0).abs() < 0.3, "observed order {order}");
    }

    #[test]
    fn simulate_holds_input_and_detects_blow_up() {
        let u = DMatrix::from_element(1, 11, 2.0);
        let xs = simulate(
            &Decay(0.0),
            &[0.0],
            0.0,
            0.1,
            &u,
            &Integrator::Rk4 { substeps: 1 },
            DEFAULT_BLOW_UP,
        )
        .unwrap();
        assert!((xs[(0, 10)] - 2.0).abs() < 1e-12);
        let u = DMatrix::zeros(1, 200);
        let r = simulate(
            &Decay(50.0),
            &[1.0],
            0.0,
            1.0,
            &u,
            &Integrator::Rk4 { substeps: 4 },
            1e6,
        );
        assert!(matches!(r, Err(CoreError::Diverged { .. })));
    }

    /// With a first-order hold, samples of a ramp input are the ramp itself, so
    /// `ẋ = λx + a + b·t` has the closed form `x(t) = (x₀ − p(t₀))·e^{λ(t−t₀)} + p(t)`,
    /// `p(t) = −(a + b·t)/λ − b/λ²`. RK4 (20 sub-steps, local error ~ (λh)⁵/120 ≈ 1e-12)
    /// and Dormand–Prince (rtol 1e-10) must meet it to 1e-9; the zero-order hold of the
    /// same samples lags the ramp by half a sample and misses by about b·dt/(2|λ|).
    #[test]
    fn first_order_hold_follows_a_ramp_exactly() {
        let (lambda, a, b, t0, dt, len) = (-0.7, 0.3, 1.5, 0.2, 0.1, 51);
        let u = DMatrix::from_fn(1, len, |_, k| a + b * (t0 + k as f64 * dt));
        let p = |t: f64| -(a + b * t) / lambda - b / (lambda * lambda);
        let x0 = 0.4;
        let exact = |t: f64| (x0 - p(t0)) * (lambda * (t - t0)).exp() + p(t);
        let rk4 = Integrator::Rk4 { substeps: 20 };
        let dp = Integrator::DormandPrince(DpOptions {
            rtol: 1e-10,
            atol: 1e-12,
            ..DpOptions::default()
        });
        for method in [rk4, dp] {
            let xs = simulate_with(
                &Decay(lambda),
                &[x0],
                t0,
                dt,
                &u,
                InterSample::Foh,
                &method,
                1e6,
            )
            .unwrap();
            for k in 0..len {
                let t = t0 + k as f64 * dt;
                assert!((xs[(0, k)] - exact(t)).abs() < 1e-9, "{method:?} at {t}");
            }
            let held = simulate(&Decay(lambda), &[x0], t0, dt, &u, &method, 1e6).unwrap();
            let t_end = t0 + (len - 1) as f64 * dt;
            let lag = exact(t_end) - held[(0, len - 1)];
            let expected = b * dt / (2.0 * lambda.abs());
            assert!(
                (lag - expected).abs() < 0.1 * expected,
                "{lag} vs {expected}"
            );
        }
    }

    /// A record of `ẋ = λx + u` driven by a multisine, read as `hold` says.
    fn decay_record(hold: InterSample) -> Experiment {
        let (len, dt, t0) = (300, 0.1, 2.0);
        let u = DMatrix::from_fn(1, len, |_, k| {
            let t = k as f64 * dt;
            (1.3 * t).sin() + 0.5 * (4.1 * t + 0.3).sin()
        });
        Experiment::new(t0, dt, u, DMatrix::zeros(1, len))
            .unwrap()
            .with_intersample(hold)
    }

    /// Over the whole record `simulate_experiment` is `simulate_with` over the record's
    /// inputs (which computes the band-limited grid itself), bit for bit; over a range of a
    /// held or linearly interpolated record it is `simulate_with` over that range's inputs
    /// from its first sample's time.
    #[test]
    fn simulate_experiment_equals_simulate_with() {
        let f = Decay(-0.7);
        let rk4 = Integrator::Rk4 { substeps: 4 };
        for hold in [InterSample::Zoh, InterSample::Foh, InterSample::Bl] {
            let exp = decay_record(hold);
            let whole = simulate_experiment(&f, &[0.4], &exp, 0..exp.len(), &rk4, 1e6).unwrap();
            let direct = simulate_with(
                &f,
                &[0.4],
                exp.t0(),
                exp.dt(),
                exp.inputs(),
                hold,
                &rk4,
                1e6,
            )
            .unwrap();
            assert_eq!(whole, direct, "{hold:?}");
            if hold == InterSample::Foh {
                // Independent of the code under test: the exact solution with the input
                // linear between samples, interval by interval from the range's start.
                let (lam, rk20) = (-0.7, Integrator::Rk4 { substeps: 20 });
                let part = simulate_experiment(&f, &[0.1], &exp, 40..170, &rk20, 1e6).unwrap();
                let mut x = 0.1;
                for k in 40..169 {
                    let (a, h) = (exp.input(k)[0], exp.dt());
                    let b = (exp.input(k + 1)[0] - a) / h;
                    // Particular solution of ẋ = λx + a + b·s: p(s) = −(a + b s)/λ − b/λ².
                    let p = |s: f64| -(a + b * s) / lam - b / (lam * lam);
                    x = (x - p(0.0)) * (lam * h).exp() + p(h);
                    assert!((part[(0, k + 1 - 40)] - x).abs() < 1e-9, "sample {}", k + 1);
                }
            }
            if hold != InterSample::Bl {
                let part = simulate_experiment(&f, &[0.1], &exp, 40..170, &rk4, 1e6).unwrap();
                let u = exp.inputs().columns(40, 130).into_owned();
                let direct =
                    simulate_with(&f, &[0.1], exp.time(40), exp.dt(), &u, hold, &rk4, 1e6).unwrap();
                assert_eq!(part, direct, "{hold:?}");
            }
        }
    }

    /// A band-limited record's free run over its first samples is the start of the free
    /// run over all of them (both read the record's grid); cut out of the record, the
    /// samples near the cut read a grid with the record's end held there instead, and the
    /// runs part.
    #[test]
    fn band_limited_prefix_is_the_start_of_the_whole_run() {
        let f = Decay(-0.7);
        let rk4 = Integrator::Rk4 { substeps: 4 };
        let exp = decay_record(InterSample::Bl);
        let whole = simulate_experiment(&f, &[0.4], &exp, 0..exp.len(), &rk4, 1e6).unwrap();
        let prefix = simulate_experiment(&f, &[0.4], &exp, 0..120, &rk4, 1e6).unwrap();
        assert_eq!(prefix, whole.columns(0, 120).into_owned());
        let cut = exp.inputs().columns(0, 120).into_owned();
        let alone = simulate_with(
            &f,
            &[0.4],
            exp.t0(),
            exp.dt(),
            &cut,
            InterSample::Bl,
            &rk4,
            1e6,
        )
        .unwrap();
        assert!((alone[(0, 119)] - whole[(0, 119)]).abs() > 1e-9);
        // A run from an inner sample starts from the state given there.
        let inner = simulate_experiment(&f, &[whole[(0, 50)]], &exp, 50..120, &rk4, 1e6).unwrap();
        for j in 0..70 {
            assert!(
                (inner[(0, j)] - whole[(0, 50 + j)]).abs() < 1e-12,
                "sample {}",
                50 + j
            );
        }
    }

    /// A range beyond the record and a state of the wrong length are errors, not panics; an
    /// empty range is an empty run.
    #[test]
    fn simulate_experiment_rejects_bad_ranges() {
        let f = Decay(-0.7);
        let rk4 = Integrator::Rk4 { substeps: 1 };
        let exp = decay_record(InterSample::Bl);
        assert!(matches!(
            simulate_experiment(&f, &[0.0], &exp, 10..301, &rk4, 1e6),
            Err(CoreError::Range {
                start: 10,
                end: 301,
                len: 300
            })
        ));
        #[allow(clippy::reversed_empty_ranges)]
        let reversed = 20..10;
        assert!(simulate_experiment(&f, &[0.0], &exp, reversed, &rk4, 1e6).is_err());
        assert!(simulate_experiment(&f, &[0.0, 1.0], &exp, 0..10, &rk4, 1e6).is_err());
        let empty = simulate_experiment(&f, &[0.0], &exp, 5..5, &rk4, 1e6).unwrap();
        assert_eq!(empty.ncols(), 0);
    }
}
