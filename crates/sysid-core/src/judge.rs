//! The one free-run judge: a continuous-time model ([`Dynamics`]) simulated over a
//! record's inputs from an estimated initial state and scored against the record's
//! measured channels. Every mmenn command that reports how well a state-space model
//! reproduces a record calls [`judge_free_run`] (and [`judge_k_step`] beside it), so the
//! same model on the same record gets the same numbers everywhere. The rule, stated in
//! every [`Judgement`] (`x0_rule`, `scored`):
//!
//! - **initial state** ([`InitialRule::Fit`]): the `x0` minimising the squared error of
//!   the judged channels over the first `window` samples of the record (every sample when
//!   the window is `None`; Levenberg–Marquardt, [`fit_initial_state`]), started from the
//!   minimum-norm solution of `C x = y(t0)` over the channels measured at `t0` and, when
//!   the model stores a state (e.g. a hybrid model's training `x̂(t0)`), also from that
//!   state; the start whose fit has the smaller squared error over the window wins (the
//!   stored state on a tie). [`InitialRule::Given`] uses a state as it is. A record with no
//!   judged channel starts from the stored state, else from zero.
//! - **scored window**: every sample of the record (the initial-state window is *not*
//!   skipped), missing measurements skipped; k-step prediction scores samples `k..N`.
//! - **metrics**: fit %, R², RMSE and error variance per judged channel
//!   ([`channel_metrics`]).
//!
//! The record's `intersample` is how the inputs are treated between samples, in the fit
//! and in the free run: set it to the model's before judging.

use std::collections::BTreeMap;

use nalgebra::{DMatrix, DVector};
use serde::Serialize;

use crate::dataset::Experiment;
use crate::dynamics::{Dynamics, Horizon};
use crate::error::{CoreError, Result};
use crate::initial::{InitialStateFit, fit_initial_state};
use crate::integrate::{Integrator, simulate_experiment};
use crate::linear::LinearModel;
use crate::metrics::{ChannelMetrics, channel_metrics};

/// Samples of the initial-state fit when no window is stated.
pub const DEFAULT_X0_WINDOW: usize = 200;

/// The channels a judgement scores: names and the rows mapping the state to them
/// (`p × n`), in the order of the record's output rows.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    /// Channel names.
    pub names: Vec<String>,
    /// `p × n` map from the state to the channels.
    pub matrix: DMatrix<f64>,
}

impl Observation {
    /// Channels `names` observed through `matrix` (one row per name). Errors when the
    /// counts differ.
    pub fn new(names: Vec<String>, matrix: DMatrix<f64>) -> Result<Self> {
        CoreError::check_len(
            "observed channel names vs rows of the observation matrix",
            names.len(),
            matrix.nrows(),
        )?;
        Ok(Self { names, matrix })
    }

    /// A linear model's outputs (`C` and its output names).
    pub fn outputs(lin: &LinearModel) -> Self {
        Self {
            names: lin.output_names().to_vec(),
            matrix: lin.c().clone(),
        }
    }

    /// The channels a record can be compared on: every state present by name, then every
    /// model output present by name that is not also a state name.
    pub fn present(lin: &LinearModel, has_column: impl Fn(&str) -> bool) -> Self {
        let n = lin.n_states();
        let mut names = Vec::new();
        let mut rows: Vec<Vec<f64>> = Vec::new();
        for (i, s) in lin.state_names().iter().enumerate() {
            if has_column(s) {
                names.push(s.clone());
                rows.push((0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect());
            }
        }
        for (i, o) in lin.output_names().iter().enumerate() {
            if has_column(o) && !lin.state_names().contains(o) {
                names.push(o.clone());
                rows.push(lin.c().row(i).iter().copied().collect());
            }
        }
        let matrix = DMatrix::from_fn(rows.len(), n, |r, c| rows[r][c]);
        Self { names, matrix }
    }
}

/// How the free-run judge gets its initial state.
#[derive(Debug, Clone, PartialEq)]
pub enum InitialRule {
    /// Fitted to the first `window` samples of the record (`None`: every sample).
    Fit {
        /// Samples from the start of the record used in the fit.
        window: Option<usize>,
    },
    /// This state.
    Given(Vec<f64>),
}

impl Default for InitialRule {
    /// Fitted to the first [`DEFAULT_X0_WINDOW`] samples.
    fn default() -> Self {
        InitialRule::Fit {
            window: Some(DEFAULT_X0_WINDOW),
        }
    }
}

/// How the judged model is simulated.
#[derive(Debug, Clone, PartialEq)]
pub struct JudgeOptions {
    /// Integrator of the free runs (and of the initial-state fit).
    pub integrator: Integrator,
    /// Bound on simulated states beyond which a free run counts as diverged.
    pub blow_up: f64,
    /// A state the model stores (e.g. a hybrid model's training `x̂(t0)`): a second start
    /// of the initial-state fit, and the initial state when the record has no judged
    /// channel.
    pub stored_state: Option<Vec<f64>>,
    /// Most Levenberg–Marquardt iterations of the initial-state fit.
    pub max_iterations: usize,
}

impl Default for JudgeOptions {
    /// RK4 with 4 sub-steps, blow-up at 1e12, no stored state, 30 iterations.
    fn default() -> Self {
        let fit = InitialStateFit::default();
        Self {
            integrator: fit.integrator,
            blow_up: fit.blow_up,
            stored_state: None,
            max_iterations: fit.max_iterations,
        }
    }
}

/// The samples a judgement scored.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScoredWindow {
    /// First scored sample (0-based).
    pub first: usize,
    /// One past the last scored sample.
    pub end: usize,
    /// Time of the first scored sample, s.
    pub t_first: f64,
    /// Time of the last scored sample, s.
    pub t_last: f64,
}

impl ScoredWindow {
    /// Samples `first..end` of `exp`.
    pub fn of(exp: &Experiment, first: usize, end: usize) -> Self {
        Self {
            first,
            end,
            t_first: exp.time(first),
            t_last: exp.time(end.saturating_sub(1)),
        }
    }
}

impl std::fmt::Display for ScoredWindow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "samples {}..{} (t = {} … {} s)",
            self.first, self.end, self.t_first, self.t_last
        )
    }
}

/// One model judged on one record.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Judgement {
    /// Free-run simulation, or k-step prediction.
    pub horizon: Horizon,
    /// Initial state of the free run.
    pub x0: Vec<f64>,
    /// The initial-state rule, in words.
    pub x0_rule: String,
    /// The samples scored.
    pub scored: ScoredWindow,
    /// How a k-step prediction was started (absent for free run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_step_rule: Option<String>,
    /// Metrics per judged channel.
    pub channels: BTreeMap<String, ChannelMetrics>,
    /// Simulated states (`n × N`; for k-step, the free-run states its starts use).
    #[serde(skip)]
    pub states: DMatrix<f64>,
    /// Predicted channels (`p × N`, NaN where a k-step prediction has no value).
    #[serde(skip)]
    pub outputs: DMatrix<f64>,
}

impl Judgement {
    /// Fit % of a channel (NaN when it was not judged).
    pub fn fit_percent(&self, channel: &str) -> f64 {
        self.channels
            .get(channel)
            .map_or(f64::NAN, |m| m.fit_percent)
    }
}

/// Metrics of `predicted` (`p × N`) against `exp`'s output rows (the channels `names`,
/// in order) over samples `first..N`, missing measurements skipped: the scoring of
/// every judgement.
pub fn score(
    names: &[String],
    exp: &Experiment,
    predicted: &DMatrix<f64>,
    first: usize,
) -> Result<BTreeMap<String, ChannelMetrics>> {
    score_rows(names, exp.outputs(), predicted, first)
}

/// [`score`] on measured rows given as a matrix (`p × N`, NaN = missing), e.g. several
/// records' scored samples side by side.
pub fn score_rows(
    names: &[String],
    measured: &DMatrix<f64>,
    predicted: &DMatrix<f64>,
    first: usize,
) -> Result<BTreeMap<String, ChannelMetrics>> {
    if predicted.nrows() != names.len()
        || measured.nrows() != names.len()
        || predicted.ncols() != measured.ncols()
    {
        return Err(CoreError::Shape {
            matrix: "predicted channels",
            rows: predicted.nrows(),
            cols: predicted.ncols(),
            expected_rows: names.len(),
            expected_cols: measured.ncols(),
        });
    }
    let mut out = BTreeMap::new();
    for (i, name) in names.iter().enumerate() {
        let y: Vec<f64> = measured.row(i).iter().skip(first).copied().collect();
        let sim: Vec<f64> = predicted.row(i).iter().skip(first).copied().collect();
        out.insert(name.clone(), channel_metrics(&y, &sim)?);
    }
    Ok(out)
}

fn check_rows<D: Dynamics + ?Sized>(model: &D, obs: &Observation, exp: &Experiment) -> Result<()> {
    if obs.names.len() != exp.n_outputs() || obs.matrix.nrows() != exp.n_outputs() {
        return Err(CoreError::Length {
            what: "judged channels vs the record's output rows",
            found: obs.names.len(),
            expected: exp.n_outputs(),
        });
    }
    if obs.matrix.ncols() != model.n_states() {
        return Err(CoreError::Shape {
            matrix: "observation",
            rows: obs.matrix.nrows(),
            cols: obs.matrix.ncols(),
            expected_rows: exp.n_outputs(),
            expected_cols: model.n_states(),
        });
    }
    if exp.is_empty() {
        return Err(CoreError::TooFewSamples {
            what: "judged record",
            found: 0,
            needed: 1,
        });
    }
    Ok(())
}

fn check_state(what: &'static str, x: &[f64], n: usize) -> Result<()> {
    if x.len() != n {
        return Err(CoreError::Length {
            what,
            found: x.len(),
            expected: n,
        });
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        return Err(CoreError::InvalidArgument {
            name: what,
            value: i as f64,
            reason: "entry at this index is not finite",
        });
    }
    Ok(())
}

/// The minimum-norm solution of `C x = y(t0)` over the channels measured at `t0` (zero
/// when none is, or when the solve fails).
fn minimum_norm_start(obs: &Observation, exp: &Experiment, n: usize) -> Vec<f64> {
    let y = exp.output(0);
    let rows: Vec<usize> = (0..obs.names.len()).filter(|&i| !y[i].is_nan()).collect();
    if rows.is_empty() {
        return vec![0.0; n];
    }
    let c = DMatrix::from_fn(rows.len(), n, |r, j| obs.matrix[(rows[r], j)]);
    let rhs = DVector::from_iterator(rows.len(), rows.iter().map(|&i| y[i]));
    match c.svd(true, true).solve(&rhs, 1e-12) {
        Ok(x) if x.iter().all(|v| v.is_finite()) => x.iter().copied().collect(),
        _ => vec![0.0; n],
    }
}

/// Squared error of the judged channels of the free response from `x0` over the fit's
/// window (infinite when it is not finite).
fn window_cost<D: Dynamics + ?Sized>(
    model: &D,
    obs: &Observation,
    exp: &Experiment,
    x0: &[f64],
    fit: &InitialStateFit,
) -> Result<f64> {
    let len = fit.window.min(exp.len());
    let xs = simulate_experiment(model, x0, exp, 0..len, &fit.integrator, fit.blow_up)?;
    let y = &obs.matrix * xs;
    let mut cost = 0.0;
    for k in 0..len {
        for (i, m) in exp.output(k).iter().enumerate() {
            if !m.is_nan() {
                cost += (m - y[(i, k)]).powi(2);
            }
        }
    }
    Ok(if cost.is_finite() {
        cost
    } else {
        f64::INFINITY
    })
}

/// The initial state by `rule` and the rule in words.
fn initial_state<D: Dynamics + ?Sized>(
    model: &D,
    exp: &Experiment,
    obs: &Observation,
    rule: &InitialRule,
    opts: &JudgeOptions,
) -> Result<(Vec<f64>, String)> {
    let n = model.n_states();
    if let Some(x) = &opts.stored_state {
        check_state("stored initial state", x, n)?;
    }
    let window = match rule {
        InitialRule::Given(x) => {
            check_state("given initial state", x, n)?;
            return Ok((x.clone(), "given".to_string()));
        }
        InitialRule::Fit { window: Some(0) } => {
            return Err(CoreError::InvalidArgument {
                name: "initial-state window",
                value: 0.0,
                reason: "must be at least 1 sample (None fits over the whole record)",
            });
        }
        InitialRule::Fit { window } => window.unwrap_or(exp.len()).min(exp.len()).max(1),
    };
    if obs.names.is_empty() {
        return Ok(match &opts.stored_state {
            Some(x) => (
                x.clone(),
                "the state stored in the model: the record has no channel to fit it to".into(),
            ),
            None => (
                vec![0.0; n],
                "zero: the record has no channel to fit it to".into(),
            ),
        });
    }
    let fit = InitialStateFit {
        window,
        max_iterations: opts.max_iterations,
        integrator: opts.integrator,
        blow_up: opts.blow_up,
    };
    let mut starts = Vec::new();
    if let Some(x) = &opts.stored_state {
        starts.push((x.clone(), "the state stored in the model"));
    }
    starts.push((
        minimum_norm_start(obs, exp, n),
        "the minimum-norm solution of C x = y(t0)",
    ));
    let mut best: Option<(Vec<f64>, f64, &str)> = None;
    let mut first_error = None;
    for (guess, label) in starts {
        match fit_initial_state(model, &obs.matrix, exp, &guess, &fit)
            .and_then(|x| window_cost(model, obs, exp, &x, &fit).map(|c| (x, c)))
        {
            Ok((x, cost)) if best.as_ref().is_none_or(|b| cost < b.1) => {
                best = Some((x, cost, label));
            }
            Ok(_) => {}
            Err(e) => {
                first_error.get_or_insert(e);
            }
        }
    }
    let (x, start) = match (best, first_error) {
        (Some((x, _, label)), _) => (x, label),
        (None, Some(e)) => return Err(e),
        // Unreachable: the minimum-norm start is always tried.
        (None, None) => {
            return Err(CoreError::InvalidArgument {
                name: "starting points",
                value: 0.0,
                reason: "no starting point for the initial-state fit",
            });
        }
    };
    Ok((
        x,
        format!(
            "least-squares fit of the free response to the first {window} of {} samples ({}), started from {start}",
            exp.len(),
            obs.names.join(", ")
        ),
    ))
}

/// The one free-run judge (rule in the module documentation): initial state by `rule`,
/// free run over the whole record, every sample scored. `exp`'s output rows are the
/// channels of `obs`, in order; its `intersample` is how the inputs are held.
///
/// Errors: channel rows that do not match the record or the model, an empty record, a
/// given or stored state of the wrong length or not finite, a fit whose every start
/// diverges, a free run that diverges, a channel with fewer than 2 measured samples.
pub fn judge_free_run<D: Dynamics + ?Sized>(
    model: &D,
    exp: &Experiment,
    obs: &Observation,
    rule: &InitialRule,
    opts: &JudgeOptions,
) -> Result<Judgement> {
    check_rows(model, obs, exp)?;
    let (x0, x0_rule) = initial_state(model, exp, obs, rule, opts)?;
    let states = simulate_experiment(
        model,
        &x0,
        exp,
        0..exp.len(),
        &opts.integrator,
        opts.blow_up,
    )?;
    let outputs = &obs.matrix * &states;
    let channels = if obs.names.is_empty() {
        BTreeMap::new()
    } else {
        score(&obs.names, exp, &outputs, 0)?
    };
    Ok(Judgement {
        horizon: Horizon::FreeRun,
        x0,
        x0_rule,
        scored: ScoredWindow::of(exp, 0, exp.len()),
        k_step_rule: None,
        channels,
        states,
        outputs,
    })
}

/// k-step-ahead prediction beside a free run (`free`, from [`judge_free_run`] on the same
/// record and model): the prediction of sample `j` starts at sample `j − k` from the
/// free-run state there with every state a judged channel measures directly (a row
/// selecting that one state with weight 1) replaced by its measurement, and simulates `k`
/// samples. Samples `k..N` are scored.
///
/// Errors: as [`judge_free_run`], `k` zero or not shorter than the record, `free` not of
/// this record's length or the model's states.
pub fn judge_k_step<D: Dynamics + ?Sized>(
    model: &D,
    exp: &Experiment,
    obs: &Observation,
    k: usize,
    free: &Judgement,
    opts: &JudgeOptions,
) -> Result<Judgement> {
    check_rows(model, obs, exp)?;
    let len = exp.len();
    if k == 0 || k >= len {
        return Err(CoreError::InvalidArgument {
            name: "horizon",
            value: k as f64,
            reason: "must be at least 1 and shorter than the record",
        });
    }
    let n = model.n_states();
    if free.states.nrows() != n || free.states.ncols() != len {
        return Err(CoreError::Shape {
            matrix: "free-run states",
            rows: free.states.nrows(),
            cols: free.states.ncols(),
            expected_rows: n,
            expected_cols: len,
        });
    }
    // Channels that measure one state directly: (row, state).
    let direct: Vec<(usize, usize)> = (0..obs.names.len())
        .filter_map(|i| {
            let row = obs.matrix.row(i);
            let nz: Vec<usize> = (0..n).filter(|&j| row[j] != 0.0).collect();
            // Exactly 1: a channel that *is* that state, not a scaled copy of it.
            (nz.len() == 1 && (row[nz[0]] - 1.0).abs() <= 0.0).then(|| (i, nz[0]))
        })
        .collect();
    let mut outputs = DMatrix::from_element(obs.names.len(), len, f64::NAN);
    for j in k..len {
        let start = j - k;
        let mut x: Vec<f64> = free.states.column(start).iter().copied().collect();
        let y = exp.output(start);
        for &(row, state) in &direct {
            if !y[row].is_nan() {
                x[state] = y[row];
            }
        }
        let xs = simulate_experiment(
            model,
            &x,
            exp,
            start..start + k + 1,
            &opts.integrator,
            opts.blow_up,
        )?;
        let yk = &obs.matrix * xs.column(k);
        outputs.column_mut(j).copy_from(&yk);
    }
    let names: Vec<String> = direct.iter().map(|&(r, _)| obs.names[r].clone()).collect();
    Ok(Judgement {
        horizon: Horizon::Steps(k),
        x0: free.x0.clone(),
        x0_rule: free.x0_rule.clone(),
        scored: ScoredWindow::of(exp, k, len),
        k_step_rule: Some(format!(
            "each sample predicted {k} samples ahead from the free-run state {k} samples earlier, with the directly measured states ({}) reset to their measurements there",
            if names.is_empty() {
                "none".to_string()
            } else {
                names.join(", ")
            }
        )),
        channels: score(&obs.names, exp, &outputs, k)?,
        states: free.states.clone(),
        outputs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::simulate;

    /// ẍ = −4x − 0.2ẋ + u, position measured.
    fn oscillator() -> LinearModel {
        LinearModel::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.2]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::zeros(2, 0),
        )
        .unwrap()
    }

    fn record(model: &LinearModel, x0: &[f64], len: usize) -> Experiment {
        let u = DMatrix::from_fn(1, len, |_, k| (0.05 * k as f64).sin());
        let xs = simulate(
            model,
            x0,
            0.0,
            0.01,
            &u,
            &Integrator::Rk4 { substeps: 4 },
            1e12,
        )
        .unwrap();
        Experiment::new(0.0, 0.01, u, model.c() * xs).unwrap()
    }

    #[test]
    fn the_true_model_is_judged_perfect_from_an_estimated_state() {
        let model = oscillator();
        let exp = record(&model, &[0.7, -1.3], 400);
        let obs = Observation::outputs(&model);
        let j = judge_free_run(
            &model,
            &exp,
            &obs,
            &InitialRule::default(),
            &JudgeOptions::default(),
        )
        .unwrap();
        assert!((j.x0[0] - 0.7).abs() < 1e-7 && (j.x0[1] + 1.3).abs() < 1e-6);
        let m = j.channels["y1"];
        assert!(m.fit_percent > 100.0 - 1e-5, "{m:?}");
        assert_eq!(m.samples, 400);
        assert_eq!((j.scored.first, j.scored.end), (0, 400));
        assert!(j.x0_rule.contains("first 200 of 400"));
    }

    /// A window of 0 samples is an error naming the window, not silently one sample.
    #[test]
    fn an_empty_initial_state_window_is_an_error() {
        let model = oscillator();
        let exp = record(&model, &[0.7, -1.3], 50);
        let obs = Observation::outputs(&model);
        let err = judge_free_run(
            &model,
            &exp,
            &obs,
            &InitialRule::Fit { window: Some(0) },
            &JudgeOptions::default(),
        )
        .unwrap_err();
        assert!(
            matches!(
                err,
                CoreError::InvalidArgument {
                    name: "initial-state window",
                    ..
                }
            ),
            "{err}"
        );
        // A window longer than the record fits over the whole record.
        let j = judge_free_run(
            &model,
            &exp,
            &obs,
            &InitialRule::Fit { window: Some(500) },
            &JudgeOptions::default(),
        )
        .unwrap();
        assert!(j.x0_rule.contains("50"), "{}", j.x0_rule);
    }

    #[test]
    fn metrics_are_those_of_the_free_run_from_the_state_it_reports() {
        // A wrong model (stiffer spring): the judge's metrics must equal channel_metrics
        // of a separate simulation from the x0 it reports, on every sample.
        let truth = oscillator();
        let exp = record(&truth, &[0.3, 0.5], 300);
        let wrong = truth
            .with_ab(
                DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -5.0, -0.2]),
                truth.b().clone(),
            )
            .unwrap();
        let obs = Observation::outputs(&wrong);
        let opts = JudgeOptions::default();
        let j = judge_free_run(
            &wrong,
            &exp,
            &obs,
            &InitialRule::Fit { window: None },
            &opts,
        )
        .unwrap();
        let xs = simulate(
            &wrong,
            &j.x0,
            0.0,
            0.01,
            exp.inputs(),
            &opts.integrator,
            1e12,
        )
        .unwrap();
        let y = wrong.c() * xs;
        let direct = channel_metrics(
            &exp.outputs().row(0).iter().copied().collect::<Vec<_>>(),
            &y.row(0).iter().copied().collect::<Vec<_>>(),
        )
        .unwrap();
        assert_eq!(j.channels["y1"], direct);
        assert!(direct.fit_percent < 99.0);
    }

    #[test]
    fn a_given_state_is_used_as_is_and_checked() {
        let model = oscillator();
        let exp = record(&model, &[0.7, -1.3], 100);
        let obs = Observation::outputs(&model);
        let opts = JudgeOptions::default();
        let j = judge_free_run(
            &model,
            &exp,
            &obs,
            &InitialRule::Given(vec![0.7, -1.3]),
            &opts,
        )
        .unwrap();
        assert_eq!(j.x0, vec![0.7, -1.3]);
        assert_eq!(j.x0_rule, "given");
        assert!(judge_free_run(&model, &exp, &obs, &InitialRule::Given(vec![0.0]), &opts).is_err());
        assert!(
            judge_free_run(
                &model,
                &exp,
                &obs,
                &InitialRule::Given(vec![f64::NAN, 0.0]),
                &opts
            )
            .is_err()
        );
        let bad_obs = Observation::new(vec!["a".into(), "b".into()], DMatrix::zeros(2, 2)).unwrap();
        assert!(judge_free_run(&model, &exp, &bad_obs, &InitialRule::default(), &opts).is_err());
        assert!(Observation::new(vec!["a".into()], DMatrix::zeros(2, 2)).is_err());
    }

    #[test]
    fn k_step_of_the_true_model_with_the_full_state_measured_is_exact() {
        // Both states measured: every k-step start is the true state, so the prediction
        // equals the measurement up to integration error.
        let model = oscillator();
        let u = DMatrix::from_fn(1, 200, |_, k| (0.05 * k as f64).sin());
        let xs = simulate(
            &model,
            &[0.7, -1.3],
            0.0,
            0.01,
            &u,
            &Integrator::Rk4 { substeps: 4 },
            1e12,
        )
        .unwrap();
        let exp = Experiment::new(0.0, 0.01, u, xs.clone()).unwrap();
        let obs = Observation::present(&model, |n| n == "x1" || n == "x2");
        assert_eq!(obs.names, vec!["x1", "x2"]);
        let opts = JudgeOptions::default();
        let free = judge_free_run(
            &model,
            &exp,
            &obs,
            &InitialRule::Given(vec![0.0, 0.0]),
            &opts,
        )
        .unwrap();
        assert!(free.fit_percent("x1") < 90.0);
        let k = judge_k_step(&model, &exp, &obs, 5, &free, &opts).unwrap();
        assert_eq!(k.horizon, Horizon::Steps(5));
        assert_eq!((k.scored.first, k.scored.end), (5, 200));
        assert_eq!(k.channels["x1"].samples, 195);
        assert!(k.fit_percent("x1") > 100.0 - 1e-6, "{:?}", k.channels);
        assert!(judge_k_step(&model, &exp, &obs, 0, &free, &opts).is_err());
        assert!(judge_k_step(&model, &exp, &obs, 200, &free, &opts).is_err());
    }

    #[test]
    fn a_record_without_channels_starts_from_the_stored_state() {
        let model = oscillator();
        let u = DMatrix::from_fn(1, 50, |_, k| k as f64 * 0.01);
        let exp = Experiment::new(0.0, 0.01, u, DMatrix::zeros(0, 50)).unwrap();
        let obs = Observation::present(&model, |_| false);
        let opts = JudgeOptions {
            stored_state: Some(vec![1.0, 2.0]),
            ..JudgeOptions::default()
        };
        let j = judge_free_run(&model, &exp, &obs, &InitialRule::default(), &opts).unwrap();
        assert_eq!(j.x0, vec![1.0, 2.0]);
        assert!(j.channels.is_empty());
        assert_eq!(j.states.ncols(), 50);
    }
}
