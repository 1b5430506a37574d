//! Uniformly sampled time-series data: named channels with units, several experiments,
//! missing samples (NaN) allowed in measured channels only, split and window.
//!
//! Storage is column-per-sample (`channels × samples`), so one sample is one contiguous
//! column of an nalgebra matrix.

use std::sync::Arc;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::bandlimited::{BL_FACTOR, band_limited_grid};
use crate::error::{CoreError, Result};
use crate::tangent::StepInput;

/// How inputs behave between samples (the `InterSample` property of MATLAB's `iddata`).
///
/// A record of a band-limited input (a multisine through a reconstruction filter) is
/// neither held nor stepped between samples; holding it delays it by half a sample,
/// which near a resonance a few samples per period long is a large phase error (on the
/// Silverbox record, 2nd-order free-run RMSE 15.5 mV held against 8.3 mV interpolated).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InterSample {
    /// Held at the sample's value until the next sample (zero-order hold).
    #[default]
    Zoh,
    /// Linear from each sample to the next (first-order hold).
    Foh,
    /// Band-limited: the windowed-sinc interpolation of the samples
    /// ([`crate::bandlimited`]), the reading of an input low-pass filtered below half the
    /// sampling rate — a multisine or filtered noise from a generator with a
    /// reconstruction filter. Linear interpolation passes only `sinc²(f/fs)` of a
    /// component at frequency `f` (69 % at a third of the sampling rate). MME reads it
    /// band-limited (a linear model's record goes to its nonlinear estimator); the linear
    /// baselines' exact discretisations read it as [`InterSample::Foh`].
    Bl,
}

/// Relative tolerance on the sample step when checking that a time vector is uniform.
///
/// Time columns written as decimal text carry round-off of about 1e-12 relative to `t`;
/// 1e-6 of a step accepts that while still catching a dropped or duplicated sample.
pub const UNIFORM_TIME_RTOL: f64 = 1e-6;

/// Largest share of the sample step that the round-off of the absolute time values may
/// take: beyond it (|t| so large that `f64` cannot resolve the step, e.g. t ≈ 1e12 s
/// with dt = 0.01 s), a time vector is refused instead of being checked with a tolerance
/// that would hide a missing sample.
pub const TIME_RESOLUTION_SHARE: f64 = 0.01;

/// Largest distance, as a share of the step, at which a recorded time may sit from the
/// uniform grid `t0 + k·dt` (`dt` the mean step) and still count as that grid's sample: a
/// clock that stamps samples with jitter (EMPS's recorded times are single-precision sums,
/// 0.99998 / 1.00002 ms steps, within 3e-5 of a step of the grid) is uniform; a missing
/// row moves every sample after it by a whole step and stays refused.
pub const TIME_JITTER_SHARE: f64 = 1e-3;

/// Tolerance on `|step − dt|` for a step ending at time `t`: [`UNIFORM_TIME_RTOL`] of
/// `dt`, plus the round-off of decimal time text (`1e-12·|t|`) but never more than
/// [`TIME_RESOLUTION_SHARE`] of `dt`, so that a missing or duplicated sample (an error
/// of a whole step) is always caught, however large `|t|` is.
pub fn uniform_step_tolerance(dt: f64, t: f64) -> f64 {
    UNIFORM_TIME_RTOL * dt + (1e-12 * t.abs()).min(TIME_RESOLUTION_SHARE * dt)
}

/// Whether `f64` time values up to `t_max` in magnitude resolve a step `dt`: four units
/// of round-off of `t_max` (the error of a difference of two rounded times) stay within
/// [`TIME_RESOLUTION_SHARE`] of `dt`.
pub fn time_resolves_step(t_max: f64, dt: f64) -> bool {
    4.0 * f64::EPSILON * t_max.abs() <= TIME_RESOLUTION_SHARE * dt
}

/// A named channel (an input, or a measured state/output) with an optional unit.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Channel {
    /// Channel name, e.g. `theta`.
    pub name: String,
    /// Physical unit, e.g. `rad`; `None` when unknown.
    pub unit: Option<String>,
}

impl Channel {
    /// A channel without a unit.
    pub fn new(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            unit: None,
        }
    }

    /// A channel with a unit.
    pub fn with_unit(name: impl Into<String>, unit: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            unit: Some(unit.into()),
        }
    }
}

/// One uniformly sampled experiment: `t_k = t0 + k·dt`.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    t0: f64,
    dt: f64,
    inputs: DMatrix<f64>,
    outputs: DMatrix<f64>,
    intersample: InterSample,
    /// The band-limited grid of the record this one was cut from and the grid point of
    /// this record's first sample ([`InterSample::Bl`] only).
    fine: Option<(Arc<Vec<f64>>, usize)>,
}

impl Experiment {
    /// Build an experiment from its start time, step and data (`m × N` inputs, `p × N`
    /// outputs; NaN marks a missing output sample).
    ///
    /// Errors: non-positive `dt`, different sample counts, non-finite inputs, infinite
    /// outputs. Channel names in errors are `u<i>` / `y<i>`; [`Dataset::new`] re-checks
    /// with real names.
    pub fn new(t0: f64, dt: f64, inputs: DMatrix<f64>, outputs: DMatrix<f64>) -> Result<Self> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(CoreError::BadSamplePeriod { dt });
        }
        if !t0.is_finite() {
            return Err(CoreError::InvalidArgument {
                name: "t0",
                value: t0,
                reason: "must be finite",
            });
        }
        CoreError::check_len(
            "input samples vs output samples",
            inputs.ncols(),
            outputs.ncols(),
        )?;
        let exp = Self {
            t0,
            dt,
            inputs,
            outputs,
            intersample: InterSample::Zoh,
            fine: None,
        };
        let names_u: Vec<String> = (0..exp.n_inputs()).map(|i| format!("u{i}")).collect();
        let names_y: Vec<String> = (0..exp.n_outputs()).map(|i| format!("y{i}")).collect();
        exp.check_values(0, &names_u, &names_y)?;
        Ok(exp)
    }

    /// Build an experiment from an explicit time vector, checking that it increases and is
    /// uniform to [`UNIFORM_TIME_RTOL`] of the mean step.
    pub fn from_times(t: &[f64], inputs: DMatrix<f64>, outputs: DMatrix<f64>) -> Result<Self> {
        let (t0, dt) = uniform_step(t)?;
        CoreError::check_len("input samples vs time samples", inputs.ncols(), t.len())?;
        Self::new(t0, dt, inputs, outputs)
    }

    fn check_values(&self, experiment: usize, inputs: &[String], outputs: &[String]) -> Result<()> {
        for k in 0..self.len() {
            for (i, name) in inputs.iter().enumerate() {
                if !self.inputs[(i, k)].is_finite() {
                    return Err(CoreError::NonFiniteInput {
                        channel: name.clone(),
                        experiment,
                        sample: k,
                    });
                }
            }
            for (i, name) in outputs.iter().enumerate() {
                if self.outputs[(i, k)].is_infinite() {
                    return Err(CoreError::InfiniteOutput {
                        channel: name.clone(),
                        experiment,
                        sample: k,
                    });
                }
            }
        }
        Ok(())
    }

    /// The same record with its inputs behaving between samples as `hold` says (free-run
    /// simulation follows it; the default is [`InterSample::Zoh`]).
    pub fn with_intersample(mut self, hold: InterSample) -> Self {
        self.set_intersample(hold);
        self
    }

    fn set_intersample(&mut self, hold: InterSample) {
        self.intersample = hold;
        if hold != InterSample::Bl {
            self.fine = None;
        } else if self.fine.is_none() {
            self.fine = Some((Arc::new(band_limited_grid(&self.inputs)), 0));
        }
    }

    /// How the inputs behave between samples.
    pub fn intersample(&self) -> InterSample {
        self.intersample
    }

    /// The input over RK4 sub-step `j` of `substeps` across the interval from sample `k`
    /// to `k + 1`, as [`Experiment::intersample`] says (`k + 1` is read only for
    /// [`InterSample::Foh`]; the band-limited grid for [`InterSample::Bl`]).
    pub fn step_input(&self, k: usize, j: usize, substeps: usize) -> StepInput<'_> {
        match (&self.intersample, &self.fine) {
            (InterSample::Zoh, _) => StepInput::Held(self.input(k)),
            (InterSample::Bl, Some((grid, offset))) => {
                let m = self.n_inputs();
                let first = (offset + k * BL_FACTOR) * m;
                StepInput::Grid {
                    points: &grid[first..first + (BL_FACTOR + 1) * m],
                    per_interval: BL_FACTOR,
                    from: j as f64 / substeps as f64,
                    per: 1.0 / substeps as f64,
                }
            }
            _ => StepInput::ramp(self.input(k), self.input(k + 1), j, substeps),
        }
    }

    /// The whole band-limited grid of this record (`(N − 1)·BL_FACTOR + 1` points of `m`
    /// values, point `i` at `t0 + i·dt/BL_FACTOR`) when it is read band-limited.
    pub fn band_limited_grid(&self) -> Option<&[f64]> {
        let (grid, offset) = self.fine.as_ref()?;
        let m = self.n_inputs();
        let points = (self.len().max(1) - 1) * BL_FACTOR + 1;
        grid.get(offset * m..(offset + points) * m)
    }

    /// The band-limited grid points of the interval from sample `k` to `k + 1`
    /// (`BL_FACTOR + 1` points of `m` values) when the record is read band-limited.
    pub fn band_limited_interval(&self, k: usize) -> Option<&[f64]> {
        let (grid, offset) = self.fine.as_ref()?;
        let m = self.n_inputs();
        let first = (offset + k * BL_FACTOR) * m;
        grid.get(first..first + (BL_FACTOR + 1) * m)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.inputs.ncols()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Time of the first sample, s.
    pub fn t0(&self) -> f64 {
        self.t0
    }

    /// Sample period, s.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Time of sample `k`, s.
    pub fn time(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }

    /// All sample times, s.
    pub fn times(&self) -> Vec<f64> {
        (0..self.len()).map(|k| self.time(k)).collect()
    }

    /// Number of input channels.
    pub fn n_inputs(&self) -> usize {
        self.inputs.nrows()
    }

    /// Number of output (measured) channels.
    pub fn n_outputs(&self) -> usize {
        self.outputs.nrows()
    }

    /// Inputs, `m × N`.
    pub fn inputs(&self) -> &DMatrix<f64> {
        &self.inputs
    }

    /// Outputs, `p × N`; NaN marks a missing sample.
    pub fn outputs(&self) -> &DMatrix<f64> {
        &self.outputs
    }

    /// Input vector at sample `k` (contiguous column).
    pub fn input(&self, k: usize) -> &[f64] {
        let m = self.n_inputs();
        &self.inputs.as_slice()[k * m..(k + 1) * m]
    }

    /// Output vector at sample `k` (contiguous column; NaN = missing).
    pub fn output(&self, k: usize) -> &[f64] {
        let p = self.n_outputs();
        &self.outputs.as_slice()[k * p..(k + 1) * p]
    }

    /// Samples `start..end` as a new experiment (time origin kept).
    pub fn window(&self, start: usize, end: usize) -> Result<Self> {
        if start >= end || end > self.len() {
            return Err(CoreError::Range {
                start,
                end,
                len: self.len(),
            });
        }
        Ok(Self {
            t0: self.time(start),
            dt: self.dt,
            inputs: self.inputs.columns(start, end - start).into_owned(),
            outputs: self.outputs.columns(start, end - start).into_owned(),
            intersample: self.intersample,
            // A window reads its parent's grid: the band-limited input near its ends is
            // the parent record's, not one held at the window's edges.
            fine: self
                .fine
                .as_ref()
                .map(|(grid, offset)| (grid.clone(), offset + start * BL_FACTOR)),
        })
    }
}

/// Check that `t` increases uniformly; return `(t0, dt)` with `dt` the mean step.
pub fn uniform_step(t: &[f64]) -> Result<(f64, f64)> {
    if t.len() < 2 {
        return Err(CoreError::TooFewSamples {
            what: "time vector",
            found: t.len(),
            needed: 2,
        });
    }
    for (k, w) in t.windows(2).enumerate() {
        if !w[1].is_finite() || !w[0].is_finite() || w[1] <= w[0] {
            return Err(CoreError::NonIncreasingTime {
                sample: k + 1,
                t_prev: w[0],
                t: w[1],
            });
        }
    }
    let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    let t_max = t[0].abs().max(t[t.len() - 1].abs());
    if !time_resolves_step(t_max, dt) {
        return Err(CoreError::InvalidArgument {
            name: "time",
            value: t_max,
            reason: "too large for double precision to resolve the sample step; \
                     subtract a time offset",
        });
    }
    if let Some((sample, step, typical)) = first_irregular_step(t) {
        return Err(CoreError::NonUniformTime {
            sample,
            step,
            dt: typical,
        });
    }
    Ok((t[0], dt))
}

/// The first irregular step of an increasing time vector (at least two samples):
/// `(sample, step, median step)` for the first sample whose step from the one before
/// differs from the median step by more than [`uniform_step_tolerance`], or — when every
/// step is within it — the last sample with the mean step, if that drifted beyond it;
/// `None` for uniform times, and for times that each lie within [`TIME_JITTER_SHARE`] of a
/// step of the uniform grid with the mean step (a jittered clock; its step is the mean).
/// Against the median, a missing or doubled row is named where it is; against the mean,
/// which the gap itself shifts, every step could look off.
pub fn first_irregular_step(t: &[f64]) -> Option<(usize, f64, f64)> {
    let n = t.len();
    if n < 2 {
        return None;
    }
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let m = steps.len();
    let typical = if m % 2 == 1 {
        steps[m / 2]
    } else {
        0.5 * (steps[m / 2 - 1] + steps[m / 2])
    };
    let mean = (t[n - 1] - t[0]) / (n - 1) as f64;
    // The first step off the median by more than `share` of it (at least the round-off
    // tolerance).
    let off = |share: f64| {
        t.windows(2)
            .enumerate()
            .find(|(_, w)| {
                let tol = uniform_step_tolerance(typical, w[1]).max(share * typical);
                (w[1] - w[0] - typical).abs() > tol
            })
            .map(|(k, w)| (k + 1, w[1] - w[0], typical))
    };
    // A step further off than a jittered clock's two stamps can make it: refused, named
    // where it is (a missing or doubled row).
    if let Some(found) = off(2.0 * TIME_JITTER_SHARE) {
        return Some(found);
    }
    let strict = off(0.0).or_else(|| {
        ((mean - typical).abs() > uniform_step_tolerance(typical, t[n - 1])).then_some((
            n - 1,
            mean,
            typical,
        ))
    });
    // Jittered stamps of a uniform clock: every sample within TIME_JITTER_SHARE of a step
    // of the grid through the first sample with the mean step.
    let on_grid = || {
        t.iter()
            .enumerate()
            .all(|(k, &tk)| (tk - (t[0] + k as f64 * mean)).abs() <= TIME_JITTER_SHARE * mean)
    };
    strict.filter(|_| !on_grid())
}

/// Several experiments sharing the same named input and output channels.
#[derive(Debug, Clone, PartialEq)]
pub struct Dataset {
    inputs: Vec<Channel>,
    outputs: Vec<Channel>,
    experiments: Vec<Experiment>,
}

impl Dataset {
    /// Build a dataset; checks channel counts, unique names and values of every experiment.
    pub fn new(
        inputs: Vec<Channel>,
        outputs: Vec<Channel>,
        experiments: Vec<Experiment>,
    ) -> Result<Self> {
        check_unique(
            "channel",
            inputs.iter().chain(outputs.iter()).map(|c| c.name.as_str()),
        )?;
        let names_u: Vec<String> = inputs.iter().map(|c| c.name.clone()).collect();
        let names_y: Vec<String> = outputs.iter().map(|c| c.name.clone()).collect();
        for (e, exp) in experiments.iter().enumerate() {
            CoreError::check_len(
                "input channels of an experiment",
                exp.n_inputs(),
                inputs.len(),
            )?;
            CoreError::check_len(
                "output channels of an experiment",
                exp.n_outputs(),
                outputs.len(),
            )?;
            exp.check_values(e, &names_u, &names_y)?;
        }
        Ok(Self {
            inputs,
            outputs,
            experiments,
        })
    }

    /// Input channels.
    pub fn input_channels(&self) -> &[Channel] {
        &self.inputs
    }

    /// Output (measured) channels.
    pub fn output_channels(&self) -> &[Channel] {
        &self.outputs
    }

    /// Names of the input channels.
    pub fn input_names(&self) -> Vec<String> {
        self.inputs.iter().map(|c| c.name.clone()).collect()
    }

    /// Names of the output channels.
    pub fn output_names(&self) -> Vec<String> {
        self.outputs.iter().map(|c| c.name.clone()).collect()
    }

    /// The experiments.
    pub fn experiments(&self) -> &[Experiment] {
        &self.experiments
    }

    /// Total number of samples over all experiments.
    pub fn total_samples(&self) -> usize {
        self.experiments.iter().map(Experiment::len).sum()
    }

    /// Index of an input channel by name.
    pub fn input_index(&self, name: &str) -> Result<usize> {
        self.inputs
            .iter()
            .position(|c| c.name == name)
            .ok_or_else(|| CoreError::UnknownName {
                kind: "input",
                name: name.into(),
            })
    }

    /// Index of an output channel by name.
    pub fn output_index(&self, name: &str) -> Result<usize> {
        self.outputs
            .iter()
            .position(|c| c.name == name)
            .ok_or_else(|| CoreError::UnknownName {
                kind: "output",
                name: name.into(),
            })
    }

    /// Split every experiment at `fraction` of its samples: first part, second part.
    pub fn split(&self, fraction: f64) -> Result<(Self, Self)> {
        if !(fraction > 0.0 && fraction < 1.0) {
            return Err(CoreError::InvalidArgument {
                name: "fraction",
                value: fraction,
                reason: "must lie in (0, 1)",
            });
        }
        let mut first = Vec::new();
        let mut second = Vec::new();
        for exp in &self.experiments {
            let cut = ((exp.len() as f64) * fraction).round() as usize;
            first.push(exp.window(0, cut)?);
            second.push(exp.window(cut, exp.len())?);
        }
        Ok((self.with_experiments(first), self.with_experiments(second)))
    }

    /// Samples `start..end` of experiment `experiment` as a one-experiment dataset.
    pub fn window(&self, experiment: usize, start: usize, end: usize) -> Result<Self> {
        let exp = self.experiments.get(experiment).ok_or(CoreError::Range {
            start: experiment,
            end: experiment + 1,
            len: self.experiments.len(),
        })?;
        Ok(self.with_experiments(vec![exp.window(start, end)?]))
    }

    /// The same data with every experiment's inputs behaving between samples as `hold`
    /// says (see [`Experiment::with_intersample`]).
    pub fn with_intersample(mut self, hold: InterSample) -> Self {
        for e in &mut self.experiments {
            e.set_intersample(hold);
        }
        self
    }

    fn with_experiments(&self, experiments: Vec<Experiment>) -> Self {
        Self {
            inputs: self.inputs.clone(),
            outputs: self.outputs.clone(),
            experiments,
        }
    }
}

/// Error on the first name that appears twice.
pub fn check_unique<'a>(kind: &'static str, names: impl Iterator<Item = &'a str>) -> Result<()> {
    let mut seen = std::collections::HashSet::new();
    for n in names {
        if !seen.insert(n) {
            return Err(CoreError::DuplicateName {
                kind,
                name: n.to_string(),
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exp(n: usize) -> Experiment {
        let u = DMatrix::from_fn(1, n, |_, k| k as f64);
        let y = DMatrix::from_fn(2, n, |i, k| (i * 100 + k) as f64);
        Experiment::new(0.5, 0.1, u, y).unwrap()
    }

    #[test]
    fn column_access_and_time() {
        let e = exp(10);
        assert_eq!(e.output(3), &[3.0, 103.0]);
        assert_eq!(e.input(4), &[4.0]);
        assert!((e.time(3) - 0.8).abs() < 1e-15);
    }

    #[test]
    fn window_and_split_keep_time() {
        let d = Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("a"), Channel::new("b")],
            vec![exp(10)],
        )
        .unwrap();
        let (a, b) = d.split(0.3).unwrap();
        assert_eq!(a.experiments()[0].len(), 3);
        assert_eq!(b.experiments()[0].len(), 7);
        assert!((b.experiments()[0].t0() - 0.8).abs() < 1e-15);
        assert_eq!(b.experiments()[0].output(0), &[3.0, 103.0]);
        assert!(matches!(d.window(0, 5, 20), Err(CoreError::Range { .. })));
    }

    #[test]
    fn bad_time_is_typed() {
        let u = DMatrix::zeros(1, 4);
        let y = DMatrix::zeros(1, 4);
        assert!(matches!(
            Experiment::from_times(&[0.0, 0.1, 0.1, 0.3], u.clone(), y.clone()),
            Err(CoreError::NonIncreasingTime { sample: 2, .. })
        ));
        assert!(matches!(
            Experiment::from_times(&[0.0, 0.1, 0.25, 0.3], u.clone(), y.clone()),
            Err(CoreError::NonUniformTime { sample: 2, .. })
        ));
        assert!(Experiment::from_times(&[0.0, 0.1, 0.2, 0.3], u, y).is_ok());
    }

    /// A row missing from the middle of a long record is named where it is (the sample
    /// after the gap, step twice the median); judged against the mean step, which the gap
    /// shifts by 0.1 %, the first sample already failed.
    #[test]
    fn a_missing_row_is_named_where_it_is() {
        let t: Vec<f64> = (0..1000)
            .filter(|&k| k != 498)
            .map(|k| 4.0 * k as f64)
            .collect();
        assert_eq!(first_irregular_step(&t), Some((498, 8.0, 4.0)));
        let n = t.len();
        let (u, y) = (DMatrix::zeros(1, n), DMatrix::zeros(1, n));
        assert!(matches!(
            Experiment::from_times(&t, u, y),
            Err(CoreError::NonUniformTime { sample: 498, .. })
        ));
        let uniform: Vec<f64> = (0..1000).map(|k| 4.0 * k as f64).collect();
        assert_eq!(first_irregular_step(&uniform), None);
    }

    /// A jittered clock (EMPS's recorded times: steps 0.99998 / 1.00002 ms, stamps within
    /// 3e-5 of a step of the 1-ms grid) is uniform; the same clock with a missing row, or
    /// steps that alternate by 10 %, is not.
    #[test]
    fn jittered_stamps_are_uniform_a_missing_row_is_not() {
        let h = 1e-3;
        let jitter = |k: usize| 2.4e-8 * (((k * 7919) % 13) as f64 / 6.0 - 1.0);
        let t: Vec<f64> = (0..25_000).map(|k| k as f64 * h + jitter(k)).collect();
        assert!(t.windows(2).any(|w| (w[1] - w[0] - h).abs() > 1e-8));
        assert_eq!(first_irregular_step(&t), None);
        let (_, dt) = uniform_step(&t).unwrap();
        assert!((dt - h).abs() < 1e-11, "{dt}");
        let mut missing = t.clone();
        missing.remove(12_345);
        assert_eq!(first_irregular_step(&missing).map(|f| f.0), Some(12_345));
        let alternating: Vec<f64> = (0..100)
            .map(|k| k as f64 * h + if k % 2 == 1 { 0.1 * h } else { 0.0 })
            .collect();
        assert!(first_irregular_step(&alternating).is_some());
        // Steps each within the jitter share but drifting away from every grid (4e-4 of a
        // step longer in the first half, shorter in the second) are not a uniform clock.
        let mut walk = vec![0.0];
        for k in 1..10_000 {
            let sign = if k < 5_000 { 1.0 } else { -1.0 };
            walk.push(walk[k - 1] + h * (1.0 + sign * 4e-4));
        }
        assert!(first_irregular_step(&walk).is_some());
    }

    /// Issue 21: at t ≈ 1e9 a missing row is caught (the old `1e-12·|t|` tolerance was
    /// 1e-3 s there, a tenth of the step at 100 Hz, and at 1e12 it was a whole second);
    /// times too large to resolve the step are refused with a typed error.
    #[test]
    fn large_absolute_times_still_catch_a_missing_row() {
        let dt = 0.01;
        let (u, y) = (DMatrix::zeros(1, 6), DMatrix::zeros(1, 6));
        let base = 1.0e9;
        let mut t: Vec<f64> = (0..7).map(|k| base + k as f64 * dt).collect();
        assert!(Experiment::from_times(&t[..6], u.clone(), y.clone()).is_ok());
        t.remove(3);
        assert!(matches!(
            Experiment::from_times(&t, u.clone(), y.clone()),
            Err(CoreError::NonUniformTime { .. })
        ));
        // At 1e12 the step cannot be resolved; at 1e15 the times even coincide.
        for base in [1.0e12, 1.0e15] {
            let mut t: Vec<f64> = (0..7).map(|k| base + k as f64 * dt).collect();
            t.remove(3);
            let r = Experiment::from_times(&t, u.clone(), y.clone());
            assert!(
                matches!(
                    r,
                    Err(CoreError::InvalidArgument { name: "time", .. }
                        | CoreError::NonIncreasingTime { .. })
                ),
                "{r:?}"
            );
        }
        // Coarse steps at large t are fine: 1 s steps around 1e12 s.
        let t: Vec<f64> = (0..6).map(|k| 1.0e12 + k as f64).collect();
        assert!(Experiment::from_times(&t, u, y).is_ok());
    }

    #[test]
    fn nan_input_rejected_nan_output_allowed() {
        let mut u = DMatrix::zeros(1, 4);
        let mut y = DMatrix::zeros(1, 4);
        y[(0, 2)] = f64::NAN;
        assert!(Experiment::new(0.0, 0.1, u.clone(), y.clone()).is_ok());
        u[(0, 1)] = f64::NAN;
        let e = Experiment::new(0.0, 0.1, u, y);
        assert!(matches!(
            e,
            Err(CoreError::NonFiniteInput { sample: 1, .. })
        ));
    }

    #[test]
    fn duplicate_channel_names_rejected() {
        let d = Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("u"), Channel::new("b")],
            vec![exp(3)],
        );
        assert!(matches!(d, Err(CoreError::DuplicateName { .. })));
    }
}
