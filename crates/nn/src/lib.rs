#![doc = include_str!("../README.md")]

pub mod config;
pub mod correction;
pub mod ensemble;
pub mod error;
pub mod jacobian;
pub mod lm;
pub mod mlp;
pub mod scaling;
pub mod sweep;
pub mod trajectory;

pub use config::{Acceleration, Damping, ErrorSpace, LmConfig, ValidationSplit};
pub use correction::{Domain, NetCorrection};
pub use error::{NnError, Result};
pub use lm::{EpochInfo, StopReason, TrainReport, split_indices, train_lm};
pub use mlp::{Architecture, Mlp, Workspace};
pub use scaling::{CONSTANT_CHANNEL_RTOL, Scaler};
pub use sweep::{
    SizingRule, SweepConfig, SweepProgress, SweepResult, SweepRow, band_members, derive_seed,
    select, sizing_sweep,
};
pub use trajectory::{
    ShootingRecord, TrajectoryConfig, TrajectoryProgress, TrajectoryReport, train_on_trajectories,
};
