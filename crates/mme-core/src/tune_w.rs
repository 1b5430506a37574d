//! The automatic `W` (covariance constraint, thesis §2.2–2.3): a bracketed root find in
//! `log α` of `ρ(α) = target`, where `W = α·shape` and `ρ` is the observation-weighted
//! mean of `residual_variance_i / R_i` (see [`crate::AutoWeight`]).
//!
//! Bracketing grows `α` (or shrinks it) by factors of 100 from the initial value until
//! `ρ − target` changes sign; the root is then polished by the Illinois variant of
//! regula falsi on `log α` (Dowell & Jarratt 1971), which converges superlinearly and
//! never leaves the bracket. If `ρ` stops changing before the sign changes (the penalty
//! no longer matters: `d̂ ≈ 0`, or the fit already interpolates), the search ends with
//! [`Termination::NotBracketed`] at the end closest to the target.

use nalgebra::DMatrix;
use sysid_core::Termination;

use crate::config::AutoWeight;
use crate::error::Result;
use crate::evaluate::Solve;
use crate::observe::{MmeEvent, MmeObserver};
use crate::result::{WCurvePoint, WSearch};
use crate::sweep::LogDet;

/// Bracket growth per step, in `ln α` (a factor of 100).
const BRACKET_STEP: f64 = 4.605_170_185_988_091;

/// Furthest the bracket search goes from the initial `α`, in `ln α` (30 decades).
const BRACKET_SPAN: f64 = 69.077_552_789_821_37;

/// `ρ` counts as saturated when two bracket steps change it by less than this (relative).
const SATURATION: f64 = 1e-9;

/// Find `α`; every evaluation is appended to `curve` (sorted by `α` on return) and told
/// to `observer` as it finishes ([`MmeEvent::WTrial`]).
pub(crate) fn tune<S: Solve>(
    solver: &mut S,
    shape: &DMatrix<f64>,
    inv_r: &[f64],
    opts: &AutoWeight,
    curve: &mut Vec<WCurvePoint>,
    observer: &dyn MmeObserver,
) -> Result<WSearch> {
    let start = curve.len();
    let count = |curve: &[WCurvePoint]| curve.len() - start;
    let eval = |z: f64, solver: &mut S, curve: &mut Vec<WCurvePoint>| -> Result<f64> {
        let alpha = z.exp();
        let w = shape * alpha;
        // So small a W that the corrections absorb everything leaves the free initial
        // state undetermined; that is the W → 0 limit, where the residuals vanish
        // (ratio 0), not a failure of the search.
        let (residual_variance, ratio, f) = match solver.solve(&w, inv_r, LogDet::Skip) {
            Err(crate::MmeError::NotObservable { .. }) => (vec![0.0; inv_r.len()], 0.0, -1.0),
            other => {
                let s = other?;
                let ratio = s.ratio(inv_r);
                (
                    s.residual_variance(),
                    ratio,
                    ratio / opts.target_ratio - 1.0,
                )
            }
        };
        curve.push(WCurvePoint {
            alpha,
            residual_variance,
            ratio,
        });
        observer.event(&MmeEvent::WTrial {
            trial: curve.len() - start,
            max_trials: opts.max_evaluations,
            alpha,
            ratio,
            target: opts.target_ratio,
        });
        Ok(f)
    };
    let done = |z: f64, f: f64, termination, evaluations| WSearch {
        alpha: z.exp(),
        ratio: (f + 1.0) * opts.target_ratio,
        termination,
        evaluations,
    };
    let budget = opts.max_evaluations;
    let z0 = opts.initial.ln();
    let f0 = eval(z0, solver, curve)?;
    if f0.abs() <= opts.tolerance {
        sort(curve);
        return Ok(done(z0, f0, Termination::Converged, 1));
    }
    // Residual too large ⇒ penalty too strong ⇒ smaller α.
    let dir = if f0 > 0.0 { -1.0 } else { 1.0 };
    let (mut za, mut fa) = (z0, f0);
    let (zb, fb) = loop {
        let z = za + dir * BRACKET_STEP;
        let f = eval(z, solver, curve)?;
        if f.abs() <= opts.tolerance {
            sort(curve);
            return Ok(done(z, f, Termination::Converged, count(curve)));
        }
        if f.signum() != fa.signum() {
            break (z, f);
        }
        let saturated = (f - fa).abs() <= SATURATION * (1.0 + f.abs());
        if saturated || (z - z0).abs() >= BRACKET_SPAN || count(curve) >= budget {
            sort(curve);
            let term = if count(curve) >= budget {
                Termination::MaxIterations
            } else {
                Termination::NotBracketed
            };
            return Ok(done(z, f, term, count(curve)));
        }
        za = z;
        fa = f;
    };
    // Illinois iteration on [za, zb] with fa·fb < 0.
    let (mut a, mut f_a, mut b, mut f_b) = (za, fa, zb, fb);
    let mut side = 0i8;
    loop {
        let z = (a * f_b - b * f_a) / (f_b - f_a);
        let f = eval(z, solver, curve)?;
        if f.abs() <= opts.tolerance {
            sort(curve);
            return Ok(done(z, f, Termination::Converged, count(curve)));
        }
        if f.signum() == f_b.signum() {
            b = z;
            f_b = f;
            if side == -1 {
                f_a *= 0.5;
            }
            side = -1;
        } else {
            a = z;
            f_a = f;
            if side == 1 {
                f_b *= 0.5;
            }
            side = 1;
        }
        // The ratio is flat in α at round-off level: no better root exists.
        if (b - a).abs() <= 1e-12 * (1.0 + a.abs()) || count(curve) >= budget {
            sort(curve);
            let term = if count(curve) >= budget {
                Termination::MaxIterations
            } else {
                Termination::Converged
            };
            return Ok(done(z, f, term, count(curve)));
        }
    }
}

fn sort(curve: &mut [WCurvePoint]) {
    curve.sort_by(|a, b| a.alpha.total_cmp(&b.alpha));
}
