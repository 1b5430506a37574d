//! Principal-component projection of NARX regressors: keep only the directions of the
//! regressor space that the training data actually excites.
//!
//! With many lags of a smoothly sampled signal the regressor vectors of the training data
//! lie close to a low-dimensional surface (the plant's state and input); a network can
//! then weigh the unexcited directions arbitrarily, and the free run, whose own errors
//! leave that surface, or a new input, which runs along another part of it, goes astray.
//! Projecting onto the principal components whose spread is at least `rtol` of the
//! largest removes those directions (the input processing MATLAB's neural-network
//! toolbox calls `processpca`; Jolliffe, *Principal Component Analysis*, 2002, §8.1 on
//! principal-component regression).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::error::{BaselineError, Result};

/// `z = V · ((φ − c) ⊘ s)`: centre, per-element scale, then the kept principal directions.
/// Deserialisation checks that the parts fit together.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ProjectionRaw")]
pub struct RegressorProjection {
    centre: Vec<f64>,
    scale: Vec<f64>,
    /// `r × n_reg`, rows are orthonormal principal directions.
    basis: DMatrix<f64>,
    /// Relative spread `σ_i/σ_1` of every component (kept or not), in decreasing order.
    spread: Vec<f64>,
}

#[derive(Deserialize)]
struct ProjectionRaw {
    centre: Vec<f64>,
    scale: Vec<f64>,
    basis: DMatrix<f64>,
    spread: Vec<f64>,
}

impl TryFrom<ProjectionRaw> for RegressorProjection {
    type Error = BaselineError;
    fn try_from(r: ProjectionRaw) -> Result<Self> {
        let n = r.basis.ncols();
        for (what, len) in [
            ("projection centre vs basis columns", r.centre.len()),
            ("projection scale vs basis columns", r.scale.len()),
            ("projection spread vs basis columns", r.spread.len()),
        ] {
            if len != n {
                return Err(BaselineError::Dimension {
                    what,
                    found: len,
                    expected: n,
                });
            }
        }
        if r.basis.nrows() == 0
            || r.basis.iter().chain(&r.centre).any(|v| !v.is_finite())
            || r.scale.iter().any(|s| !(s.is_finite() && *s > 0.0))
        {
            return Err(BaselineError::InvalidConfig {
                field: "projection",
                value: r.basis.nrows() as f64,
                reason: "needs at least one direction, finite entries and positive scales",
            });
        }
        Ok(Self {
            centre: r.centre,
            scale: r.scale,
            basis: r.basis,
            spread: r.spread,
        })
    }
}

impl RegressorProjection {
    /// Fit to regressors `n_reg × rows`. `blocks` gives the length of each channel's
    /// block of consecutive lags; every element of a block is scaled by the block's
    /// pooled standard deviation (so the lag structure within a channel is kept while
    /// channels of different units weigh the same). Components with spread below `rtol`
    /// of the largest are dropped.
    ///
    /// Errors: fewer than 2 rows, blocks not covering the regressor, `rtol` outside [0, 1).
    pub fn fit(regressors: &DMatrix<f64>, blocks: &[usize], rtol: f64) -> Result<Self> {
        let (n, rows) = regressors.shape();
        if rows < 2 {
            return Err(BaselineError::TooFewRows {
                what: "regressor rows for the principal-component projection",
                found: rows,
                needed: 2,
            });
        }
        if blocks.iter().sum::<usize>() != n {
            return Err(BaselineError::Dimension {
                what: "regressor blocks vs regressor length",
                found: blocks.iter().sum(),
                expected: n,
            });
        }
        if !(0.0..1.0).contains(&rtol) {
            return Err(BaselineError::InvalidConfig {
                field: "projection.rtol",
                value: rtol,
                reason: "must be in [0, 1)",
            });
        }
        let centre: Vec<f64> = regressors.row_iter().map(|r| r.mean()).collect();
        let mut scale = vec![1.0; n];
        let mut start = 0;
        for &len in blocks {
            let ss: f64 = (start..start + len)
                .map(|i| {
                    regressors
                        .row(i)
                        .iter()
                        .map(|v| (v - centre[i]).powi(2))
                        .sum::<f64>()
                })
                .sum();
            let sd = (ss / (len * (rows - 1)).max(1) as f64).sqrt();
            let sd = if sd > 0.0 { sd } else { 1.0 };
            scale[start..start + len].iter_mut().for_each(|s| *s = sd);
            start += len;
        }
        let z = DMatrix::from_fn(n, rows, |i, k| (regressors[(i, k)] - centre[i]) / scale[i]);
        // SVD of the scaled data itself (not of its covariance), so that spreads are
        // resolved to round-off ε rather than √ε.
        let svd = z.svd(true, false);
        let Some(u) = svd.u else {
            return Err(BaselineError::TooFewRows {
                what: "regressor rows for the principal-component projection",
                found: rows,
                needed: 2,
            });
        };
        let sv = &svd.singular_values;
        let mut order: Vec<usize> = (0..sv.len()).collect();
        order.sort_by(|&a, &b| sv[b].total_cmp(&sv[a]));
        let top = sv[order[0]];
        let mut spread: Vec<f64> = order
            .iter()
            .map(|&i| if top > 0.0 { sv[i] / top } else { 0.0 })
            .collect();
        // A wide matrix has fewer singular values than regressor elements; the missing
        // directions have no spread at all.
        spread.resize(n, 0.0);
        let kept: Vec<usize> = order
            .iter()
            .zip(&spread)
            .filter(|(_, s)| **s >= rtol && **s > 0.0)
            .map(|(i, _)| *i)
            .collect();
        let basis = DMatrix::from_fn(kept.len().max(1), n, |r, c| {
            kept.get(r).map_or(0.0, |&i| u[(c, i)])
        });
        Ok(Self {
            centre,
            scale,
            basis,
            spread,
        })
    }

    /// Number of kept components (the network's input count).
    pub fn dim(&self) -> usize {
        self.basis.nrows()
    }

    /// Regressor length it reads.
    pub fn input_len(&self) -> usize {
        self.basis.ncols()
    }

    /// Relative spread `σ_i/σ_1` of every principal component, decreasing.
    pub fn spread(&self) -> &[f64] {
        &self.spread
    }

    /// Project one regressor into `z` (`dim()` long); `tmp` is scratch of the regressor's
    /// length.
    pub fn apply(&self, phi: &[f64], tmp: &mut [f64], z: &mut [f64]) {
        for (i, t) in tmp.iter_mut().enumerate() {
            *t = (phi[i] - self.centre[i]) / self.scale[i];
        }
        for (r, zr) in z.iter_mut().enumerate() {
            *zr = self
                .basis
                .row(r)
                .iter()
                .zip(tmp.iter())
                .map(|(a, b)| a * b)
                .sum();
        }
    }

    /// `∂z/∂φ` (`dim × n_reg`): the kept directions with each column divided by its
    /// element's scale (the projection is affine).
    pub fn jacobian(&self) -> DMatrix<f64> {
        DMatrix::from_fn(self.basis.nrows(), self.basis.ncols(), |i, v| {
            self.basis[(i, v)] / self.scale[v]
        })
    }

    /// Project every column of `n_reg × rows`.
    pub fn apply_all(&self, regressors: &DMatrix<f64>) -> DMatrix<f64> {
        let z = DMatrix::from_fn(regressors.nrows(), regressors.ncols(), |i, k| {
            (regressors[(i, k)] - self.centre[i]) / self.scale[i]
        });
        &self.basis * z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on the line `t·(1, 2, −1)` plus a tiny wobble of relative size 1e-6 in
    /// another direction: one component has spread 1, the wobble ~1e-6, the third 0
    /// (round-off, ~1e-16).
    #[test]
    fn keeps_only_the_excited_directions() {
        let rows = 200;
        let m = DMatrix::from_fn(3, rows, |i, k| {
            let t = (k as f64 * 0.37).sin();
            let wobble = 1e-6 * (k as f64 * 1.1).cos();
            [1.0, 2.0, -1.0][i] * t + [0.0, 1.0, 2.0][i] * wobble
        });
        let p = RegressorProjection::fit(&m, &[3], 1e-3).unwrap();
        assert_eq!(p.dim(), 1);
        assert!(p.spread()[1] < 1e-5 && p.spread()[1] > 1e-7);
        let keep_all = RegressorProjection::fit(&m, &[3], 1e-9).unwrap();
        assert_eq!(keep_all.dim(), 2);
        // The projection of a point is its coordinate along the line (up to sign).
        let mut tmp = [0.0; 3];
        let mut z = [0.0];
        let zs = p.apply_all(&m);
        p.apply(m.column(5).as_slice(), &mut tmp, &mut z);
        assert!((z[0] - zs[(0, 5)]).abs() < 1e-14);
    }
}
