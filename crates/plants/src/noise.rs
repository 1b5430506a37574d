//! Seeded Gaussian measurement noise (ChaCha8: the same seed and stream give the same
//! numbers on every platform and rand version that keeps the ChaCha8 stream).

use nalgebra::DMatrix;
use rand::SeedableRng;
use rand::rngs::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::error::{PlantError, Result};

/// Zero-mean Gaussian noise, `variances.len() × len`, row `i` with variance
/// `variances[i]` (0 gives an exact zero row).
///
/// Draws come from `ChaCha8Rng::seed_from_u64(seed)` on ChaCha stream `stream`, channel by
/// channel (all of row 0, then row 1, …), so a channel's noise does not depend on the
/// variances of the others. Use different `stream`s for records that share a seed.
pub fn gaussian_noise(
    variances: &[f64],
    len: usize,
    seed: u64,
    stream: u64,
) -> Result<DMatrix<f64>> {
    for &v in variances {
        if !(v.is_finite() && v >= 0.0) {
            return Err(PlantError::InvalidArgument {
                name: "noise variance",
                value: v,
                reason: "must be non-negative and finite",
            });
        }
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    let mut out = DMatrix::zeros(variances.len(), len);
    for (i, &v) in variances.iter().enumerate() {
        let sd = v.sqrt();
        for k in 0..len {
            let z: f64 = StandardNormal.sample(&mut rng);
            out[(i, k)] = sd * z;
        }
    }
    Ok(out)
}

/// Add [`gaussian_noise`] to `values` in place (`variances.len()` must equal the rows).
pub fn add_noise(
    values: &mut DMatrix<f64>,
    variances: &[f64],
    seed: u64,
    stream: u64,
) -> Result<()> {
    if variances.len() != values.nrows() {
        return Err(PlantError::InvalidArgument {
            name: "noise variances",
            value: variances.len() as f64,
            reason: "need one variance per row",
        });
    }
    let noise = gaussian_noise(variances, values.ncols(), seed, stream)?;
    *values += noise;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sample variance of N draws has relative standard deviation √(2/(N−1))
    /// (≈ 1 % for N = 20 000); 5 % is five of those. The sample mean has standard
    /// deviation σ/√N, checked to 5σ/√N.
    #[test]
    fn variance_mean_and_determinism() {
        let n = 20_000;
        let vars = [0.09, 1e-4, 0.0];
        let a = gaussian_noise(&vars, n, 42, 0).unwrap();
        for (i, &v) in vars.iter().enumerate() {
            let row = a.row(i);
            let mean = row.sum() / n as f64;
            let var = row.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
            if v == 0.0 {
                assert!(row.iter().all(|x| *x == 0.0));
            } else {
                assert!(
                    (var / v - 1.0).abs() < 5.0 * (2.0 / (n - 1) as f64).sqrt(),
                    "row {i}: {var}"
                );
                assert!(
                    mean.abs() < 5.0 * (v / n as f64).sqrt(),
                    "row {i}: mean {mean}"
                );
            }
        }
        assert_eq!(a, gaussian_noise(&vars, n, 42, 0).unwrap());
        assert_ne!(a, gaussian_noise(&vars, n, 43, 0).unwrap());
        assert_ne!(a, gaussian_noise(&vars, n, 42, 1).unwrap());
        // Row 0 does not depend on the other rows' variances.
        let b = gaussian_noise(&vars[..1], n, 42, 0).unwrap();
        assert_eq!(a.row(0), b.row(0));
        assert!(gaussian_noise(&[-1.0], 3, 0, 0).is_err());
    }
}
