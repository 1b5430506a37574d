//! The noise floor of `d̂`: what MME's correction looks like when the assumed model is
//! right, at the same `W`, `R`, sampling and input. Discovery compares `d̂` against it.
//!
//! # How to obtain it
//!
//! MME's `d̂` is never exactly zero: even with a perfect model it follows the measurement
//! noise through the smoother, by an amount set by `W` and `R`. The reliable way to know
//! that amount is to measure it (this crate never calls the estimator; the caller does):
//!
//! 1. simulate the **assumed** model from the estimated initial state `x̂(t0)` with the
//!    measured inputs, so the data are model-consistent by construction;
//! 2. add Gaussian noise with the variance `R` used by MME;
//! 3. run MME on it with the same `W`, sub-steps and `E`;
//! 4. pass its `d̂` to [`NoiseFloor::from_corrections`] (or the whole estimate to
//!    [`NoiseFloor::from_estimate`]).
//!
//! The floor keeps, per corrected equation, the RMS of that `d̂` and its effective-sample
//! ratio `N_eff/N` (Bartlett, [`crate::stats::effective_sample_size`]): `d̂` is smooth, so
//! its samples are far from independent, and every significance test against the floor
//! counts samples by `N_eff`.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::MmeEstimate;

use crate::error::{DiscoveryError, Result};
use crate::samples::centred_corrections;
use crate::stats::effective_sample_size;

/// RMS and effective-sample ratio of `d̂` under a correct model, per corrected equation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NoiseFloor {
    /// RMS of `d̂` under a correct model, per corrected equation (units of `ẋ_i`; ≥ 0).
    pub rms: Vec<f64>,
    /// `N_eff/N` of that `d̂`, per corrected equation (in `(0, 1]`; 1 = white).
    pub neff_ratio: Vec<f64>,
}

impl NoiseFloor {
    /// A floor from known values; errors name the equation and the bad value.
    pub fn new(rms: Vec<f64>, neff_ratio: Vec<f64>) -> Result<Self> {
        if rms.len() != neff_ratio.len() {
            return Err(DiscoveryError::Length {
                what: "noise floor neff_ratio vs rms",
                found: neff_ratio.len(),
                expected: rms.len(),
            });
        }
        for (equation, (&r, &q)) in rms.iter().zip(&neff_ratio).enumerate() {
            if !(r.is_finite() && r >= 0.0) {
                return Err(DiscoveryError::InvalidFloor {
                    what: "rms",
                    equation,
                    value: r,
                    reason: "must be finite and non-negative",
                });
            }
            if !(q.is_finite() && q > 0.0 && q <= 1.0) {
                return Err(DiscoveryError::InvalidFloor {
                    what: "neff_ratio",
                    equation,
                    value: q,
                    reason: "must be in (0, 1]",
                });
            }
        }
        Ok(Self { rms, neff_ratio })
    }

    /// A zero floor for `q` equations (noise-free corrections, e.g. a plant's truth):
    /// any nonzero `d̂` is significant.
    pub fn zero(q: usize) -> Self {
        Self {
            rms: vec![0.0; q],
            neff_ratio: vec![1.0; q],
        }
    }

    /// The floor from `d̂` at the samples of a run on model-consistent data, one `q × N`
    /// matrix per experiment (see the module doc for the recipe).
    pub fn from_corrections(runs: &[&DMatrix<f64>]) -> Result<Self> {
        let Some(first) = runs.first() else {
            return Err(DiscoveryError::TooFewSamples {
                what: "noise floor runs",
                found: 0,
                needed: 1,
            });
        };
        let q = first.nrows();
        let mut rms = Vec::with_capacity(q);
        let mut ratio = Vec::with_capacity(q);
        for i in 0..q {
            let mut rows: Vec<Vec<f64>> = Vec::with_capacity(runs.len());
            for (e, run) in runs.iter().enumerate() {
                if run.nrows() != q {
                    return Err(DiscoveryError::Shape {
                        what: "noise floor corrections",
                        experiment: e,
                        rows: run.nrows(),
                        cols: run.ncols(),
                        expected_rows: q,
                        expected_cols: run.ncols(),
                    });
                }
                let row: Vec<f64> = run.row(i).iter().copied().collect();
                if let Some(k) = row.iter().position(|v| !v.is_finite()) {
                    return Err(DiscoveryError::NonFinite {
                        what: "noise floor corrections",
                        experiment: e,
                        row: i,
                        sample: k,
                    });
                }
                rows.push(row);
            }
            let n: usize = rows.iter().map(Vec::len).sum();
            if n < 3 {
                return Err(DiscoveryError::TooFewSamples {
                    what: "noise floor",
                    found: n,
                    needed: 3,
                });
            }
            let ss: f64 = rows.iter().flatten().map(|v| v * v).sum();
            rms.push((ss / n as f64).sqrt());
            let segments: Vec<&[f64]> = rows.iter().map(Vec::as_slice).collect();
            ratio.push(effective_sample_size(&segments) / n as f64);
        }
        Self::new(rms, ratio)
    }

    /// The floor from a whole MME estimate on model-consistent data (corrections centred
    /// on the samples, as discovery uses them).
    pub fn from_estimate(estimate: &MmeEstimate) -> Result<Self> {
        let d: Vec<DMatrix<f64>> = estimate
            .experiments
            .iter()
            .map(centred_corrections)
            .collect();
        let refs: Vec<&DMatrix<f64>> = d.iter().collect();
        Self::from_corrections(&refs)
    }

    /// Number of corrected equations.
    pub fn len(&self) -> usize {
        self.rms.len()
    }

    /// True when the floor covers no equation.
    pub fn is_empty(&self) -> bool {
        self.rms.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rms_and_ratio_from_runs() {
        // Alternating ±2 (ρ₁ = −1 ⇒ N_eff = N) in one row, constant 3 (no variance ⇒ N) in
        // the other; two experiments pooled.
        let a = DMatrix::from_fn(2, 10, |i, k| {
            if i == 0 {
                if k % 2 == 0 { 2.0 } else { -2.0 }
            } else {
                3.0
            }
        });
        let f = NoiseFloor::from_corrections(&[&a, &a]).unwrap_or_else(|e| panic!("{e}"));
        assert!((f.rms[0] - 2.0).abs() < 1e-15 && (f.rms[1] - 3.0).abs() < 1e-15);
        assert!((f.neff_ratio[0] - 1.0).abs() < 1e-15);
    }

    #[test]
    fn invalid_floors_are_named() {
        assert!(matches!(
            NoiseFloor::new(vec![0.1, -1.0], vec![1.0, 1.0]),
            Err(DiscoveryError::InvalidFloor {
                what: "rms",
                equation: 1,
                ..
            })
        ));
        assert!(matches!(
            NoiseFloor::new(vec![0.1], vec![0.0]),
            Err(DiscoveryError::InvalidFloor {
                what: "neff_ratio",
                equation: 0,
                ..
            })
        ));
        assert!(NoiseFloor::from_corrections(&[]).is_err());
    }
}
