#![doc = include_str!("../README.md")]

mod binding;
pub mod config;
pub mod discretize;
pub mod error;
mod estimate;
mod evaluate;
mod kernel;
mod linear;
mod linearize;
pub mod noise;
pub mod nonlinear;
pub mod observe;
pub mod result;
pub mod robust;
mod sweep;
pub mod tune_w;
pub mod update;

pub use config::{
    AutoWeight, IterationOptions, MmeConfig, NoiseSpec, StartTrajectory, StatePrior, WeightShape,
    WeightSpec,
};
pub use discretize::default_substeps;
pub use error::{MmeError, Result};
pub use estimate::{estimate, estimate_with_observer, estimate_with_report};
pub use nonlinear::{
    NonlinearModel, estimate_nonlinear, estimate_nonlinear_with_observer,
    estimate_nonlinear_with_report,
};
pub use observe::{MmeEvent, MmeObserver, MmePhase, NoObserver};
pub use result::{MmeOutput, NoiseMethod, NoiseReport, WCurvePoint, WSearch};
pub use robust::{
    Outlier, RobustConfig, RobustOutput, estimate_nonlinear_robust,
    estimate_nonlinear_robust_with_observer, estimate_robust, estimate_robust_with_observer,
    screen_outliers,
};
pub use update::{
    Coefficient, CorrectionRegression, Intercept, ModelUpdate, RegressionPoints, UpdateConfig,
    update_model,
};
