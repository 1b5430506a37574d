#![doc = include_str!("../README.md")]

pub mod acquisition;
pub mod atomic;
pub mod benchmarks;
pub mod compare;
pub mod data_file;
pub mod discover;
pub mod error;
pub mod estimate;
pub mod fit;
pub mod greyest;
pub mod html;
pub mod hybrid;
pub mod model;
pub mod model_file;
pub mod monitor;
pub mod plot;
pub mod predict;
pub mod progress;
pub mod show;
pub mod simulate;
pub mod words;

pub use error::{CsvProblem, MmennError, ModelProblem, Result};
pub use model::{LoadedModel, ModelKind, judge_free_run};
pub use model_file::{ModelSpec, NoiseVariance, TermEntry, read_model, write_model};

/// Condition monitoring (features, classifiers, cross-validation).
pub use condmon;
/// Naming the missing effect (catalogue, localisation, selection, calibration).
pub use discovery;
/// The Minimum Model Error estimator.
pub use mme_core;
/// Feed-forward networks.
pub use nn;
/// The simulated truth systems and experiment recipes.
pub use plants;
/// The comparison methods (PACF, NARX, output-error models, evaluation tables).
pub use sysid_baselines;
/// The shared vocabulary (datasets, traits, linear model, integrators, metrics).
pub use sysid_core;
