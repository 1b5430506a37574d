//! Bounds by a change of variable (as MINUIT and lmfit do): the solver moves an
//! unbounded `z`, the model sees `p(z)` inside `[lower, upper]`.
//!
//! - both bounds: `p = lo + (hi − lo)(1 + sin z)/2`;
//! - a lower bound only: `p = lo + s(√(1 + z²) − 1)` (upper only: mirrored), `s` the
//!   start's distance from the bound, so `z` starts at `√3`;
//! - none: `p = z`.
//!
//! A bound is reached where `dp/dz = 0` (`cos z = 0`, `z = 0`): a parameter whose
//! derivative there has fallen below [`AT_BOUND`] of its largest is reported at its bound
//! and left out of the covariance. A start exactly on a bound (where the derivative is
//! zero and the solver could never move it) is moved inside by [`NUDGE`] in `z`.

/// Below this fraction of its largest `|dp/dz|` a parameter counts as at its bound.
pub(crate) const AT_BOUND: f64 = 1e-3;

/// Distance in `z` a start on a bound is moved inside.
pub(crate) const NUDGE: f64 = 0.05;

/// The change of variable of one free parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Transform {
    /// No bound.
    Identity,
    /// Both bounds.
    Interval { lo: f64, hi: f64 },
    /// Lower bound only (`s` the scale).
    Lower { lo: f64, s: f64 },
    /// Upper bound only.
    Upper { hi: f64, s: f64 },
}

impl Transform {
    /// The transform for bounds `[lo, hi]` and the `z` of the start `p0` (inside them).
    pub fn new(lo: f64, hi: f64, p0: f64) -> (Self, f64) {
        let scale = |d: f64| {
            if d > 0.0 { d } else { 1e-3 * p0.abs().max(1.0) }
        };
        match (lo.is_finite(), hi.is_finite()) {
            (true, true) if hi > lo => {
                let z = (2.0 * (p0 - lo) / (hi - lo) - 1.0).clamp(-1.0, 1.0).asin();
                let limit = std::f64::consts::FRAC_PI_2 - NUDGE;
                (Transform::Interval { lo, hi }, z.clamp(-limit, limit))
            }
            // lo == hi: the grey-box estimation holds such a parameter at its value, out
            // of the solver (`free_parameters`), so no transform of it is ever used.
            (true, true) => (Transform::Identity, p0),
            (true, false) => {
                let s = scale(p0 - lo);
                let z = if p0 > lo { 3f64.sqrt() } else { NUDGE };
                (Transform::Lower { lo, s }, z)
            }
            (false, true) => {
                let s = scale(hi - p0);
                let z = if p0 < hi { 3f64.sqrt() } else { NUDGE };
                (Transform::Upper { hi, s }, z)
            }
            (false, false) => (Transform::Identity, p0),
        }
    }

    /// `p(z)`, inside the bounds.
    pub fn value(&self, z: f64) -> f64 {
        match *self {
            Transform::Identity => z,
            Transform::Interval { lo, hi } => {
                (lo + (hi - lo) * (1.0 + z.sin()) / 2.0).clamp(lo, hi)
            }
            Transform::Lower { lo, s } => lo + s * ((1.0 + z * z).sqrt() - 1.0),
            Transform::Upper { hi, s } => hi - s * ((1.0 + z * z).sqrt() - 1.0),
        }
    }

    /// `dp/dz`.
    pub fn derivative(&self, z: f64) -> f64 {
        match *self {
            Transform::Identity => 1.0,
            Transform::Interval { lo, hi } => (hi - lo) / 2.0 * z.cos(),
            Transform::Lower { s, .. } => s * z / (1.0 + z * z).sqrt(),
            Transform::Upper { s, .. } => -s * z / (1.0 + z * z).sqrt(),
        }
    }

    /// Which bound `z` sits on, if any (module doc).
    pub fn at_bound(&self, z: f64) -> Option<super::ActiveBound> {
        use super::ActiveBound::{Lower, Upper};
        match *self {
            Transform::Identity => None,
            Transform::Interval { .. } => {
                (z.cos().abs() < AT_BOUND).then_some(if z.sin() > 0.0 { Upper } else { Lower })
            }
            Transform::Lower { .. } => (z.abs() < AT_BOUND).then_some(Lower),
            Transform::Upper { .. } => (z.abs() < AT_BOUND).then_some(Upper),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_derivatives_match_differences() {
        for (lo, hi, p0) in [
            (0.0, 1.0, 0.3),
            (0.0, f64::INFINITY, 0.004),
            (f64::NEG_INFINITY, 2.0, -1.0),
            (f64::NEG_INFINITY, f64::INFINITY, 5.0),
        ] {
            let (t, z) = Transform::new(lo, hi, p0);
            // The start maps back to itself to rounding (relative 1e-12 of the range).
            assert!(
                (t.value(z) - p0).abs() <= 1e-12 * p0.abs().max(1.0),
                "{t:?}"
            );
            let h = 1e-6;
            let fd = (t.value(z + h) - t.value(z - h)) / (2.0 * h);
            // Central difference: error O(h²) ≈ 1e-12, relative 1e-8 is ample.
            assert!(
                (fd - t.derivative(z)).abs() <= 1e-8 * fd.abs().max(1e-6),
                "{t:?}"
            );
            assert!(t.at_bound(z).is_none());
        }
    }

    #[test]
    fn a_start_on_a_bound_is_moved_inside() {
        let (t, z) = Transform::new(0.0, 1.0, 0.0);
        assert!(t.value(z) > 0.0 && t.derivative(z) > 0.0);
        let (t, z) = Transform::new(0.0, f64::INFINITY, 0.0);
        assert!(t.value(z) > 0.0 && t.derivative(z) > 0.0);
        assert_eq!(
            t.at_bound(0.0),
            Some(crate::greybox::ActiveBound::Lower),
            "z = 0 is the bound"
        );
    }
}
