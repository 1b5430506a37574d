//! The band-limited reading of a sampled input ([`InterSample::Bl`]): between samples the
//! input is the windowed-sinc interpolation of its samples, evaluated once per record on a
//! grid [`BL_FACTOR`] times finer than the sampling, from which every integrator step reads
//! its stage inputs (linear between grid points; exact at RK4 stages when the sub-steps
//! divide `BL_FACTOR / 2`).
//!
//! Kernel: `sinc(x)·w(x/H)` with the Blackman window `w` over `|x| < H`,
//! `H =` [`BL_HALF_WIDTH`] samples, normalised to sum to one at every fraction (a constant
//! input stays constant). Beyond the record's ends the first and last samples are held,
//! so the reading is exact there only for an input that settles; a record of a
//! band-limited signal loses accuracy within about `H` samples of its ends.
//!
//! Written here: the kernel is a dozen lines, and the grid must line up with the
//! integrators' sub-steps, which a resampling crate would not know about.

use nalgebra::DMatrix;

#[cfg(doc)]
use crate::dataset::InterSample;

/// Grid points per sample interval.
pub const BL_FACTOR: usize = 16;

/// Half-width of the interpolation kernel, samples.
pub const BL_HALF_WIDTH: usize = 32;

/// The band-limited grid of `inputs` (`m × N`): `(N − 1)·BL_FACTOR + 1` points, point `i`
/// at `t0 + i·dt/BL_FACTOR`, its `m` values at `[i·m, (i + 1)·m)`. Every
/// `BL_FACTOR`-th point is the sample itself.
pub fn band_limited_grid(inputs: &DMatrix<f64>) -> Vec<f64> {
    let (m, n) = (inputs.nrows(), inputs.ncols());
    if n == 0 {
        return Vec::new();
    }
    let f = BL_FACTOR;
    let weights: Vec<Vec<f64>> = (1..f).map(|j| kernel(j as f64 / f as f64)).collect();
    let points = (n - 1) * f + 1;
    let mut out = vec![0.0; points * m];
    let data = inputs.as_slice();
    let h = BL_HALF_WIDTH as isize;
    for k in 0..n {
        out[k * f * m..(k * f + 1) * m].copy_from_slice(&data[k * m..(k + 1) * m]);
        if k + 1 == n {
            break;
        }
        for (j, w) in weights.iter().enumerate() {
            let dst = &mut out[(k * f + j + 1) * m..(k * f + j + 2) * m];
            for (tap, wt) in (-h + 1..=h).zip(w) {
                let idx = (k as isize + tap).clamp(0, n as isize - 1) as usize;
                for (d, u) in dst.iter_mut().zip(&data[idx * m..(idx + 1) * m]) {
                    *d += wt * u;
                }
            }
        }
    }
    out
}

/// Normalised kernel weights for a point `frac` (0 < frac < 1) of an interval, taps
/// `−H + 1 ..= H` about the interval's first sample.
fn kernel(frac: f64) -> Vec<f64> {
    use std::f64::consts::PI;
    let h = BL_HALF_WIDTH as isize;
    let mut w: Vec<f64> = (-h + 1..=h)
        .map(|tap| {
            let x = frac - tap as f64;
            let z = (x / BL_HALF_WIDTH as f64).clamp(-1.0, 1.0);
            let window = 0.42 + 0.5 * (PI * z).cos() + 0.08 * (2.0 * PI * z).cos();
            (PI * x).sin() / (PI * x) * window
        })
        .collect();
    let sum: f64 = w.iter().sum();
    for v in &mut w {
        *v /= sum;
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sinusoid at 0.3 of the sampling rate (where linear interpolation passes 73 % of
    /// its amplitude) is recovered between samples, away from the record's ends, to the
    /// kernel's accuracy; linear interpolation misses by tens of percent there.
    #[test]
    fn recovers_a_sinusoid_near_a_third_of_the_sampling_rate() {
        let n = 400;
        let nu = 0.3;
        let u = DMatrix::from_fn(1, n, |_, k| {
            (2.0 * std::f64::consts::PI * nu * k as f64).sin()
        });
        let grid = band_limited_grid(&u);
        assert_eq!(grid.len(), (n - 1) * BL_FACTOR + 1);
        let (mut worst, mut worst_linear) = (0.0f64, 0.0f64);
        for (i, g) in grid
            .iter()
            .enumerate()
            .take(320 * BL_FACTOR)
            .skip(80 * BL_FACTOR)
        {
            let t = i as f64 / BL_FACTOR as f64;
            let truth = (2.0 * std::f64::consts::PI * nu * t).sin();
            worst = worst.max((g - truth).abs());
            let (k, s) = (t.floor() as usize, t.fract());
            let lin = u[(0, k)] + s * (u[(0, k + 1)] - u[(0, k)]);
            worst_linear = worst_linear.max((lin - truth).abs());
        }
        assert!(worst < 2e-3, "band-limited error {worst}");
        assert!(worst_linear > 0.2, "linear error {worst_linear}");
        // Samples are kept exactly.
        for k in 0..n {
            assert!((grid[k * BL_FACTOR] - u[(0, k)]).abs() < 1e-15);
        }
    }

    /// A constant stays constant everywhere, ends included; two channels interleave.
    #[test]
    fn constants_and_channels() {
        let u = DMatrix::from_fn(2, 50, |i, _| if i == 0 { 1.5 } else { -2.0 });
        let grid = band_limited_grid(&u);
        for p in grid.chunks_exact(2) {
            assert!((p[0] - 1.5).abs() < 1e-12 && (p[1] + 2.0).abs() < 1e-12);
        }
        assert!(band_limited_grid(&DMatrix::zeros(1, 0)).is_empty());
    }
}
