#![doc = include_str!("../README.md")]

pub mod acquisition;
pub mod bandlimited;
pub mod budget;
pub mod correlation;
pub mod dataset;
pub mod dynamics;
pub mod error;
pub mod estimate;
pub mod expr;
pub mod greybox;
pub mod hybrid;
pub mod initial;
pub mod integrate;
pub mod judge;
pub mod least_squares;
pub mod linear;
pub mod metrics;
pub mod physical;
pub mod stiff;
pub mod tangent;
pub mod terms;

pub use budget::{Budget, BudgetExhausted, BudgetLimit};
pub use correlation::{Confidence, acf, confidence_bound, xcf};
pub use dataset::{Channel, Dataset, Experiment, InterSample};
pub use dynamics::{Correction, Dynamics, Horizon, Model, Prediction};
pub use error::{CoreError, Result};
pub use estimate::{ExperimentEstimate, IterationRecord, MmeEstimate, SolveReport, Termination};
pub use expr::{Expr, ExprError, Func};
pub use greybox::{
    ActiveBound, GreyboxData, GreyboxFit, GreyboxOptions, ParameterEstimate, Shooting, StageReport,
    estimate_parameters, estimate_parameters_with, free_run_residuals,
};
pub use hybrid::CorrectedModel;
pub use initial::{InitialStateFit, fit_initial_state};
pub use integrate::{DpOptions, Integrator, simulate, simulate_experiment, simulate_with};
pub use judge::{
    DEFAULT_X0_WINDOW, InitialRule, JudgeOptions, Judgement, Observation, ScoredWindow,
    judge_free_run, judge_k_step, score, score_rows,
};
pub use least_squares::{
    AcceptedStep, Control, LeastSquaresProblem, LmReport, LmSettings, LmSolution,
    STATIONARY_COSINE, Scaling, levenberg_marquardt,
};
pub use linear::{DiscreteLinear, LinearModel, ModelNames, discretize_zoh, ramp_gain};
pub use metrics::{ChannelMetrics, channel_metrics};
pub use physical::{
    Estimation, MAX_DOF, MechanicsSpec, Parameter, ParametricDynamics, PhysicalError,
    PhysicalModel, PhysicalTerm,
};
pub use stiff::{StiffProbe, Substeps, auto_rk4, measured_start, probe_substeps, resolve_substeps};
pub use terms::{Term, TermError, TermModel, TermSpec, term_variables};
