//! Per-channel affine scaling of network inputs and outputs to [−1, 1] (the map of
//! MATLAB's `mapminmax`), stored inside the network.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::error::{NnError, Result, check_finite};

/// A channel whose range is at most this fraction of `max(1, |centre|)` counts as
/// constant: it is centred but not divided by its (near-zero) half-range.
///
/// Dividing by a range at round-off level (≈1e-16 relative) would turn noise into ±1
/// inputs; 1e-12 leaves four orders of margin above double-precision round-off.
pub const CONSTANT_CHANNEL_RTOL: f64 = 1e-12;

/// Affine map `s = (v − centre) / half_range` per channel.
///
/// [`Scaler::fit`] takes `centre = (min + max)/2` and `half_range = (max − min)/2`, so
/// the training data map exactly onto [−1, 1] (`mapminmax`). A constant channel gets
/// `half_range = 1`: it maps to 0 and no division by zero occurs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ScalerRaw")]
pub struct Scaler {
    centre: Vec<f64>,
    half_range: Vec<f64>,
}

#[derive(Deserialize)]
struct ScalerRaw {
    centre: Vec<f64>,
    half_range: Vec<f64>,
}

impl TryFrom<ScalerRaw> for Scaler {
    type Error = NnError;
    fn try_from(raw: ScalerRaw) -> Result<Self> {
        Scaler::new(raw.centre, raw.half_range)
    }
}

impl Scaler {
    /// A scaler from explicit centres and half-ranges.
    ///
    /// Errors: different lengths, an empty list, a non-finite centre, or a half-range that
    /// is not positive and finite.
    pub fn new(centre: Vec<f64>, half_range: Vec<f64>) -> Result<Self> {
        if centre.len() != half_range.len() {
            return Err(NnError::Length {
                what: "scaler half-ranges",
                found: half_range.len(),
                expected: centre.len(),
            });
        }
        if centre.is_empty() {
            return Err(NnError::ZeroDimension {
                what: "scaler channels",
                layer: 0,
            });
        }
        for (channel, (&c, &h)) in centre.iter().zip(&half_range).enumerate() {
            if !c.is_finite() {
                return Err(NnError::BadScaler {
                    channel,
                    reason: "centre must be finite",
                });
            }
            if !(h.is_finite() && h > 0.0) {
                return Err(NnError::BadScaler {
                    channel,
                    reason: "half-range must be positive and finite",
                });
            }
        }
        Ok(Self { centre, half_range })
    }

    /// The identity map on `n` channels (centre 0, half-range 1).
    pub fn identity(n: usize) -> Self {
        Self {
            centre: vec![0.0; n],
            half_range: vec![1.0; n],
        }
    }

    /// Fit to `channels × samples` data so each channel's min and max map to −1 and +1.
    ///
    /// Errors: zero channels, zero samples, a non-finite entry.
    pub fn fit(data: &DMatrix<f64>) -> Result<Self> {
        if data.nrows() == 0 {
            return Err(NnError::ZeroDimension {
                what: "scaler channels",
                layer: 0,
            });
        }
        if data.ncols() == 0 {
            return Err(NnError::TooFewSamples {
                what: "scaler fit",
                found: 0,
                needed: 1,
            });
        }
        check_finite("scaler data", data)?;
        let mut centre = Vec::with_capacity(data.nrows());
        let mut half_range = Vec::with_capacity(data.nrows());
        for row in data.row_iter() {
            let lo = row.min();
            let hi = row.max();
            let c = 0.5 * (lo + hi);
            let h = 0.5 * (hi - lo);
            centre.push(c);
            half_range.push(if h > CONSTANT_CHANNEL_RTOL * c.abs().max(1.0) {
                h
            } else {
                1.0
            });
        }
        Ok(Self { centre, half_range })
    }

    /// Number of channels.
    pub fn len(&self) -> usize {
        self.centre.len()
    }

    /// Whether the scaler has no channels (never true for a validated scaler).
    pub fn is_empty(&self) -> bool {
        self.centre.is_empty()
    }

    /// Centre of each channel (maps to 0).
    pub fn centre(&self) -> &[f64] {
        &self.centre
    }

    /// Half-range of each channel (a change of one half-range maps to a change of 1).
    pub fn half_range(&self) -> &[f64] {
        &self.half_range
    }

    /// Scale one sample into `out`: `s = (v − centre) / half_range`.
    pub(crate) fn scale_into(&self, v: &[f64], out: &mut [f64]) {
        for (((o, &x), &c), &h) in out
            .iter_mut()
            .zip(v)
            .zip(&self.centre)
            .zip(&self.half_range)
        {
            *o = (x - c) / h;
        }
    }

    /// Undo the scaling of one sample into `out`: `v = centre + half_range · s`.
    pub(crate) fn unscale_into(&self, s: &[f64], out: &mut [f64]) {
        for (((o, &x), &c), &h) in out
            .iter_mut()
            .zip(s)
            .zip(&self.centre)
            .zip(&self.half_range)
        {
            *o = c + h * x;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(
        clippy::float_cmp,
        reason = "every value here is exact in binary floating point"
    )]
    fn fit_maps_range_to_unit_interval_and_handles_constant_channel() {
        // Channel 0 spans [−3, 5]; channel 1 is constant 7.
        let data = DMatrix::from_row_slice(2, 3, &[-3.0, 1.0, 5.0, 7.0, 7.0, 7.0]);
        let s = Scaler::fit(&data).unwrap();
        let mut out = [0.0; 2];
        s.scale_into(&[-3.0, 7.0], &mut out);
        assert_eq!(out, [-1.0, 0.0]);
        s.scale_into(&[5.0, 7.0], &mut out);
        assert_eq!(out, [1.0, 0.0]);
        let mut back = [0.0; 2];
        s.unscale_into(&out, &mut back);
        assert_eq!(back, [5.0, 7.0]);
        assert_eq!(s.half_range()[1], 1.0);
    }

    #[test]
    fn rejects_bad_parameters() {
        assert!(matches!(
            Scaler::new(vec![0.0], vec![0.0]),
            Err(NnError::BadScaler { channel: 0, .. })
        ));
        assert!(matches!(
            Scaler::new(vec![0.0], vec![]),
            Err(NnError::Length { .. })
        ));
        let nan = DMatrix::from_row_slice(1, 2, &[0.0, f64::NAN]);
        assert!(matches!(
            Scaler::fit(&nan),
            Err(NnError::NonFinite {
                channel: 0,
                sample: 1,
                ..
            })
        ));
    }
}
