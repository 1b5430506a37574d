//! Sample auto- and cross-correlation (normalised, biased estimator, as in Box–Jenkins
//! and MATLAB's `autocorr`/`crosscorr`) with the large-sample confidence bound `±z/√N`.

use crate::error::{CoreError, Result};

/// Two-sided confidence level of a whiteness band.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Confidence {
    /// 95 % (z = 1.959964).
    P95,
    /// 99 % (z = 2.575829).
    P99,
}

impl Confidence {
    /// Standard-normal quantile `z` with `P(|Z| < z)` equal to the level.
    pub fn z(self) -> f64 {
        match self {
            Confidence::P95 => 1.959_963_984_540_054,
            Confidence::P99 => 2.575_829_303_548_901,
        }
    }
}

/// Band `±z/√N` within which the correlation of a white sequence of length `N` lies with
/// the given probability.
pub fn confidence_bound(samples: usize, level: Confidence) -> f64 {
    level.z() / (samples as f64).sqrt()
}

fn centred(x: &[f64], what: &'static str) -> Result<(Vec<f64>, f64)> {
    if x.len() < 2 {
        return Err(CoreError::TooFewSamples {
            what,
            found: x.len(),
            needed: 2,
        });
    }
    if let Some(k) = x.iter().position(|v| !v.is_finite()) {
        return Err(CoreError::InvalidArgument {
            name: what,
            value: k as f64,
            reason: "series is not finite at this sample index",
        });
    }
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let c: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let ss = c.iter().map(|v| v * v).sum::<f64>();
    Ok((c, ss))
}

/// Normalised autocorrelation `r(τ) = Σ_{k} x̃_k x̃_{k+τ} / Σ x̃_k²` for `τ = 0..=max_lag`
/// (`x̃` the mean-removed series). A constant series gives NaN beyond lag 0.
pub fn acf(x: &[f64], max_lag: usize) -> Result<Vec<f64>> {
    let (c, ss) = centred(x, "autocorrelation series")?;
    let n = c.len();
    Ok((0..=max_lag)
        .map(|tau| {
            if tau >= n {
                return 0.0;
            }
            let s: f64 = (0..n - tau).map(|k| c[k] * c[k + tau]).sum();
            s / ss
        })
        .collect())
}

/// Normalised cross-correlation `r_xy(τ) = Σ_k x̃_k ỹ_{k+τ} / √(Σx̃² Σỹ²)` for
/// `τ = −max_lag..=max_lag`; element `i` is lag `i − max_lag`. A positive lag means `y`
/// follows `x`.
pub fn xcf(x: &[f64], y: &[f64], max_lag: usize) -> Result<Vec<f64>> {
    CoreError::check_len("cross-correlation series", y.len(), x.len())?;
    let (cx, sx) = centred(x, "cross-correlation series x")?;
    let (cy, sy) = centred(y, "cross-correlation series y")?;
    let n = cx.len() as isize;
    let norm = (sx * sy).sqrt();
    let ml = max_lag as isize;
    Ok((-ml..=ml)
        .map(|tau| {
            let mut s = 0.0;
            for k in 0..n {
                let j = k + tau;
                if (0..n).contains(&j) {
                    s += cx[k as usize] * cy[j as usize];
                }
            }
            s / norm
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn acf_of_short_series_by_direct_formula() {
        let x = [1.0, 3.0, 2.0, 5.0, 4.0];
        // mean 3, centred [-2, 0, -1, 2, 1], ss = 10.
        let r = acf(&x, 2).unwrap();
        assert!((r[0] - 1.0).abs() < 1e-15);
        assert!((r[1] - (0.0 + 0.0 - 2.0 + 2.0) / 10.0).abs() < 1e-15);
        assert!((r[2] - (2.0 + 0.0 + -1.0) / 10.0).abs() < 1e-15);
    }

    #[test]
    fn xcf_of_delayed_copy_peaks_at_delay() {
        let x: Vec<f64> = (0..200).map(|k| ((k * 7919) % 101) as f64).collect();
        let y: Vec<f64> = (0..200)
            .map(|k| if k >= 3 { x[k - 3] } else { 0.0 })
            .collect();
        let r = xcf(&x, &y, 10).unwrap();
        let (imax, _) =
            r.iter().enumerate().fold(
                (0, f64::MIN),
                |a, (i, v)| if *v > a.1 { (i, *v) } else { a },
            );
        assert_eq!(imax as isize - 10, 3);
    }

    #[test]
    fn bounds() {
        assert!((confidence_bound(100, Confidence::P95) - 0.1959964).abs() < 1e-6);
    }
}
