//! The acquisition filter a record's input and output channels share, and the measurement
//! model it implies: `y_meas = Ã·N(Ã⁻¹·u_meas)` for a model `N` of the system between the
//! channels' filters.
//!
//! A linear filter `H` applied to both recorded channels cancels from the linear relation
//! between them, so a model calibrated on the records absorbs it in the input's band. It
//! does not cancel from a nonlinear system's distortion: the system responds to the input
//! *before* `H` and its distortion products, which may lie above the input's band, are
//! recorded *through* `H`. Where `H`'s phase is not linear (near an anti-alias filter's
//! edge) the recorded products lag the model's. `Ã` is `H` without its in-band delay: one
//! below [`AcquisitionOptions::pass_below_hz`], and above it the complex gain of the
//! measured on the simulated output per band, estimated from a calibrated model's training
//! free run ([`AcquisitionFilter::estimate`]).
//!
//! Written here: the estimate needs the DFT at the bins of a few bands only (Goertzel's
//! recurrence, no FFT crate), and the filter is applied as a windowed FIR designed by
//! frequency sampling, with the record's ends held as [`crate::bandlimited`] holds them.

use nalgebra::Complex;

use crate::error::{CoreError, Result};

/// Where the filter is one and how its bands above that are cut.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AcquisitionOptions {
    /// Below this frequency (Hz) the filter is one: the input's band, where the calibrated
    /// model absorbs the shared filter.
    pub pass_below_hz: f64,
    /// Lower edge of the first estimated band (Hz), above `pass_below_hz`.
    pub first_band_hz: f64,
    /// Width of each band (Hz); bands run from `first_band_hz` up to the Nyquist frequency.
    pub band_hz: f64,
}

/// Half-length of the FIR that applies the filter, samples (taps `2·FIR_HALF + 1`).
pub const FIR_HALF: usize = 512;

/// Points of the frequency grid the FIR is sampled on.
const FIR_GRID: usize = 4 * FIR_HALF;

/// A band's centre (Hz) and its complex gain.
type Band = (f64, Complex<f64>);

/// The shared acquisition filter without its in-band delay (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct AcquisitionFilter {
    pass_below_hz: f64,
    /// Band centres (Hz) and the complex gain estimated there.
    bands: Vec<(f64, Complex<f64>)>,
    /// Each band's standard error of its complex gain (`None` where it was given, not
    /// estimated, or estimated from a single DFT bin).
    standard_errors: Vec<Option<f64>>,
}

impl AcquisitionFilter {
    /// Estimate the filter from a record's measured output and a calibrated model's free
    /// run of it (same samples, interval `dt`): per band, `Σ Y·S̄ / Σ |S|²` over the
    /// record's DFT bins in it, with its standard error
    /// `sqrt(Σ|Y − G·S|² / ((K − 1)·Σ|S|²))` over the band's `K` bins (the least-squares
    /// error of one complex gain whose residual bins are independent with a common
    /// variance; `None` for a band of one bin). A band with no simulated content (power below 10⁻¹² of the
    /// strongest band's, or of the whole simulated output's) is left out; the filter
    /// interpolates across it. A record whose simulated output has no content above the
    /// pass band at all (a linear model: only integration error lies there) is an error
    /// rather than a filter estimated from rounding.
    pub fn estimate(
        measured: &[f64],
        simulated: &[f64],
        dt: f64,
        options: &AcquisitionOptions,
    ) -> Result<Self> {
        let n = measured.len();
        if simulated.len() != n {
            return Err(CoreError::Length {
                what: "simulated output (acquisition filter)",
                expected: n,
                found: simulated.len(),
            });
        }
        if n < 16 {
            return Err(CoreError::TooFewSamples {
                what: "acquisition filter estimate",
                found: n,
                needed: 16,
            });
        }
        if !(dt.is_finite() && dt > 0.0) {
            return Err(CoreError::BadSamplePeriod { dt });
        }
        if let Some(k) = measured
            .iter()
            .chain(simulated)
            .position(|v| !v.is_finite())
        {
            return Err(CoreError::InvalidArgument {
                name: "acquisition filter record",
                value: (k % n) as f64,
                reason: "a sample (index given) is not finite",
            });
        }
        let nyquist = 0.5 / dt;
        let AcquisitionOptions {
            pass_below_hz,
            first_band_hz,
            band_hz,
        } = *options;
        check_options(options, nyquist)?;
        let df = 1.0 / (n as f64 * dt);
        let mut bands = Vec::new();
        let mut lo = first_band_hz;
        while lo < nyquist {
            let hi = (lo + band_hz).min(nyquist);
            let (k0, k1) = ((lo / df).ceil() as usize, (hi / df).ceil() as usize);
            let mut cross = Complex::new(0.0, 0.0);
            let (mut power, mut measured_power, mut bins) = (0.0, 0.0, 0usize);
            // Bins at or above Nyquist are not in any band.
            for k in k0..k1.min(n.div_ceil(2)) {
                let omega = std::f64::consts::TAU * k as f64 / n as f64;
                let ys = goertzel(measured, omega);
                let ss = goertzel(simulated, omega);
                cross += ys * ss.conj();
                power += ss.norm_sqr();
                measured_power += ys.norm_sqr();
                bins += 1;
            }
            bands.push((0.5 * (lo + hi), cross, power, measured_power, bins));
            lo += band_hz;
        }
        // Bands whose simulated power is rounding error beside the strongest band's or
        // beside the whole simulated output's (Parseval: Σ_k |S_k|² = n·Σ s², half of it
        // at positive frequencies).
        let strongest = bands.iter().map(|b| b.2).fold(0.0, f64::max);
        let whole = 0.5 * n as f64 * simulated.iter().map(|v| v * v).sum::<f64>();
        let (bands, standard_errors): (Vec<Band>, Vec<Option<f64>>) = bands
            .into_iter()
            .filter(|&(_, _, p, _, _)| p > 1e-12 * strongest && p > 1e-12 * whole && p > 0.0)
            .map(|(c, cross, p, yy, bins)| {
                // Σ|Y − G·S|² = Σ|Y|² − |Σ Y·S̄|²/Σ|S|² at the least-squares G (never
                // below 0 but for rounding).
                let residual = (yy - cross.norm_sqr() / p).max(0.0);
                let se = (bins > 1).then(|| (residual / ((bins - 1) as f64 * p)).sqrt());
                ((c, cross / p), se)
            })
            .unzip();
        if bands.is_empty() {
            return Err(CoreError::TooFewSamples {
                what: "acquisition filter bands with simulated content",
                found: 0,
                needed: 1,
            });
        }
        Ok(Self {
            pass_below_hz,
            bands,
            standard_errors,
        })
    }

    /// A filter from given band gains (centres in Hz, increasing, above `pass_below_hz`).
    pub fn from_bands(pass_below_hz: f64, bands: Vec<(f64, Complex<f64>)>) -> Result<Self> {
        if !(pass_below_hz.is_finite() && pass_below_hz >= 0.0) {
            return Err(CoreError::InvalidArgument {
                name: "pass_below_hz",
                value: pass_below_hz,
                reason: "must be finite and non-negative",
            });
        }
        let mut last = pass_below_hz;
        for &(f, g) in &bands {
            if !(f > last && f.is_finite() && g.re.is_finite() && g.im.is_finite()) {
                return Err(CoreError::InvalidArgument {
                    name: "acquisition band centre",
                    value: f,
                    reason: "band centres must increase from pass_below_hz with finite gains",
                });
            }
            last = f;
        }
        let standard_errors = vec![None; bands.len()];
        Ok(Self {
            pass_below_hz,
            bands,
            standard_errors,
        })
    }

    /// The filter with each band's standard error of its gain given (one entry per band,
    /// `None` where unknown; each known one finite and non-negative).
    pub fn with_standard_errors(mut self, standard_errors: Vec<Option<f64>>) -> Result<Self> {
        if standard_errors.len() != self.bands.len() {
            return Err(CoreError::Length {
                what: "acquisition band standard errors",
                expected: self.bands.len(),
                found: standard_errors.len(),
            });
        }
        if let Some(bad) = standard_errors
            .iter()
            .flatten()
            .find(|v| !(v.is_finite() && **v >= 0.0))
        {
            return Err(CoreError::InvalidArgument {
                name: "acquisition band standard error",
                value: *bad,
                reason: "must be finite and non-negative",
            });
        }
        self.standard_errors = standard_errors;
        Ok(self)
    }

    /// Band centres (Hz) and their complex gains.
    pub fn bands(&self) -> &[(f64, Complex<f64>)] {
        &self.bands
    }

    /// Each band's standard error of its complex gain, in the order of [`Self::bands`]
    /// (`None` where not known). Under the estimate's assumptions `|Ĝ − G|²/se²` is
    /// exponentially distributed with mean one, so `|Ĝ − G| ≤ 2·se` holds with
    /// probability `1 − e⁻⁴ ≈ 0.98`.
    pub fn standard_errors(&self) -> &[Option<f64>] {
        &self.standard_errors
    }

    /// Below this frequency (Hz) the filter is one.
    pub fn pass_below_hz(&self) -> f64 {
        self.pass_below_hz
    }

    /// The filter's response at `f` Hz (`|f|` up to Nyquist): one up to `pass_below_hz`,
    /// linear in real and imaginary parts between it and the band centres, held past the
    /// last centre; conjugate at negative frequencies.
    pub fn response(&self, f: f64) -> Complex<f64> {
        let (a, negative) = (f.abs(), f < 0.0);
        let mut prev = (self.pass_below_hz, Complex::new(1.0, 0.0));
        let mut value = None;
        if a <= prev.0 {
            value = Some(prev.1);
        } else {
            for &(c, g) in &self.bands {
                if a <= c {
                    let s = (a - prev.0) / (c - prev.0);
                    value = Some(prev.1 + (g - prev.1) * s);
                    break;
                }
                prev = (c, g);
            }
        }
        let v = value.unwrap_or(prev.1);
        if negative { v.conj() } else { v }
    }

    /// The record `x`, sampled every `dt` s, through the filter.
    pub fn apply(&self, x: &[f64], dt: f64) -> Result<Vec<f64>> {
        Ok(convolve(&self.taps(false, dt)?, x))
    }

    /// The record `x`, sampled every `dt` s, through the filter's inverse (the response's
    /// reciprocal).
    pub fn apply_inverse(&self, x: &[f64], dt: f64) -> Result<Vec<f64>> {
        Ok(convolve(&self.taps(true, dt)?, x))
    }

    /// FIR taps `h[−FIR_HALF ..= FIR_HALF]` of the response (or its reciprocal), sampled
    /// on a grid of `FIR_GRID` frequencies and Hann-windowed.
    fn taps(&self, inverse: bool, dt: f64) -> Result<Vec<f64>> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(CoreError::BadSamplePeriod { dt });
        }
        let l = FIR_GRID;
        let fs = 1.0 / dt;
        let grid: Vec<Complex<f64>> = (0..=l / 2)
            .map(|k| {
                let r = self.response(k as f64 * fs / l as f64);
                if inverse { r.inv() } else { r }
            })
            .collect();
        let half = FIR_HALF as isize;
        Ok((-half..=half)
            .map(|n| {
                let mut sum = grid[0].re + grid[l / 2].re * if n % 2 == 0 { 1.0 } else { -1.0 };
                for (k, g) in grid.iter().enumerate().take(l / 2).skip(1) {
                    let phase = std::f64::consts::TAU * (k as f64) * (n as f64) / l as f64;
                    sum += 2.0 * (g * Complex::new(phase.cos(), phase.sin())).re;
                }
                let w = 0.5 * (1.0 + (std::f64::consts::PI * n as f64 / (half + 1) as f64).cos());
                w * sum / l as f64
            })
            .collect())
    }
}

fn check_options(o: &AcquisitionOptions, nyquist: f64) -> Result<()> {
    let bad = |name, value, reason| {
        Err(CoreError::InvalidArgument {
            name,
            value,
            reason,
        })
    };
    if !(o.pass_below_hz.is_finite() && o.pass_below_hz >= 0.0) {
        return bad(
            "pass_below_hz",
            o.pass_below_hz,
            "must be finite and non-negative",
        );
    }
    if !(o.first_band_hz > o.pass_below_hz && o.first_band_hz < nyquist) {
        return bad(
            "first_band_hz",
            o.first_band_hz,
            "must lie above pass_below_hz and below the Nyquist frequency",
        );
    }
    if !(o.band_hz.is_finite() && o.band_hz > 0.0) {
        return bad("band_hz", o.band_hz, "must be finite and positive");
    }
    Ok(())
}

/// The DFT `Σ x[n]·e^{−iωn}` by Goertzel's recurrence (one multiply per sample), whose
/// result `e^{iω(N−1)}·X(ω)` is rotated back here. Also mme-core's spectral floor (the
/// periodogram of a few hundred bins, where no FFT is needed).
pub fn goertzel(x: &[f64], omega: f64) -> Complex<f64> {
    let c = 2.0 * omega.cos();
    let (mut s1, mut s2) = (0.0, 0.0);
    for &v in x {
        let s0 = v + c * s1 - s2;
        s2 = s1;
        s1 = s0;
    }
    let y = Complex::new(s1, 0.0) - Complex::new(omega.cos(), -omega.sin()) * s2;
    let back = omega * (x.len() as f64 - 1.0);
    y * Complex::new(back.cos(), -back.sin())
}

/// `Σ_n h[n]·x[i − n]` with `h` centred (`h[FIR_HALF]` at lag 0) and `x` held at its ends.
fn convolve(h: &[f64], x: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n == 0 {
        return Vec::new();
    }
    let half = (h.len() / 2) as isize;
    let last = n as isize - 1;
    (0..n as isize)
        .map(|i| {
            h.iter()
                .enumerate()
                .map(|(j, &c)| c * x[(i - (j as isize - half)).clamp(0, last) as usize])
                .sum()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The DFT by its definition.
    fn dft(x: &[f64], omega: f64) -> Complex<f64> {
        x.iter()
            .enumerate()
            .map(|(n, &v)| v * Complex::new((omega * n as f64).cos(), -(omega * n as f64).sin()))
            .sum()
    }

    #[test]
    fn goertzel_is_the_dft() {
        let x: Vec<f64> = (0..1000)
            .map(|n| ((n * 7919) % 101) as f64 - 50.0)
            .collect();
        for k in [1usize, 37, 250, 499] {
            let omega = std::f64::consts::TAU * k as f64 / x.len() as f64;
            let (a, b) = (goertzel(&x, omega), dft(&x, omega));
            assert!(
                (a - b).norm() < 1e-8 * b.norm().max(1.0),
                "bin {k}: {a} vs {b}"
            );
        }
    }

    /// A known filter: one below 100 Hz, then a lag growing to 90° at 200 Hz with the gain
    /// falling to 0.5 (fs = 500 Hz).
    fn truth(f: f64) -> Complex<f64> {
        if f <= 100.0 {
            return Complex::new(1.0, 0.0);
        }
        let s = ((f - 100.0) / 100.0).min(1.5);
        Complex::from_polar(1.0 - 0.5 * s, -s * std::f64::consts::FRAC_PI_2)
    }

    /// Tones at bin frequencies (every 0.5 Hz from 20 to 240 Hz) with fixed pseudo-random
    /// phases, and the same tones through `truth`, written out analytically.
    fn tones(n: usize, dt: f64) -> (Vec<f64>, Vec<f64>) {
        let df = 1.0 / (n as f64 * dt);
        let (mut s, mut y) = (vec![0.0; n], vec![0.0; n]);
        let mut k = (20.0 / df) as usize;
        let mut seed = 12345u64;
        while (k as f64) * df < 240.0 {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let phase = (seed >> 11) as f64 / (1u64 << 53) as f64 * std::f64::consts::TAU;
            let f = k as f64 * df;
            let g = truth(f);
            for i in 0..n {
                let w = std::f64::consts::TAU * f * i as f64 * dt;
                s[i] += (w + phase).cos();
                y[i] += g.norm() * (w + phase + g.arg()).cos();
            }
            k += (0.5 / df) as usize;
        }
        (s, y)
    }

    #[test]
    fn estimate_recovers_a_known_filter_band_by_band() {
        let (n, dt) = (4000, 1.0 / 500.0);
        let (s, y) = tones(n, dt);
        let options = AcquisitionOptions {
            pass_below_hz: 100.0,
            first_band_hz: 105.0,
            band_hz: 5.0,
        };
        let filter = AcquisitionFilter::estimate(&y, &s, dt, &options).unwrap();
        // Bands above 240 Hz have no simulated content and are left out.
        assert_eq!(filter.bands().len(), 27);
        for &(c, g) in filter.bands() {
            // Each 5-Hz band holds ten tones at c − 2.5 … c + 2: their mean gain.
            let mean: Complex<f64> = (0..10)
                .map(|j| truth(c - 2.5 + 0.5 * j as f64))
                .sum::<Complex<f64>>()
                / 10.0;
            assert!((g - mean).norm() < 0.02, "band at {c} Hz: {g} vs {mean}");
        }
        // Interpolated between centres, one below the pass band, held past the last band.
        assert!((filter.response(50.0) - Complex::new(1.0, 0.0)).norm() < 1e-12);
        assert!((filter.response(-150.0) - filter.response(150.0).conj()).norm() < 1e-12);
        assert!((filter.response(249.0) - filter.bands()[26].1).norm() < 1e-12);
    }

    /// The standard errors against their reference distribution under the estimate
    /// itself: a white Gaussian record through a known gain (0.8 in every band) plus
    /// white Gaussian noise, 60 seeds × 29 bands of 40 bins. Under the estimate's
    /// assumptions `|Ĝ − G|²/se²` has mean (K − 1)/(K − 2) ≈ 1.03 and `|Ĝ − G| ≤ 2·se`
    /// holds with probability 1 − (1 + 4/(K − 1))^−(K−1) ≈ 0.978 (K = 40); the bounds
    /// below are about four standard deviations of the pooled statistics wide.
    #[test]
    fn standard_errors_cover_the_true_gain_as_often_as_they_claim() {
        let (n, dt, gain) = (4000, 1.0 / 500.0, 0.8);
        let options = AcquisitionOptions {
            pass_below_hz: 100.0,
            first_band_hz: 105.0,
            band_hz: 5.0,
        };
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut uniform = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let mut gauss = move || {
            let (a, b) = (uniform(), uniform());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let (mut z_sum, mut covered, mut count) = (0.0, 0usize, 0usize);
        for _ in 0..60 {
            let s: Vec<f64> = (0..n).map(|_| gauss()).collect();
            let y: Vec<f64> = s.iter().map(|v| gain * v + 0.3 * gauss()).collect();
            let filter = AcquisitionFilter::estimate(&y, &s, dt, &options).unwrap();
            assert_eq!(filter.standard_errors().len(), filter.bands().len());
            for (&(_, g), se) in filter.bands().iter().zip(filter.standard_errors()) {
                let se = se.expect("a band of 40 bins has a standard error");
                let err = (g - Complex::new(gain, 0.0)).norm();
                z_sum += (err / se).powi(2);
                covered += usize::from(err <= 2.0 * se);
                count += 1;
            }
        }
        assert_eq!(count, 60 * 29);
        let (mean, coverage) = (z_sum / count as f64, covered as f64 / count as f64);
        assert!((0.93..=1.13).contains(&mean), "mean |Ĝ − G|²/se² = {mean}");
        assert!(
            (0.964..=0.99).contains(&coverage),
            "|Ĝ − G| ≤ 2·se in {coverage} of the bands"
        );
        // Given gains carry none; given errors are checked.
        let given =
            AcquisitionFilter::from_bands(100.0, vec![(110.0, Complex::new(0.9, 0.1))]).unwrap();
        assert_eq!(given.standard_errors(), &[None]);
        assert!(given.clone().with_standard_errors(vec![]).is_err());
        assert!(
            given
                .clone()
                .with_standard_errors(vec![Some(-1.0)])
                .is_err()
        );
        assert!(
            given
                .clone()
                .with_standard_errors(vec![Some(f64::NAN)])
                .is_err()
        );
        let known = given.with_standard_errors(vec![Some(0.01)]).unwrap();
        assert_eq!(known.standard_errors(), &[Some(0.01)]);
    }

    #[test]
    fn the_filter_and_its_inverse_act_on_a_tone_as_their_response_says() {
        let dt = 1.0 / 500.0;
        let bands: Vec<(f64, Complex<f64>)> = (0..30)
            .map(|j| {
                let c = 102.5 + 5.0 * j as f64;
                (c, truth(c))
            })
            .collect();
        let filter = AcquisitionFilter::from_bands(100.0, bands).unwrap();
        let n = 6000;
        for f in [60.0, 137.3, 181.0, 210.0] {
            let x: Vec<f64> = (0..n)
                .map(|i| (std::f64::consts::TAU * f * i as f64 * dt).cos())
                .collect();
            let r = filter.response(f);
            for (out, g) in [
                (filter.apply(&x, dt).unwrap(), r),
                (filter.apply_inverse(&x, dt).unwrap(), r.inv()),
            ] {
                // Away from the ends (held there), the output is the tone times the response.
                let err = (2000..4000)
                    .map(|i| {
                        let w = std::f64::consts::TAU * f * i as f64 * dt;
                        (out[i] - g.norm() * (w + g.arg()).cos()).abs()
                    })
                    .fold(0.0, f64::max);
                assert!(err < 0.01 * g.norm(), "{f} Hz: error {err} for gain {g}");
            }
        }
    }

    #[test]
    fn bad_input_is_an_error() {
        let options = AcquisitionOptions {
            pass_below_hz: 100.0,
            first_band_hz: 105.0,
            band_hz: 5.0,
        };
        let x = vec![0.0; 100];
        assert!(AcquisitionFilter::estimate(&x, &x[..99], 0.002, &options).is_err());
        let mut y = x.clone();
        y[7] = f64::NAN;
        assert!(AcquisitionFilter::estimate(&y, &x, 0.002, &options).is_err());
        assert!(AcquisitionFilter::estimate(&x, &x, -1.0, &options).is_err());
        let wide = AcquisitionOptions {
            first_band_hz: 300.0,
            ..options
        };
        assert!(AcquisitionFilter::estimate(&x, &x, 0.002, &wide).is_err());
        // All-zero simulated output: no band has content.
        assert!(AcquisitionFilter::estimate(&x, &x, 0.002, &options).is_err());
    }

    /// A linear model's output: tones below the pass band only, plus content above it at
    /// the level of integration error (1e-8 of the tones' amplitude, power 1e-16 of
    /// theirs). Relative to the strongest band that content is all there is, so only the
    /// whole output's power can tell it is none; with distortion at 1e-3 it is estimated.
    #[test]
    fn a_record_without_content_above_the_pass_band_is_an_error() {
        let (n, dt) = (4000, 1.0 / 500.0);
        let options = AcquisitionOptions {
            pass_below_hz: 100.0,
            first_band_hz: 105.0,
            band_hz: 5.0,
        };
        let record = |high: f64| -> Vec<f64> {
            (0..n)
                .map(|i| {
                    let t = i as f64 * dt;
                    let tau = std::f64::consts::TAU;
                    (tau * 20.0 * t).cos()
                        + 0.5 * (tau * 55.5 * t + 1.0).cos()
                        + high * (tau * 150.25 * t + 0.3).cos()
                        + high * (tau * 201.0 * t + 2.0).cos()
                })
                .collect()
        };
        let rounding = record(1e-8);
        assert!(AcquisitionFilter::estimate(&rounding, &rounding, dt, &options).is_err());
        let distorted = record(1e-3);
        let filter = AcquisitionFilter::estimate(&distorted, &distorted, dt, &options).unwrap();
        assert!(!filter.bands().is_empty());
        for &(c, g) in filter.bands() {
            assert!(
                (g - Complex::new(1.0, 0.0)).norm() < 1e-9,
                "band at {c} Hz: {g}"
            );
        }
    }
}
