#![doc = include_str!("../README.md")]

pub mod augment;
pub mod candidates;
pub mod catalogue;
pub mod error;
pub mod floor;
pub mod gauge;
mod json;
pub mod judge;
pub mod localise;
pub mod propose;
pub mod refine;
pub mod roles;
pub mod samples;
mod screen;
pub mod select;
pub mod standin;
pub mod stats;
mod term_set;
#[cfg(test)]
mod test_support;
pub mod transfer;
pub mod workflow;

pub use augment::{
    Calibration, CalibrationConfig, InitialState, OutputWeights, augment, calibrate, free_run_cost,
    measured_values, simulate_outputs,
};
pub use candidates::{Candidate, EquationLibrary, LibraryConfig, build_library};
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
pub use transfer::{conserved_variant, refine_with_transfers, routings, transfer_candidates};
