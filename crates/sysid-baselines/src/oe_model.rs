//! The fitted output-error model as a [`sysid_core::Model`]: free-run simulation from an
//! initial state (zero, given, or estimated from the first measured samples) and k-step
//! prediction by re-estimating the state from a window of past measurements, each with
//! the exact discretisation of the experiment's inputs between samples (held or linear).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use sysid_core::{Experiment, Horizon, LinearModel, Model, Prediction};

use crate::discrete::SampleStep;
use crate::error::{BaselineError, Result};
use crate::lsq::RANK_RTOL;
use crate::oe_sim::simulate_states;

/// Where a free-run simulation of an [`OeModel`] starts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum X0Policy {
    /// `x0 = 0`.
    Zero,
    /// A known initial state (`n` values), used for every experiment.
    Given(Vec<f64>),
    /// Least-squares estimate from the first [`OeModel::observer_window`] measured samples
    /// (the model and the inputs being known, the outputs are linear in `x0`). Those
    /// samples are reported as [`Prediction::initial_samples`], so metrics skip them.
    FromData,
}

/// A continuous-time linear model `ẋ = A x + B u`, `y = C x`, simulated exactly for the
/// inputs between samples that each experiment declares
/// ([`Experiment::intersample`](sysid_core::Experiment::intersample)): held (zero-order
/// hold, `x⁺ = Ad x + Bd u_k`) or linear (first-order hold,
/// `x⁺ = Ad x + Bd u_k + Γ₂ (u_{k+1} − u_k)`). The state at a sample reads the inputs up to
/// that sample only, so no input beyond a record's last sample is needed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OeModel {
    /// The model (`E` is carried along but unused).
    pub model: LinearModel,
    /// Initial state of free-run simulation.
    pub initial_state: X0Policy,
    /// Samples used to estimate a state from measurements ([`X0Policy::FromData`] and
    /// k-step prediction). At least `⌈n/p⌉`; more averages the noise.
    pub observer_window: usize,
}

impl OeModel {
    /// A model with [`X0Policy::FromData`] and an observer window of `10·n` samples
    /// (0.1 s of a 100 Hz record for n = 2: short against the record, long enough to
    /// average measurement noise by √20).
    pub fn new(model: LinearModel) -> Self {
        let n = model.n_states();
        Self {
            model,
            initial_state: X0Policy::FromData,
            observer_window: (10 * n).max(1),
        }
    }

    fn check(&self, experiment: &Experiment, needs_outputs: bool) -> Result<()> {
        if experiment.n_inputs() != self.model.n_inputs() {
            return Err(BaselineError::Dimension {
                what: "input channels of the experiment vs the model",
                found: experiment.n_inputs(),
                expected: self.model.n_inputs(),
            });
        }
        if needs_outputs && experiment.n_outputs() != self.model.n_outputs() {
            return Err(BaselineError::Dimension {
                what: "output channels of the experiment vs the model",
                found: experiment.n_outputs(),
                expected: self.model.n_outputs(),
            });
        }
        if needs_outputs && self.observer_window == 0 {
            return Err(BaselineError::InvalidConfig {
                field: "observer_window",
                value: 0.0,
                reason: "must be at least 1",
            });
        }
        Ok(())
    }

    /// The exact step over the experiment's sample period for its inputs between samples.
    fn discrete(&self, experiment: &Experiment) -> Result<SampleStep> {
        SampleStep::new(
            self.model.a(),
            self.model.b(),
            experiment.dt(),
            experiment.intersample(),
        )
    }

    /// Outputs `p × N` from state `x0` at sample `start` (columns before `start` are NaN).
    fn run_from(
        &self,
        step: &SampleStep,
        x0: &[f64],
        inputs: &DMatrix<f64>,
        start: usize,
    ) -> Result<DMatrix<f64>> {
        let len = inputs.ncols();
        let tail = inputs.columns(start, len - start).into_owned();
        let states =
            simulate_states(step, x0, &tail).ok_or_else(|| diverged(step, x0, &tail, start))?;
        let y = self.model.c() * states;
        let mut out = DMatrix::from_element(self.model.n_outputs(), len, f64::NAN);
        out.columns_mut(start, len - start).copy_from(&y);
        Ok(out)
    }

    /// Free-run simulation from `x0` over the experiment's inputs (any initial state).
    pub fn simulate_from(&self, experiment: &Experiment, x0: &[f64]) -> Result<Prediction> {
        self.check(experiment, false)?;
        if x0.len() != self.model.n_states() {
            return Err(BaselineError::Dimension {
                what: "initial state vs model states",
                found: x0.len(),
                expected: self.model.n_states(),
            });
        }
        let step = self.discrete(experiment)?;
        let outputs = self.run_from(&step, x0, experiment.inputs(), 0)?;
        Ok(Prediction {
            horizon: Horizon::FreeRun,
            outputs,
            initial_samples: 0,
        })
    }

    /// Least-squares state at sample `start` from the measurements of samples
    /// `start..start + window` (missing samples skipped).
    pub fn estimate_state(
        &self,
        experiment: &Experiment,
        start: usize,
        window: usize,
    ) -> Result<Vec<f64>> {
        self.check(experiment, true)?;
        let step = self.discrete(experiment)?;
        state_from_window(&self.model, &step, experiment, start, window)
    }
}

fn diverged(step: &SampleStep, x0: &[f64], inputs: &DMatrix<f64>, start: usize) -> BaselineError {
    // Re-run to locate the sample and state that left the bound.
    let mut x = DVector::from_column_slice(x0);
    for k in 1..inputs.ncols() {
        x = step.advance(&x, inputs, k - 1);
        if let Some((i, v)) = x
            .iter()
            .enumerate()
            .find(|(_, v)| !v.is_finite() || v.abs() > sysid_core::integrate::DEFAULT_BLOW_UP)
        {
            return BaselineError::Diverged {
                sample: start + k,
                channel: format!("state {i}"),
                value: *v,
            };
        }
    }
    BaselineError::Diverged {
        sample: start,
        channel: "state".into(),
        value: f64::NAN,
    }
}

/// Least-squares `x_start` from `y_k = C Ad^(k−start) x_start + forced response`,
/// `k = start..start+window`, over the measured samples. The forced response follows
/// `step` (inputs held or linear); it reads inputs `start..start+window` only.
pub(crate) fn state_from_window(
    model: &LinearModel,
    step: &SampleStep,
    experiment: &Experiment,
    start: usize,
    window: usize,
) -> Result<Vec<f64>> {
    let ad = &step.ad;
    let n = model.n_states();
    let p = model.n_outputs();
    let end = start + window;
    if window == 0 || end > experiment.len() {
        return Err(BaselineError::LagsExceedData {
            what: "observer window",
            experiment: 0,
            needed: end.max(1),
            available: experiment.len(),
        });
    }
    let c = model.c();
    let mut rows: Vec<(Vec<f64>, f64)> = Vec::with_capacity(window * p);
    let mut phi = DMatrix::<f64>::identity(n, n);
    let mut forced = DVector::<f64>::zeros(n);
    for k in start..end {
        let co = c * &phi;
        let yf = c * &forced;
        for (i, y) in experiment.output(k).iter().enumerate() {
            if !y.is_nan() {
                rows.push((co.row(i).iter().copied().collect(), y - yf[i]));
            }
        }
        // The state after the window's last sample is not needed (and for linear inputs
        // would read the input after the window).
        if k + 1 < end {
            phi = ad * phi;
            forced = step.advance(&forced, experiment.inputs(), k);
        }
    }
    let unobservable = BaselineError::Unobservable {
        sample: start,
        window,
    };
    if rows.len() < n {
        return Err(unobservable);
    }
    let o = DMatrix::from_fn(rows.len(), n, |r, j| rows[r].0[j]);
    let rhs = DVector::from_iterator(rows.len(), rows.iter().map(|r| r.1));
    let svd = o.svd(true, true);
    let smax = svd.singular_values.max();
    if smax.is_nan() || smax <= 0.0 || svd.singular_values.min() < RANK_RTOL * smax {
        return Err(unobservable);
    }
    let x = svd
        .solve(&rhs, RANK_RTOL * smax)
        .map_err(|_| BaselineError::Unobservable {
            sample: start,
            window,
        })?;
    Ok(x.iter().copied().collect())
}

impl Model for OeModel {
    type Error = BaselineError;

    fn output_names(&self) -> Vec<String> {
        self.model.output_names().to_vec()
    }

    /// Free-run simulation from the [`X0Policy`]; with [`X0Policy::FromData`] the first
    /// `observer_window` samples are consumed (`initial_samples`).
    fn simulate(&self, experiment: &Experiment) -> Result<Prediction> {
        let from_data = matches!(self.initial_state, X0Policy::FromData);
        self.check(experiment, from_data)?;
        let step = self.discrete(experiment)?;
        let (x0, skip) = match &self.initial_state {
            X0Policy::Zero => (vec![0.0; self.model.n_states()], 0),
            X0Policy::Given(x0) => {
                if x0.len() != self.model.n_states() {
                    return Err(BaselineError::Dimension {
                        what: "given initial state vs model states",
                        found: x0.len(),
                        expected: self.model.n_states(),
                    });
                }
                (x0.clone(), 0)
            }
            X0Policy::FromData => (
                state_from_window(&self.model, &step, experiment, 0, self.observer_window)?,
                self.observer_window,
            ),
        };
        let outputs = self.run_from(&step, &x0, experiment.inputs(), 0)?;
        Ok(Prediction {
            horizon: Horizon::FreeRun,
            outputs,
            initial_samples: skip,
        })
    }

    /// k-step prediction: the output at sample `t` is simulated from the state estimated
    /// (least squares, [`OeModel::observer_window`] samples) from the measurements ending
    /// at `t − k`, so only data up to `t − k` is used. The first `window + k − 1` samples
    /// are consumed and hold NaN. Errors: `k = 0`, too short an experiment, or a window
    /// whose measurements do not determine the state ([`BaselineError::Unobservable`],
    /// e.g. when too few outputs are measured or too many samples are missing).
    fn predict(&self, experiment: &Experiment, k: usize) -> Result<Prediction> {
        crate::error::check_horizon(k)?;
        self.check(experiment, true)?;
        let w = self.observer_window;
        let len = experiment.len();
        let skip = w + k - 1;
        if skip >= len {
            return Err(BaselineError::LagsExceedData {
                what: "observer window plus prediction horizon",
                experiment: 0,
                needed: skip + 1,
                available: len,
            });
        }
        let step = self.discrete(experiment)?;
        let c = self.model.c();
        let mut outputs = DMatrix::from_element(self.model.n_outputs(), len, f64::NAN);
        for t in skip..len {
            let start = t + 1 - k - w;
            let x = state_from_window(&self.model, &step, experiment, start, w)?;
            let mut x = DVector::from_column_slice(&x);
            // The inputs up to sample t are known (only the outputs are withheld); with
            // linear inputs the last step reads u_t.
            for j in start..t {
                x = step.advance(&x, experiment.inputs(), j);
            }
            if let Some((i, v)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(BaselineError::Diverged {
                    sample: t,
                    channel: format!("state {i}"),
                    value: *v,
                });
            }
            outputs.set_column(t, &(c * x));
        }
        Ok(Prediction {
            horizon: Horizon::Steps(k),
            outputs,
            initial_samples: skip,
        })
    }
}
