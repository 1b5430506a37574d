#![doc = include_str!("../README.md")]

pub mod classify;
pub mod cv;
mod data;
pub mod error;
pub mod features;
pub mod pca;
pub mod pipeline;
pub mod standardise;
pub mod table;

pub use classify::{
    Classifier, ClassifierModel, ClassifierSpec, KnnConfig, KnnModel, LdaConfig, LdaModel,
    NaiveBayesConfig, NaiveBayesModel, Predictions, Priors, QdaConfig, QdaModel, ScoreKind,
    Shrinkage, TrainedModel,
};
pub use cv::{
    ConfusionMatrix, CvConfig, CvResult, CvScheme, Interval, cross_validate, folds_for,
    stratified_folds, wilson_interval,
};
pub use error::{CondmonError, Result};
pub use features::{
    FeatureMatrix, NamedFeatures, canonical_weights, canonicalise, physical_features, raw_weights,
    stack, weight_names,
};
pub use pca::{ComponentSelection, Pca};
pub use pipeline::{
    FeatureScaling, FittedPreprocessing, Preprocessing, Reduction, TrainedPipeline,
};
pub use standardise::Standardiser;
pub use table::{ErrorTable, error_table};
