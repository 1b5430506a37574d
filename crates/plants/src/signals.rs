//! Excitation signals: sine, random-phase multisine, linear/log chirp, step sequences,
//! APRBS and maximum-length PRBS. Each is a pure function of its settings (and seed),
//! evaluated on a [`SampleGrid`]; the simulators hold each sample until the next one
//! (zero-order hold).

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};

use crate::error::{PlantError, Result};

mod prbs;
pub use prbs::{PRBS_MAX_ORDER, PRBS_MIN_ORDER, Prbs};

/// A uniform sample grid `t_k = t0 + k·dt`, `k = 0..len`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleGrid {
    /// Time of the first sample, s.
    pub t0: f64,
    /// Sample period, s (> 0).
    pub dt: f64,
    /// Number of samples.
    pub len: usize,
}

impl SampleGrid {
    /// Time of sample `k`, s.
    pub fn time(&self, k: usize) -> f64 {
        self.t0 + k as f64 * self.dt
    }

    fn check(&self) -> Result<()> {
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(PlantError::InvalidArgument {
                name: "dt",
                value: self.dt,
                reason: "sample period must be positive and finite",
            });
        }
        if !self.t0.is_finite() {
            return Err(PlantError::InvalidArgument {
                name: "t0",
                value: self.t0,
                reason: "must be finite",
            });
        }
        Ok(())
    }
}

/// An excitation signal.
#[derive(Debug, Clone, PartialEq)]
pub enum Excitation {
    /// A constant level.
    Constant(f64),
    /// `offset + amplitude·sin(ω t + φ)`.
    Sine(Sine),
    /// Random-phase multisine.
    Multisine(Multisine),
    /// Linear or logarithmic frequency sweep.
    Chirp(Chirp),
    /// A fixed sequence of levels with a common hold time.
    Steps(Steps),
    /// Amplitude-modulated pseudo-random binary sequence (seeded levels and hold times).
    Aprbs(Aprbs),
    /// Maximum-length pseudo-random binary sequence.
    Prbs(Prbs),
}

impl Excitation {
    /// Evaluate the signal at every sample of `grid`.
    pub fn sample(&self, grid: &SampleGrid) -> Result<Vec<f64>> {
        grid.check()?;
        match self {
            Excitation::Constant(c) => {
                check_finite("constant", "level", *c)?;
                Ok(vec![*c; grid.len])
            }
            Excitation::Sine(s) => s.sample(grid),
            Excitation::Multisine(s) => s.sample(grid),
            Excitation::Chirp(s) => s.sample(grid),
            Excitation::Steps(s) => s.sample(grid),
            Excitation::Aprbs(s) => s.sample(grid),
            Excitation::Prbs(s) => s.sample(grid),
        }
    }
}

pub(crate) fn check_finite(signal: &'static str, field: &'static str, value: f64) -> Result<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(PlantError::InvalidSignal {
            signal,
            field,
            value,
            reason: "must be finite",
        })
    }
}

fn check_positive(signal: &'static str, field: &'static str, value: f64) -> Result<()> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(PlantError::InvalidSignal {
            signal,
            field,
            value,
            reason: "must be positive and finite",
        })
    }
}

/// `offset + amplitude·sin(omega·t + phase)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sine {
    /// Amplitude (input units).
    pub amplitude: f64,
    /// Angular frequency, rad/s.
    pub omega: f64,
    /// Phase at t = 0, rad.
    pub phase: f64,
    /// Constant added, input units.
    pub offset: f64,
}

impl Default for Sine {
    /// `sin(t)`.
    fn default() -> Self {
        Self {
            amplitude: 1.0,
            omega: 1.0,
            phase: 0.0,
            offset: 0.0,
        }
    }
}

impl Sine {
    fn sample(&self, grid: &SampleGrid) -> Result<Vec<f64>> {
        for (f, v) in [
            ("amplitude", self.amplitude),
            ("omega", self.omega),
            ("phase", self.phase),
            ("offset", self.offset),
        ] {
            check_finite("sine", f, v)?;
        }
        Ok((0..grid.len)
            .map(|k| self.offset + self.amplitude * (self.omega * grid.time(k) + self.phase).sin())
            .collect())
    }
}

/// Random-phase multisine `Σ_i a·sin(2π f_i t + φ_i)` with `lines` equally spaced
/// frequencies from `f_min` to `f_max` (Hz), equal amplitudes `a = rms·√(2/lines)` (so
/// the signal's RMS over a common period is `rms`), and phases drawn uniformly in
/// `[0, 2π)` from `seed` (ChaCha8).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Multisine {
    /// Root-mean-square value of the oscillating part (input units).
    pub rms: f64,
    /// Lowest line, Hz (> 0).
    pub f_min: f64,
    /// Highest line, Hz (≥ `f_min`).
    pub f_max: f64,
    /// Number of lines (≥ 1); one line sits at `f_min`.
    pub lines: usize,
    /// Seed of the phases.
    pub seed: u64,
    /// Constant added, input units.
    pub offset: f64,
}

impl Default for Multisine {
    fn default() -> Self {
        Self {
            rms: 1.0,
            f_min: 0.1,
            f_max: 1.0,
            lines: 10,
            seed: 0,
            offset: 0.0,
        }
    }
}

impl Multisine {
    /// The line frequencies, Hz.
    pub fn frequencies(&self) -> Vec<f64> {
        if self.lines <= 1 {
            return vec![self.f_min; self.lines];
        }
        let step = (self.f_max - self.f_min) / (self.lines - 1) as f64;
        (0..self.lines)
            .map(|i| self.f_min + i as f64 * step)
            .collect()
    }

    /// The seeded phases, rad.
    pub fn phases(&self) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        (0..self.lines)
            .map(|_| rng.random::<f64>() * std::f64::consts::TAU)
            .collect()
    }

    /// Amplitude of each line.
    pub fn line_amplitude(&self) -> f64 {
        self.rms * (2.0 / self.lines.max(1) as f64).sqrt()
    }

    fn sample(&self, grid: &SampleGrid) -> Result<Vec<f64>> {
        check_finite("multisine", "rms", self.rms)?;
        check_finite("multisine", "offset", self.offset)?;
        check_positive("multisine", "f_min", self.f_min)?;
        if !(self.f_max.is_finite() && self.f_max >= self.f_min) {
            return Err(PlantError::InvalidSignal {
                signal: "multisine",
                field: "f_max",
                value: self.f_max,
                reason: "must be finite and at least f_min",
            });
        }
        if self.lines == 0 {
            return Err(PlantError::InvalidSignal {
                signal: "multisine",
                field: "lines",
                value: 0.0,
                reason: "needs at least one line",
            });
        }
        let f = self.frequencies();
        let ph = self.phases();
        let a = self.line_amplitude();
        Ok((0..grid.len)
            .map(|k| {
                let t = grid.time(k);
                self.offset
                    + f.iter()
                        .zip(&ph)
                        .map(|(fi, pi)| a * (std::f64::consts::TAU * fi * t + pi).sin())
                        .sum::<f64>()
            })
            .collect())
    }
}

/// How a chirp's frequency moves from `f0` to `f1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sweep {
    /// `f(t) = f0 + (f1 − f0)·t/T`.
    Linear,
    /// `f(t) = f0·(f1/f0)^(t/T)`.
    Logarithmic,
}

/// Frequency sweep `offset + amplitude·sin(2π ∫₀ᵗ f(s) ds)` from `f0` at t = 0 to `f1` at
/// `t = duration`; after `duration` the frequency stays at `f1` (the phase runs on
/// continuously). Time is measured from t = 0, not from the grid's start.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chirp {
    /// Amplitude (input units).
    pub amplitude: f64,
    /// Start frequency, Hz.
    pub f0: f64,
    /// End frequency, Hz.
    pub f1: f64,
    /// Sweep time `T`, s.
    pub duration: f64,
    /// Linear or logarithmic.
    pub sweep: Sweep,
    /// Constant added, input units.
    pub offset: f64,
}

impl Default for Chirp {
    fn default() -> Self {
        Self {
            amplitude: 1.0,
            f0: 0.1,
            f1: 1.0,
            duration: 10.0,
            sweep: Sweep::Linear,
            offset: 0.0,
        }
    }
}

impl Chirp {
    /// Instantaneous frequency at `t`, Hz.
    pub fn frequency(&self, t: f64) -> f64 {
        let s = (t / self.duration).clamp(0.0, 1.0);
        match self.sweep {
            Sweep::Linear => self.f0 + (self.f1 - self.f0) * s,
            Sweep::Logarithmic => self.f0 * (self.f1 / self.f0).powf(s),
        }
    }

    /// Phase `2π ∫₀ᵗ f(s) ds`, rad (`t ≥ 0`).
    pub fn phase(&self, t: f64) -> f64 {
        let tt = t.clamp(0.0, self.duration);
        let big_t = self.duration;
        let cycles = match self.sweep {
            Sweep::Linear => self.f0 * tt + (self.f1 - self.f0) * tt * tt / (2.0 * big_t),
            Sweep::Logarithmic => {
                let r = self.f1 / self.f0;
                if (r - 1.0).abs() < 1e-12 {
                    self.f0 * tt
                } else {
                    self.f0 * big_t / r.ln() * (r.powf(tt / big_t) - 1.0)
                }
            }
        };
        let extra = (t - big_t).max(0.0) * self.f1;
        std::f64::consts::TAU * (cycles + extra)
    }

    fn sample(&self, grid: &SampleGrid) -> Result<Vec<f64>> {
        check_finite("chirp", "amplitude", self.amplitude)?;
        check_finite("chirp", "offset", self.offset)?;
        check_positive("chirp", "duration", self.duration)?;
        match self.sweep {
            Sweep::Linear => {
                check_finite("chirp", "f0", self.f0)?;
                check_finite("chirp", "f1", self.f1)?;
            }
            Sweep::Logarithmic => {
                check_positive("chirp", "f0", self.f0)?;
                check_positive("chirp", "f1", self.f1)?;
            }
        }
        Ok((0..grid.len)
            .map(|k| {
                let t = grid.time(k).max(0.0);
                self.offset + self.amplitude * self.phase(t).sin()
            })
            .collect())
    }
}

/// A fixed level sequence: `levels[i]` on `[i·hold, (i+1)·hold)` s, the first level
/// before t = 0 and the last level after the sequence ends.
#[derive(Debug, Clone, PartialEq)]
pub struct Steps {
    /// Levels, input units (at least one).
    pub levels: Vec<f64>,
    /// Hold time of each level, s.
    pub hold: f64,
}

impl Default for Steps {
    fn default() -> Self {
        Self {
            levels: vec![0.0, 1.0],
            hold: 1.0,
        }
    }
}

impl Steps {
    fn sample(&self, grid: &SampleGrid) -> Result<Vec<f64>> {
        check_positive("steps", "hold", self.hold)?;
        if self.levels.is_empty() {
            return Err(PlantError::InvalidSignal {
                signal: "steps",
                field: "levels",
                value: 0.0,
                reason: "needs at least one level",
            });
        }
        for &l in &self.levels {
            check_finite("steps", "levels", l)?;
        }
        let tol = 1e-9 * grid.dt;
        let last = self.levels.len() - 1;
        Ok((0..grid.len)
            .map(|k| {
                let t = grid.time(k) + tol;
                let i = if t <= 0.0 {
                    0
                } else {
                    ((t / self.hold).floor() as usize).min(last)
                };
                self.levels[i]
            })
            .collect())
    }
}

/// Amplitude-modulated PRBS: a staircase whose levels are uniform in
/// `[min_level, max_level]` and whose hold times are uniform in `[min_hold, max_hold]`,
/// rounded to a multiple of `quantum` (when `quantum > 0`, at least one quantum), all
/// drawn from `seed` (ChaCha8). Segments start at t = 0; the first level also holds before.
///
/// With hold times on a `quantum` grid, every sample rate whose period divides `quantum`
/// sees the switches at the same instants, so data at 10, 5, 1 and 0.5 Hz share one input.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aprbs {
    /// Lowest level, input units.
    pub min_level: f64,
    /// Highest level, input units.
    pub max_level: f64,
    /// Shortest hold, s.
    pub min_hold: f64,
    /// Longest hold, s.
    pub max_hold: f64,
    /// Hold-time quantum, s (0 = continuous hold times).
    pub quantum: f64,
    /// Seed of levels and holds.
    pub seed: u64,
}

impl Default for Aprbs {
    fn default() -> Self {
        Self {
            min_level: -1.0,
            max_level: 1.0,
            min_hold: 1.0,
            max_hold: 5.0,
            quantum: 0.0,
            seed: 0,
        }
    }
}

impl Aprbs {
    /// Switch times (s, starting with 0) and levels covering `[0, t_end]`.
    pub fn segments(&self, t_end: f64) -> Result<(Vec<f64>, Vec<f64>)> {
        self.check()?;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut starts = Vec::new();
        let mut levels = Vec::new();
        let mut t = 0.0;
        loop {
            starts.push(t);
            let u: f64 = rng.random();
            levels.push(self.min_level + u * (self.max_level - self.min_level));
            let v: f64 = rng.random();
            let mut hold = self.min_hold + v * (self.max_hold - self.min_hold);
            if self.quantum > 0.0 {
                hold = ((hold / self.quantum).round() * self.quantum).max(self.quantum);
            }
            t += hold;
            if t > t_end {
                break;
            }
        }
        Ok((starts, levels))
    }

    fn check(&self) -> Result<()> {
        check_finite("aprbs", "min_level", self.min_level)?;
        if !(self.max_level.is_finite() && self.max_level >= self.min_level) {
            return Err(PlantError::InvalidSignal {
                signal: "aprbs",
                field: "max_level",
                value: self.max_level,
                reason: "must be finite and at least min_level",
            });
        }
        check_positive("aprbs", "min_hold", self.min_hold)?;
        if !(self.max_hold.is_finite() && self.max_hold >= self.min_hold) {
            return Err(PlantError::InvalidSignal {
                signal: "aprbs",
                field: "max_hold",
                value: self.max_hold,
                reason: "must be finite and at least min_hold",
            });
        }
        if !(self.quantum.is_finite() && self.quantum >= 0.0) {
            return Err(PlantError::InvalidSignal {
                signal: "aprbs",
                field: "quantum",
                value: self.quantum,
                reason: "must be non-negative and finite",
            });
        }
        Ok(())
    }

    fn sample(&self, grid: &SampleGrid) -> Result<Vec<f64>> {
        let t_end = grid.time(grid.len.saturating_sub(1)).max(0.0);
        let (starts, levels) = self.segments(t_end)?;
        // A sample within 1e-9·dt after a switch counts as after it (round-off of k·dt).
        let tol = 1e-9 * grid.dt;
        let mut seg = 0;
        Ok((0..grid.len)
            .map(|k| {
                let t = grid.time(k) + tol;
                while seg + 1 < starts.len() && starts[seg + 1] <= t {
                    seg += 1;
                }
                levels[seg]
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(dt: f64, len: usize) -> SampleGrid {
        SampleGrid { t0: 0.0, dt, len }
    }

    /// A multisine whose lines fall on DFT bins: the DFT (computed here by direct
    /// summation) has magnitude `N·a/2` at every requested line and is zero (to
    /// round-off, ~1e-12 relative) elsewhere.
    #[test]
    fn multisine_lines_at_requested_frequencies() {
        let ms = Multisine {
            rms: 2.0,
            f_min: 0.3,
            f_max: 1.2,
            lines: 10,
            seed: 5,
            offset: 0.0,
        };
        // Record of 10 s at 20 Hz: bin spacing 0.1 Hz, lines at bins 3, 4, …, 12.
        let n = 200;
        let x = ms.sample(&grid(0.05, n)).unwrap();
        let a = ms.line_amplitude();
        let lines: Vec<usize> = ms
            .frequencies()
            .iter()
            .map(|f| (f / 0.1).round() as usize)
            .collect();
        assert_eq!(lines, (3..=12).collect::<Vec<_>>());
        for bin in 0..n / 2 {
            let (mut re, mut im) = (0.0, 0.0);
            for (k, xk) in x.iter().enumerate() {
                let w = std::f64::consts::TAU * (bin * k) as f64 / n as f64;
                re += xk * w.cos();
                im -= xk * w.sin();
            }
            let mag = re.hypot(im);
            let want = if lines.contains(&bin) {
                n as f64 * a / 2.0
            } else {
                0.0
            };
            assert!(
                (mag - want).abs() < 1e-9 * n as f64 * a,
                "bin {bin}: {mag} vs {want}"
            );
        }
        // The RMS over the common period is the requested one.
        let rms = (x.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        assert!((rms - 2.0).abs() < 1e-12, "rms {rms}");
        // Phases are seeded: same seed same signal, other seed other phases.
        assert_eq!(ms.phases(), ms.phases());
        assert_ne!(ms.phases(), Multisine { seed: 6, ..ms }.phases());
    }

    /// Zero crossings of `sin(2π∫f)` count `2∫f dt` (± 2 for the ends); the integral is
    /// done here in closed form, independently of `Chirp::phase`.
    #[test]
    fn chirp_crossings_match_the_integrated_frequency() {
        for (sweep, cycles) in [
            (Sweep::Linear, 20.0 * (0.5 + 3.0) / 2.0),
            (Sweep::Logarithmic, 0.5 * 20.0 * (6.0 - 1.0) / 6.0_f64.ln()),
        ] {
            let c = Chirp {
                amplitude: 1.0,
                f0: 0.5,
                f1: 3.0,
                duration: 20.0,
                sweep,
                offset: 0.0,
            };
            let x = c.sample(&grid(0.001, 20_001)).unwrap();
            let crossings = x.windows(2).filter(|w| w[0] * w[1] < 0.0).count() as f64;
            assert!(
                (crossings - 2.0 * cycles).abs() <= 2.0,
                "{sweep:?}: {crossings} vs {}",
                2.0 * cycles
            );
            assert!((c.frequency(20.0) - 3.0).abs() < 1e-12);
        }
    }

    #[test]
    fn aprbs_levels_and_quantised_holds() {
        let s = Aprbs {
            min_level: 4.0,
            max_level: 6.0,
            min_hold: 10.0,
            max_hold: 40.0,
            quantum: 2.0,
            seed: 3,
        };
        let (starts, levels) = s.segments(500.0).unwrap();
        assert!(*starts.last().unwrap() <= 500.0 && starts.len() > 5);
        for w in starts.windows(2) {
            let hold = w[1] - w[0];
            assert!(
                (hold / 2.0 - (hold / 2.0).round()).abs() < 1e-9
                    && (10.0 - 1e-9..=40.0 + 1e-9).contains(&hold)
            );
        }
        assert!(levels.iter().all(|l| (4.0..=6.0).contains(l)));
        // The same input at 10 Hz and 0.5 Hz: the slow grid is every 20th fast sample.
        let fast = s.sample(&grid(0.1, 3601)).unwrap();
        let slow = s.sample(&grid(2.0, 181)).unwrap();
        for (j, v) in slow.iter().enumerate() {
            assert!((v - fast[20 * j]).abs() < f64::EPSILON, "slow sample {j}");
        }
        // Level changes only at switch times.
        let changes = fast
            .windows(2)
            .filter(|w| (w[0] - w[1]).abs() > 0.0)
            .count();
        assert_eq!(
            changes,
            starts.iter().filter(|&&t| t > 0.0 && t <= 360.0).count()
        );
    }

    #[test]
    fn steps_and_bad_settings() {
        let s = Steps {
            levels: vec![1.0, 2.0, 3.0],
            hold: 0.5,
        };
        let x = s.sample(&grid(0.25, 8)).unwrap();
        assert_eq!(x, vec![1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 3.0, 3.0]);
        let bad = Excitation::Sine(Sine {
            omega: f64::NAN,
            ..Sine::default()
        });
        assert!(matches!(
            bad.sample(&grid(0.1, 3)),
            Err(PlantError::InvalidSignal { field: "omega", .. })
        ));
        let bad = Excitation::Chirp(Chirp {
            sweep: Sweep::Logarithmic,
            f0: 0.0,
            ..Chirp::default()
        });
        assert!(matches!(
            bad.sample(&grid(0.1, 3)),
            Err(PlantError::InvalidSignal { field: "f0", .. })
        ));
        assert!(matches!(
            Excitation::Constant(1.0).sample(&grid(0.0, 3)),
            Err(PlantError::InvalidArgument { name: "dt", .. })
        ));
    }
}
