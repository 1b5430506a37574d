//! Judging any [`sysid_core::Model`] on a dataset: per-channel fit %, R², RMSE and error
//! variance, pooled over experiments and skipping each prediction's initial samples, with
//! the [`Horizon`] carried along; and a table that refuses rows of another horizon, so
//! free-run and k-step numbers can never be mixed.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::{ChannelMetrics, Dataset, Experiment, Horizon, Model, Prediction, score_rows};

use crate::error::{BaselineError, Result};

/// Metrics of one output channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChannelEvaluation {
    /// Channel name.
    pub name: String,
    /// Fit %, R², RMSE, error variance and the number of samples used.
    pub metrics: ChannelMetrics,
}

/// A model judged on a dataset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Free-run simulation or k-step prediction.
    pub horizon: Horizon,
    /// One entry per model output, in the model's order.
    pub channels: Vec<ChannelEvaluation>,
    /// Samples skipped as initial conditions, summed over experiments.
    pub initial_samples: usize,
}

impl Evaluation {
    /// Metrics of a channel by name.
    pub fn channel(&self, name: &str) -> Option<&ChannelMetrics> {
        self.channels
            .iter()
            .find(|c| c.name == name)
            .map(|c| &c.metrics)
    }
}

/// Run a model on one experiment (index `experiment`, for errors) with the given horizon
/// and check the prediction's horizon and shape.
pub(crate) fn predict_one<M: Model>(
    model: &M,
    exp: &Experiment,
    experiment: usize,
    horizon: Horizon,
) -> Result<Prediction> {
    let pred = match horizon {
        Horizon::FreeRun => model.simulate(exp),
        Horizon::Steps(k) => model.predict(exp, k),
    }
    .map_err(|e| BaselineError::Model {
        experiment,
        source: Box::new(e),
    })?;
    if pred.horizon != horizon {
        return Err(BaselineError::MixedHorizon {
            table: "predictions".into(),
            row: format!("experiment {experiment}"),
            expected: horizon,
            found: pred.horizon,
        });
    }
    let p = model.output_names().len();
    if pred.outputs.nrows() != p {
        return Err(BaselineError::Dimension {
            what: "prediction channels vs model outputs",
            found: pred.outputs.nrows(),
            expected: p,
        });
    }
    if pred.outputs.ncols() != exp.len() {
        return Err(BaselineError::Dimension {
            what: "prediction samples vs experiment samples",
            found: pred.outputs.ncols(),
            expected: exp.len(),
        });
    }
    Ok(pred)
}

/// Run a model on every experiment with the given horizon (free-run simulation or
/// k-step prediction).
///
/// Errors: the model's own errors (wrapped in [`BaselineError::Model`] with the
/// experiment index), a prediction whose horizon or shape differs from what was asked.
pub fn predictions<M: Model>(
    model: &M,
    data: &Dataset,
    horizon: Horizon,
) -> Result<Vec<Prediction>> {
    data.experiments()
        .iter()
        .enumerate()
        .map(|(e, exp)| predict_one(model, exp, e, horizon))
        .collect()
}

/// Check that the data's outputs are the model's, by name and in order (models that read
/// measured outputs take them by position).
pub(crate) fn check_outputs(model_outputs: &[String], data: &Dataset) -> Result<()> {
    let names = data.output_names();
    if let Some(missing) = model_outputs.iter().find(|n| !names.contains(n)) {
        return Err(BaselineError::UnknownOutput {
            name: missing.clone(),
        });
    }
    if names.len() != model_outputs.len() {
        return Err(BaselineError::Dimension {
            what: "output channels of the data vs the model",
            found: names.len(),
            expected: model_outputs.len(),
        });
    }
    for (position, (found, expected)) in names.iter().zip(model_outputs).enumerate() {
        if found != expected {
            return Err(BaselineError::ChannelMismatch {
                kind: "output",
                position,
                found: found.clone(),
                expected: expected.clone(),
            });
        }
    }
    Ok(())
}

/// Evaluate a model on a dataset with the given horizon: per output channel, metrics of
/// the predictions against the measurements pooled over every experiment, from each
/// prediction's `initial_samples` on, missing measurements skipped, scored by the one
/// judge's scoring ([`sysid_core::score_rows`]).
///
/// This is the judge of input–output models whose initial condition is a window of
/// measured samples they consume (NARX's delay line, an output-error model's observer
/// window): those samples are not scored. A continuous-time state-space model is judged
/// by [`sysid_core::judge_free_run`] (initial state fitted to a stated window, every
/// sample scored), as mmenn's commands do.
///
/// The data's output channels must be the model's (names, in order). Errors: channel
/// mismatch, the model's own errors, a non-finite prediction where a measurement exists,
/// fewer than 2 samples.
pub fn evaluate<M: Model>(model: &M, data: &Dataset, horizon: Horizon) -> Result<Evaluation> {
    let names = model.output_names();
    check_outputs(&names, data)?;
    let preds = predictions(model, data, horizon)?;
    let p = names.len();
    let mut measured: Vec<f64> = Vec::new();
    let mut predicted: Vec<f64> = Vec::new();
    let mut initial = 0;
    for (exp, pred) in data.experiments().iter().zip(&preds) {
        let start = pred.initial_samples.min(exp.len());
        initial += start;
        for k in start..exp.len() {
            measured.extend(exp.output(k).iter().copied());
            predicted.extend((0..p).map(|i| pred.outputs[(i, k)]));
        }
    }
    let cols = measured.len() / p.max(1);
    let scored = score_rows(
        &names,
        &DMatrix::from_column_slice(p, cols, &measured),
        &DMatrix::from_column_slice(p, cols, &predicted),
        0,
    )?;
    let channels = names
        .into_iter()
        .map(|name| ChannelEvaluation {
            metrics: scored[&name],
            name,
        })
        .collect();
    Ok(Evaluation {
        horizon,
        channels,
        initial_samples: initial,
    })
}

/// One labelled row of an [`EvaluationTable`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TableRow {
    /// Row label, e.g. `NARX (6 delays)`.
    pub label: String,
    /// The evaluation.
    pub evaluation: Evaluation,
}

/// A comparison table whose rows all share one [`Horizon`]: adding a row evaluated with
/// another horizon (free-run vs k-step, or a different k) is an error.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvaluationTable {
    title: String,
    horizon: Horizon,
    rows: Vec<TableRow>,
}

impl EvaluationTable {
    /// An empty table for results of one horizon.
    pub fn new(title: impl Into<String>, horizon: Horizon) -> Self {
        Self {
            title: title.into(),
            horizon,
            rows: Vec::new(),
        }
    }

    /// Add a row. Errors with [`BaselineError::MixedHorizon`] when the evaluation's
    /// horizon is not the table's (the table is then unchanged).
    pub fn push(&mut self, label: impl Into<String>, evaluation: Evaluation) -> Result<()> {
        let label = label.into();
        if evaluation.horizon != self.horizon {
            return Err(BaselineError::MixedHorizon {
                table: self.title.clone(),
                row: label,
                expected: self.horizon,
                found: evaluation.horizon,
            });
        }
        self.rows.push(TableRow { label, evaluation });
        Ok(())
    }

    /// The table's title.
    pub fn title(&self) -> &str {
        &self.title
    }

    /// The horizon every row shares.
    pub fn horizon(&self) -> Horizon {
        self.horizon
    }

    /// The rows, in insertion order.
    pub fn rows(&self) -> &[TableRow] {
        &self.rows
    }
}
