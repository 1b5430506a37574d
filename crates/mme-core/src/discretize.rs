//! Choice of the sub-step count and the exact discretisation of the assumed linear
//! model (held inputs, plus the ramp term for first-order-hold inputs), once per distinct
//! sample period.

use nalgebra::DMatrix;
pub use sysid_core::ramp_gain;
use sysid_core::{InterSample, LinearModel};

use crate::error::{MmeError, Result};

/// Most sub-steps the automatic choice will pick.
pub const MAX_DEFAULT_SUBSTEPS: usize = 64;

/// Fraction of the fastest model time constant that one sub-step may span by default.
pub const SUBSTEP_FRACTION: f64 = 0.1;

/// Default sub-steps for a model `ẋ = A x + …` sampled every `dt`: the smallest `s ≥ 1`
/// with `dt/s ≤ SUBSTEP_FRACTION · τ_min`, where `τ_min = 1/max|λ(A)|` is the fastest
/// time constant (or inverse natural frequency) of `A`, capped at
/// [`MAX_DEFAULT_SUBSTEPS`]. A model with `A = 0` (pure integrators) gets `s = 1`.
///
/// The discretisation is exact for piecewise-constant `d` at any `s`; sub-steps only refine
/// the time resolution of `d̂` where the model itself moves fast within one sample.
pub fn default_substeps(a: &DMatrix<f64>, dt: f64) -> usize {
    let rate = a
        .complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max);
    if !(rate.is_finite() && rate > 0.0) {
        return 1;
    }
    let tau = 1.0 / rate;
    let s = (dt / (SUBSTEP_FRACTION * tau)).ceil();
    if !s.is_finite() || s < 1.0 {
        1
    } else {
        (s as usize).min(MAX_DEFAULT_SUBSTEPS)
    }
}

/// The sub-step count to use for an experiment sampled every `dt`.
pub(crate) fn substeps_for(requested: Option<usize>, a: &DMatrix<f64>, dt: f64) -> Result<usize> {
    match requested {
        Some(0) => Err(MmeError::InvalidSetting {
            name: "substeps",
            value: 0.0,
            reason: "need at least one sub-step per sample",
        }),
        Some(s) => Ok(s),
        None => Ok(default_substeps(a, dt)),
    }
}

/// The assumed linear model discretised over one sub-step.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Discrete {
    /// Sample period, s.
    pub dt: f64,
    /// Sub-steps per sample.
    pub substeps: usize,
    /// Sub-step `h = dt/s`, s.
    pub h: f64,
    /// `exp(A h)`.
    pub ad: DMatrix<f64>,
    /// `∫₀ʰ exp(A τ) dτ · B`.
    pub bd: DMatrix<f64>,
    /// `∫₀ʰ exp(A τ) dτ · E`.
    pub ed: DMatrix<f64>,
    /// `Γ₂ = (1/h)∫₀ʰ exp(A(h−τ)) τ dτ · B` ([`ramp_gain`]), present when some experiment
    /// with this period has first-order-hold inputs.
    pub ramp: Option<DMatrix<f64>>,
}

/// Discretise `model` for each experiment (its period and its inputs' behaviour between
/// samples), sharing work between equal periods. The ramp gain is computed only for
/// experiments whose inputs are interpolated ([`InterSample::Foh`]).
pub(crate) fn discretize_all(
    model: &LinearModel,
    experiments: &[(f64, InterSample)],
    requested: Option<usize>,
) -> Result<Vec<Discrete>> {
    let mut out: Vec<Discrete> = Vec::with_capacity(experiments.len());
    for &(dt, hold) in experiments {
        let s = substeps_for(requested, model.a(), dt)?;
        // Bitwise-equal periods (the usual case) reuse the same matrices.
        let prev = out
            .iter()
            .find(|d| d.dt.to_bits() == dt.to_bits() && d.substeps == s)
            .cloned();
        let mut disc = match prev {
            Some(prev) => prev,
            None => {
                let h = dt / s as f64;
                let zoh = model.discretize(h)?;
                Discrete {
                    dt,
                    substeps: s,
                    h,
                    ad: zoh.ad,
                    bd: zoh.bd,
                    ed: zoh.ed,
                    ramp: None,
                }
            }
        };
        match hold {
            // Held inputs never read the ramp gain; drop a shared one.
            InterSample::Zoh => disc.ramp = None,
            InterSample::Foh => {
                if disc.ramp.is_none() {
                    disc.ramp = Some(ramp_gain(model.a(), model.b(), disc.h)?);
                }
            }
        }
        out.push(disc);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn substeps_follow_the_fastest_mode() {
        // Eigenvalues −1 and −50: τ_min = 0.02 s; dt = 0.01 → s = ceil(0.01/0.002) = 5.
        let a = DMatrix::from_row_slice(2, 2, &[-1.0, 0.0, 0.0, -50.0]);
        assert_eq!(default_substeps(&a, 0.01), 5);
        // Oscillator ω = 2 rad/s: τ = 0.5 s; dt = 0.01 → 1 sub-step.
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, 0.0]);
        assert_eq!(default_substeps(&a, 0.01), 1);
        assert_eq!(default_substeps(&DMatrix::zeros(2, 2), 1.0), 1);
        assert_eq!(default_substeps(&a, 1e6), MAX_DEFAULT_SUBSTEPS);
    }
}
