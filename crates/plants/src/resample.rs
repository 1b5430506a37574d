//! Decimation (keep every k-th sample, optionally after a centred block average of the
//! measured channels) and resampling (linear interpolation for measured channels,
//! zero-order hold for inputs) of matrices, experiments and datasets.

use nalgebra::DMatrix;
use sysid_core::{Dataset, Experiment};

use crate::error::{PlantError, Result};

/// Anti-alias treatment of measured channels before decimation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AntiAlias {
    /// Keep every k-th sample as it is.
    #[default]
    None,
    /// Replace each kept sample by the mean of the `2⌊k/2⌋ + 1` samples centred on it
    /// (truncated at the record ends; NaN samples skipped, all-NaN gives NaN). The window
    /// is symmetric, so it adds no delay; white noise variance drops by about the window
    /// length. It is a crude low-pass (a moving average), not a sharp anti-alias filter.
    CenteredMean,
}

fn check_factor(factor: usize) -> Result<()> {
    if factor == 0 {
        return Err(PlantError::InvalidArgument {
            name: "decimation factor",
            value: 0.0,
            reason: "must be at least 1",
        });
    }
    Ok(())
}

/// The integer decimation factor from rate `fs_from` to rate `fs_to` (Hz); errors unless
/// both are positive and `fs_from / fs_to` is an integer (to 1e-9 relative).
pub fn decimation_factor(fs_from: f64, fs_to: f64) -> Result<usize> {
    for (name, v) in [("fs_from", fs_from), ("fs_to", fs_to)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(PlantError::InvalidArgument {
                name,
                value: v,
                reason: "must be positive and finite",
            });
        }
    }
    let r = fs_from / fs_to;
    let k = r.round();
    if k < 1.0 || (r - k).abs() > 1e-9 * r {
        return Err(PlantError::InvalidArgument {
            name: "fs_from / fs_to",
            value: r,
            reason: "must be a positive integer",
        });
    }
    Ok(k as usize)
}

/// Decimate the columns (samples) of `values` by `factor`: column `j` of the result is
/// column `j·factor` of the input (treated as `anti_alias` says).
pub fn decimate(
    values: &DMatrix<f64>,
    factor: usize,
    anti_alias: AntiAlias,
) -> Result<DMatrix<f64>> {
    check_factor(factor)?;
    let n = values.ncols();
    let len = n.div_ceil(factor);
    let half = factor / 2;
    Ok(DMatrix::from_fn(values.nrows(), len, |i, j| {
        let k = j * factor;
        match anti_alias {
            AntiAlias::None => values[(i, k)],
            AntiAlias::CenteredMean => {
                let lo = k.saturating_sub(half);
                let hi = (k + half).min(n - 1);
                let (sum, count) = (lo..=hi)
                    .map(|c| values[(i, c)])
                    .filter(|v| !v.is_nan())
                    .fold((0.0, 0usize), |(s, c), v| (s + v, c + 1));
                if count == 0 {
                    f64::NAN
                } else {
                    sum / count as f64
                }
            }
        }
    }))
}

/// Decimate an experiment: inputs keep every `factor`-th sample (they are held signals;
/// this is exact only when the input is constant over each block, e.g. an APRBS whose
/// holds are multiples of the new period), outputs are decimated with `anti_alias`.
pub fn decimate_experiment(
    exp: &Experiment,
    factor: usize,
    anti_alias: AntiAlias,
) -> Result<Experiment> {
    let u = decimate(exp.inputs(), factor, AntiAlias::None)?;
    let y = decimate(exp.outputs(), factor, anti_alias)?;
    Ok(Experiment::new(exp.t0(), exp.dt() * factor as f64, u, y)?)
}

/// Decimate every experiment of a dataset (see [`decimate_experiment`]).
pub fn decimate_dataset(ds: &Dataset, factor: usize, anti_alias: AntiAlias) -> Result<Dataset> {
    let exps = ds
        .experiments()
        .iter()
        .map(|e| decimate_experiment(e, factor, anti_alias))
        .collect::<Result<Vec<_>>>()?;
    Ok(Dataset::new(
        ds.input_channels().to_vec(),
        ds.output_channels().to_vec(),
        exps,
    )?)
}

/// How to read a signal between its samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interpolation {
    /// Straight line between neighbouring samples (measured channels).
    Linear,
    /// The last sample at or before the time (held inputs).
    Hold,
}

/// Resample `values` (columns on the grid `t0 + k·dt`) onto the grid `t0 + j·new_dt`
/// covering the same span (last new time ≤ last old time). NaN neighbours give NaN under
/// linear interpolation.
pub fn resample(
    values: &DMatrix<f64>,
    dt: f64,
    new_dt: f64,
    interpolation: Interpolation,
) -> Result<DMatrix<f64>> {
    for (name, v) in [("dt", dt), ("new_dt", new_dt)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(PlantError::InvalidArgument {
                name,
                value: v,
                reason: "must be positive and finite",
            });
        }
    }
    let n = values.ncols();
    if n == 0 {
        return Ok(DMatrix::zeros(values.nrows(), 0));
    }
    let span = (n - 1) as f64 * dt;
    // Tolerate round-off so a new sample landing on the last old one is kept.
    let len = ((span / new_dt) * (1.0 + 1e-12)).floor() as usize + 1;
    Ok(DMatrix::from_fn(values.nrows(), len, |i, j| {
        let pos = (j as f64 * new_dt / dt).min((n - 1) as f64);
        let near = pos.round();
        // Positions within 1e-9 of a sample are that sample (avoids 0.999… → previous).
        let pos = if (pos - near).abs() < 1e-9 { near } else { pos };
        let k = (pos.floor() as usize).min(n - 1);
        match interpolation {
            Interpolation::Hold => values[(i, k)],
            Interpolation::Linear => {
                if k + 1 >= n {
                    values[(i, k)]
                } else {
                    let w = pos - k as f64;
                    if w == 0.0 {
                        values[(i, k)]
                    } else {
                        (1.0 - w) * values[(i, k)] + w * values[(i, k + 1)]
                    }
                }
            }
        }
    }))
}

/// Resample an experiment to a new period: inputs by hold, outputs linearly.
pub fn resample_experiment(exp: &Experiment, new_dt: f64) -> Result<Experiment> {
    let u = resample(exp.inputs(), exp.dt(), new_dt, Interpolation::Hold)?;
    let y = resample(exp.outputs(), exp.dt(), new_dt, Interpolation::Linear)?;
    Ok(Experiment::new(exp.t0(), new_dt, u, y)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::gaussian_noise;

    #[test]
    fn keeps_every_kth_sample() {
        let m = DMatrix::from_fn(2, 11, |i, k| (10 * i + k) as f64);
        let d = decimate(&m, 5, AntiAlias::None).unwrap();
        assert_eq!(d.ncols(), 3);
        assert_eq!(
            d.row(0).iter().copied().collect::<Vec<_>>(),
            vec![0.0, 5.0, 10.0]
        );
        assert!(decimate(&m, 0, AntiAlias::None).is_err());
        assert_eq!(decimation_factor(10.0, 0.5).unwrap(), 20);
        assert!(decimation_factor(10.0, 3.0).is_err());
    }

    /// A symmetric mean reproduces a straight line exactly at interior samples (no delay),
    /// and divides white-noise variance by the window length 2⌊k/2⌋+1 (checked to 10 %,
    /// several standard errors of a variance estimate from 4 000 kept samples).
    #[test]
    fn centred_mean_has_no_delay_and_reduces_noise() {
        let ramp = DMatrix::from_fn(1, 101, |_, k| 0.3 * k as f64 - 2.0);
        let d = decimate(&ramp, 4, AntiAlias::CenteredMean).unwrap();
        for j in 1..d.ncols() - 1 {
            assert!((d[(0, j)] - (0.3 * (4 * j) as f64 - 2.0)).abs() < 1e-12);
        }
        let noise = gaussian_noise(&[1.0], 4000 * 5, 7, 0).unwrap();
        let d = decimate(&noise, 5, AntiAlias::CenteredMean).unwrap();
        let var = d.iter().map(|v| v * v).sum::<f64>() / d.ncols() as f64;
        assert!((var * 5.0 - 1.0).abs() < 0.1, "variance {var}");
    }

    #[test]
    fn resampling_is_exact_for_lines_and_steps() {
        let line = DMatrix::from_fn(1, 21, |_, k| 1.0 + 0.5 * (k as f64 * 0.1));
        let r = resample(&line, 0.1, 0.03, Interpolation::Linear).unwrap();
        assert_eq!(r.ncols(), 67);
        for j in 0..r.ncols() {
            assert!((r[(0, j)] - (1.0 + 0.5 * (j as f64 * 0.03))).abs() < 1e-12);
        }
        let steps = DMatrix::from_fn(1, 4, |_, k| k as f64);
        let h = resample(&steps, 1.0, 0.5, Interpolation::Hold).unwrap();
        assert_eq!(
            h.row(0).iter().copied().collect::<Vec<_>>(),
            vec![0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 3.0]
        );
    }
}
