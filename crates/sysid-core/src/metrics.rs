//! Fit metrics per channel: NRMSE fit % (as MATLAB's `compare`), R², RMSE and error
//! variance. Samples where the measurement is NaN (missing) are skipped.

use serde::{Deserialize, Serialize};

use crate::error::{CoreError, Result};

/// Metrics of one channel's prediction against its measurement.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChannelMetrics {
    /// `100·(1 − ‖y − ŷ‖ / ‖y − ȳ‖)`, %.
    pub fit_percent: f64,
    /// Coefficient of determination `1 − SSE/SST`.
    pub r2: f64,
    /// Root-mean-square error, in the channel's unit.
    pub rmse: f64,
    /// Variance of the error `y − ŷ` about its own mean (divisor `N − 1`).
    pub error_variance: f64,
    /// Number of samples used (non-missing).
    pub samples: usize,
}

/// Compute the metrics of `predicted` against `measured`, skipping NaN measurements.
///
/// Errors: different lengths, fewer than 2 valid samples, a non-finite prediction where
/// the measurement is present.
pub fn channel_metrics(measured: &[f64], predicted: &[f64]) -> Result<ChannelMetrics> {
    CoreError::check_len(
        "predicted vs measured samples",
        predicted.len(),
        measured.len(),
    )?;
    let pairs = || measured.iter().zip(predicted).filter(|(y, _)| !y.is_nan());
    let n = pairs().count();
    if n < 2 {
        return Err(CoreError::TooFewSamples {
            what: "fit metrics",
            found: n,
            needed: 2,
        });
    }
    if let Some(k) = measured
        .iter()
        .zip(predicted)
        .position(|(y, p)| !y.is_nan() && !p.is_finite())
    {
        return Err(CoreError::InvalidArgument {
            name: "prediction",
            value: k as f64,
            reason: "prediction is not finite at this sample index",
        });
    }
    let nf = n as f64;
    let mean_y = pairs().map(|(y, _)| y).sum::<f64>() / nf;
    let sse: f64 = pairs().map(|(y, p)| (y - p) * (y - p)).sum();
    let sst: f64 = pairs().map(|(y, _)| (y - mean_y) * (y - mean_y)).sum();
    let mean_e = pairs().map(|(y, p)| y - p).sum::<f64>() / nf;
    let var_e = pairs()
        .map(|(y, p)| (y - p - mean_e) * (y - p - mean_e))
        .sum::<f64>()
        / (nf - 1.0);
    let (fit, r2) = if sst > 0.0 {
        (100.0 * (1.0 - (sse / sst).sqrt()), 1.0 - sse / sst)
    } else {
        (f64::NAN, f64::NAN)
    };
    Ok(ChannelMetrics {
        fit_percent: fit,
        r2,
        rmse: (sse / nf).sqrt(),
        error_variance: var_e,
        samples: n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_values() {
        // y = [1, 2, 3, 4], ŷ = [1, 2, 4, 3]: e = [0, 0, -1, 1], SSE = 2, ȳ = 2.5, SST = 5.
        let m = channel_metrics(&[1.0, 2.0, 3.0, 4.0], &[1.0, 2.0, 4.0, 3.0]).unwrap();
        assert!((m.rmse - (0.5_f64).sqrt()).abs() < 1e-15);
        assert!((m.r2 - 0.6).abs() < 1e-15);
        assert!((m.fit_percent - 100.0 * (1.0 - (0.4_f64).sqrt())).abs() < 1e-12);
        // mean e = 0, var = (0+0+1+1)/3.
        assert!((m.error_variance - 2.0 / 3.0).abs() < 1e-15);
        assert_eq!(m.samples, 4);
    }

    #[test]
    fn missing_samples_are_skipped() {
        let full = channel_metrics(&[1.0, 2.0, 3.0, 4.0], &[1.0, 2.0, 4.0, 3.0]).unwrap();
        let gap =
            channel_metrics(&[1.0, f64::NAN, 2.0, 3.0, 4.0], &[1.0, 99.0, 2.0, 4.0, 3.0]).unwrap();
        assert_eq!(full, gap);
    }

    #[test]
    fn perfect_prediction_and_errors() {
        let m = channel_metrics(&[1.0, 3.0, 2.0], &[1.0, 3.0, 2.0]).unwrap();
        assert!((m.fit_percent - 100.0).abs() < 1e-12 && (m.r2 - 1.0).abs() < 1e-12);
        assert!(channel_metrics(&[1.0], &[1.0]).is_err());
        assert!(channel_metrics(&[1.0, 2.0], &[1.0]).is_err());
    }
}
