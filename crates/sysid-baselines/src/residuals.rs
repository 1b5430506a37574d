//! Residual analysis of any [`sysid_core::Model`] on one experiment: the residual
//! autocorrelation and the residual–input cross-correlation with their 99 % bands, as
//! serialisable data for the facade's figures.

use serde::{Deserialize, Serialize};
use sysid_core::{Confidence, Dataset, Horizon, Model, Prediction};

use crate::correlation::{Correlogram, autocorrelation, cross_correlation};
use crate::error::{BaselineError, Result, check_config};
use crate::evaluate::{check_outputs, predict_one};

/// Settings of the residual analysis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ResidualConfig {
    /// Largest lag of both correlograms, samples. Default 25 (MATLAB `resid`'s default).
    pub max_lag: usize,
}

impl Default for ResidualConfig {
    fn default() -> Self {
        Self { max_lag: 25 }
    }
}

/// Correlation of one output's residual with one input.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputCorrelation {
    /// Input channel name.
    pub input: String,
    /// `r_ue(τ)`, lags `−max_lag..=max_lag`; positive lags: the residual follows the input.
    pub correlogram: Correlogram,
}

/// Residual analysis of one output channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualChannel {
    /// Output channel name.
    pub output: String,
    /// Root-mean-square residual over the analysed samples.
    pub rms: f64,
    /// Residual autocorrelation, lags `0..=max_lag`.
    pub autocorrelation: Correlogram,
    /// Residual–input cross-correlation, one per input.
    pub cross: Vec<InputCorrelation>,
    /// Lags (excluding 0) where the autocorrelation leaves the 99 % band.
    pub acf_outside_99: Vec<i64>,
    /// Per input, lags where the cross-correlation leaves the 99 % band.
    pub xcf_outside_99: Vec<Vec<i64>>,
}

/// Residual correlations of a model on one experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResidualAnalysis {
    /// How the predictions were made.
    pub horizon: Horizon,
    /// Experiment index in the dataset.
    pub experiment: usize,
    /// Initial samples skipped (the prediction's own initialisation).
    pub initial_samples: usize,
    /// One entry per output channel.
    pub channels: Vec<ResidualChannel>,
}

/// Run the model on experiment `experiment` of the data with the given horizon and
/// analyse its residuals `y − ŷ`.
///
/// Errors: experiment index out of range, channel mismatch between data and model, the
/// model's own errors, too few samples after the initial ones for `max_lag`.
pub fn residual_analysis<M: Model>(
    model: &M,
    data: &Dataset,
    experiment: usize,
    horizon: Horizon,
    config: &ResidualConfig,
) -> Result<ResidualAnalysis> {
    check_outputs(&model.output_names(), data)?;
    let exp = data
        .experiments()
        .get(experiment)
        .ok_or(sysid_core::CoreError::Range {
            start: experiment,
            end: experiment + 1,
            len: data.experiments().len(),
        })?;
    let pred = predict_one(model, exp, experiment, horizon)?;
    analyse_prediction(&pred, data, experiment, config)
}

/// Analyse the residuals of a given prediction of experiment `experiment`.
///
/// Errors: experiment index out of range, prediction shape not matching the data, fewer
/// analysed samples than `max_lag + 2`.
pub fn analyse_prediction(
    prediction: &Prediction,
    data: &Dataset,
    experiment: usize,
    config: &ResidualConfig,
) -> Result<ResidualAnalysis> {
    let exp = data
        .experiments()
        .get(experiment)
        .ok_or(sysid_core::CoreError::Range {
            start: experiment,
            end: experiment + 1,
            len: data.experiments().len(),
        })?;
    let (p, len) = (exp.n_outputs(), exp.len());
    if prediction.outputs.nrows() != p || prediction.outputs.ncols() != len {
        return Err(BaselineError::Dimension {
            what: "prediction samples vs experiment samples",
            found: prediction.outputs.ncols(),
            expected: len,
        });
    }
    let start = prediction.initial_samples;
    check_config(
        "max_lag",
        config.max_lag as f64,
        "must be at least 1",
        config.max_lag >= 1,
    )?;
    if start + config.max_lag + 2 > len {
        return Err(BaselineError::LagsExceedData {
            what: "residual correlation lags after the initial samples",
            experiment,
            needed: start + config.max_lag + 2,
            available: len,
        });
    }
    let inputs: Vec<Vec<f64>> = (0..exp.n_inputs())
        .map(|j| (start..len).map(|k| exp.inputs()[(j, k)]).collect())
        .collect();
    let channels = data
        .output_names()
        .into_iter()
        .enumerate()
        .map(|(i, output)| {
            let e: Vec<f64> = (start..len)
                .map(|k| exp.outputs()[(i, k)] - prediction.outputs[(i, k)])
                .collect();
            let valid: Vec<f64> = e.iter().copied().filter(|v| !v.is_nan()).collect();
            let rms = (valid.iter().map(|v| v * v).sum::<f64>() / valid.len().max(1) as f64).sqrt();
            let acf = autocorrelation(&[&e], config.max_lag)?;
            let cross = data
                .input_names()
                .into_iter()
                .zip(&inputs)
                .map(|(input, u)| {
                    Ok(InputCorrelation {
                        input,
                        correlogram: cross_correlation(&[u], &[&e], config.max_lag)?,
                    })
                })
                .collect::<Result<Vec<_>>>()?;
            Ok(ResidualChannel {
                output,
                rms,
                acf_outside_99: acf.outside(Confidence::P99),
                xcf_outside_99: cross
                    .iter()
                    .map(|c| c.correlogram.outside(Confidence::P99))
                    .collect(),
                autocorrelation: acf,
                cross,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(ResidualAnalysis {
        horizon: prediction.horizon,
        experiment,
        initial_samples: start,
        channels,
    })
}
