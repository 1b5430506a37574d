#![doc = include_str!("../README.md")]

pub mod compound_pendulum;
pub mod double_pendulum;
pub mod error;
pub mod msd;
pub mod noise;
pub mod oscillator;
pub mod params;
pub mod pendulum;
pub mod recipe;
pub mod resample;
pub mod signals;
pub mod system;
pub mod two_tank;
pub mod van_der_pol;

#[cfg(test)]
mod testutil;

pub use compound_pendulum::{CompoundPendulum, CompoundPendulumParams};
pub use double_pendulum::{
    DoublePendulum, DoublePendulumConstants, DoublePendulumParams, JOINT_DAMPING_CLASSES,
};
pub use error::{PlantError, Result};
pub use msd::{MSD_DAMPING_CLASSES, MsdCubic, MsdCubicParams};
pub use noise::{add_noise, gaussian_noise};
pub use oscillator::{Oscillator, OscillatorParams};
pub use params::{ParamInfo, Parameters};
pub use pendulum::{Pendulum, PendulumParams};
pub use recipe::{
    AssumedSpec, MAX_SAMPLES, MIN_NOISE_VARIANCE, Recipe, SimulatedData, SimulationRequest,
    SystemInfo, Truth, build_system, simulate_system, system_parameters, systems, truth_integrator,
};
pub use resample::{
    AntiAlias, Interpolation, decimate, decimate_dataset, decimate_experiment, decimation_factor,
    resample, resample_experiment,
};
pub use signals::{Aprbs, Chirp, Excitation, Multisine, Prbs, SampleGrid, Sine, Steps, Sweep};
pub use system::{RecipeSpec, TruthCorrection, TruthSystem, model_error};
pub use two_tank::{TwoTank, TwoTankParams};
pub use van_der_pol::{VanDerPol, VanDerPolParams};
