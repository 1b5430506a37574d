#![doc = include_str!("../README.md")]

pub mod atomic;
pub mod benchmarks;
pub mod compare;
pub mod data_file;
pub mod discover;
pub mod error;
pub mod estimate;
pub mod fit;
pub mod model_file;
pub mod monitor;
pub mod plot;
pub mod progress;
pub mod refine;
pub mod simulate;
pub mod words;

pub use error::{CsvProblem, MmennError, ModelProblem, Result};
pub use model_file::{ModelSpec, NoiseVariance, TermEntry, read_model, write_model};

/// The Minimum Model Error estimator.
pub use mme_core;
/// Feed-forward networks.
pub use nn;
/// The simulated truth systems and experiment recipes.
pub use plants;
/// The shared vocabulary (datasets, traits, linear model, integrators, metrics).
pub use sysid_core;
