//! The grey-box calibration as a least-squares problem: weighted output errors of RK4
//! simulations over segments of the records (one segment per record for a free run),
//! continuity defects between consecutive segments (multiple shooting), and their exact
//! Jacobian from the tangent RK4 step (`∂x/∂x0` and `∂x/∂p` through
//! [`ParametricDynamics::parameter_jacobian`]).

// Index loops over tangent columns read like the Jacobian's layout they fill.
#![allow(clippy::needless_range_loop)]

use std::cell::RefCell;

use nalgebra::DMatrix;

use crate::dataset::Experiment;
use crate::error::{CoreError, Result};
use crate::least_squares::{AcceptedStep, Control, LeastSquaresProblem};
use crate::physical::ParametricDynamics;
use crate::tangent::{Rk4, TangentSource};

use super::transform::Transform;

/// A stretch of one record simulated from its own start state: samples `start..end`
/// are scored; when `linked`, the state simulated to sample `end` must meet the next
/// segment's start state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Segment {
    pub record: usize,
    pub start: usize,
    pub end: usize,
    pub linked: bool,
}

/// `F_p`: the free parameters' columns of `∂f/∂p` in the first `free.len()` tangent
/// columns (the start-state columns have no direct source).
struct FreeColumns<'a, D> {
    model: &'a D,
    free: &'a [usize],
    all: RefCell<DMatrix<f64>>,
}

impl<D: ParametricDynamics> TangentSource for FreeColumns<'_, D> {
    fn add_to(&self, t: f64, x: &[f64], u: &[f64], out: &mut DMatrix<f64>) {
        let mut all = self.all.borrow_mut();
        self.model.parameter_jacobian(t, x, u, &mut all);
        for (col, &j) in self.free.iter().enumerate() {
            for i in 0..all.nrows() {
                out[(i, col)] += all[(i, j)];
            }
        }
    }
}

/// What [`Calibration::accepted`] reports.
pub(super) type Observer<'o> = &'o mut dyn FnMut(&str, usize, f64);

/// The calibration problem (θ = transformed free parameters, then one start state per
/// segment).
pub(super) struct Calibration<'a, 'o, D: ParametricDynamics> {
    pub model: &'a D,
    pub c: &'a DMatrix<f64>,
    /// `1/σ` per output.
    pub weight: Vec<f64>,
    pub records: &'a [Experiment],
    pub free: Vec<usize>,
    pub transforms: Vec<Transform>,
    pub segments: Vec<Segment>,
    /// Weight of a continuity defect (per unit of state).
    pub continuity: f64,
    /// RK4 steps per sample interval, per record.
    pub substeps: Vec<usize>,
    pub blow_up: f64,
    /// Jacobian columns along the physical parameters rather than the transformed ones
    /// (for the covariance).
    pub physical_columns: bool,
    pub rows: usize,
    pub observer: Option<Observer<'o>>,
    /// The stage named to the observer.
    pub stage: &'static str,
    /// The job's budget: every Jacobian charges the RK4 steps of its simulation.
    pub budget: crate::Budget,
    /// Jacobians formed so far (one per solver iteration).
    jacobians: usize,
    values: Vec<f64>,
    x: Vec<f64>,
    s: DMatrix<f64>,
    rk: Rk4,
}

impl<'a, 'o, D: ParametricDynamics> Calibration<'a, 'o, D> {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        model: &'a D,
        c: &'a DMatrix<f64>,
        weight: Vec<f64>,
        records: &'a [Experiment],
        free: Vec<usize>,
        transforms: Vec<Transform>,
        segments: Vec<Segment>,
        continuity: f64,
        substeps: Vec<usize>,
        blow_up: f64,
    ) -> Self {
        let n = model.n_states();
        let r = free.len() + n;
        let mut rows = 0;
        for seg in &segments {
            let exp = &records[seg.record];
            for k in seg.start..seg.end {
                rows += exp.output(k).iter().filter(|v| !v.is_nan()).count();
            }
            if seg.linked {
                rows += n;
            }
        }
        let values = model.parameters().iter().map(|p| p.value).collect();
        Self {
            model,
            c,
            weight,
            records,
            free,
            transforms,
            segments,
            continuity,
            substeps,
            blow_up,
            physical_columns: false,
            rows,
            observer: None,
            stage: "free run",
            budget: crate::Budget::default(),
            jacobians: 0,
            values,
            x: vec![0.0; n],
            s: DMatrix::zeros(n, r),
            rk: Rk4::new(n, model.n_inputs(), r),
        }
    }

    /// Number of θ entries.
    pub fn dimension(&self) -> usize {
        self.free.len() + self.segments.len() * self.model.n_states()
    }

    /// The model at `theta`'s parameter values.
    pub fn model_at(&mut self, theta: &[f64]) -> Result<D> {
        for ((&j, tr), &z) in self.free.iter().zip(&self.transforms).zip(theta) {
            self.values[j] = tr.value(z);
        }
        self.model
            .with_parameters(&self.values)
            .map_err(|e| CoreError::InvalidArgument {
                name: "parameter values",
                value: f64::NAN,
                reason: match e {
                    crate::physical::PhysicalError::BadParameter { .. } => {
                        "a parameter left its bounds"
                    }
                    _ => "the model rejected the parameter values",
                },
            })
    }

    /// One RK4 interval `k − 1 → k` of record `record` (with tangents when `tangents` is
    /// given), in that record's sub-steps. False when the state leaves the blow-up bound.
    fn interval(
        &mut self,
        model: &D,
        record: usize,
        k: usize,
        tangents: Option<&FreeColumns<'_, D>>,
    ) -> bool {
        let exp = &self.records[record];
        let substeps = self.substeps[record];
        let h = exp.dt() / substeps as f64;
        for j in 0..substeps {
            let t = exp.time(k - 1) + j as f64 * h;
            let input = exp.step_input(k - 1, j, substeps);
            match tangents {
                Some(src) => {
                    self.rk
                        .step_with_tangents(model, src, t, h, &mut self.x, &mut self.s, &input)
                }
                None => self.rk.step(model, t, h, &mut self.x, &input),
            }
        }
        self.x
            .iter()
            .all(|v| v.is_finite() && v.abs() <= self.blow_up)
    }

    fn start_of(&self, seg: usize) -> usize {
        self.free.len() + seg * self.model.n_states()
    }

    /// Residuals at `theta`; false when a simulation diverges.
    fn fill_residuals(&mut self, theta: &[f64], r: &mut [f64]) -> Result<bool> {
        let model = self.model_at(theta)?;
        let n = self.model.n_states();
        let records = self.records;
        let mut row = 0;
        for si in 0..self.segments.len() {
            let seg = self.segments[si];
            let exp = &records[seg.record];
            let at = self.start_of(si);
            self.x.copy_from_slice(&theta[at..at + n]);
            for k in seg.start..seg.end {
                if k > seg.start && !self.interval(&model, seg.record, k, None) {
                    return Ok(false);
                }
                for (i, &y) in exp.output(k).iter().enumerate() {
                    if !y.is_nan() {
                        let yhat: f64 = (0..n).map(|l| self.c[(i, l)] * self.x[l]).sum();
                        r[row] = self.weight[i] * (y - yhat);
                        row += 1;
                    }
                }
            }
            if seg.linked {
                if !self.interval(&model, seg.record, seg.end, None) {
                    return Ok(false);
                }
                let next = at + n;
                for l in 0..n {
                    r[row] = self.continuity * (self.x[l] - theta[next + l]);
                    row += 1;
                }
            }
        }
        Ok(true)
    }

    /// The Jacobian at `theta` (rows as [`Self::fill_residuals`]).
    fn fill_jacobian(&mut self, theta: &[f64], jac: &mut DMatrix<f64>) -> Result<()> {
        let steps: usize = self
            .segments
            .iter()
            .map(|s| (s.end - s.start).saturating_sub(1) * self.substeps[s.record])
            .sum();
        let stage = if self.stage == "free run" {
            "grey-box free-run iteration"
        } else {
            "grey-box multiple-shooting iteration"
        };
        self.budget
            .charge(steps as u64, stage, self.jacobians, None)?;
        self.jacobians += 1;
        let model = self.model_at(theta)?;
        let n = self.model.n_states();
        let nf = self.free.len();
        let scale: Vec<f64> = if self.physical_columns {
            vec![1.0; nf]
        } else {
            self.transforms
                .iter()
                .zip(theta)
                .map(|(tr, &z)| tr.derivative(z))
                .collect()
        };
        let free = std::mem::take(&mut self.free);
        let src = FreeColumns {
            model: &model,
            free: &free,
            all: RefCell::new(DMatrix::zeros(n, self.model.parameters().len())),
        };
        jac.fill(0.0);
        let records = self.records;
        let mut row = 0;
        let mut failed = None;
        'segments: for si in 0..self.segments.len() {
            let seg = self.segments[si];
            let exp = &records[seg.record];
            let at = nf + si * n;
            self.x.copy_from_slice(&theta[at..at + n]);
            self.s.fill(0.0);
            for l in 0..n {
                self.s[(l, nf + l)] = 1.0;
            }
            for k in seg.start..seg.end {
                if k > seg.start && !self.interval(&model, seg.record, k, Some(&src)) {
                    failed = Some(exp.time(k));
                    break 'segments;
                }
                for (i, &y) in exp.output(k).iter().enumerate() {
                    if y.is_nan() {
                        continue;
                    }
                    let w = self.weight[i];
                    for col in 0..nf + n {
                        let cs: f64 = (0..n).map(|l| self.c[(i, l)] * self.s[(l, col)]).sum();
                        let target = if col < nf { col } else { at + col - nf };
                        let sc = if col < nf { scale[col] } else { 1.0 };
                        jac[(row, target)] = -w * cs * sc;
                    }
                    row += 1;
                }
            }
            if seg.linked {
                if !self.interval(&model, seg.record, seg.end, Some(&src)) {
                    failed = Some(exp.time(seg.end));
                    break 'segments;
                }
                for l in 0..n {
                    for col in 0..nf + n {
                        let target = if col < nf { col } else { at + col - nf };
                        let sc = if col < nf { scale[col] } else { 1.0 };
                        jac[(row, target)] = self.continuity * self.s[(l, col)] * sc;
                    }
                    jac[(row, at + n + l)] = -self.continuity;
                    row += 1;
                }
            }
        }
        self.free = free;
        match failed {
            None => Ok(()),
            Some(t) => {
                let (state, value) = self
                    .x
                    .iter()
                    .enumerate()
                    .find(|(_, v)| !v.is_finite() || v.abs() > self.blow_up)
                    .map_or((0, f64::NAN), |(i, v)| (i, *v));
                Err(CoreError::Diverged { t, state, value })
            }
        }
    }

    /// Residuals at `theta` (false when a simulation diverges), for the caller's check
    /// of the start.
    pub fn residuals_checked(&mut self, theta: &[f64], r: &mut [f64]) -> Result<bool> {
        self.fill_residuals(theta, r)
    }

    /// States of `record` over samples `start..end` simulated from the start state in
    /// `probe` (`[z | x]`), NaN after a divergence.
    pub fn simulate_one(
        &mut self,
        probe: &[f64],
        record: usize,
        start: usize,
        end: usize,
    ) -> Result<DMatrix<f64>> {
        let model = self.model_at(probe)?;
        let n = self.model.n_states();
        let nf = self.free.len();
        self.x.copy_from_slice(&probe[nf..nf + n]);
        let mut xs = DMatrix::from_element(n, end - start, f64::NAN);
        xs.column_mut(0).copy_from_slice(&self.x);
        for k in start + 1..end {
            if !self.interval(&model, record, k, None) {
                break;
            }
            xs.column_mut(k - start).copy_from_slice(&self.x);
        }
        Ok(xs)
    }

    /// Free-run state trajectories of every record (`n × N` each) at `theta`, whose
    /// start states are one per record (free-run segments).
    pub fn trajectories(&mut self, theta: &[f64]) -> Result<Vec<DMatrix<f64>>> {
        let model = self.model_at(theta)?;
        let n = self.model.n_states();
        let records = self.records;
        let mut out = Vec::with_capacity(self.segments.len());
        for si in 0..self.segments.len() {
            let seg = self.segments[si];
            let exp = &records[seg.record];
            let at = self.start_of(si);
            self.x.copy_from_slice(&theta[at..at + n]);
            let mut xs = DMatrix::from_element(n, exp.len(), f64::NAN);
            xs.column_mut(seg.start).copy_from_slice(&self.x);
            for k in seg.start + 1..seg.end {
                if !self.interval(&model, seg.record, k, None) {
                    break;
                }
                xs.column_mut(k).copy_from_slice(&self.x);
            }
            out.push(xs);
        }
        Ok(out)
    }
}

impl<D: ParametricDynamics> LeastSquaresProblem for Calibration<'_, '_, D> {
    type Error = CoreError;

    fn residual_count(&self) -> usize {
        self.rows
    }

    fn residuals(&mut self, theta: &[f64], r: &mut [f64]) -> Result<bool> {
        self.fill_residuals(theta, r)
    }

    fn jacobian(&mut self, theta: &[f64], _r: &[f64], jac: &mut DMatrix<f64>) -> Result<()> {
        self.fill_jacobian(theta, jac)
    }

    fn accepted(&mut self, step: &AcceptedStep<'_>) -> Control {
        if let Some(obs) = self.observer.as_mut() {
            obs(self.stage, step.iteration, step.cost);
        }
        Control::Continue
    }
}
