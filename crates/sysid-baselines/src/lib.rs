#![doc = include_str!("../README.md")]

pub mod correlation;
mod discrete;
pub mod error;
pub mod evaluate;
pub mod free_params;
pub mod frols;
pub mod lags;
pub mod linear_ss;
mod lsq;
pub mod narx;
pub mod narx_model;
mod narx_refine;
mod narx_sim;
pub mod oe;
pub mod oe_model;
mod oe_sim;
pub mod poly_narx;
pub mod projection;
pub mod regressors;
pub mod residuals;
pub mod subspace;

pub use correlation::{
    CorrelationKind, Correlogram, autocorrelation, cross_correlation, pacf_from_acf,
    partial_autocorrelation,
};
pub use error::{BaselineError, Result};
pub use evaluate::{
    ChannelEvaluation, Evaluation, EvaluationTable, TableRow, evaluate, predictions,
};
pub use free_params::{FreeParameter, StateMatrix, parse_free_parameters};
pub use frols::{
    FrolsConfig, FrolsFit, FrolsKfoldFit, KFOLD_FOLDS, PrefixFailure, PrefixScore, RankedTerm,
    TermCount, count_by_free_run, fit_frols, fit_frols_kfold,
};
pub use lags::{
    InputOutputXcf, LagCandidate, LagGrid, LagOutcome, LagSearch, LagSearchConfig, LagSuggestion,
    OutputPacf, SuggestionConfig, search_lags, suggest_lags,
};
pub use linear_ss::{
    LinearSsConfig, LinearSsFit, LinearSsModel, OrderCandidate, Section, fit_linear_ss,
};
pub use narx::{
    NarxConfig, NarxFit, NetworkChoice, Projection, RestartRecord, RestartSelection, fit_narx,
    refine_narx,
};
pub use narx_model::NarxModel;
pub use oe::{
    InitialStateTreatment, OeConfig, OeFit, ParameterEstimate, Stability, StabilityVerdict, fit_oe,
};
pub use oe_model::{OeModel, X0Policy};
pub use poly_narx::{Focus, PolyNarxConfig, PolyNarxFit, PolyNarxModel, Refinement, fit_poly_narx};
pub use projection::RegressorProjection;
pub use regressors::NarxOrders;
pub use residuals::{
    InputCorrelation, ResidualAnalysis, ResidualChannel, ResidualConfig, analyse_prediction,
    residual_analysis,
};
pub use subspace::{DiscreteStateSpace, Moesp, fit_b_d_x0, moesp};
