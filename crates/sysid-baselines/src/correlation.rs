//! Correlation analysis: autocorrelation, partial autocorrelation (Durbin–Levinson) and
//! cross-correlation of series that may have missing samples and may come in several
//! experiments, returned as [`Correlogram`]s carrying their 95 % and 99 % bands.
//!
//! A single complete series is handed to `sysid_core::{acf, xcf}`. With missing samples
//! (NaN) or several experiments, the same normalised estimator is pooled: each
//! experiment is centred on the mean of its own valid samples, lagged products are summed
//! over pairs where both samples are present, and the sums of every experiment are added
//! before dividing by the pooled sums of squares. On one complete series the two agree
//! exactly (tested).

use serde::{Deserialize, Serialize};
use sysid_core::{Confidence, confidence_bound};

use crate::error::{BaselineError, Result};

/// Relative floor of the Durbin–Levinson prediction-error variance: below
/// `PACF_VARIANCE_FLOOR · r(0)` the series is predicted exactly (to working precision) by
/// the lags already used, and partial autocorrelations at higher lags are reported as 0.
/// Round-off in the recursion is of order `ε·k` relative at lag `k`, so 1e-12 keeps well
/// clear of it for any lag count used here.
pub const PACF_VARIANCE_FLOOR: f64 = 1e-12;

/// Which correlation a [`Correlogram`] holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CorrelationKind {
    /// Autocorrelation `r(τ)`, lags `0..=max_lag`.
    Auto,
    /// Partial autocorrelation `φ(τ, τ)`, lags `0..=max_lag` (lag 0 is 1 by convention).
    Partial,
    /// Cross-correlation `r_xy(τ)`, lags `−max_lag..=max_lag`; a positive lag means the
    /// second series follows the first.
    Cross,
}

/// A correlation sequence with its lags and whiteness bands.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Correlogram {
    /// What it holds.
    pub kind: CorrelationKind,
    /// Lag of each value, samples.
    pub lags: Vec<i64>,
    /// Correlation at each lag, in [−1, 1] (NaN for a constant series).
    pub values: Vec<f64>,
    /// Valid samples (auto) or valid pairs at lag 0 (cross) the estimate is based on.
    pub samples: usize,
    /// Half-width of the 95 % band `1.96/√N`.
    pub bound95: f64,
    /// Half-width of the 99 % band `2.576/√N`.
    pub bound99: f64,
}

impl Correlogram {
    fn new(kind: CorrelationKind, lags: Vec<i64>, values: Vec<f64>, samples: usize) -> Self {
        Self {
            kind,
            lags,
            values,
            samples,
            bound95: confidence_bound(samples, Confidence::P95),
            bound99: confidence_bound(samples, Confidence::P99),
        }
    }

    /// Band half-width at a confidence level.
    pub fn bound(&self, level: Confidence) -> f64 {
        match level {
            Confidence::P95 => self.bound95,
            Confidence::P99 => self.bound99,
        }
    }

    /// Lags whose value lies outside the band (lag 0 of an auto or partial correlogram,
    /// which is 1 by definition, is never counted).
    pub fn outside(&self, level: Confidence) -> Vec<i64> {
        let b = self.bound(level);
        self.lags
            .iter()
            .zip(&self.values)
            .filter(|(lag, v)| !(self.kind != CorrelationKind::Cross && **lag == 0) && v.abs() > b)
            .map(|(lag, _)| *lag)
            .collect()
    }

    /// Largest positive lag outside the band, if any.
    pub fn largest_significant_lag(&self, level: Confidence) -> Option<usize> {
        self.outside(level)
            .into_iter()
            .filter(|&l| l > 0)
            .max()
            .map(|l| l as usize)
    }

    /// Value at a lag, if the correlogram covers it.
    pub fn at(&self, lag: i64) -> Option<f64> {
        self.lags
            .iter()
            .position(|&l| l == lag)
            .map(|i| self.values[i])
    }
}

/// Centre a series on the mean of its valid samples; returns the centred series (NaN kept),
/// the sum of squares and the valid count.
fn centre(x: &[f64]) -> (Vec<f64>, f64, usize) {
    let valid: Vec<f64> = x.iter().copied().filter(|v| !v.is_nan()).collect();
    if valid.is_empty() {
        return (x.to_vec(), 0.0, 0);
    }
    let mean = valid.iter().sum::<f64>() / valid.len() as f64;
    let c: Vec<f64> = x.iter().map(|v| v - mean).collect();
    let ss = c.iter().filter(|v| !v.is_nan()).map(|v| v * v).sum();
    (c, ss, valid.len())
}

fn check_series(series: &[&[f64]], what: &'static str) -> Result<()> {
    if series.is_empty() {
        return Err(BaselineError::TooFewRows {
            what,
            found: 0,
            needed: 2,
        });
    }
    for s in series {
        if let Some(k) = s.iter().position(|v| v.is_infinite()) {
            return Err(sysid_core::CoreError::InvalidArgument {
                name: what,
                value: k as f64,
                reason: "series is infinite at this sample index",
            }
            .into());
        }
    }
    Ok(())
}

fn is_single_complete(series: &[&[f64]]) -> bool {
    series.len() == 1 && series[0].iter().all(|v| v.is_finite())
}

/// Lagged products `Σ_k a_k b_{k+τ}` over pairs where both are present.
fn lagged_sum(a: &[f64], b: &[f64], tau: i64) -> f64 {
    let n = a.len().min(b.len()) as i64;
    let mut s = 0.0;
    for k in 0..n {
        let j = k + tau;
        if (0..n).contains(&j) {
            let p = a[k as usize] * b[j as usize];
            if !p.is_nan() {
                s += p;
            }
        }
    }
    s
}

/// Autocorrelation of one or more series (one slice per experiment), lags `0..=max_lag`,
/// missing samples (NaN) skipped.
///
/// Errors: no series, fewer than 2 valid samples in total, an infinite sample.
pub fn autocorrelation(series: &[&[f64]], max_lag: usize) -> Result<Correlogram> {
    check_series(series, "autocorrelation series")?;
    let lags: Vec<i64> = (0..=max_lag as i64).collect();
    if is_single_complete(series) {
        let values = sysid_core::acf(series[0], max_lag)?;
        return Ok(Correlogram::new(
            CorrelationKind::Auto,
            lags,
            values,
            series[0].len(),
        ));
    }
    let parts: Vec<(Vec<f64>, f64, usize)> = series.iter().map(|s| centre(s)).collect();
    let count: usize = parts.iter().map(|p| p.2).sum();
    if count < 2 {
        return Err(BaselineError::TooFewRows {
            what: "autocorrelation samples",
            found: count,
            needed: 2,
        });
    }
    let ss: f64 = parts.iter().map(|p| p.1).sum();
    let values = lags
        .iter()
        .map(|&tau| {
            parts
                .iter()
                .map(|p| lagged_sum(&p.0, &p.0, tau))
                .sum::<f64>()
                / ss
        })
        .collect();
    Ok(Correlogram::new(CorrelationKind::Auto, lags, values, count))
}

/// Cross-correlation `r_xy(τ)` of paired series (one pair per experiment), lags
/// `−max_lag..=max_lag`; a positive lag means `y` follows `x`. Missing samples skipped.
///
/// Errors: no series, series of different lengths within a pair, fewer than 2 valid
/// pairs, an infinite sample.
pub fn cross_correlation(x: &[&[f64]], y: &[&[f64]], max_lag: usize) -> Result<Correlogram> {
    check_series(x, "cross-correlation series x")?;
    check_series(y, "cross-correlation series y")?;
    if x.len() != y.len() {
        return Err(BaselineError::Dimension {
            what: "experiments of the two cross-correlated series",
            found: y.len(),
            expected: x.len(),
        });
    }
    for (a, b) in x.iter().zip(y) {
        if a.len() != b.len() {
            return Err(BaselineError::Dimension {
                what: "samples of the two cross-correlated series",
                found: b.len(),
                expected: a.len(),
            });
        }
    }
    let ml = max_lag as i64;
    let lags: Vec<i64> = (-ml..=ml).collect();
    if is_single_complete(x) && is_single_complete(y) {
        let values = sysid_core::xcf(x[0], y[0], max_lag)?;
        return Ok(Correlogram::new(
            CorrelationKind::Cross,
            lags,
            values,
            x[0].len(),
        ));
    }
    // Centre each series on the samples where both are present, so that lag 0 of
    // r_xx equals 1 and the normalisation matches the complete-data estimator.
    let mut pairs = 0;
    let mut sx = 0.0;
    let mut sy = 0.0;
    let mut centred = Vec::with_capacity(x.len());
    for (a, b) in x.iter().zip(y) {
        let both: Vec<bool> = a
            .iter()
            .zip(*b)
            .map(|(p, q)| !p.is_nan() && !q.is_nan())
            .collect();
        let mask = |s: &[f64]| -> Vec<f64> {
            s.iter()
                .zip(&both)
                .map(|(v, ok)| if *ok { *v } else { f64::NAN })
                .collect()
        };
        let (ca, ssa, n) = centre(&mask(a));
        let (cb, ssb, _) = centre(&mask(b));
        pairs += n;
        sx += ssa;
        sy += ssb;
        centred.push((ca, cb));
    }
    if pairs < 2 {
        return Err(BaselineError::TooFewRows {
            what: "cross-correlation pairs",
            found: pairs,
            needed: 2,
        });
    }
    let norm = (sx * sy).sqrt();
    let values = lags
        .iter()
        .map(|&tau| {
            centred
                .iter()
                .map(|(a, b)| lagged_sum(a, b, tau))
                .sum::<f64>()
                / norm
        })
        .collect();
    Ok(Correlogram::new(
        CorrelationKind::Cross,
        lags,
        values,
        pairs,
    ))
}

/// Partial autocorrelation from an autocorrelation sequence `r(0..=K)` (with `r(0) = 1`)
/// by the Durbin–Levinson recursion (Box, Jenkins & Reinsel, *Time Series Analysis*,
/// §3.2.6): `φ_kk = (r_k − Σ_{j<k} φ_{k−1,j} r_{k−j}) / v_{k−1}`,
/// `φ_kj = φ_{k−1,j} − φ_kk φ_{k−1,k−j}`, `v_k = v_{k−1}(1 − φ_kk²)`, `v_0 = r_0`.
///
/// Returns `φ(τ,τ)` for `τ = 0..=K` with `φ(0,0) = 1`. Once `v_k` falls below
/// [`PACF_VARIANCE_FLOOR`]`·r(0)` the remaining values are 0 (see there); a NaN input
/// (constant series) gives NaN.
pub fn pacf_from_acf(r: &[f64]) -> Vec<f64> {
    let k_max = r.len().saturating_sub(1);
    let mut out = vec![0.0; k_max + 1];
    if r.is_empty() {
        return out;
    }
    out[0] = 1.0;
    if r.iter().any(|v| v.is_nan()) {
        out.iter_mut().skip(1).for_each(|v| *v = f64::NAN);
        return out;
    }
    let mut phi = vec![0.0; k_max + 1];
    let mut prev = vec![0.0; k_max + 1];
    let mut v = r[0];
    let floor = PACF_VARIANCE_FLOOR * r[0].abs();
    for k in 1..=k_max {
        if v <= floor {
            break;
        }
        let mut num = r[k];
        for j in 1..k {
            num -= prev[j] * r[k - j];
        }
        let pkk = (num / v).clamp(-1.0, 1.0);
        phi[k] = pkk;
        for j in 1..k {
            phi[j] = prev[j] - pkk * prev[k - j];
        }
        out[k] = pkk;
        v *= 1.0 - pkk * pkk;
        prev[..=k].copy_from_slice(&phi[..=k]);
    }
    out
}

/// Partial autocorrelation of one or more series, lags `0..=max_lag`, from the pooled
/// autocorrelation by Durbin–Levinson. Bands use the valid sample count (the large-sample
/// variance of a PACF value of a white series beyond the true order is `1/N`, Quenouille).
pub fn partial_autocorrelation(series: &[&[f64]], max_lag: usize) -> Result<Correlogram> {
    let acf = autocorrelation(series, max_lag)?;
    let values = pacf_from_acf(&acf.values);
    Ok(Correlogram::new(
        CorrelationKind::Partial,
        acf.lags,
        values,
        acf.samples,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pooled_estimator_equals_core_on_one_complete_series() {
        let x: Vec<f64> = (0..300).map(|k| ((k * 37 % 101) as f64).sin()).collect();
        let y: Vec<f64> = (0..300).map(|k| ((k * 53 % 97) as f64).cos()).collect();
        // Force the pooled path with a second, empty experiment.
        let empty: &[f64] = &[];
        let a = autocorrelation(&[&x], 12).unwrap();
        let b = autocorrelation(&[&x, empty], 12).unwrap();
        for (p, q) in a.values.iter().zip(&b.values) {
            assert!((p - q).abs() < 1e-14);
        }
        let a = cross_correlation(&[&x], &[&y], 7).unwrap();
        let b = cross_correlation(&[&x, empty], &[&y, empty], 7).unwrap();
        for (p, q) in a.values.iter().zip(&b.values) {
            assert!((p - q).abs() < 1e-14);
        }
    }

    #[test]
    fn ar1_pacf_is_phi_then_zero() {
        // Exact ACF of an AR(1) with φ = 0.6: r(k) = 0.6^k, PACF = [1, 0.6, 0, 0, …].
        let r: Vec<f64> = (0..6).map(|k| 0.6_f64.powi(k)).collect();
        let p = pacf_from_acf(&r);
        assert!((p[1] - 0.6).abs() < 1e-15);
        for v in &p[2..] {
            assert!(v.abs() < 1e-15);
        }
    }

    #[test]
    fn deterministic_series_gives_zero_beyond_exact_order() {
        // r(k) = cos(ωk) is the ACF of a pure sinusoid: an exact AR(2), so v_2 = 0.
        let w = 0.3_f64;
        let r: Vec<f64> = (0..8).map(|k| (w * k as f64).cos()).collect();
        let p = pacf_from_acf(&r);
        assert!((p[1] - w.cos()).abs() < 1e-12);
        assert!((p[2] + 1.0).abs() < 1e-9);
        for v in &p[3..] {
            assert!(v.abs() < 1e-15);
        }
    }

    #[test]
    fn missing_samples_are_skipped_not_propagated() {
        let mut x: Vec<f64> = (0..200).map(|k| (0.2 * k as f64).sin()).collect();
        x[50] = f64::NAN;
        let c = autocorrelation(&[&x], 5).unwrap();
        assert_eq!(c.samples, 199);
        assert!(c.values.iter().all(|v| v.is_finite()));
        assert!((c.values[0] - 1.0).abs() < 1e-15);
    }
}
