//! The "where" of discovery: time windows in which `d̂` (and the free-run simulation
//! error) rises significantly above its noise level, state/input regions in which `d̂`'s
//! mean is significantly nonzero, and the data for plots of `d̂` against each state and
//! input.
//!
//! # Time windows
//!
//! The centred moving RMS of `d̂` over `L` samples is compared with
//! `threshold_ratio × floor RMS` (default 2: under a correct model a window's mean square
//! scatters around `floor²` with relative spread `√(2/L_eff)`, so doubling the RMS —
//! four times the mean square — is rare for windows of more than a few effective
//! samples). Consecutive samples above the threshold form a raw window; its edges are
//! then refined to where the moving mean square crosses half-way between `floor²` and the
//! window's peak (for a step-like onset the moving mean square ramps linearly over `L`
//! samples and crosses the mid-level exactly at the onset, so the refined edges are
//! accurate to about a sample plus noise, instead of ±`L/2`). Refined windows closer than
//! `L` samples are merged.
//!
//! The free-run error `y − ŷ_sim` of the assumed model is treated the same way against
//! the measurement noise `√R`. It accumulates (a disturbance at `t₁` shifts the simulation
//! for all later times), so its windows show where the model *drifts away*; `d̂`'s windows
//! show where the model *is wrong*.
//!
//! # State-space regions
//!
//! For each corrected equation and each state and input, the samples are sorted by that
//! variable and split into `bins` bins of equal count. A bin's mean of `d̂` gets the
//! standard error `floor/√(count·ρ)` (`ρ` the floor's `N_eff/N`), and the bin is a
//! significant region when `|mean| > bin_z·se` (default z = 3).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::LinearModel;

use crate::error::{DiscoveryError, Result};
use crate::floor::NoiseFloor;
use crate::samples::Samples;

/// Length of the moving window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WindowLength {
    /// `max(5, N/50)` samples.
    Auto,
    /// This many samples (≥ 2).
    Samples(usize),
    /// This many seconds (rounded to whole samples, at least 2).
    Seconds(f64),
}

/// Settings of [`localise`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocaliseConfig {
    /// Moving-window length. Default [`WindowLength::Auto`].
    pub window: WindowLength,
    /// A window is flagged where the moving RMS exceeds this multiple of the noise RMS
    /// (> 1). Default 2.
    pub threshold_ratio: f64,
    /// Equal-count bins per variable (≥ 2). Default 10.
    pub bins: usize,
    /// z-score above which a bin's mean `d̂` is significant (> 0). Default 3.
    pub bin_z: f64,
    /// Most scatter points kept per plot (≥ 1; thinned by a fixed stride). Default 2000.
    pub max_points: usize,
}

impl Default for LocaliseConfig {
    fn default() -> Self {
        Self {
            window: WindowLength::Auto,
            threshold_ratio: 2.0,
            bins: 10,
            bin_z: 3.0,
            max_points: 2000,
        }
    }
}

impl LocaliseConfig {
    /// Check ranges before any work.
    pub fn validate(&self) -> Result<()> {
        let bad = |field, value, reason| {
            Err(DiscoveryError::InvalidConfig {
                field,
                value,
                reason,
            })
        };
        match self.window {
            WindowLength::Samples(s) if s < 2 => {
                return bad("window", s as f64, "at least 2 samples");
            }
            WindowLength::Seconds(s) if !(s.is_finite() && s > 0.0) => {
                return bad("window", s, "seconds must be positive and finite");
            }
            _ => {}
        }
        if !(self.threshold_ratio.is_finite() && self.threshold_ratio > 1.0) {
            return bad(
                "threshold_ratio",
                self.threshold_ratio,
                "must be finite and > 1",
            );
        }
        if self.bins < 2 {
            return bad("bins", self.bins as f64, "at least 2");
        }
        if !(self.bin_z.is_finite() && self.bin_z > 0.0) {
            return bad("bin_z", self.bin_z, "must be positive and finite");
        }
        if self.max_points == 0 {
            return bad("max_points", 0.0, "at least 1");
        }
        Ok(())
    }
}

/// The free-run simulation of the assumed model against the data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreeRun<'a> {
    /// Measured outputs `p × N` (NaN = missing), in the model's output order.
    pub measured: &'a DMatrix<f64>,
    /// Simulated outputs `p × N`.
    pub simulated: &'a DMatrix<f64>,
    /// Measurement-noise variance per output (> 0).
    pub noise_variance: &'a [f64],
}

/// What a window was found in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WindowSource {
    /// MME's correction `d̂` of a state equation.
    Correction,
    /// The free-run simulation error of an output.
    FreeRun,
}

/// A time window of significant disagreement.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DisagreementWindow {
    /// Where it was found.
    pub source: WindowSource,
    /// The state (for `d̂`) or output channel.
    pub channel: String,
    /// Start, s.
    pub start: f64,
    /// End, s.
    pub end: f64,
    /// Largest moving RMS over the reference (`None` for a zero reference).
    pub peak_ratio: Option<f64>,
    /// Mean moving RMS over the reference inside the window.
    pub mean_ratio: Option<f64>,
}

/// A moving-RMS series for plots (`t_k = t0 + k·dt`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MovingRms {
    /// Where it comes from.
    pub source: WindowSource,
    /// The channel.
    pub channel: String,
    /// The noise RMS it is compared with.
    pub reference: f64,
    /// The threshold (`threshold_ratio × reference`).
    pub threshold: f64,
    /// Moving RMS per sample (NaN where a free-run window holds no measurement).
    #[serde(with = "crate::json::nullable_vec")]
    pub values: Vec<f64>,
}

/// One equal-count bin of a variable.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Bin {
    /// Smallest value of the variable in the bin.
    pub lo: f64,
    /// Largest value.
    pub hi: f64,
    /// Samples in the bin.
    pub count: usize,
    /// Mean of `d̂` in the bin.
    pub mean_d: f64,
    /// Its standard error under a correct model.
    pub std_error: f64,
    /// `mean_d/std_error` (`None` for a zero floor).
    pub z: Option<f64>,
    /// Whether the bin's mean is significant.
    pub significant: bool,
}

/// `d̂` of one equation against one variable: scatter points and bins.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    /// State whose equation `d̂` corrects.
    pub equation: String,
    /// The state or input on the horizontal axis.
    pub variable: String,
    /// `[value, d̂]` pairs (thinned).
    pub points: Vec<[f64; 2]>,
    /// Equal-count bins.
    pub bins: Vec<Bin>,
}

/// A significant state-space region.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Region {
    /// State whose equation `d̂` corrects.
    pub equation: String,
    /// The variable binned.
    pub variable: String,
    /// Range of the variable.
    pub lo: f64,
    /// Range of the variable.
    pub hi: f64,
    /// Mean `d̂` there.
    pub mean_d: f64,
    /// Its z-score (`None` for a zero floor).
    pub z: Option<f64>,
}

/// Where the model disagrees with the data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Localisation {
    /// Window length used, samples.
    pub window_samples: usize,
    /// Window length used, s.
    pub window_seconds: f64,
    /// Threshold ratio used.
    pub threshold_ratio: f64,
    /// Significant windows, `d̂` first, then free-run errors.
    pub windows: Vec<DisagreementWindow>,
    /// Moving RMS series (for plots).
    pub moving_rms: Vec<MovingRms>,
    /// Significant state-space regions.
    pub regions: Vec<Region>,
    /// `d̂` against every state and input, per equation (for plots).
    pub profiles: Vec<Profile>,
}

/// Localise the disagreement of one experiment (`t_k = t0 + k·dt`).
///
/// Errors: invalid config or `dt`; `E` not a selection; shapes of `samples`, `floor` or
/// `free_run` not matching the model; a non-positive noise variance.
pub fn localise(
    model: &LinearModel,
    samples: &Samples,
    t0: f64,
    dt: f64,
    floor: &NoiseFloor,
    free_run: Option<&FreeRun<'_>>,
    config: &LocaliseConfig,
) -> Result<Localisation> {
    config.validate()?;
    if !(dt.is_finite() && dt > 0.0) {
        return Err(DiscoveryError::InvalidConfig {
            field: "dt",
            value: dt,
            reason: "must be positive and finite",
        });
    }
    let (n, m, q) = (model.n_states(), model.n_inputs(), model.n_corrections());
    samples.check(0, n, m, q)?;
    if floor.len() != q {
        return Err(DiscoveryError::Length {
            what: "noise floor equations",
            found: floor.len(),
            expected: q,
        });
    }
    let corrected = model
        .corrected_states()
        .ok_or(DiscoveryError::NotSelection { matrix: "E" })?;
    let len = samples.len();
    let window = match config.window {
        WindowLength::Auto => (len / 50).max(5),
        WindowLength::Samples(s) => s,
        WindowLength::Seconds(s) => ((s / dt).round() as usize).max(2),
    };
    let mut windows = Vec::new();
    let mut moving = Vec::new();
    let states = model.state_names();
    for (i, &eq) in corrected.iter().enumerate() {
        let d: Vec<f64> = samples.corrections().row(i).iter().copied().collect();
        let ms = moving_mean_square(&d, window);
        let reference = floor.rms[i];
        windows.extend(
            find_windows(&ms, reference, config.threshold_ratio, window, t0, dt)
                .into_iter()
                .map(|(start, end, peak, mean)| DisagreementWindow {
                    source: WindowSource::Correction,
                    channel: states[eq].clone(),
                    start,
                    end,
                    peak_ratio: peak,
                    mean_ratio: mean,
                }),
        );
        moving.push(MovingRms {
            source: WindowSource::Correction,
            channel: states[eq].clone(),
            reference,
            threshold: config.threshold_ratio * reference,
            values: ms.iter().map(|v| v.sqrt()).collect(),
        });
    }
    if let Some(fr) = free_run {
        let p = model.n_outputs();
        for (what, mat) in [
            ("measured outputs", fr.measured),
            ("simulated outputs", fr.simulated),
        ] {
            if mat.nrows() != p || mat.ncols() != len {
                return Err(DiscoveryError::Shape {
                    what,
                    experiment: 0,
                    rows: mat.nrows(),
                    cols: mat.ncols(),
                    expected_rows: p,
                    expected_cols: len,
                });
            }
        }
        if fr.noise_variance.len() != p {
            return Err(DiscoveryError::Length {
                what: "noise variances",
                found: fr.noise_variance.len(),
                expected: p,
            });
        }
        for (ch, name) in model.output_names().iter().enumerate() {
            let var = fr.noise_variance[ch];
            if !(var.is_finite() && var > 0.0) {
                return Err(DiscoveryError::InvalidConfig {
                    field: "noise_variance",
                    value: var,
                    reason: "must be positive and finite",
                });
            }
            let e: Vec<f64> = (0..len)
                .map(|k| fr.measured[(ch, k)] - fr.simulated[(ch, k)])
                .collect();
            let ms = moving_mean_square(&e, window);
            let reference = var.sqrt();
            windows.extend(
                find_windows(&ms, reference, config.threshold_ratio, window, t0, dt)
                    .into_iter()
                    .map(|(start, end, peak, mean)| DisagreementWindow {
                        source: WindowSource::FreeRun,
                        channel: name.clone(),
                        start,
                        end,
                        peak_ratio: peak,
                        mean_ratio: mean,
                    }),
            );
            moving.push(MovingRms {
                source: WindowSource::FreeRun,
                channel: name.clone(),
                reference,
                threshold: config.threshold_ratio * reference,
                values: ms.iter().map(|v| v.sqrt()).collect(),
            });
        }
    }
    let (profiles, regions) = profiles(model, samples, &corrected, floor, config);
    Ok(Localisation {
        window_samples: window,
        window_seconds: window as f64 * dt,
        threshold_ratio: config.threshold_ratio,
        windows,
        moving_rms: moving,
        regions,
        profiles,
    })
}

/// Centred moving mean square over `window` samples (`[k − ⌊w/2⌋, k − ⌊w/2⌋ + w)`,
/// clipped to the record), skipping NaN; NaN where a window holds no finite value.
pub fn moving_mean_square(x: &[f64], window: usize) -> Vec<f64> {
    let len = x.len();
    let mut sum = vec![0.0; len + 1];
    let mut count = vec![0usize; len + 1];
    for (k, v) in x.iter().enumerate() {
        let ok = v.is_finite();
        sum[k + 1] = sum[k] + if ok { v * v } else { 0.0 };
        count[k + 1] = count[k] + usize::from(ok);
    }
    let half = window / 2;
    (0..len)
        .map(|k| {
            let a = k.saturating_sub(half);
            let b = (a + window).min(len);
            let c = count[b] - count[a];
            if c == 0 {
                f64::NAN
            } else {
                ((sum[b] - sum[a]) / c as f64).max(0.0)
            }
        })
        .collect()
}

type RawWindow = (f64, f64, Option<f64>, Option<f64>);

/// Windows where `√ms > ratio·reference`, edges refined at the half-way level, merged
/// when closer than `window` samples.
fn find_windows(
    ms: &[f64],
    reference: f64,
    ratio: f64,
    window: usize,
    t0: f64,
    dt: f64,
) -> Vec<RawWindow> {
    let limit = (ratio * reference).powi(2);
    let above = |v: f64| v.is_finite() && v > limit && v > 0.0;
    // Raw runs, then refined.
    let mut refined: Vec<(usize, usize)> = Vec::new();
    let mut k = 0;
    while k < ms.len() {
        if !above(ms[k]) {
            k += 1;
            continue;
        }
        let start = k;
        while k < ms.len() && above(ms[k]) {
            k += 1;
        }
        let end = k - 1;
        let peak = ms[start..=end].iter().copied().fold(0.0, f64::max);
        let half = 0.5 * (reference * reference + peak);
        let a = (start..=end).find(|&j| ms[j] >= half).unwrap_or(start);
        let b = (start..=end).rev().find(|&j| ms[j] >= half).unwrap_or(end);
        refined.push((a, b));
    }
    let mut merged: Vec<(usize, usize)> = Vec::new();
    for (a, b) in refined {
        match merged.last_mut() {
            Some(last) if a <= last.1 + window => last.1 = b.max(last.1),
            _ => merged.push((a, b)),
        }
    }
    merged
        .into_iter()
        .map(|(a, b)| {
            let slice = &ms[a..=b];
            let (peak, mean) = if reference > 0.0 {
                let peak = slice
                    .iter()
                    .copied()
                    .filter(|v| v.is_finite())
                    .fold(0.0, f64::max);
                let finite: Vec<f64> = slice.iter().copied().filter(|v| v.is_finite()).collect();
                let mean =
                    finite.iter().map(|v| v.sqrt()).sum::<f64>() / finite.len().max(1) as f64;
                (Some(peak.sqrt() / reference), Some(mean / reference))
            } else {
                (None, None)
            };
            (t0 + a as f64 * dt, t0 + b as f64 * dt, peak, mean)
        })
        .collect()
}

fn profiles(
    model: &LinearModel,
    samples: &Samples,
    corrected: &[usize],
    floor: &NoiseFloor,
    config: &LocaliseConfig,
) -> (Vec<Profile>, Vec<Region>) {
    let n = model.n_states();
    let len = samples.len();
    let names: Vec<&String> = model
        .state_names()
        .iter()
        .chain(model.input_names())
        .collect();
    let stride = len.div_ceil(config.max_points).max(1);
    let mut profiles = Vec::new();
    let mut regions = Vec::new();
    for (i, &eq) in corrected.iter().enumerate() {
        let d: Vec<f64> = samples.corrections().row(i).iter().copied().collect();
        for (v, name) in names.iter().enumerate() {
            let values: Vec<f64> = if v < n {
                samples.states().row(v).iter().copied().collect()
            } else {
                samples.inputs().row(v - n).iter().copied().collect()
            };
            let points = (0..len)
                .step_by(stride)
                .map(|k| [values[k], d[k]])
                .collect();
            let mut order: Vec<usize> = (0..len).collect();
            order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
            let bins_n = config.bins.min(len.max(1));
            let mut bins = Vec::with_capacity(bins_n);
            for b in 0..bins_n {
                let lo_i = b * len / bins_n;
                let hi_i = (b + 1) * len / bins_n;
                if hi_i <= lo_i {
                    continue;
                }
                let idx = &order[lo_i..hi_i];
                let count = idx.len();
                let mean_d = idx.iter().map(|&k| d[k]).sum::<f64>() / count as f64;
                let se = floor.rms[i] / (count as f64 * floor.neff_ratio[i]).max(1.0).sqrt();
                let z = (se > 0.0).then(|| mean_d / se);
                let significant = match z {
                    Some(z) => z.abs() > config.bin_z,
                    None => mean_d != 0.0,
                };
                let bin = Bin {
                    lo: values[idx[0]],
                    hi: values[idx[count - 1]],
                    count,
                    mean_d,
                    std_error: se,
                    z,
                    significant,
                };
                if significant {
                    regions.push(Region {
                        equation: model.state_names()[eq].clone(),
                        variable: (*name).clone(),
                        lo: bin.lo,
                        hi: bin.hi,
                        mean_d,
                        z,
                    });
                }
                bins.push(bin);
            }
            profiles.push(Profile {
                equation: model.state_names()[eq].clone(),
                variable: (*name).clone(),
                points,
                bins,
            });
        }
    }
    (profiles, regions)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moving_mean_square_by_hand() {
        let ms = moving_mean_square(&[1.0, 2.0, f64::NAN, 4.0], 2);
        // Windows [0,2), [0,2), [1,3), [2,4).
        let bits: Vec<u64> = ms.iter().map(|v| v.to_bits()).collect();
        assert_eq!(bits, [2.5, 2.5, 4.0, 16.0].map(f64::to_bits));
        assert!(moving_mean_square(&[f64::NAN; 3], 2)[1].is_nan());
    }

    /// A noise-free rectangular burst of amplitude 1 on samples 100..=199 with zero
    /// background: the refined window is exactly the burst (the moving mean square ramps
    /// linearly and crosses half its plateau at the burst's edges, up to one sample).
    #[test]
    fn refined_edges_of_a_step_burst() {
        let d: Vec<f64> = (0..400)
            .map(|k| if (100..200).contains(&k) { 1.0 } else { 0.0 })
            .collect();
        let ms = moving_mean_square(&d, 20);
        let w = find_windows(&ms, 0.01, 2.0, 20, 0.0, 1.0);
        assert_eq!(w.len(), 1);
        assert!(
            (w[0].0 - 100.0).abs() <= 1.0 && (w[0].1 - 199.0).abs() <= 1.0,
            "{w:?}"
        );
    }
}
