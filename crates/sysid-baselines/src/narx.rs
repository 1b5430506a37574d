//! NARX training (thesis §3.2): series-parallel (one-step targets from measured lags)
//! Levenberg–Marquardt training of an [`nn::Mlp`] over every experiment, several
//! initialisations or the hidden-layer sizing sweep, and the choice among them.

use nalgebra::DMatrix;
use nn::{LmConfig, Mlp, StopReason, SweepConfig, SweepRow, derive_seed, sizing_sweep, train_lm};
use serde::{Deserialize, Serialize};
use sysid_core::{Dataset, Model};

use crate::error::{BaselineError, Result, check_config};
use crate::narx_model::NarxModel;
use crate::poly_narx::{Focus, Refinement};
use crate::projection::RegressorProjection;
use crate::regressors::{NarxOrders, training_rows};

/// How the network is sized.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NetworkChoice {
    /// One `tanh` hidden layer of `units` units, trained from `restarts` initialisations
    /// (seeds `nn::derive_seed(seed, units, r)`), one chosen by [`RestartSelection`].
    Hidden {
        /// Hidden units (≥ 1).
        units: usize,
        /// Initialisations (≥ 1).
        restarts: usize,
    },
    /// The sizing sweep of `nn` (thesis §3.1) on the regressors: the last `test_fraction`
    /// of each experiment's rows is its test set, and `nn`'s [`nn::SizingRule`] picks
    /// the network by one-step test MSE.
    Sweep {
        /// Sweep settings (sizes, initialisations, seed, training).
        sweep: SweepConfig,
        /// Fraction of rows held out for the test MSE, in (0, 1).
        test_fraction: f64,
    },
}

/// Preprocessing of the regressor before the network.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Projection {
    /// The network reads the raw regressor (scaled by its own input scaler).
    None,
    /// The network reads the principal components of the regressor whose spread is at
    /// least `rtol` of the largest (see [`RegressorProjection`]).
    Pca {
        /// Relative spread threshold, in [0, 1).
        rtol: f64,
    },
}

/// Which of several trained networks becomes the model.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RestartSelection {
    /// Lowest free-run simulation error on the training data (mean over outputs of
    /// `SSE/SST`); a run that diverges is never chosen unless all do, then as for
    /// `OneStep`. This judges the networks the way they will be used.
    #[default]
    FreeRunTraining,
    /// Lowest one-step validation MSE (training MSE without a validation split).
    OneStep,
}

/// Settings of [`fit_narx`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NarxConfig {
    /// Tapped delays. Default `na = nb = 2`, `nk = 1`.
    pub orders: NarxOrders,
    /// Network size. Default 3 hidden units, 5 restarts.
    pub network: NetworkChoice,
    /// Levenberg–Marquardt settings for [`NetworkChoice::Hidden`]. Default: `nn`'s
    /// defaults with errors measured on normalised outputs (so channels of different
    /// units weigh the same).
    pub lm: LmConfig,
    /// Base seed of the initialisations. Default 0.
    pub seed: u64,
    /// Choice among restarts. Default [`RestartSelection::FreeRunTraining`].
    pub selection: RestartSelection,
    /// Regressor preprocessing. Default PCA with `rtol = 1e-3`.
    pub projection: Projection,
    /// A simulated output more than this many half-ranges of the training data away from
    /// the data's centre counts as diverged. Default 100.
    pub divergence_factor: f64,
    /// What the chosen network's weights finally minimise. Default
    /// [`Focus::Prediction`] (the one-step training alone). [`Focus::Simulation`] refines
    /// them by Levenberg–Marquardt on the free-run error over every training record, with
    /// exact sensitivities of the recursion (docs/decisions/narx-simulation-focus.md); a
    /// chosen network whose free run leaves the divergence limits cannot start it, and the
    /// fit fails with the divergence.
    pub focus: Focus,
}

impl Default for NarxConfig {
    fn default() -> Self {
        Self {
            orders: NarxOrders::default(),
            network: NetworkChoice::Hidden {
                units: 3,
                restarts: 5,
            },
            lm: LmConfig {
                error_space: nn::ErrorSpace::Normalised,
                ..LmConfig::default()
            },
            seed: 0,
            selection: RestartSelection::FreeRunTraining,
            projection: Projection::Pca { rtol: 1e-3 },
            divergence_factor: 100.0,
            focus: Focus::Prediction,
        }
    }
}

impl NarxConfig {
    /// Check every field.
    pub fn validate(&self) -> Result<()> {
        self.orders.validate()?;
        check_config(
            "divergence_factor",
            self.divergence_factor,
            "must be finite and > 1",
            self.divergence_factor.is_finite() && self.divergence_factor > 1.0,
        )?;
        self.focus.validate()?;
        match &self.network {
            NetworkChoice::Hidden { units, restarts } => {
                check_config("network.units", *units as f64, "must be ≥ 1", *units >= 1)?;
                check_config(
                    "network.restarts",
                    *restarts as f64,
                    "must be ≥ 1",
                    *restarts >= 1,
                )?;
                self.lm.validate()?;
            }
            NetworkChoice::Sweep {
                sweep,
                test_fraction,
            } => {
                check_config(
                    "network.test_fraction",
                    *test_fraction,
                    "must be in (0, 1)",
                    *test_fraction > 0.0 && *test_fraction < 1.0,
                )?;
                sweep.validate()?;
            }
        }
        Ok(())
    }
}

/// One trained network of a fit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RestartRecord {
    /// Hidden units.
    pub hidden: usize,
    /// Seed of its initial weights.
    pub seed: u64,
    /// One-step training MSE (in the training's error space).
    pub train_mse: f64,
    /// One-step validation MSE, if a validation split was used.
    pub val_mse: Option<f64>,
    /// One-step test MSE (sweep only).
    pub test_mse: Option<f64>,
    /// LM epochs.
    pub epochs: usize,
    /// Why training stopped.
    pub termination: StopReason,
    /// Free-run score on the training data (mean `SSE/SST` over outputs); `None` if not
    /// computed or the run diverged.
    pub free_run_score: Option<f64>,
}

/// Result of [`fit_narx`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NarxFit {
    /// The chosen model.
    pub model: NarxModel,
    /// Every trained network.
    pub restarts: Vec<RestartRecord>,
    /// Index of the chosen one in `restarts`.
    pub chosen: usize,
    /// Training rows used.
    pub rows: usize,
    /// Rows skipped because they touch a missing sample.
    pub skipped_rows: usize,
    /// The simulation-error refinement of the chosen network, when
    /// [`NarxConfig::focus`] asked for it.
    #[serde(default)]
    pub refinement: Option<Refinement>,
}

/// Train a NARX model on the data, series-parallel: each row's regressor holds measured
/// past outputs and inputs, its target the measured output.
///
/// Errors: invalid config, an experiment no longer than the lag window, no row free of
/// missing samples, network errors (shapes, non-finite data).
pub fn fit_narx(data: &Dataset, config: &NarxConfig) -> Result<NarxFit> {
    config.validate()?;
    let rows = training_rows(data, &config.orders)?;
    let limits = divergence_limits(data, config.divergence_factor)?;
    let projection = match config.projection {
        Projection::None => None,
        Projection::Pca { rtol } => {
            let (p, m) = (data.output_channels().len(), data.input_channels().len());
            let blocks: Vec<usize> = std::iter::repeat_n(config.orders.na, p)
                .chain(std::iter::repeat_n(config.orders.nb, m))
                .filter(|&b| b > 0)
                .collect();
            Some(RegressorProjection::fit(&rows.inputs, &blocks, rtol)?)
        }
    };
    let net_inputs = match &projection {
        Some(proj) => proj.apply_all(&rows.inputs),
        None => rows.inputs.clone(),
    };
    let assemble = |net: Mlp| {
        NarxModel::new(
            net,
            projection.clone(),
            config.orders,
            data.input_names(),
            data.output_names(),
            limits.clone(),
        )
    };
    let mut candidates: Vec<(NarxModel, RestartRecord)> = Vec::new();
    match &config.network {
        NetworkChoice::Hidden { units, restarts } => {
            for r in 0..*restarts {
                let seed = derive_seed(config.seed, *units, r);
                let mut net = Mlp::for_data(&net_inputs, &rows.targets, &[*units], seed)?;
                let report = train_lm(&mut net, &net_inputs, &rows.targets, &config.lm, None)?;
                let record = RestartRecord {
                    hidden: *units,
                    seed,
                    train_mse: report.train_mse,
                    val_mse: report.val_mse,
                    test_mse: None,
                    epochs: report.epochs,
                    termination: report.termination,
                    free_run_score: None,
                };
                candidates.push((assemble(net)?, record));
            }
        }
        NetworkChoice::Sweep {
            sweep,
            test_fraction,
        } => {
            let (train, test) = split_tail(
                &net_inputs,
                &rows.targets,
                &rows.per_experiment,
                *test_fraction,
            )?;
            let result = sizing_sweep(&train.0, &train.1, &test.0, &test.1, sweep, None)?;
            let chosen = result.chosen;
            let row: &SweepRow = result.chosen_row();
            let record = RestartRecord {
                hidden: row.hidden,
                seed: row.seed,
                train_mse: row.train_mse,
                val_mse: row.val_mse,
                test_mse: Some(row.test_mse),
                epochs: row.epochs,
                termination: row.termination,
                free_run_score: None,
            };
            let mut model = assemble(result.networks[chosen].clone())?;
            let mut record = record;
            record.free_run_score = free_run_score(&model, data)?;
            let refinement = refine_for(&config.focus, &mut model, data)?;
            return Ok(NarxFit {
                model,
                restarts: vec![record],
                chosen: 0,
                rows: rows.inputs.ncols(),
                skipped_rows: rows.skipped,
                refinement,
            });
        }
    }
    if config.selection == RestartSelection::FreeRunTraining {
        for (model, record) in candidates.iter_mut() {
            record.free_run_score = free_run_score(model, data)?;
        }
    }
    let one_step = |r: &RestartRecord| r.val_mse.unwrap_or(r.train_mse);
    let by = |key: &dyn Fn(&RestartRecord) -> Option<f64>| {
        candidates
            .iter()
            .enumerate()
            .filter_map(|(i, (_, r))| key(r).filter(|v| v.is_finite()).map(|v| (i, v)))
            .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)))
            .map(|(i, _)| i)
    };
    let chosen = match config.selection {
        RestartSelection::FreeRunTraining => {
            by(&|r| r.free_run_score).or_else(|| by(&|r| Some(one_step(r))))
        }
        RestartSelection::OneStep => by(&|r| Some(one_step(r))),
    }
    .ok_or(BaselineError::TooFewRows {
        what: "trained NARX networks with a finite error",
        found: 0,
        needed: 1,
    })?;
    let restarts: Vec<RestartRecord> = candidates.iter().map(|c| c.1.clone()).collect();
    let mut model = candidates.swap_remove(chosen).0;
    let refinement = refine_for(&config.focus, &mut model, data)?;
    Ok(NarxFit {
        model,
        restarts,
        chosen,
        rows: rows.inputs.ncols(),
        skipped_rows: rows.skipped,
        refinement,
    })
}

/// Refine a network NARX already in hand by its free-run error over `data`: the step
/// [`Focus::Simulation`] adds to [`fit_narx`] after the restart is chosen (so
/// `fit_narx` with that focus equals `fit_narx` with [`Focus::Prediction`] followed by
/// this), at most `max_iterations` Jacobians. The model keeps its architecture,
/// projection, orders and divergence limits; only the weights move.
///
/// Errors: `max_iterations` of 0, channel counts differing from the model's, records no
/// longer than the delay window, a start whose free run leaves the divergence limits
/// (the sample is named).
pub fn refine_narx(
    model: &mut NarxModel,
    data: &Dataset,
    max_iterations: usize,
) -> Result<Refinement> {
    check_config(
        "max_iterations",
        max_iterations as f64,
        "must be ≥ 1",
        max_iterations >= 1,
    )?;
    crate::narx_refine::refine(model, data, max_iterations)
}

/// The simulation-error refinement `focus` asks for, if any.
fn refine_for(focus: &Focus, model: &mut NarxModel, data: &Dataset) -> Result<Option<Refinement>> {
    match *focus {
        Focus::Prediction => Ok(None),
        Focus::Simulation { max_iterations } => {
            crate::narx_refine::refine(model, data, max_iterations).map(Some)
        }
    }
}

/// Per output, `centre ± factor·half-range` of the measured data.
pub(crate) fn divergence_limits(data: &Dataset, factor: f64) -> Result<Vec<(f64, f64)>> {
    let p = data.output_channels().len();
    let mut lo = vec![f64::INFINITY; p];
    let mut hi = vec![f64::NEG_INFINITY; p];
    for exp in data.experiments() {
        for k in 0..exp.len() {
            for (i, v) in exp.output(k).iter().enumerate() {
                if !v.is_nan() {
                    lo[i] = lo[i].min(*v);
                    hi[i] = hi[i].max(*v);
                }
            }
        }
    }
    (0..p)
        .map(|i| {
            if !(lo[i].is_finite() && hi[i].is_finite()) {
                return Err(BaselineError::TooFewRows {
                    what: "measured samples of an output channel",
                    found: 0,
                    needed: 1,
                });
            }
            let centre = 0.5 * (lo[i] + hi[i]);
            // A constant channel still gets a band of its own magnitude (or 1).
            let half = (0.5 * (hi[i] - lo[i])).max(1e-12 * centre.abs().max(1.0));
            Ok((centre - factor * half, centre + factor * half))
        })
        .collect()
}

/// Mean over outputs of `SSE/SST` of the free run on every experiment (pooled), skipping
/// the initial window and missing samples; `None` if the run diverges.
pub(crate) fn free_run_score(model: &NarxModel, data: &Dataset) -> Result<Option<f64>> {
    let p = data.output_channels().len();
    let mut sse = vec![0.0; p];
    let mut sum = vec![0.0; p];
    let mut sum2 = vec![0.0; p];
    let mut count = vec![0usize; p];
    for exp in data.experiments() {
        let pred = match model.simulate(exp) {
            Ok(pred) => pred,
            Err(BaselineError::Diverged { .. }) => return Ok(None),
            Err(e) => return Err(e),
        };
        for k in pred.initial_samples..exp.len() {
            for (i, y) in exp.output(k).iter().enumerate() {
                if !y.is_nan() {
                    let e = y - pred.outputs[(i, k)];
                    sse[i] += e * e;
                    sum[i] += y;
                    sum2[i] += y * y;
                    count[i] += 1;
                }
            }
        }
    }
    let mut score = 0.0;
    for i in 0..p {
        let n = count[i] as f64;
        let sst = sum2[i] - sum[i] * sum[i] / n;
        if count[i] < 2 || sst.is_nan() || sst <= 0.0 {
            return Ok(None);
        }
        score += sse[i] / sst;
    }
    Ok(Some(score / p as f64))
}

type Split = (DMatrix<f64>, DMatrix<f64>);

/// Split rows into (train, test) with the last `fraction` of each experiment's rows in
/// the test part.
fn split_tail(
    inputs: &DMatrix<f64>,
    targets: &DMatrix<f64>,
    per_experiment: &[usize],
    fraction: f64,
) -> Result<(Split, Split)> {
    let mut train_idx = Vec::new();
    let mut test_idx = Vec::new();
    let mut start = 0;
    for &rows in per_experiment {
        let n_test = ((rows as f64) * fraction).round() as usize;
        let cut = start + rows - n_test;
        train_idx.extend(start..cut);
        test_idx.extend(cut..start + rows);
        start += rows;
    }
    if train_idx.is_empty() || test_idx.is_empty() {
        return Err(BaselineError::TooFewRows {
            what: "rows on each side of the sweep's train/test split",
            found: train_idx.len().min(test_idx.len()),
            needed: 1,
        });
    }
    let pick = |m: &DMatrix<f64>, idx: &[usize]| m.select_columns(idx.iter());
    Ok((
        (pick(inputs, &train_idx), pick(targets, &train_idx)),
        (pick(inputs, &test_idx), pick(targets, &test_idx)),
    ))
}
