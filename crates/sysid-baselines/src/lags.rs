//! NARX lag selection as in the thesis (§3.2.1, ch. 5): a suggestion from the largest
//! significant partial autocorrelation lag of each output and the largest significant
//! positive cross-correlation lag between each input and output, then a small search
//! over lags around it, judged by free-run simulation on validation data.

use serde::{Deserialize, Serialize};
use sysid_core::{ChannelMetrics, Confidence, Dataset, Horizon};

use crate::correlation::{Correlogram, cross_correlation, partial_autocorrelation};
use crate::error::{BaselineError, Result, check_config};
use crate::evaluate::evaluate;
use crate::narx::{NarxConfig, NarxFit, fit_narx};
use crate::regressors::NarxOrders;

/// Settings of [`suggest_lags`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SuggestionConfig {
    /// Largest lag examined (the cap of the suggestion). Default 20.
    pub max_lag: usize,
    /// Band that makes a correlation significant. Default 95 %.
    pub confidence: Confidence,
    /// Input dead time `nk` of the suggested orders. Default 1.
    pub nk: usize,
}

impl Default for SuggestionConfig {
    fn default() -> Self {
        Self {
            max_lag: 20,
            confidence: Confidence::P95,
            nk: 1,
        }
    }
}

/// The partial autocorrelation of one output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputPacf {
    /// Output channel.
    pub output: String,
    /// PACF, lags `0..=max_lag`.
    pub correlogram: Correlogram,
    /// Largest lag outside the band (`None`: none is).
    pub largest_significant: Option<usize>,
}

/// The cross-correlation of one input with one output.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputOutputXcf {
    /// Input channel.
    pub input: String,
    /// Output channel.
    pub output: String,
    /// `r_uy(τ)`, lags `−max_lag..=max_lag`; positive: the output follows the input.
    pub correlogram: Correlogram,
    /// Largest positive lag outside the band (`None`: none is).
    pub largest_significant: Option<usize>,
}

/// Suggested NARX orders and the correlograms they came from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LagSuggestion {
    /// `na` = the largest significant PACF lag over outputs (at least 1); `nb` = the
    /// largest significant positive XCF lag over input–output pairs minus `nk − 1` (at
    /// least 1); both at most `max_lag`.
    pub orders: NarxOrders,
    /// Per output.
    pub pacf: Vec<OutputPacf>,
    /// Per (input, output) pair.
    pub xcf: Vec<InputOutputXcf>,
}

/// Suggest NARX orders from the data's correlations (pooled over experiments, missing
/// samples skipped).
///
/// Errors: `max_lag` 0 or not shorter than every experiment, no input or output channel.
pub fn suggest_lags(data: &Dataset, config: &SuggestionConfig) -> Result<LagSuggestion> {
    check_config(
        "max_lag",
        config.max_lag as f64,
        "must be at least 1",
        config.max_lag >= 1,
    )?;
    if data.input_channels().is_empty() || data.output_channels().is_empty() {
        return Err(BaselineError::Dimension {
            what: "input and output channels for lag suggestion",
            found: 0,
            expected: 1,
        });
    }
    for (e, exp) in data.experiments().iter().enumerate() {
        if exp.len() <= config.max_lag + 1 {
            return Err(BaselineError::LagsExceedData {
                what: "correlation lags",
                experiment: e,
                needed: config.max_lag + 2,
                available: exp.len(),
            });
        }
    }
    fn slices(v: &[Vec<f64>]) -> Vec<&[f64]> {
        v.iter().map(|s| s.as_slice()).collect()
    }
    let row =
        |m: &nalgebra::DMatrix<f64>, i: usize| -> Vec<f64> { m.row(i).iter().copied().collect() };
    let outputs: Vec<Vec<Vec<f64>>> = (0..data.output_channels().len())
        .map(|i| {
            data.experiments()
                .iter()
                .map(|e| row(e.outputs(), i))
                .collect()
        })
        .collect();
    let inputs: Vec<Vec<Vec<f64>>> = (0..data.input_channels().len())
        .map(|j| {
            data.experiments()
                .iter()
                .map(|e| row(e.inputs(), j))
                .collect()
        })
        .collect();

    let mut pacf = Vec::new();
    for (name, y) in data.output_names().into_iter().zip(&outputs) {
        let c = partial_autocorrelation(&slices(y), config.max_lag)?;
        pacf.push(OutputPacf {
            output: name,
            largest_significant: c.largest_significant_lag(config.confidence),
            correlogram: c,
        });
    }
    let mut xcf = Vec::new();
    for (input, u) in data.input_names().into_iter().zip(&inputs) {
        for (output, y) in data.output_names().into_iter().zip(&outputs) {
            let c = cross_correlation(&slices(u), &slices(y), config.max_lag)?;
            xcf.push(InputOutputXcf {
                input: input.clone(),
                output,
                largest_significant: c.largest_significant_lag(config.confidence),
                correlogram: c,
            });
        }
    }
    let na = pacf
        .iter()
        .filter_map(|p| p.largest_significant)
        .max()
        .unwrap_or(1)
        .max(1);
    let nb = xcf
        .iter()
        .filter_map(|x| x.largest_significant)
        .filter(|&lag| lag >= config.nk)
        .map(|lag| lag + 1 - config.nk)
        .max()
        .unwrap_or(1)
        .clamp(1, config.max_lag);
    Ok(LagSuggestion {
        orders: NarxOrders {
            na,
            nb,
            nk: config.nk,
        },
        pacf,
        xcf,
    })
}

/// Which orders a lag search tries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LagGrid {
    /// `na = nb = d` for `d` within `radius` of `max(na, nb)` (the thesis's practice).
    #[default]
    Equal,
    /// Every `(na, nb)` with each within `radius` of its suggestion.
    Independent,
}

/// Settings of [`search_lags`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LagSearchConfig {
    /// How far around the suggestion to look. Default 2.
    pub radius: usize,
    /// Grid shape. Default [`LagGrid::Equal`].
    pub grid: LagGrid,
    /// Candidates whose mean validation R² is within this of the best are equally good;
    /// the one with the fewest taps (`na + nb`, then `na`) wins. Default 0.002.
    pub tolerance: f64,
}

impl Default for LagSearchConfig {
    fn default() -> Self {
        Self {
            radius: 2,
            grid: LagGrid::Equal,
            tolerance: 0.002,
        }
    }
}

/// How a candidate did on the validation data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LagOutcome {
    /// Free-run metrics per output and their mean R².
    Evaluated {
        /// Mean R² over outputs.
        mean_r2: f64,
        /// Per output, in the data's order.
        channels: Vec<ChannelMetrics>,
    },
    /// The free run left the divergence limits.
    Diverged,
}

/// One candidate of a lag search.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LagCandidate {
    /// Orders tried.
    pub orders: NarxOrders,
    /// Result on the validation data (free run).
    pub outcome: LagOutcome,
}

/// Result of [`search_lags`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LagSearch {
    /// Every candidate, in the order tried.
    pub candidates: Vec<LagCandidate>,
    /// Index of the chosen one.
    pub chosen: usize,
    /// The chosen candidate's trained model.
    pub fit: NarxFit,
}

/// Train a NARX model (with `base`'s settings) for each orders candidate around
/// `around`, judge each by free-run simulation on `validation`, and keep the smallest
/// structure whose mean R² is within `tolerance` of the best.
///
/// Errors: invalid settings, every candidate diverging, and any training or evaluation
/// error other than divergence.
pub fn search_lags(
    train: &Dataset,
    validation: &Dataset,
    around: NarxOrders,
    base: &NarxConfig,
    config: &LagSearchConfig,
) -> Result<LagSearch> {
    check_config(
        "tolerance",
        config.tolerance,
        "must be finite and ≥ 0",
        config.tolerance.is_finite() && config.tolerance >= 0.0,
    )?;
    let range = |c: usize| c.saturating_sub(config.radius).max(1)..=c + config.radius;
    let orders: Vec<NarxOrders> = match config.grid {
        LagGrid::Equal => range(around.na.max(around.nb))
            .map(|d| NarxOrders {
                na: d,
                nb: d,
                nk: around.nk,
            })
            .collect(),
        LagGrid::Independent => range(around.na)
            .flat_map(|na| {
                range(around.nb).map(move |nb| NarxOrders {
                    na,
                    nb,
                    nk: around.nk,
                })
            })
            .collect(),
    };
    let mut candidates = Vec::with_capacity(orders.len());
    let mut fits = Vec::with_capacity(orders.len());
    for o in orders {
        let config = NarxConfig {
            orders: o,
            ..base.clone()
        };
        let fit = fit_narx(train, &config)?;
        let outcome = match evaluate(&fit.model, validation, Horizon::FreeRun) {
            Ok(ev) => {
                let channels: Vec<ChannelMetrics> = ev.channels.iter().map(|c| c.metrics).collect();
                let mean_r2 = channels.iter().map(|c| c.r2).sum::<f64>() / channels.len() as f64;
                LagOutcome::Evaluated { mean_r2, channels }
            }
            Err(BaselineError::Model { source, .. })
                if matches!(
                    source.downcast_ref::<BaselineError>(),
                    Some(BaselineError::Diverged { .. })
                ) =>
            {
                LagOutcome::Diverged
            }
            Err(e) => return Err(e),
        };
        candidates.push(LagCandidate { orders: o, outcome });
        fits.push(fit);
    }
    let score = |c: &LagCandidate| match c.outcome {
        LagOutcome::Evaluated { mean_r2, .. } if mean_r2.is_finite() => Some(mean_r2),
        _ => None,
    };
    let best =
        candidates
            .iter()
            .filter_map(score)
            .reduce(f64::max)
            .ok_or(BaselineError::TooFewRows {
                what: "lag candidates whose free run did not diverge",
                found: 0,
                needed: 1,
            })?;
    let chosen = candidates
        .iter()
        .enumerate()
        .filter(|(_, c)| score(c).is_some_and(|s| s >= best - config.tolerance))
        .min_by_key(|(_, c)| (c.orders.na + c.orders.nb, c.orders.na))
        .map(|(i, _)| i)
        .unwrap_or(0);
    let fit = fits.swap_remove(chosen);
    Ok(LagSearch {
        candidates,
        chosen,
        fit,
    })
}
