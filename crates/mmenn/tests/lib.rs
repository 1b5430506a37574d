//! Integration tests of the facade: every workflow end to end through files.

mod acquisition;
mod band_limited;
mod cli;
mod compare;
mod discover;
mod estimate_start;
mod examples;
mod fit;
mod fit_guard;
mod fit_mme_convergence;
mod greyest;
mod greyest_starts;
mod hidden_effects;
mod mme_progress;
mod mme_ratio_band;
mod model;
mod monitor;
mod never_panics;
mod physical;
mod physical_discover;
mod real_data;
mod reliability;
mod simulate;
mod stand_in;
mod truth;
