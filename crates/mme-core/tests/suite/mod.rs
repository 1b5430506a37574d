//! Test modules and their shared helpers.

pub mod common;

mod auto_w;
mod brute;
mod errors;
mod intersample;
mod limits;
mod msd;
mod noise;
mod nonlinear;
mod observer;
mod prior;
mod robust;
mod start;
mod stiff;
mod strong_zero_slope;
mod update;
