//! Measurement-noise variance from the data: a difference-based start, then maximum
//! restricted (diffuse) marginal likelihood of the equivalent state-space model.
//!
//! **Model.** MME's cost is, up to constants, `−2 log` of the joint density of the data
//! and the corrections in the state-space model `x_{j+1} = Φx_j + Γd_j + c_j`,
//! `d_j ~ N(0, (hW)⁻¹)` (process noise per sub-step), `ỹ_k = Cx_{ks} + v_k`,
//! `v_k ~ N(0, R)`, with a flat (diffuse) prior on `x_0`. Integrating the Gaussian
//! exactly over `x_0` and every `d_j` gives the restricted marginal likelihood
//!
//! `−2 log L(W, R) = J_min + Σ_{k,i obs} log R_i − Σ_j log det(hW) + log det A + const`,
//!
//! where `A = ½∇²J` is the Hessian of the whole least-squares problem. The sweep's
//! backward pass is block Gaussian elimination of `A`, so
//! `log det A = Σ_j log det S_j + log det P_0` comes for free. This equals the
//! prediction-error decomposition of the Kalman filter with an exact diffuse
//! initialisation (de Jong 1991, *Ann. Statist.* 19:1073–1083; Harvey 1989,
//! *Forecasting, Structural Time Series Models and the Kalman Filter*, §3.4), and it
//! handles missing samples, sub-steps and several experiments without special cases.
//!
//! **Search.** With `R = σ²ρ` (`ρ_1 = 1`) and `W = (β/σ²)·shape`, the estimate depends on
//! `β` and `ρ` only and `σ²` has the closed form `σ̂² = J̃/(M − nE)` (`M` observations,
//! `E` experiments), so the likelihood is concentrated over `σ²`. `log β` is scanned on a
//! grid around the covariance-constraint value, then `(log β, log ρ_2, …)` are polished by
//! Nelder–Mead.
//!
//! **Start / cross-check.** The difference-based estimator of Hall, Kay & Titterington
//! (1990, *Biometrika* 77:521–528) with the normalised second difference
//! `(1, −2, 1)/√6` (Gasser, Sroka & Jennen-Steinmetz 1986, *Biometrika* 73:625–633):
//! `σ̂² = mean over windows of three consecutive observed samples of ((y_k − 2y_{k+1} +
//! y_{k+2})²/6)`. It annihilates linear trends, so a signal that moves smoothly within a
//! sample contributes only `(ẍ·dt²)²/6`.

use nalgebra::DMatrix;
use sysid_core::Dataset;

use crate::binding::Binding;
use crate::config::AutoWeight;
use crate::error::{MmeError, Result};
use crate::evaluate::{Solve, Summary};
use crate::observe::{MmeEvent, MmeObserver};
use crate::result::{NoiseMethod, NoiseReport};
use crate::sweep::LogDet;
use crate::tune_w::tune;

const LN10: f64 = std::f64::consts::LN_10;

/// Difference-based noise variance per model output (see the module doc).
pub(crate) fn difference_variance(
    data: &Dataset,
    binding: &Binding,
    names: &[String],
) -> Result<Vec<f64>> {
    let mut out = Vec::with_capacity(binding.outputs.len());
    for (i, &row) in binding.outputs.iter().enumerate() {
        let (mut sum, mut windows) = (0.0, 0usize);
        for exp in data.experiments() {
            let y = exp.outputs().row(row);
            for k in 0..exp.len().saturating_sub(2) {
                let (a, b, c) = (y[k], y[k + 1], y[k + 2]);
                if !(a.is_nan() || b.is_nan() || c.is_nan()) {
                    let dd = a - 2.0 * b + c;
                    sum += dd * dd / 6.0;
                    windows += 1;
                }
            }
        }
        if windows < 2 {
            return Err(MmeError::TooFewMeasurements {
                channel: names[i].clone(),
                found: windows,
                needed: 2,
            });
        }
        // A noise-free channel gives 0; keep R positive (round-off of the data scale).
        let v = sum / windows as f64;
        out.push(if v > 0.0 { v } else { f64::MIN_POSITIVE.sqrt() });
    }
    Ok(out)
}

/// Longest Welch segment of [`spectral_floor`].
const FLOOR_SEGMENT: usize = 256;
/// Shortest Welch segment worth using (fewer bins cannot separate a band from the signal).
const FLOOR_MIN_SEGMENT: usize = 32;
/// Frequency bands of [`spectral_floor`] between DC and the Nyquist frequency.
const FLOOR_BANDS: usize = 8;

/// Spectral floor per model output: an upper bound on the variance of the *white* part of
/// the measurement noise that does not depend on how smooth the signal is.
///
/// White noise of variance `σ²` has a flat spectrum; whatever the signal adds lies on
/// top of it. The Welch periodogram (segments of `L` samples, half overlapping, each with
/// its least-squares line removed and a periodic Hann window, normalised by `Σw²` so that
/// white noise of variance `σ²` has expected value `σ²` in every bin) is averaged over the
/// segments of every experiment, its bins `1 … L/2 − 1` are cut into [`FLOOR_BANDS`]
/// contiguous bands, the lowest band (DC leakage, drifts) is dropped, and the floor is the
/// lowest mean of the others. `L` is the largest power of two not above
/// [`FLOOR_SEGMENT`] nor a quarter of the longest experiment; segments with a missing
/// sample are skipped. `+∞` when no segment of at least [`FLOOR_MIN_SEGMENT`] samples
/// exists.
///
/// Unlike second differences, it is not inflated by a signal with content near the
/// Nyquist frequency, as long as one band of the spectrum carries (almost) noise alone: on
/// the Silverbox record (610 Hz, excited to 200 Hz, oscillating near 70 Hz) second
/// differences give 1.3e-4 V² and this floor 1.4e-10 V². Being the least of several band
/// means, it is biased low by about a standard deviation of one band's mean for white
/// noise (≈ 10–25 % on 1 000–10 000 samples); a sensor's anti-aliasing filter, which
/// removes noise near the Nyquist frequency, lowers it further. So it bounds the white
/// noise the likelihood models from above and is no estimate of a coloured sensor noise.
pub(crate) fn spectral_floor(data: &Dataset, binding: &Binding) -> Vec<f64> {
    let longest = data
        .experiments()
        .iter()
        .map(|e| e.len())
        .max()
        .unwrap_or(0);
    let mut l = FLOOR_SEGMENT;
    while l > longest / 4 && l >= FLOOR_MIN_SEGMENT {
        l /= 2;
    }
    if l < FLOOR_MIN_SEGMENT {
        return vec![f64::INFINITY; binding.outputs.len()];
    }
    let half = l / 2;
    let tau = std::f64::consts::TAU;
    let window: Vec<f64> = (0..l)
        .map(|k| 0.5 * (1.0 - (tau * k as f64 / l as f64).cos()))
        .collect();
    let norm: f64 = window.iter().map(|w| w * w).sum();
    // Least-squares line over k = 0..l: centred abscissa.
    let mid = (l as f64 - 1.0) / 2.0;
    let sxx: f64 = (0..l).map(|k| (k as f64 - mid).powi(2)).sum();
    let mut seg = vec![0.0; l];
    let mut power = vec![0.0; half];
    let mut out = Vec::with_capacity(binding.outputs.len());
    for &row in &binding.outputs {
        power.iter_mut().for_each(|p| *p = 0.0);
        let mut segments = 0usize;
        for exp in data.experiments() {
            let y = exp.outputs().row(row);
            let mut start = 0;
            while start + l <= exp.len() {
                let mut ok = true;
                let (mut sy, mut sxy) = (0.0, 0.0);
                for k in 0..l {
                    let v = y[start + k];
                    if v.is_nan() {
                        ok = false;
                        break;
                    }
                    seg[k] = v;
                    sy += v;
                    sxy += (k as f64 - mid) * v;
                }
                if ok {
                    let (mean, slope) = (sy / l as f64, sxy / sxx);
                    for (k, (s, w)) in seg.iter_mut().zip(&window).enumerate() {
                        *s = (*s - mean - slope * (k as f64 - mid)) * w;
                    }
                    for (j, p) in power.iter_mut().enumerate().skip(1) {
                        let omega = tau * j as f64 / l as f64;
                        *p += sysid_core::acquisition::goertzel(&seg, omega).norm_sqr() / norm;
                    }
                    segments += 1;
                }
                start += half;
            }
        }
        if segments == 0 {
            out.push(f64::INFINITY);
            continue;
        }
        let bins = half - 1; // 1 ..= half − 1
        let floor = (1..FLOOR_BANDS)
            .map(|b| {
                let lo = 1 + b * bins / FLOOR_BANDS;
                let hi = 1 + (b + 1) * bins / FLOOR_BANDS;
                power[lo..hi].iter().sum::<f64>() / ((hi - lo) * segments) as f64
            })
            .fold(f64::INFINITY, f64::min);
        out.push(floor);
    }
    out
}

/// Terms of `−2 log L` that need the problem's structure.
#[derive(Debug, Clone)]
pub(crate) struct LikelihoodShape {
    /// Per experiment: pieces and `h`.
    pub pieces: Vec<(usize, f64)>,
    /// `n`.
    pub n: usize,
    /// `q`.
    pub q: usize,
    /// `log det shape`.
    pub logdet_shape: f64,
}

impl LikelihoodShape {
    /// Exact `−2 log L` (without the constant `(M − nE) log 2π`) at `W = alpha·shape` and
    /// the `R` that produced `s`.
    pub fn neg2_loglik(&self, s: &Summary, alpha: f64, r: &[f64]) -> f64 {
        let log_r: f64 = s
            .count
            .iter()
            .zip(r)
            .map(|(&c, ri)| c as f64 * ri.ln())
            .sum();
        let prior: f64 = self
            .pieces
            .iter()
            .map(|&(d, h)| d as f64 * (self.q as f64 * (h * alpha).ln() + self.logdet_shape))
            .sum();
        s.cost + log_r - prior + s.logdet_s + s.logdet_p0
    }

    /// `−2 log L` concentrated over the common scale `σ²`, from a solve at `W = β·shape`,
    /// `R = ρ`. Returns `(value, σ̂²)`.
    pub fn concentrated(&self, s: &Summary, beta: f64, rho: &[f64]) -> (f64, f64) {
        let m: usize = s.count.iter().sum();
        let dof = m as f64 - (self.n * self.pieces.len()) as f64;
        let sigma2 = s.cost / dof;
        let value = self.neg2_loglik(s, beta, rho) - s.cost + dof * (sigma2.ln() + 1.0);
        (value, sigma2)
    }
}

/// Estimate `R` by maximum restricted marginal likelihood (see the module doc); each
/// solve is told to `observer` as it finishes.
pub(crate) fn estimate_noise<S: Solve>(
    solver: &mut S,
    shape: &DMatrix<f64>,
    data: &Dataset,
    binding: &Binding,
    names: &[String],
    observer: &dyn MmeObserver,
) -> Result<NoiseReport> {
    let start = difference_variance(data, binding, names)?;
    let p = start.len();
    let n = solver.n_states();
    let m: usize = binding.observed.iter().sum();
    let experiments = data.experiments().len();
    if m <= n * experiments + 1 {
        return Err(MmeError::TooFewSamples {
            experiment: 0,
            found: m,
            needed: n * experiments + 2,
        });
    }
    let logdet_shape = shape
        .clone()
        .cholesky()
        .map(|c| 2.0 * c.l().diagonal().map(f64::ln).sum());
    let Some(logdet_shape) = logdet_shape else {
        return Err(MmeError::NotPositiveDefinite {
            matrix: "W shape",
            reason: "Cholesky factorisation failed",
        });
    };
    let lik = LikelihoodShape {
        pieces: solver.pieces(),
        n,
        q: solver.n_corrections(),
        logdet_shape,
    };

    // Start β from the covariance constraint at the difference-based R.
    let inv_start: Vec<f64> = start.iter().map(|v| 1.0 / v).collect();
    let mut curve = Vec::new();
    let opts = AutoWeight {
        tolerance: 1e-2,
        ..AutoWeight::default()
    };
    let cc = tune(solver, shape, &inv_start, &opts, &mut curve, observer)?;
    let mut evaluations = cc.evaluations;
    let rho0: Vec<f64> = start.iter().map(|v| v / start[0]).collect();
    let z_beta0 = (cc.alpha * start[0]).ln();

    // Objective over z = (ln β, ln ρ_2, …, ln ρ_p).
    let z_lo = z_beta0 - 16.0 * LN10;
    let z_hi = z_beta0 + 16.0 * LN10;
    let mut objective = |z: &[f64], solver: &mut S| -> Result<f64> {
        if z[0] < z_lo || z[0] > z_hi || z[1..].iter().any(|v| v.abs() > 12.0 * LN10) {
            return Ok(f64::INFINITY);
        }
        let beta = z[0].exp();
        let rho: Vec<f64> = (0..p)
            .map(|i| if i == 0 { 1.0 } else { z[i].exp() })
            .collect();
        let inv: Vec<f64> = rho.iter().map(|r| 1.0 / r).collect();
        evaluations += 1;
        // An undetermined initial state (W so small that d absorbs everything) has no
        // finite likelihood here: outside the feasible region.
        let s = match solver.solve(&(shape * beta), &inv, LogDet::Accumulate) {
            Err(MmeError::NotObservable { .. }) => {
                observer.event(&MmeEvent::NoiseStep {
                    evaluation: evaluations,
                    neg2_log_likelihood: f64::INFINITY,
                });
                return Ok(f64::INFINITY);
            }
            other => other?,
        };
        let (v, _) = lik.concentrated(&s, beta, &rho);
        let v = if v.is_finite() { v } else { f64::INFINITY };
        observer.event(&MmeEvent::NoiseStep {
            evaluation: evaluations,
            neg2_log_likelihood: v,
        });
        Ok(v)
    };

    // Grid over ln β (half-decade steps), extended while the minimum sits on an edge.
    let mut z: Vec<f64> = std::iter::once(0.0)
        .chain(rho0.iter().skip(1).map(|r| r.ln()))
        .collect();
    let mut grid: Vec<(f64, f64)> = Vec::new();
    let (mut lo, mut hi) = (z_beta0 - 4.0 * LN10, z_beta0 + 4.0 * LN10);
    let mut zb = lo;
    while zb <= hi + 1e-9 {
        z[0] = zb;
        grid.push((zb, objective(&z, solver)?));
        zb += 0.5 * LN10;
    }
    for _ in 0..3 {
        let best = argmin(&grid);
        if best == 0 && lo > z_lo {
            let new_lo = (lo - 4.0 * LN10).max(z_lo);
            let mut zb = lo - 0.5 * LN10;
            while zb >= new_lo - 1e-9 {
                z[0] = zb;
                grid.insert(0, (zb, objective(&z, solver)?));
                zb -= 0.5 * LN10;
            }
            lo = new_lo;
        } else if best == grid.len() - 1 && hi < z_hi {
            let new_hi = (hi + 4.0 * LN10).min(z_hi);
            let mut zb = hi + 0.5 * LN10;
            while zb <= new_hi + 1e-9 {
                z[0] = zb;
                grid.push((zb, objective(&z, solver)?));
                zb += 0.5 * LN10;
            }
            hi = new_hi;
        } else {
            break;
        }
    }
    z[0] = grid[argmin(&grid)].0;

    // Polish all parameters.
    let mut steps = vec![0.3; p];
    steps[0] = 0.5 * LN10;
    let (z_best, f_best) = nelder_mead(&mut |zz: &[f64]| objective(zz, solver), &z, &steps, 400)?;

    // Final values at the optimum.
    let beta = z_best[0].exp();
    let rho: Vec<f64> = (0..p)
        .map(|i| if i == 0 { 1.0 } else { z_best[i].exp() })
        .collect();
    let inv: Vec<f64> = rho.iter().map(|r| 1.0 / r).collect();
    let s = solver.solve(&(shape * beta), &inv, LogDet::Accumulate)?;
    let (at_optimum, sigma2) = lik.concentrated(&s, beta, &rho);
    observer.event(&MmeEvent::NoiseStep {
        evaluation: evaluations + 1,
        neg2_log_likelihood: at_optimum,
    });
    let variance: Vec<f64> = rho.iter().map(|r| r * sigma2).collect();
    // Degenerate likelihood: when the corrections can interpolate the data, the likelihood
    // can keep rising as R → 0 (seen on the short, coarsely sampled Cascaded Tanks record:
    // 1e-9 V² against a difference-based 5e-4 V²). A variance more than
    // `DEGENERATE_RATIO` below the model-free reference of any channel — the lower of the
    // difference-based estimate and the spectral floor, both upper bounds of the white
    // noise — is taken as that boundary, and the reference is used instead. (With second
    // differences alone, a record oscillating near the Nyquist frequency, where they
    // measure the signal's curvature, had every likelihood estimate below 1 % of them
    // rejected: on Silverbox 1.3e-4 V², 11 mV RMS, where published models simulate the
    // record to 0.26 mV.)
    let floor = spectral_floor(data, binding);
    let reference: Vec<f64> = start.iter().zip(&floor).map(|(d, f)| d.min(*f)).collect();
    if variance
        .iter()
        .zip(&reference)
        .any(|(v, r)| *v < r / DEGENERATE_RATIO)
    {
        let from_floor = floor.iter().zip(&start).any(|(f, d)| f < d);
        let floor = floor.iter().map(|f| f.is_finite().then_some(*f)).collect();
        return Ok(NoiseReport {
            method: if from_floor {
                NoiseMethod::SpectralFloor
            } else {
                NoiseMethod::DifferenceBased
            },
            variance: reference,
            difference_based: start,
            spectral_floor: floor,
            likelihood_alpha: Some(beta / sigma2),
            neg2_log_likelihood: Some(f_best),
            evaluations: evaluations + 1,
        });
    }
    Ok(NoiseReport {
        method: NoiseMethod::MarginalLikelihood,
        variance,
        difference_based: start,
        spectral_floor: floor.iter().map(|f| f.is_finite().then_some(*f)).collect(),
        likelihood_alpha: Some(beta / sigma2),
        neg2_log_likelihood: Some(f_best),
        evaluations: evaluations + 1,
    })
}

/// How far below the model-free reference (see [`estimate_noise`]) a likelihood estimate may fall before it is
/// taken as the degenerate `R → 0` boundary (two orders of magnitude).
const DEGENERATE_RATIO: f64 = 100.0;

fn argmin(grid: &[(f64, f64)]) -> usize {
    let mut best = 0;
    for (i, g) in grid.iter().enumerate() {
        if g.1 < grid[best].1 {
            best = i;
        }
    }
    best
}

/// Nelder–Mead minimisation (Nelder & Mead 1965; standard coefficients 1, 2, ½, ½).
/// Stops when the simplex's function values agree to 1e-10 relative and its size is
/// below 1e-7, or after `max_evals`.
pub(crate) fn nelder_mead<F>(
    f: &mut F,
    x0: &[f64],
    steps: &[f64],
    max_evals: usize,
) -> Result<(Vec<f64>, f64)>
where
    F: FnMut(&[f64]) -> Result<f64>,
{
    let dim = x0.len();
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(dim + 1);
    simplex.push((x0.to_vec(), f(x0)?));
    for i in 0..dim {
        let mut x = x0.to_vec();
        x[i] += steps[i];
        let v = f(&x)?;
        simplex.push((x, v));
    }
    let mut evals = dim + 1;
    let point = |a: &[f64], b: &[f64], t: f64| -> Vec<f64> {
        a.iter().zip(b).map(|(ai, bi)| ai + t * (bi - ai)).collect()
    };
    while evals < max_evals {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let (best, worst) = (simplex[0].1, simplex[dim].1);
        let size = simplex[1..]
            .iter()
            .map(|(x, _)| {
                x.iter()
                    .zip(&simplex[0].0)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max)
            })
            .fold(0.0, f64::max);
        if (worst - best).abs() <= 1e-10 * (1.0 + best.abs()) && size < 1e-7 {
            break;
        }
        let mut centroid = vec![0.0; dim];
        for (x, _) in &simplex[..dim] {
            for (c, xi) in centroid.iter_mut().zip(x) {
                *c += xi / dim as f64;
            }
        }
        let xw = simplex[dim].0.clone();
        let xr = point(&centroid, &xw, -1.0);
        let fr = f(&xr)?;
        evals += 1;
        if fr < simplex[0].1 {
            let xe = point(&centroid, &xw, -2.0);
            let fe = f(&xe)?;
            evals += 1;
            simplex[dim] = if fe < fr { (xe, fe) } else { (xr, fr) };
        } else if fr < simplex[dim - 1].1 {
            simplex[dim] = (xr, fr);
        } else {
            let (xc, fc) = if fr < worst {
                let xc = point(&centroid, &xr, 0.5);
                let fc = f(&xc)?;
                (xc, fc)
            } else {
                let xc = point(&centroid, &xw, 0.5);
                let fc = f(&xc)?;
                (xc, fc)
            };
            evals += 1;
            if fc < fr.min(worst) {
                simplex[dim] = (xc, fc);
            } else {
                let x_best = simplex[0].0.clone();
                for item in simplex.iter_mut().skip(1) {
                    let xs = point(&x_best, &item.0, 0.5);
                    let fs = f(&xs)?;
                    *item = (xs, fs);
                    evals += 1;
                }
            }
        }
    }
    simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (x, v) = simplex.swap_remove(0);
    Ok((x, v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linear::LinearRun;
    use nalgebra::DVector;
    use sysid_core::{Channel, Experiment, LinearModel};

    /// A small problem: oscillator, position measured with gaps, 2 sub-steps, 40 samples.
    fn problem() -> (LinearModel, Dataset) {
        let model = LinearModel::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -3.0, -0.4]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
        )
        .unwrap();
        let len = 40;
        let mut y = DMatrix::from_fn(1, len, |_, k| {
            (0.3 * k as f64).sin() + 0.1 * (((k * 7919) % 97) as f64 / 48.0 - 1.0)
        });
        y[(0, 7)] = f64::NAN;
        y[(0, 20)] = f64::NAN;
        let u = DMatrix::from_fn(1, len, |_, k| (0.1 * k as f64).cos());
        let exp = Experiment::new(0.0, 0.1, u, y).unwrap();
        let data = Dataset::new(
            vec![Channel::new("u1")],
            vec![Channel::new("y1")],
            vec![exp],
        )
        .unwrap();
        (model, data)
    }

    /// Dense pieces: for each observed sample, the output's dependence on `x0` (row of X),
    /// on the stacked pieces (row of G) and its forced part μ; `h` and the piece count.
    fn dense(
        model: &LinearModel,
        data: &Dataset,
    ) -> (
        DMatrix<f64>,
        DMatrix<f64>,
        DVector<f64>,
        DVector<f64>,
        f64,
        usize,
    ) {
        let exp = &data.experiments()[0];
        let s = 2;
        let h = exp.dt() / s as f64;
        let z = model.discretize(h).unwrap();
        let pieces = (exp.len() - 1) * s;
        let dim = 2 + pieces;
        let mut m = DMatrix::<f64>::zeros(2, dim);
        m.view_mut((0, 0), (2, 2)).fill_with_identity();
        let mut mu = DVector::<f64>::zeros(2);
        let (mut xr, mut gr, mut mr, mut yr) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for k in 0..exp.len() {
            let y = exp.outputs()[(0, k)];
            if !y.is_nan() {
                let row = model.c() * &m;
                xr.push(row.columns(0, 2).into_owned());
                gr.push(row.columns(2, pieces).into_owned());
                mr.push((model.c() * &mu)[0]);
                yr.push(y);
            }
            if k + 1 < exp.len() {
                let u = DVector::from_element(1, exp.inputs()[(0, k)]);
                for r in 0..s {
                    let mut next = &z.ad * &m;
                    next.view_mut((0, 2 + k * s + r), (2, 1)).copy_from(&z.ed);
                    m = next;
                    mu = &z.ad * &mu + &z.bd * &u;
                }
            }
        }
        let x = DMatrix::from_fn(xr.len(), 2, |i, j| xr[i][(0, j)]);
        let g = DMatrix::from_fn(gr.len(), pieces, |i, j| gr[i][(0, j)]);
        (
            x,
            g,
            DVector::from_vec(mr),
            DVector::from_vec(yr),
            h,
            pieces,
        )
    }

    fn logdet_spd(m: &DMatrix<f64>) -> f64 {
        2.0 * m
            .clone()
            .cholesky()
            .unwrap()
            .l()
            .diagonal()
            .map(f64::ln)
            .sum()
    }

    /// `−2 log` of the restricted likelihood from the marginal Gaussian of the data,
    /// `y ~ N(Xβ + μ, R + G(hαI)⁻¹Gᵀ)` with β flat (without the constant).
    fn dense_neg2(model: &LinearModel, data: &Dataset, alpha: f64, r: f64) -> f64 {
        let (x, g, mu, y, h, _) = dense(model, data);
        let m = y.len();
        let sigma = DMatrix::<f64>::identity(m, m) * r + &g * g.transpose() / (h * alpha);
        let si = sigma.clone().try_inverse().unwrap();
        let xt_si_x = x.transpose() * &si * &x;
        let res = &y - &mu;
        let proj = &si - &si * &x * xt_si_x.clone().try_inverse().unwrap() * x.transpose() * &si;
        logdet_spd(&sigma) + logdet_spd(&xt_si_x) + (res.transpose() * proj * &res)[0]
    }

    #[test]
    fn sweep_logdet_is_the_log_determinant_of_the_normal_matrix() {
        let (model, data) = problem();
        let mut run = LinearRun::new(&model, &data, Some(2)).unwrap();
        let (alpha, r) = (0.7, 0.02);
        let s = run
            .solve(
                &DMatrix::from_element(1, 1, alpha),
                &[1.0 / r],
                LogDet::Accumulate,
            )
            .unwrap();
        // Whitened least-squares matrix: rows C·M_k/√r, then √(hα) on each piece.
        let (x, g, _, _, h, pieces) = dense(&model, &data);
        let mut hm = DMatrix::zeros(x.nrows() + pieces, 2 + pieces);
        hm.view_mut((0, 0), (x.nrows(), 2))
            .copy_from(&(&x / r.sqrt()));
        hm.view_mut((0, 2), (x.nrows(), pieces))
            .copy_from(&(&g / r.sqrt()));
        for j in 0..pieces {
            hm[(x.nrows() + j, 2 + j)] = (h * alpha).sqrt();
        }
        let dense_logdet = logdet_spd(&(hm.transpose() * &hm));
        let sweep_logdet = s.logdet_s + s.logdet_p0;
        // Both are sums of ~80 logarithms of O(1…1e4) numbers: agree to round-off.
        assert!(
            (sweep_logdet - dense_logdet).abs() < 1e-9 * dense_logdet.abs(),
            "{sweep_logdet} vs {dense_logdet}"
        );
    }

    #[test]
    fn likelihood_matches_the_marginal_gaussian_up_to_a_constant() {
        let (model, data) = problem();
        let mut run = LinearRun::new(&model, &data, Some(2)).unwrap();
        let shape = LikelihoodShape {
            pieces: run.pieces(),
            n: 2,
            q: 1,
            logdet_shape: 0.0,
        };
        let ours = |run: &mut LinearRun, alpha: f64, r: f64| {
            let s = run
                .solve(
                    &DMatrix::from_element(1, 1, alpha),
                    &[1.0 / r],
                    LogDet::Accumulate,
                )
                .unwrap();
            (shape.neg2_loglik(&s, alpha, &[r]), s)
        };
        let settings = [(0.7, 0.02), (5.0, 0.005), (0.05, 0.1)];
        let base = ours(&mut run, settings[0].0, settings[0].1).0
            - dense_neg2(&model, &data, settings[0].0, settings[0].1);
        for &(alpha, r) in &settings[1..] {
            let (value, s) = ours(&mut run, alpha, r);
            let diff = value - dense_neg2(&model, &data, alpha, r);
            // The offset is the constant (M − n)·log 2π-type term only: identical for all
            // parameters to round-off of the O(1e2) values.
            assert!(
                (diff - base).abs() < 1e-8 * value.abs().max(1.0),
                "{diff} vs {base}"
            );
            // Concentrating over σ² at (β = αr, ρ = 1) gives the value at the optimal
            // scale, which no other scale beats.
            let s_unit = run
                .solve(
                    &DMatrix::from_element(1, 1, alpha * r),
                    &[1.0],
                    LogDet::Accumulate,
                )
                .unwrap();
            let (conc, sigma2) = shape.concentrated(&s_unit, alpha * r, &[1.0]);
            let mut at = |scale: f64| ours(&mut run, alpha * r / scale, scale).0;
            let direct = at(sigma2);
            assert!(
                (conc - direct).abs() < 1e-9 * conc.abs().max(1.0),
                "{conc} vs {direct}"
            );
            assert!(at(sigma2 * 1.1) > conc && at(sigma2 / 1.1) > conc);
            assert!(s.cost > 0.0);
        }
    }

    #[test]
    fn nelder_mead_finds_rosenbrock_minimum() {
        let mut f = |x: &[f64]| -> Result<f64> {
            Ok((1.0 - x[0]).powi(2) + 100.0 * (x[1] - x[0] * x[0]).powi(2))
        };
        let (x, v) = nelder_mead(&mut f, &[-1.2, 1.0], &[0.5, 0.5], 2000).unwrap();
        // Exact minimum (1, 1) with value 0; NM's tolerance 1e-7 on the simplex size.
        assert!(
            (x[0] - 1.0).abs() < 1e-5 && (x[1] - 1.0).abs() < 1e-5,
            "{x:?}"
        );
        assert!(v < 1e-10);
    }
}
