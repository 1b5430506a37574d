//! The flexible stand-in: is what MME still has to correct *predictable*?
//!
//! The judge ([`crate::judge`]) asks whether the free-run error of a model is as small
//! as noise, and whether its residual is as white. A third question decides whether
//! something is left to explain: can a model far more flexible than the catalogue
//! predict MME's correction `d̂` from the estimated states and inputs, better than the
//! terms the model already has? A right model leaves `d̂` as smoothed noise, which no
//! function of `(x̂, u)` predicts out of sample; an effect that catalogue terms only
//! imitate, or one outside the catalogue, leaves a function of the state behind.
//!
//! # The statistic
//!
//! Per corrected equation, on the samples of every record (ends trimmed, thinned to at
//! most [`StandInConfig::max_samples`]), two regressions of `d̂_i` are compared by blocked
//! cross-validation (contiguous folds, so that `d̂`'s smoothness does not leak between
//! training and test rows):
//!
//! * the **base**: an intercept, every state and input (linear corrections of `A` and
//!   `B` stay allowed) and every term the model already has, evaluated at `(x̂, u)`
//!   (so that a coefficient slightly off is not mistaken for structure);
//! * the **stand-in**: the base plus two ridge-penalised Gaussian layers on the
//!   standardised `(x̂, u)`: an additive one ([`StandInConfig::knots`] bumps per
//!   variable at its quantiles — most missing laws read one variable, and one-variable
//!   bumps interpolate where a contiguous held-out block lies) and a joint one
//!   ([`StandInConfig::centres`] centres by farthest-point sampling, width the median
//!   distance from a centre to its nearest neighbour) for interactions.
//!
//! The gain is `1 − SSE_stand-in / SSE_base` over the held-out folds (the share of the
//! base's out-of-sample error the stand-in removes); the statistic is the largest gain
//! over the equations.
//!
//! # Its reference
//!
//! The gain of a right model is not 0: MME's state estimates and `d̂` come from the same
//! noise, and the stand-in fits some of it. Its reference distribution is measured under
//! the pipeline that produced it: the model is simulated from MME's `x̂(t0)` by the
//! adaptive Dormand–Prince integrator at tight tolerance, seeded Gaussian noise of MME's
//! variance is added, MME is rerun at the same `W` and `R` (by the caller, this crate
//! never calls the estimator), and the gain is computed on each draw. The stand-in
//! *finds structure* when the statistic exceeds both the normal `level` quantile matched
//! to the draws' mean and spread and [`StandInConfig::min_gain`] — a stand-in that
//! removes less than a tenth of the base's out-of-sample error is not evidence of a
//! missing effect, however many samples make it significant.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};
use sysid_core::{Dataset, Integrator, MmeEstimate, TermModel};

use crate::error::{DiscoveryError, Result};
use crate::samples::{Samples, samples_from_estimate};

/// Settings of [`stand_in`] and [`gains`].
#[derive(Debug, Clone, PartialEq)]
pub struct StandInConfig {
    /// Reference draws (≥ 4). Default 12.
    pub draws: usize,
    /// Quantile of the normal distribution matched to the draws' gains above which the
    /// statistic finds structure. Default 0.999.
    pub level: f64,
    /// Smallest gain that counts as structure, whatever the reference. Default 0.1.
    pub min_gain: f64,
    /// Radial-basis centres of the joint layer (interactions; 0: none). Default 10.
    pub centres: usize,
    /// One-variable bumps per state and input (the additive layer). Default 10.
    pub knots: usize,
    /// Cross-validation folds (contiguous blocks). Default 5.
    pub folds: usize,
    /// Most samples used (thinned evenly when there are more). Default 2000.
    pub max_samples: usize,
    /// Fraction of samples dropped at each end of every record (the smoother's end
    /// effects). Default 0.05.
    pub trim_fraction: f64,
    /// Ridge penalty of the radial-basis weights, relative to the mean diagonal of their
    /// Gram matrix. Default 0.1.
    pub ridge: f64,
    /// Seed of the reference noise.
    pub seed: u64,
    /// Integrator that simulates the reference records. Default Dormand–Prince at rtol
    /// 1e-10, atol 1e-12 (as the judge's).
    pub truth_integrator: Integrator,
}

impl Default for StandInConfig {
    fn default() -> Self {
        Self {
            draws: 12,
            level: 0.999,
            min_gain: 0.1,
            centres: 10,
            knots: 10,
            folds: 5,
            max_samples: 2000,
            trim_fraction: 0.05,
            ridge: 0.1,
            seed: 29,
            truth_integrator: crate::judge::truth_integrator(),
        }
    }
}

/// The stand-in's statistic and its reference (see the module documentation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandIn {
    /// The largest cross-validated gain over the corrected equations.
    pub statistic: f64,
    /// The gain per corrected equation.
    pub per_equation: Vec<f64>,
    /// The statistic on every reference draw that completed.
    pub reference: Vec<f64>,
    /// Draws asked for.
    pub draws: usize,
    /// Draws whose simulation or MME run failed (left out of `reference`).
    pub failed: usize,
    /// Mean of `reference`.
    pub mean: f64,
    /// Standard deviation of `reference`.
    pub sd: f64,
    /// The larger of the `level` quantile of the normal matched to `reference` and
    /// `min_gain`.
    pub threshold: f64,
    /// The quantile level.
    pub level: f64,
    /// The smallest gain that counts.
    pub min_gain: f64,
}

impl StandIn {
    /// Whether nothing predictable is left: the statistic lies within the threshold.
    pub fn accepts(&self) -> bool {
        self.statistic.is_finite() && self.statistic <= self.threshold
    }
}

fn check_config(config: &StandInConfig) -> Result<()> {
    let bad = |field, value: f64, reason| {
        Err(DiscoveryError::InvalidConfig {
            field,
            value,
            reason,
        })
    };
    if config.draws < 4 {
        return bad("draws", config.draws as f64, "at least 4");
    }
    if !(config.level > 0.5 && config.level < 1.0) {
        return bad("level", config.level, "must lie in (0.5, 1)");
    }
    if !(config.min_gain.is_finite() && config.min_gain >= 0.0) {
        return bad(
            "min_gain",
            config.min_gain,
            "must be finite and non-negative",
        );
    }
    if config.knots == 0 && config.centres == 0 {
        return bad("knots", 0.0, "knots or centres must be at least 1");
    }
    if config.folds < 2 {
        return bad("folds", config.folds as f64, "at least 2");
    }
    if config.max_samples < 10 * config.folds {
        return bad(
            "max_samples",
            config.max_samples as f64,
            "at least 10 per fold",
        );
    }
    if !(config.trim_fraction >= 0.0 && config.trim_fraction < 0.5) {
        return bad(
            "trim_fraction",
            config.trim_fraction,
            "must lie in [0, 0.5)",
        );
    }
    if !(config.ridge.is_finite() && config.ridge > 0.0) {
        return bad("ridge", config.ridge, "must be positive and finite");
    }
    Ok(())
}

/// The rows the regressions use: `(experiment, sample)` after trimming and thinning, in
/// time order within each record (so that contiguous folds are contiguous in time).
fn rows(samples: &[Samples], config: &StandInConfig) -> Vec<(usize, usize)> {
    let mut all = Vec::new();
    for (e, s) in samples.iter().enumerate() {
        let n = s.len();
        let cut = (config.trim_fraction * n as f64).floor() as usize;
        all.extend((cut..n.saturating_sub(cut)).map(|k| (e, k)));
    }
    let stride = all.len().div_ceil(config.max_samples).max(1);
    all.into_iter().step_by(stride).collect()
}

/// The cross-validated gain of the stand-in over the base, per corrected equation of
/// `samples` (MME's `x̂`, `u` and `d̂` with `model`). Errors: a config out of range, fewer
/// than 20 rows per fold, samples not matching the model.
pub fn gains(model: &TermModel, samples: &[Samples], config: &StandInConfig) -> Result<Vec<f64>> {
    check_config(config)?;
    let lin = model.linear();
    let (n, m) = (lin.n_states(), lin.n_inputs());
    let q = samples.first().map_or(0, |s| s.corrections().nrows());
    for (e, s) in samples.iter().enumerate() {
        s.check(e, n, m, q)?;
    }
    let rows = rows(samples, config);
    let needed = 20 * config.folds;
    if rows.len() < needed {
        return Err(DiscoveryError::TooFewSamples {
            what: "samples for the stand-in's cross-validation",
            found: rows.len(),
            needed,
        });
    }
    let len = rows.len();
    // Standardised (x̂, u); constant variables dropped from the radial layer.
    let dim = n + m;
    let mut raw = DMatrix::zeros(len, dim);
    for (r, &(e, k)) in rows.iter().enumerate() {
        let s = &samples[e];
        for i in 0..n {
            raw[(r, i)] = s.states()[(i, k)];
        }
        for j in 0..m {
            raw[(r, n + j)] = s.inputs()[(j, k)];
        }
    }
    let mut z_cols = Vec::new();
    for c in 0..dim {
        let col = raw.column(c);
        let mean = col.mean();
        let sd = (col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / len as f64).sqrt();
        if sd > 1e-12 * (1.0 + mean.abs()) {
            z_cols.push(col.map(|v| (v - mean) / sd));
        }
    }
    let z = DMatrix::from_columns(&z_cols);
    // Base columns: intercept, standardised variables, the model's terms (standardised;
    // a constant term is the intercept's).
    let mut base_cols: Vec<DVector<f64>> = vec![DVector::from_element(len, 1.0)];
    base_cols.extend(z_cols.iter().cloned());
    let mut x = vec![0.0; n];
    let mut u = vec![0.0; m];
    for term in model.terms() {
        let mut col = DVector::zeros(len);
        for (r, &(e, k)) in rows.iter().enumerate() {
            let s = &samples[e];
            for (i, xi) in x.iter_mut().enumerate() {
                *xi = s.states()[(i, k)];
            }
            for (j, uj) in u.iter_mut().enumerate() {
                *uj = s.inputs()[(j, k)];
            }
            col[r] = term.expr.eval_parts(&x, &u);
        }
        let mean = col.mean();
        let sd = (col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / len as f64).sqrt();
        if col.iter().all(|v| v.is_finite()) && sd > 1e-12 * (1.0 + mean.abs()) {
            base_cols.push(col.map(|v| (v - mean) / sd));
        }
    }
    let base = DMatrix::from_columns(&base_cols);
    let phi = {
        let additive = additive_layer(&z, config.knots);
        let joint = radial_layer(&z, config.centres);
        let mut cols: Vec<DVector<f64>> = additive.column_iter().map(|c| c.into_owned()).collect();
        cols.extend(joint.column_iter().map(|c| c.into_owned()));
        if cols.is_empty() {
            DMatrix::zeros(len, 0)
        } else {
            DMatrix::from_columns(&cols)
        }
    };
    let folds: Vec<usize> = (0..len).map(|r| r * config.folds / len).collect();
    let mut out = Vec::with_capacity(q);
    for i in 0..q {
        let mut d = DVector::<f64>::zeros(len);
        for (r, &(e, k)) in rows.iter().enumerate() {
            d[r] = samples[e].corrections()[(i, k)];
        }
        let (mut sse_base, mut sse_flex) = (0.0, 0.0);
        for f in 0..config.folds {
            let train: Vec<usize> = (0..len).filter(|&r| folds[r] != f).collect();
            let test: Vec<usize> = (0..len).filter(|&r| folds[r] == f).collect();
            sse_base += held_out_sse(&base, None, &d, &train, &test, config.ridge);
            sse_flex += held_out_sse(&base, Some(&phi), &d, &train, &test, config.ridge);
        }
        out.push(if sse_base > 0.0 && sse_flex.is_finite() {
            1.0 - sse_flex / sse_base
        } else {
            0.0
        });
    }
    Ok(out)
}

/// One-variable Gaussian bumps: for every column of `z`, `k` centres at its
/// `(j + ½)/k` quantiles, each as wide as the gap to its neighbours (the additive part
/// of the stand-in; most missing laws read one variable).
fn additive_layer(z: &DMatrix<f64>, k: usize) -> DMatrix<f64> {
    let (len, dim) = z.shape();
    let mut cols: Vec<DVector<f64>> = Vec::new();
    for c in 0..dim {
        let mut sorted: Vec<f64> = z.column(c).iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        let at = |p: f64| sorted[((p * (len - 1) as f64).round() as usize).min(len - 1)];
        let centres: Vec<f64> = (0..k).map(|j| at((j as f64 + 0.5) / k as f64)).collect();
        for (j, &m) in centres.iter().enumerate() {
            let left = if j > 0 {
                m - centres[j - 1]
            } else {
                f64::INFINITY
            };
            let right = if j + 1 < k {
                centres[j + 1] - m
            } else {
                f64::INFINITY
            };
            let width = left.min(right);
            if !(width.is_finite() && width > 0.0) {
                continue;
            }
            let scale = 1.0 / (2.0 * width * width);
            cols.push(z.column(c).map(|v| (-(v - m).powi(2) * scale).exp()));
        }
    }
    if cols.is_empty() {
        DMatrix::zeros(len, 0)
    } else {
        DMatrix::from_columns(&cols)
    }
}

/// Gaussian radial-basis features of the rows of `z`: `k` centres by farthest-point
/// sampling from the row nearest the mean (deterministic), width the median distance from
/// a centre to its nearest other centre.
fn radial_layer(z: &DMatrix<f64>, k: usize) -> DMatrix<f64> {
    let (len, dim) = z.shape();
    if dim == 0 || k == 0 {
        return DMatrix::zeros(len, 0);
    }
    let dist2 = |a: usize, b: usize| -> f64 {
        (0..dim)
            .map(|c| (z[(a, c)] - z[(b, c)]).powi(2))
            .sum::<f64>()
    };
    let norm2 = |a: usize| -> f64 { (0..dim).map(|c| z[(a, c)].powi(2)).sum::<f64>() };
    let first = (0..len)
        .min_by(|&a, &b| norm2(a).total_cmp(&norm2(b)))
        .unwrap_or(0);
    let mut centres = vec![first];
    let mut nearest: Vec<f64> = (0..len).map(|r| dist2(r, first)).collect();
    while centres.len() < k.min(len) {
        let (next, far) = nearest
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(r, d)| (r, *d))
            .unwrap_or((0, 0.0));
        if far <= 0.0 {
            break;
        }
        centres.push(next);
        for (r, d) in nearest.iter_mut().enumerate() {
            *d = d.min(dist2(r, next));
        }
    }
    let mut spacing: Vec<f64> = centres
        .iter()
        .map(|&a| {
            centres
                .iter()
                .filter(|&&b| b != a)
                .map(|&b| dist2(a, b))
                .fold(f64::INFINITY, f64::min)
                .sqrt()
        })
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    spacing.sort_by(f64::total_cmp);
    let width = spacing.get(spacing.len() / 2).copied().unwrap_or(1.0);
    let scale = 1.0 / (2.0 * width * width);
    DMatrix::from_fn(len, centres.len(), |r, c| {
        (-dist2(r, centres[c]) * scale).exp()
    })
}

/// Squared error on `test` rows of the regression of `d` on `[base | extra]` fitted on
/// `train` rows: least squares on `base`, ridge `ridge · mean diag(ΦᵀΦ)` on `extra`.
fn held_out_sse(
    base: &DMatrix<f64>,
    extra: Option<&DMatrix<f64>>,
    d: &DVector<f64>,
    train: &[usize],
    test: &[usize],
    ridge: f64,
) -> f64 {
    let nb = base.ncols();
    let ne = extra.map_or(0, DMatrix::ncols);
    let p = nb + ne;
    let row = |r: usize, c: usize| -> f64 {
        if c < nb {
            base[(r, c)]
        } else {
            extra.map_or(0.0, |x| x[(r, c - nb)])
        }
    };
    let mut gram = DMatrix::<f64>::zeros(p, p);
    let mut rhs = DVector::<f64>::zeros(p);
    let mut v = vec![0.0; p];
    for &r in train {
        for (c, vc) in v.iter_mut().enumerate() {
            *vc = row(r, c);
        }
        for a in 0..p {
            rhs[a] += v[a] * d[r];
            for b in a..p {
                gram[(a, b)] += v[a] * v[b];
            }
        }
    }
    for a in 0..p {
        for b in 0..a {
            gram[(a, b)] = gram[(b, a)];
        }
    }
    let mean_diag = |from: usize, to: usize| -> f64 {
        if to > from {
            (from..to).map(|c| gram[(c, c)]).sum::<f64>() / (to - from) as f64
        } else {
            0.0
        }
    };
    // A whisper of ridge on the base keeps collinear columns (a term equal to a state)
    // solvable; the radial layer carries the real penalty.
    let base_ridge = 1e-10 * mean_diag(0, nb).max(f64::MIN_POSITIVE);
    let extra_ridge = ridge * mean_diag(nb, p).max(f64::MIN_POSITIVE);
    for c in 0..p {
        gram[(c, c)] += if c < nb { base_ridge } else { extra_ridge };
    }
    let Some(chol) = gram.cholesky() else {
        return f64::INFINITY;
    };
    let beta = chol.solve(&rhs);
    test.iter()
        .map(|&r| {
            let fit: f64 = (0..p).map(|c| row(r, c) * beta[c]).sum();
            (d[r] - fit).powi(2)
        })
        .sum()
}

/// The stand-in's statistic on `estimate` (MME with `model` on `data`) and its reference:
/// `rerun` is MME at the estimate's `W` and `R` on a simulated copy of `data`, given the
/// initial states the copy was simulated from (a fallback start); `None` when it fails.
///
/// Errors: a bad config, too few samples, a noise variance that is not positive and
/// finite, the model's own simulation failing on the records, or fewer than half of the
/// draws completing.
pub fn stand_in<F>(
    model: &TermModel,
    data: &Dataset,
    estimate: &MmeEstimate,
    config: &StandInConfig,
    rerun: F,
) -> Result<StandIn>
where
    F: Fn(&Dataset, &[Vec<f64>]) -> Option<MmeEstimate> + Sync,
{
    check_config(config)?;
    if let Some(&v) = estimate
        .noise_variance
        .iter()
        .find(|v| !(v.is_finite() && **v > 0.0))
    {
        return Err(DiscoveryError::InvalidConfig {
            field: "noise_variance",
            value: v,
            reason: "must be positive and finite",
        });
    }
    let per_equation = gains(model, &samples_from_estimate(estimate, data)?, config)?;
    let statistic = per_equation
        .iter()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    let x0: Vec<Vec<f64>> = estimate
        .experiments
        .iter()
        .map(|e| e.states.column(0).iter().copied().collect())
        .collect();
    let draws: Vec<Option<f64>> = (0..config.draws)
        .into_par_iter()
        .map(|b| -> Result<Option<f64>> {
            let sim = crate::judge::draw(
                model,
                data,
                &x0,
                &estimate.noise_variance,
                &config.truth_integrator,
                config.seed,
                (b as u64) << 20,
            )?;
            let Some(est) = rerun(&sim, &x0) else {
                return Ok(None);
            };
            let Ok(samples) = samples_from_estimate(&est, &sim) else {
                return Ok(None);
            };
            Ok(gains(model, &samples, config)
                .ok()
                .map(|g| g.into_iter().fold(f64::NEG_INFINITY, f64::max))
                .filter(|g| g.is_finite()))
        })
        .collect::<Result<Vec<_>>>()?;
    let reference: Vec<f64> = draws.into_iter().flatten().collect();
    let failed = config.draws - reference.len();
    if reference.len() * 2 < config.draws {
        return Err(DiscoveryError::TooFewSamples {
            what: "completed reference draws of the stand-in",
            found: reference.len(),
            needed: config.draws.div_ceil(2),
        });
    }
    let k = reference.len() as f64;
    let mean = reference.iter().sum::<f64>() / k;
    let sd = (reference.iter().map(|g| (g - mean).powi(2)).sum::<f64>() / (k - 1.0)).sqrt();
    let z = Normal::new(0.0, 1.0)
        .map(|n| n.inverse_cdf(config.level))
        .unwrap_or(3.09);
    Ok(StandIn {
        statistic,
        per_equation,
        reference,
        draws: config.draws,
        failed,
        mean,
        sd,
        threshold: (mean + z * sd).max(config.min_gain),
        level: config.level,
        min_gain: config.min_gain,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand::rngs::ChaCha8Rng;
    use rand_distr::{Distribution, StandardNormal};

    use crate::test_support::oscillator;

    /// States of a quasi-periodic trajectory, an input, and `d̂ = f(x, v) + smoothed
    /// noise` (a 5-sample moving average of white noise of sd `sd`, as MME's `d̂` is
    /// smooth), 3000 samples.
    fn samples(f: impl Fn(f64, f64) -> f64, sd: f64, seed: u64) -> Vec<Samples> {
        let n = 3000;
        let t = |k: usize| k as f64 * 0.01;
        let x = DMatrix::from_fn(2, n, |i, k| {
            let s = t(k);
            if i == 0 {
                (1.3 * s).sin() + 0.5 * (0.37 * s).cos()
            } else {
                1.3 * (1.3 * s).cos() - 0.185 * (0.37 * s).sin()
            }
        });
        let u = DMatrix::from_fn(1, n, |_, k| (0.9 * t(k)).sin());
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let white: Vec<f64> = (0..n + 4)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut rng);
                sd * z
            })
            .collect();
        let d = DMatrix::from_fn(1, n, |_, k| {
            f(x[(0, k)], x[(1, k)]) + white[k..k + 5].iter().sum::<f64>() / 5.0
        });
        vec![Samples::new(x, u, d).unwrap_or_else(|e| panic!("{e}"))]
    }

    fn gain(model: &TermModel, s: &[Samples]) -> f64 {
        gains(model, s, &StandInConfig::default()).unwrap_or_else(|e| panic!("{e}"))[0]
    }

    /// Smoothed noise: nothing for the stand-in to predict (the radial layer fits only
    /// noise, which the held-out folds punish): gain near 0 for five seeds.
    #[test]
    fn noise_leaves_nothing_to_predict() {
        let model = oscillator(&[]);
        for seed in 0..5 {
            let g = gain(&model, &samples(|_, _| 0.0, 0.1, seed));
            assert!(g < 0.03, "seed {seed}: gain {g}");
        }
    }

    /// A smooth step in velocity the model lacks (Coulomb-like, 3× the noise's sd):
    /// most of the base's held-out error is predictable.
    #[test]
    fn a_missing_law_is_predictable() {
        let model = oscillator(&[]);
        let g = gain(&model, &samples(|_, v| 0.3 * (5.0 * v).tanh(), 0.1, 7));
        assert!(g > 0.5, "gain {g}");
    }

    /// The same law, already a term of the model with a wrong coefficient: the base
    /// refits it, so nothing is left to the stand-in. Linear-in-state errors likewise.
    #[test]
    fn a_model_term_with_the_wrong_coefficient_is_not_structure() {
        let model = oscillator(&[("coulomb_friction_smooth", "tanh(5*v)", 1.0)]);
        let g = gain(&model, &samples(|_, v| 0.3 * (5.0 * v).tanh(), 0.1, 7));
        assert!(g < 0.03, "term in model: gain {g}");
        let g = gain(&model, &samples(|x, v| 0.4 * x - 0.2 * v, 0.1, 8));
        assert!(g < 0.03, "linear: gain {g}");
    }

    #[test]
    fn bad_config_and_short_records_are_errors() {
        let model = oscillator(&[]);
        let s = samples(|_, _| 0.0, 0.1, 1);
        let bad = StandInConfig {
            folds: 1,
            ..StandInConfig::default()
        };
        assert!(matches!(
            gains(&model, &s, &bad),
            Err(DiscoveryError::InvalidConfig { field: "folds", .. })
        ));
        let short = vec![
            Samples::new(
                s[0].states().columns(0, 50).into_owned(),
                s[0].inputs().columns(0, 50).into_owned(),
                s[0].corrections().columns(0, 50).into_owned(),
            )
            .unwrap_or_else(|e| panic!("{e}")),
        ];
        assert!(matches!(
            gains(&model, &short, &StandInConfig::default()),
            Err(DiscoveryError::TooFewSamples { .. })
        ));
    }
}
