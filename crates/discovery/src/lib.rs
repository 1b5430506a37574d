#![doc = include_str!("../README.md")]

mod augment;
mod candidates;
mod catalogue;
pub mod error;
mod floor;
pub mod force;
mod gauge;
mod json;
mod judge;
mod localise;
mod propose;
mod refine;
mod roles;
mod samples;
mod screen;
mod select;
mod standin;
mod stats;
mod term_set;
#[cfg(test)]
mod test_support;
mod transfer;
pub mod validation;
pub mod workflow;

pub use augment::{
    Calibration, CalibrationConfig, InitialState, OutputWeights, augment, calibrate, free_run_cost,
    measured_values, simulate_outputs,
};
pub use candidates::{Candidate, EquationLibrary, LibraryConfig, build_library, term_connections};
pub use catalogue::{Effect, Slot, coefficient_unit};
pub use error::{DiscoveryError, Result};
pub use floor::NoiseFloor;
pub use gauge::{ban_touching, scale_free_states, touches};
pub use judge::{BootstrapJudgement, JudgeConfig, Protocol, judge};
pub use localise::{
    Bin, DisagreementWindow, FreeRun, Localisation, LocaliseConfig, MovingRms, Profile, Region,
    WindowLength, WindowSource, localise,
};
pub use propose::{
    Alias, Discovery, DiscoveryConfig, EquationReport, FoundEffect, ScreenedCandidate, StepRecord,
    Verdict, equation_design, propose,
};
pub use refine::{
    Holdout, RefineCandidate, RefineConfig, RefineStep, Refinement, Search, refine_by_free_run,
    refine_with_holdout,
};
pub use roles::{EquationKind, Role, StateRoles};
pub use samples::{Samples, centred_corrections, samples_from_estimate};
pub use select::{
    Design, Screened, SelectedTerm, Selection, SelectionConfig, Step, StepAction, select,
};
pub use standin::{StandIn, StandInConfig, gains as stand_in_gains, stand_in};
pub use stats::chi2_quantile;
pub use transfer::{conserved_variant, refine_with_transfers, routings, transfer_candidates};
