//! Choice of the sub-step count and the exact discretisation of the assumed linear
//! model (held inputs, plus the ramp term for first-order-hold inputs), once per distinct
//! sample period.

use nalgebra::DMatrix;
pub use sysid_core::ramp_gain;
use sysid_core::stiff::spectral_radius;
use sysid_core::{InterSample, LinearModel};

use crate::error::{MmeError, Result};

/// Most sub-steps the automatic choice will pick.
pub const MAX_DEFAULT_SUBSTEPS: usize = 64;

/// Fraction of the fastest model time constant that one sub-step may span by default.
pub const SUBSTEP_FRACTION: f64 = 0.1;

/// Most sub-steps per sample interval a user may ask for (`--substeps`). Checked before
/// anything is allocated.
pub const MAX_SUBSTEPS: usize = 1000;

/// Most bytes the sub-step grid of one experiment may need (estimated by
/// [`sweep_bytes`]): 4 GiB. Checked before anything of that size is allocated.
pub const MAX_SWEEP_BYTES: u128 = 4 << 30;

/// Estimated bytes of the per-sub-step storage of a sweep with `n` states and `q`
/// corrections over `steps` sub-steps, in `f64`s: for a linear model the pieces `d_j` and
/// the gains `F_j`, `f_j`; for a nonlinear one also the linearisation `Φ_j`, `Γ_j`, `c_j`
/// and the trajectory `x_j`, `d_j` (current and trial).
pub fn sweep_bytes(n: usize, q: usize, steps: usize, nonlinear: bool) -> u128 {
    let (n, q) = (n as u128, q as u128);
    let per_step = if nonlinear {
        n * n + n * q + n + 3 * (n + q) + q * n + q
    } else {
        q * n + 2 * q
    };
    8 * per_step * steps as u128
}

/// Check an experiment's sub-step grid against [`MAX_SWEEP_BYTES`].
pub(crate) fn check_grid(
    experiment: usize,
    samples: usize,
    substeps: usize,
    n: usize,
    q: usize,
    nonlinear: bool,
) -> Result<()> {
    let steps = (samples.saturating_sub(1) as u128) * substeps as u128;
    let bytes = sweep_bytes(n, q, 1, nonlinear).saturating_mul(steps);
    if bytes > MAX_SWEEP_BYTES {
        return Err(MmeError::TooLarge {
            experiment,
            samples,
            substeps,
            steps: usize::try_from(steps).unwrap_or(usize::MAX),
            bytes,
            limit: MAX_SWEEP_BYTES,
        });
    }
    Ok(())
}

/// Default sub-steps for a model `ẋ = A x + …` sampled every `dt`: the smallest `s ≥ 1`
/// with `dt/s ≤ SUBSTEP_FRACTION · τ_min`, where `τ_min = 1/max|λ(A)|` is the fastest
/// time constant (or inverse natural frequency) of `A`, capped at
/// [`MAX_DEFAULT_SUBSTEPS`]. A model with `A = 0` (pure integrators) gets `s = 1`, and
/// so does an empty `A` or one with a non-finite entry (callers check finiteness first
/// and report it; this function never panics and never loops).
///
/// The discretisation is exact for piecewise-constant `d` at any `s`; sub-steps only refine
/// the time resolution of `d̂` where the model itself moves fast within one sample.
pub fn default_substeps(a: &DMatrix<f64>, dt: f64) -> usize {
    let Some(rate) = spectral_radius(a) else {
        return 1;
    };
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

/// Largest `|h·λ|` a sub-step may span on a fast relaxation mode of a stiff model:
/// sysid-core's rule for free runs (`sysid_core::stiff`), the same bound here.
pub use sysid_core::stiff::STIFF_STEP;

/// Default sub-steps for the nonlinear estimator, from the model's Jacobian `a` at the
/// start: [`default_substeps`], unless that rule asks for more than
/// [`MAX_DEFAULT_SUBSTEPS`] — the model is stiff at this sample period, as a steep
/// friction law makes it near zero velocity. Then the accuracy rule (`dt/s ≤ τ/10`)
/// applies only to the modes that are not fast relaxations, and a fast relaxation
/// (eigenvalue with `Re λ < 0` and `|Im λ| ≤ |Re λ|`) only has to be stable:
/// `|h·λ| ≤ STIFF_STEP`. The count is capped at [`MAX_DEFAULT_SUBSTEPS`] as before, so a
/// stiff model never takes more sub-steps than it did, and a model that is not stiff
/// takes exactly as many.
pub fn nonlinear_substeps(a: &DMatrix<f64>, dt: f64) -> usize {
    let wanted = |rate: f64, fraction: f64| -> f64 {
        let s = (dt * rate / fraction).ceil();
        if s.is_finite() && s >= 1.0 { s } else { 1.0 }
    };
    let base = default_substeps(a, dt);
    let Some(rate) = spectral_radius(a) else {
        return base;
    };
    if wanted(rate, SUBSTEP_FRACTION) <= MAX_DEFAULT_SUBSTEPS as f64 {
        return base;
    }
    let Some(schur) = nalgebra::linalg::Schur::try_new(
        a.clone(),
        f64::EPSILON,
        sysid_core::stiff::SCHUR_MAX_ITERATIONS,
    ) else {
        return base;
    };
    let (mut slow, mut fast) = (0.0_f64, 0.0_f64);
    for z in schur.complex_eigenvalues().iter() {
        if z.re < 0.0 && z.im.abs() <= -z.re {
            fast = fast.max(z.norm());
        } else {
            slow = slow.max(z.norm());
        }
    }
    let s = wanted(slow, SUBSTEP_FRACTION).max(wanted(fast, STIFF_STEP));
    (s as usize).clamp(1, MAX_DEFAULT_SUBSTEPS)
}

/// The sub-step count to use for an experiment sampled every `dt`.
pub(crate) fn substeps_for(requested: Option<usize>, a: &DMatrix<f64>, dt: f64) -> Result<usize> {
    match requested {
        Some(0) => Err(MmeError::InvalidSetting {
            name: "substeps",
            value: 0.0,
            reason: "need at least one sub-step per sample",
        }),
        Some(s) if s > MAX_SUBSTEPS => Err(MmeError::InvalidSetting {
            name: "substeps",
            value: s as f64,
            reason: "at most MAX_SUBSTEPS = 1000 sub-steps per sample interval",
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

/// Discretise `model` for each experiment (its period, its inputs' behaviour between
/// samples and its sample count, checked against [`MAX_SWEEP_BYTES`]), sharing work between equal periods. The ramp gain is computed only for
/// experiments whose inputs are interpolated ([`InterSample::Foh`]).
pub(crate) fn discretize_all(
    model: &LinearModel,
    experiments: &[(f64, InterSample, usize)],
    requested: Option<usize>,
) -> Result<Vec<Discrete>> {
    let mut out: Vec<Discrete> = Vec::with_capacity(experiments.len());
    for (e, &(dt, hold, samples)) in experiments.iter().enumerate() {
        let s = substeps_for(requested, model.a(), dt)?;
        check_grid(
            e,
            samples,
            s,
            model.n_states(),
            model.n_corrections(),
            false,
        )?;
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
            // MME reads a band-limited input as linear between samples.
            InterSample::Foh | InterSample::Bl => {
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

    #[test]
    fn degenerate_matrices_give_one_substep_without_panicking_or_looping() {
        assert_eq!(default_substeps(&DMatrix::zeros(0, 0), 0.1), 1);
        let nan = DMatrix::from_row_slice(2, 2, &[f64::NAN, 1.0, 0.0, -1.0]);
        assert_eq!(default_substeps(&nan, 0.1), 1);
        let inf = DMatrix::from_row_slice(2, 2, &[0.0, f64::INFINITY, 0.0, -1.0]);
        assert_eq!(default_substeps(&inf, 0.1), 1);
        // Huge but finite entries: finishes, capped.
        let big = DMatrix::from_row_slice(2, 2, &[1e300, -1e300, 1e300, 1e300]);
        assert_eq!(default_substeps(&big, 0.1), MAX_DEFAULT_SUBSTEPS);
    }

    #[test]
    fn requested_substeps_are_capped_before_allocating() {
        let a = DMatrix::zeros(1, 1);
        assert!(substeps_for(Some(MAX_SUBSTEPS), &a, 0.1).is_ok());
        assert!(matches!(
            substeps_for(Some(MAX_SUBSTEPS + 1), &a, 0.1),
            Err(MmeError::InvalidSetting {
                name: "substeps",
                ..
            })
        ));
        assert!(matches!(
            substeps_for(Some(4_294_967_296), &a, 0.1),
            Err(MmeError::InvalidSetting { .. })
        ));
        assert!(check_grid(0, 1_000_000, 64, 3, 1, false).is_ok());
        assert!(check_grid(0, 1_000_000, 8, 3, 1, true).is_ok());
        assert!(matches!(
            check_grid(0, 1_000_000, 64, 3, 1, true),
            Err(MmeError::TooLarge { .. })
        ));
        assert!(matches!(
            check_grid(0, 10_000_000, 1000, 3, 1, false),
            Err(MmeError::TooLarge { .. })
        ));
    }
}
