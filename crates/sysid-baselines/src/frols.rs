//! Sparse polynomial NARX by Forward Regression Orthogonal Least Squares (FROLS; Billings,
//! Chen & Korenberg 1989; Billings 2013, *Nonlinear System Identification: NARMAX Methods*,
//! ch. 3), the polynomial NARX of the literature.
//!
//! The candidate terms are the dense [`crate::poly_narx`] structure's (a constant, every
//! output lag and input tap, every monomial of degree `2..=degree` in the newest
//! `nonlinear_lags` lags and taps), built on the same regressor rows. Each variable is
//! divided by its root mean square over the rows and not centred, so a model that is sparse
//! in the recorded signals stays sparse among the candidates. Terms are chosen one at a
//! time: modified Gram–Schmidt keeps every remaining candidate orthogonal to the chosen
//! ones, and the candidate with the largest Error Reduction Ratio
//! `ERR = (wᵀr)² / (wᵀw · yᵀy)` (`w` its orthogonal part, `r` the target's, `yᵀy`
//! uncentred) joins next. The number of terms minimises an information criterion of the
//! one-step residual (AIC or BIC), or is fixed; the coefficients solve the unit triangular
//! system of the Gram–Schmidt factors (least squares on the chosen columns). The result is
//! a [`PolyNarxModel`], so its free run, prediction and divergence report are the dense
//! model's. Nothing here is random; ties go to the first candidate in dictionary order.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use sysid_core::{Dataset, Experiment, Model};

use crate::error::{BaselineError, Result, check_config};
use crate::narx::divergence_limits;
use crate::poly_narx::{PolyNarxModel, check_dictionary, structure_terms};
use crate::regressors::{NarxOrders, fill_regressor, training_rows};

/// A candidate whose part orthogonal to the chosen terms is shorter than this fraction of
/// its own norm depends on them and is not eligible.
const DEPENDENT_RTOL: f64 = 1e-9;
/// The selection stops once the residual's squared norm falls below this fraction of
/// `yᵀy` (nothing left to explain).
const EXACT_RTOL: f64 = 1e-24;

/// How the number of terms is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TermCount {
    /// Minimise `AIC(n) = N ln(SSE(n)/N) + 2n` over the terms selected.
    Aic,
    /// Minimise `BIC(n) = N ln(SSE(n)/N) + n ln N` over the terms selected.
    Bic,
    /// The first `n` terms selected (fewer when the selection stopped earlier).
    Fixed(usize),
}

impl TermCount {
    /// `AIC`, `BIC` or `n terms`.
    pub fn label(&self) -> String {
        match self {
            TermCount::Aic => "AIC".into(),
            TermCount::Bic => "BIC".into(),
            TermCount::Fixed(n) => format!("{n} terms"),
        }
    }
}

/// Settings of [`fit_frols`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct FrolsConfig {
    /// Tapped delays of the linear candidates. Default `na = nb = 2`, `nk = 1`.
    pub orders: NarxOrders,
    /// Highest total degree of a candidate monomial (1: sparse ARX). Default 3.
    pub degree: usize,
    /// How many of the newest output lags and input taps (each channel) enter the
    /// candidate monomials of degree ≥ 2. Default 2.
    pub nonlinear_lags: usize,
    /// Terms selected at most (the cap of the criterion's search). Default 40.
    pub max_terms: usize,
    /// How many of the selected terms the model keeps. Default [`TermCount::Aic`].
    pub count: TermCount,
    /// A simulated output more than this many half-ranges of the training data away from
    /// the data's centre counts as diverged. Default 100.
    pub divergence_factor: f64,
}

impl Default for FrolsConfig {
    fn default() -> Self {
        Self {
            orders: NarxOrders::default(),
            degree: 3,
            nonlinear_lags: 2,
            max_terms: 40,
            count: TermCount::Aic,
            divergence_factor: 100.0,
        }
    }
}

impl FrolsConfig {
    /// Check every field.
    pub fn validate(&self) -> Result<()> {
        check_dictionary(&self.orders, self.degree, self.nonlinear_lags)?;
        check_config(
            "max_terms",
            self.max_terms as f64,
            "must be ≥ 1",
            self.max_terms >= 1,
        )?;
        if let TermCount::Fixed(n) = self.count {
            check_config(
                "count",
                n as f64,
                "a fixed number of terms must be between 1 and max_terms",
                n >= 1 && n <= self.max_terms,
            )?;
        }
        check_config(
            "divergence_factor",
            self.divergence_factor,
            "must be finite and > 1",
            self.divergence_factor.is_finite() && self.divergence_factor > 1.0,
        )
    }
}

/// One selected term, in the order FROLS chose it.
#[derive(Debug, Clone, PartialEq)]
pub struct RankedTerm {
    /// The term in the recorded signals, e.g. `y(k-1)*u(k-1)` (`1`: the constant).
    pub name: String,
    /// Its Error Reduction Ratio (share of `yᵀy` it explains).
    pub err: f64,
    /// One-step residual sum of squares with the terms up to and including this one.
    pub sse: f64,
    /// AIC with the terms up to and including this one.
    pub aic: f64,
    /// BIC with the terms up to and including this one.
    pub bic: f64,
}

/// What [`fit_frols`] returns.
#[derive(Debug, Clone)]
pub struct FrolsFit {
    /// The model with the chosen number of terms.
    pub model: PolyNarxModel,
    /// Terms the model keeps (a prefix of [`FrolsFit::ranking`]).
    pub n_terms: usize,
    /// Every selected term in the order of selection (up to the cap).
    pub ranking: Vec<RankedTerm>,
    /// Coefficients of the model's terms in the recorded signals' units (the model itself
    /// holds them for the scaled variables).
    pub coefficients: Vec<f64>,
    /// Candidate terms in the dictionary.
    pub candidates: usize,
    /// Rows fitted (rows touching a missing sample are skipped).
    pub rows: usize,
    /// Rows skipped for missing samples.
    pub skipped_rows: usize,
    /// One-step RMSE of the model on the rows fitted.
    pub one_step_rmse: f64,
    factors: Factors,
}

/// What it takes to build the model of any prefix of the ranking.
#[derive(Debug, Clone)]
struct Factors {
    orders: NarxOrders,
    scale: Vec<f64>,
    /// The selected terms, in order.
    terms: Vec<Vec<usize>>,
    /// `k × k` unit upper-triangular factor, row-major: `P_sel = Q A`.
    a: Vec<f64>,
    /// `y ≈ Q g`.
    g: Vec<f64>,
    input_names: Vec<String>,
    output_names: Vec<String>,
    limits: Vec<(f64, f64)>,
    /// Samples of each experiment FROLS ranked on (a K-fold record must be that record).
    record_lens: Vec<usize>,
}

impl Factors {
    /// Coefficients (scaled variables) of the first `n` selected terms: `A_n θ = g_n`.
    fn solve(&self, n: usize) -> Vec<f64> {
        let k = self.g.len();
        let mut theta = vec![0.0; n];
        for t in (0..n).rev() {
            let row = &self.a[t * k + t + 1..t * k + n];
            theta[t] = self.g[t] - dot(row, &theta[t + 1..n]);
        }
        theta
    }

    fn model(&self, n: usize) -> Result<PolyNarxModel> {
        self.model_from(&self.solve(n))
    }

    /// The model of the first `theta.len()` selected terms with coefficients `theta`
    /// (scaled variables).
    fn model_from(&self, theta: &[f64]) -> Result<PolyNarxModel> {
        let n = theta.len();
        PolyNarxModel::from_parts(
            self.orders,
            vec![0.0; self.scale.len()],
            self.scale.clone(),
            self.terms[..n].to_vec(),
            DMatrix::from_row_slice(1, n, theta),
            self.input_names.clone(),
            self.output_names.clone(),
            self.limits.clone(),
        )
    }
}

impl FrolsFit {
    /// The number of terms `count` keeps.
    pub fn count(&self, count: TermCount) -> usize {
        choose_count(&self.ranking, count)
    }

    /// The model of the first `n` selected terms (`1 ≤ n ≤ ranking.len()`), coefficients
    /// by least squares on those terms' columns.
    pub fn model_with(&self, n: usize) -> Result<PolyNarxModel> {
        check_config(
            "n",
            n as f64,
            "must be between 1 and the number of terms selected",
            n >= 1 && n <= self.ranking.len(),
        )?;
        self.factors.model(n)
    }
}

/// Why a prefix count has no held-out score (it is then not eligible).
#[derive(Debug)]
pub enum PrefixFailure {
    /// Building or running the prefix model failed; a free run leaving the divergence
    /// limits is [`BaselineError::Diverged`], with its sample.
    Run(BaselineError),
    /// The free run gave a non-finite output after the skipped samples.
    NonFinite,
}

impl std::fmt::Display for PrefixFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PrefixFailure::Run(e) => e.fmt(f),
            PrefixFailure::NonFinite => f.write_str("non-finite output"),
        }
    }
}

/// One prefix count's free run over held-out records ([`FrolsFit::free_run_scores`]) or
/// over the held folds of a K-fold split ([`FrolsFit::kfold_scores`]).
#[derive(Debug)]
pub struct PrefixScore {
    /// Terms kept: the first `n` of the ranking.
    pub n: usize,
    /// Free-run RMSE over the held-out samples after the skipped ones, in the recorded
    /// output's units, or why there is none.
    pub rmse: std::result::Result<f64, PrefixFailure>,
}

impl PrefixScore {
    /// The score, `None` when the count is not eligible.
    pub fn value(&self) -> Option<f64> {
        self.rmse.as_ref().ok().copied()
    }
}

impl FrolsFit {
    /// Every prefix count `n = 1..=ranking.len()` run free over each of `held` (records
    /// the selection did not fit), each run started from the record's measured outputs as
    /// [`PolyNarxModel`]'s free run is. The score is the RMSE over every sample after the
    /// first `skip` of each record, all records pooled (samples whose measured output is
    /// not finite left out). A count whose run fails on any record (diverges: the error
    /// names the sample) or gives a non-finite output there has no score and is not
    /// eligible (docs/decisions/frols-term-count-by-free-run.md).
    ///
    /// Errors: no held-out record, or no measured sample after `skip` in any of them.
    pub fn free_run_scores(&self, held: &[Experiment], skip: usize) -> Result<Vec<PrefixScore>> {
        let samples: usize = held
            .iter()
            .map(|e| {
                let y = e.outputs();
                (skip..e.len())
                    .filter(|&k| y.nrows() == 1 && y[(0, k)].is_finite())
                    .count()
            })
            .sum();
        if samples == 0 {
            return Err(BaselineError::TooFewRows {
                what: "held-out samples after the skipped ones",
                found: 0,
                needed: 1,
            });
        }
        let score = |n: usize| -> std::result::Result<f64, PrefixFailure> {
            let model = self.factors.model(n).map_err(PrefixFailure::Run)?;
            let mut sse = 0.0;
            for e in held {
                let sim = model.simulate(e).map_err(PrefixFailure::Run)?;
                let y = e.outputs();
                for k in skip..e.len() {
                    let s = sim.outputs[(0, k)];
                    if !s.is_finite() {
                        return Err(PrefixFailure::NonFinite);
                    }
                    if y[(0, k)].is_finite() {
                        sse += (y[(0, k)] - s) * (y[(0, k)] - s);
                    }
                }
            }
            Ok((sse / samples as f64).sqrt())
        };
        Ok((1..=self.ranking.len())
            .map(|n| PrefixScore { n, rmse: score(n) })
            .collect())
    }
}

/// How many contiguous folds the K-fold term count pools (docs/decisions/
/// frols-count-kfold.md, rule 2).
pub const KFOLD_FOLDS: usize = 5;

impl FrolsFit {
    /// Every prefix count `n = 1..=ranking.len()` scored by free run pooled over `folds`
    /// contiguous folds of `data` (docs/decisions/frols-count-kfold.md), so that a count
    /// is chosen on the whole record rather than on one held-out stretch's noise.
    ///
    /// `data` must be the one-experiment record this fit ranked its terms on: the ranking
    /// stays fixed and each fold uses its first `n` terms. The record is cut into `folds`
    /// folds of `len / folds` samples (the last takes the remainder). For fold `k` and every
    /// `n`, the first `n` terms' coefficients are refitted by least squares on the
    /// regression rows of the other folds only — a row whose lag window or target reaches
    /// into fold `k` is dropped, as is a row touching a missing sample — and that model runs
    /// free over fold `k` from the fold's measured start (its first measured samples start
    /// the run, as [`PolyNarxModel`]'s free run does; the first `skip` samples are the delay
    /// window and are not scored). A count's score is the RMSE of the squared errors after
    /// the first `skip` samples of every fold, pooled (samples whose measured output is not
    /// finite left out). A count has no score, and is not eligible, when on any fold its free run
    /// diverges (the error names the sample of `data`), gives a non-finite output, or its
    /// refit has no unique solution because a term depends on the earlier ones on the other
    /// folds' rows ([`BaselineError::Unidentifiable`], naming the term).
    ///
    /// One Householder QR per fold of the selected terms' columns (variables scaled as in
    /// the fit) gives every prefix: the columns are in ranking order, so the first `n`
    /// columns' least-squares coefficients solve the leading `n × n` block of `R` against
    /// the first `n` entries of `Qᵀy`. The divergence limits are the fit's.
    ///
    /// Errors: `folds < 2`; `skip` shorter than the lag window; `data` with other than one
    /// experiment or one output, other input channels than the fit's, or another length
    /// than the record ranked on (or a fit ranked on several experiments); a fold no longer
    /// than `skip`; no more usable rows outside a fold than terms selected; no measured
    /// sample after `skip` in any fold.
    pub fn kfold_scores(
        &self,
        data: &Dataset,
        folds: usize,
        skip: usize,
    ) -> Result<Vec<PrefixScore>> {
        let f = &self.factors;
        let o = f.orders;
        let lag = o.max_lag();
        check_config("folds", folds as f64, "must be at least 2", folds >= 2)?;
        check_config(
            "skip",
            skip as f64,
            "must be at least the lag window (max_lag) of the model",
            skip >= lag,
        )?;
        let experiments = data.experiments();
        if experiments.len() != 1 {
            return Err(BaselineError::Dimension {
                what: "experiments of a K-fold record",
                found: experiments.len(),
                expected: 1,
            });
        }
        let e = &experiments[0];
        let (p, m) = (e.n_outputs(), e.n_inputs());
        if p != 1 || m != f.input_names.len() {
            return Err(BaselineError::Dimension {
                what: "channels of the K-fold record (one output, the fit's inputs)",
                found: p + m,
                expected: 1 + f.input_names.len(),
            });
        }
        let len = e.len();
        match f.record_lens[..] {
            [ranked] if ranked == len => {}
            [ranked] => {
                return Err(BaselineError::Dimension {
                    what: "samples of the K-fold record vs the record FROLS ranked on",
                    found: len,
                    expected: ranked,
                });
            }
            _ => {
                return Err(BaselineError::Dimension {
                    what: "experiments FROLS ranked on (a K-fold record is one)",
                    found: f.record_lens.len(),
                    expected: 1,
                });
            }
        }
        let fold_len = len / folds;
        if fold_len <= skip {
            return Err(BaselineError::TooFewRows {
                what: "samples per K-fold fold (more than the skipped ones)",
                found: fold_len,
                needed: skip + 1,
            });
        }
        // Every regression row of the record (target sample lag + r): the selected terms'
        // scaled columns (column-major), the target, and whether it touches a missing sample.
        let k = self.ranking.len();
        let all = len - lag;
        let (y, u) = (e.outputs(), e.inputs());
        let mut phi = vec![0.0; all * k];
        let mut target = vec![f64::NAN; all];
        let mut reg = vec![0.0; f.scale.len()];
        for (r, tr) in target.iter_mut().enumerate() {
            let t = lag + r;
            fill_regressor(|c, j| y[(c, j)], |c, j| u[(c, j)], (p, m), t, &o, &mut reg);
            if y[(0, t)].is_nan() || reg.iter().any(|v| v.is_nan()) {
                continue;
            }
            *tr = y[(0, t)];
            for (z, s) in reg.iter_mut().zip(&f.scale) {
                *z /= s;
            }
            for (j, vars) in f.terms.iter().enumerate() {
                phi[j * all + r] = vars.iter().map(|&i| reg[i]).product();
            }
        }
        let mut sse = vec![0.0; k];
        let mut failed: Vec<Option<PrefixFailure>> = (0..k).map(|_| None).collect();
        let mut samples = 0;
        let mut theta = vec![0.0; k];
        let mut rows = Vec::with_capacity(all);
        for fold in 0..folds {
            let a = fold * fold_len;
            let b = if fold + 1 == folds { len } else { a + fold_len };
            // Rows whose window t − lag ..= t misses the fold a..b.
            rows.clear();
            rows.extend((0..all).filter(|&r| !target[r].is_nan() && (lag + r < a || r >= b)));
            if rows.len() <= k {
                return Err(BaselineError::TooFewRows {
                    what: "FROLS K-fold regression rows outside a fold (more than the terms selected)",
                    found: rows.len(),
                    needed: k + 1,
                });
            }
            let mat = DMatrix::from_fn(rows.len(), k, |i, j| phi[j * all + rows[i]]);
            let norms: Vec<f64> = mat.column_iter().map(|c| c.norm()).collect();
            let mut rhs = DVector::from_iterator(rows.len(), rows.iter().map(|&r| target[r]));
            let qr = mat.qr();
            qr.q_tr_mul(&mut rhs);
            let rr = qr.r();
            // The first term whose column is (numerically) dependent on the earlier ones
            // on these rows: no prefix containing it has a unique refit.
            let dependent = (0..k).find(|&j| {
                let d = rr[(j, j)].abs();
                d.is_nan() || d <= DEPENDENT_RTOL * norms[j]
            });
            let held = e.window(a, b)?;
            samples += (a + skip..b).filter(|&t| y[(0, t)].is_finite()).count();
            for n in 1..=k {
                if failed[n - 1].is_some() {
                    continue;
                }
                if let Some(j) = dependent.filter(|&j| j < n) {
                    failed[n - 1] = Some(PrefixFailure::Run(BaselineError::Unidentifiable {
                        name: self.ranking[j].name.clone(),
                        ratio: rr[(j, j)].abs() / norms[j],
                    }));
                    continue;
                }
                for t in (0..n).rev() {
                    let mut s = rhs[t];
                    for (c, th) in theta.iter().enumerate().take(n).skip(t + 1) {
                        s -= rr[(t, c)] * th;
                    }
                    theta[t] = s / rr[(t, t)];
                }
                let run = f
                    .model_from(&theta[..n])
                    .and_then(|model| model.simulate(&held));
                let sim = match run {
                    Ok(sim) => sim,
                    Err(BaselineError::Diverged {
                        sample,
                        channel,
                        value,
                    }) => {
                        failed[n - 1] = Some(PrefixFailure::Run(BaselineError::Diverged {
                            sample: a + sample,
                            channel,
                            value,
                        }));
                        continue;
                    }
                    Err(err) => {
                        failed[n - 1] = Some(PrefixFailure::Run(err));
                        continue;
                    }
                };
                let mut fold_sse = 0.0;
                for i in skip..b - a {
                    let s = sim.outputs[(0, i)];
                    if !s.is_finite() {
                        failed[n - 1] = Some(PrefixFailure::NonFinite);
                        break;
                    }
                    let ym = y[(0, a + i)];
                    if ym.is_finite() {
                        fold_sse += (ym - s) * (ym - s);
                    }
                }
                sse[n - 1] += fold_sse;
            }
        }
        if samples == 0 {
            return Err(BaselineError::TooFewRows {
                what: "measured samples after the skipped ones of the K-fold folds",
                found: 0,
                needed: 1,
            });
        }
        Ok(failed
            .into_iter()
            .zip(sse)
            .enumerate()
            .map(|(i, (fail, s))| PrefixScore {
                n: i + 1,
                rmse: match fail {
                    Some(why) => Err(why),
                    None => Ok((s / samples as f64).sqrt()),
                },
            })
            .collect())
    }
}

/// The number of terms chosen by held-out free run (docs/decisions/
/// frols-term-count-by-free-run.md): `scores` holds, for prefix counts `n`, the held-out
/// free-run RMSE of the first `n` terms, or `None` where that run failed (diverged or not
/// finite) — such a count is not eligible. The smallest `n` whose RMSE is within
/// `tolerance` (relative, e.g. 0.02) of the best eligible one, with that RMSE; `None` when
/// no count is eligible. [`FrolsFit::free_run_scores`] gives the scores
/// (`(s.n, s.value())`).
pub fn count_by_free_run(scores: &[(usize, Option<f64>)], tolerance: f64) -> Option<(usize, f64)> {
    let eligible = || {
        scores
            .iter()
            .filter_map(|&(n, r)| r.filter(|v| v.is_finite()).map(|v| (n, v)))
    };
    let best = eligible().map(|(_, v)| v).fold(f64::INFINITY, f64::min);
    if !best.is_finite() {
        return None;
    }
    eligible()
        .filter(|&(_, v)| v <= best * (1.0 + tolerance))
        .min_by_key(|&(n, _)| n)
}

/// [`fit_frols_kfold`]'s result.
#[derive(Debug)]
pub struct FrolsKfoldFit {
    /// FROLS on every record of the data, keeping [`FrolsKfoldFit::count`] terms.
    pub fit: FrolsFit,
    /// Terms kept (a prefix of the first record's ranking, refitted on every record).
    pub count: usize,
    /// Its pooled K-fold free-run RMSE on the first record.
    pub score: f64,
    /// Every prefix count's pooled K-fold free-run score on the first record.
    pub scores: Vec<PrefixScore>,
}

/// A sparse polynomial NARX model whose term count is chosen by free run
/// (docs/decisions/frols-count-kfold.md): FROLS ranks up to `config.max_terms` terms on
/// the first record of `data`; every prefix count is scored by [`FrolsFit::kfold_scores`]
/// over [`KFOLD_FOLDS`] contiguous folds of that record (each fold's first `max_lag`
/// samples its delay window); the smallest count within `tolerance` (relative) of the
/// best pooled score is kept ([`count_by_free_run`]), and FROLS runs again on every record
/// of `data` keeping that many terms (`config.count` is ignored). A count whose free run
/// fails on any fold is never kept.
///
/// Errors: those of [`fit_frols`] and [`FrolsFit::kfold_scores`];
/// [`BaselineError::NoStableCount`] when every prefix count fails on some fold.
pub fn fit_frols_kfold(
    data: &Dataset,
    config: &FrolsConfig,
    tolerance: f64,
) -> Result<FrolsKfoldFit> {
    check_config(
        "tolerance",
        tolerance,
        "must be finite and ≥ 0",
        tolerance.is_finite() && tolerance >= 0.0,
    )?;
    let Some(first_record) = data.experiments().first() else {
        return Err(BaselineError::TooFewRows {
            what: "records for a K-fold term count",
            found: 0,
            needed: 1,
        });
    };
    let first = Dataset::new(
        data.input_channels().to_vec(),
        data.output_channels().to_vec(),
        vec![first_record.clone()],
    )?;
    let ranking_config = FrolsConfig {
        count: TermCount::Aic,
        ..config.clone()
    };
    let ranked = fit_frols(&first, &ranking_config)?;
    let scores = ranked.kfold_scores(&first, KFOLD_FOLDS, config.orders.max_lag())?;
    let pairs: Vec<(usize, Option<f64>)> = scores.iter().map(|s| (s.n, s.value())).collect();
    let Some((count, score)) = count_by_free_run(&pairs, tolerance) else {
        return Err(BaselineError::NoStableCount {
            ranked: ranked.ranking.len(),
            folds: KFOLD_FOLDS,
        });
    };
    let fit = fit_frols(
        data,
        &FrolsConfig {
            count: TermCount::Fixed(count),
            ..config.clone()
        },
    )?;
    Ok(FrolsKfoldFit {
        fit,
        count,
        score,
        scores,
    })
}

fn choose_count(ranking: &[RankedTerm], count: TermCount) -> usize {
    let pick = |f: fn(&RankedTerm) -> f64| {
        let mut best = 0;
        for (i, r) in ranking.iter().enumerate() {
            if f(r) < f(&ranking[best]) {
                best = i;
            }
        }
        best + 1
    };
    match count {
        TermCount::Aic => pick(|r| r.aic),
        TermCount::Bic => pick(|r| r.bic),
        TermCount::Fixed(n) => n.min(ranking.len()),
    }
}

/// What the orthogonal selection found.
struct Selection {
    /// Dictionary indices, in order.
    chosen: Vec<usize>,
    err: Vec<f64>,
    sse: Vec<f64>,
    /// `k × k` row-major unit upper-triangular factor.
    a: Vec<f64>,
    g: Vec<f64>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// FROLS on the `n × m` column-major dictionary `cols` (overwritten by the candidates'
/// orthogonal parts) and target `y`, at most `cap` terms.
fn select(cols: &mut [f64], n: usize, y: &[f64], cap: usize) -> Selection {
    let m = cols.len() / n;
    let yy = dot(y, y);
    let mut r = y.to_vec();
    let mut q = vec![0.0; n];
    // Per candidate: original norm, current squared norm, current wᵀr, eligibility.
    let norm0: Vec<f64> = cols.chunks_exact(n).map(|c| dot(c, c).sqrt()).collect();
    let mut ww: Vec<f64> = norm0.iter().map(|v| v * v).collect();
    let mut wr: Vec<f64> = cols.chunks_exact(n).map(|c| dot(c, &r)).collect();
    let mut eligible = vec![true; m];
    // c[s·m + j]: the coefficient of chosen term s in candidate j's Gram–Schmidt.
    let mut c = vec![0.0; cap * m];
    let (mut chosen, mut err, mut sse, mut g) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for s in 0..cap {
        let mut best: Option<(usize, f64)> = None;
        for j in 0..m {
            if !eligible[j] {
                continue;
            }
            let tol = DEPENDENT_RTOL * norm0[j];
            if ww[j].is_nan() || ww[j] <= tol * tol {
                eligible[j] = false;
                continue;
            }
            let e = wr[j] * wr[j] / (ww[j] * yy);
            if best.is_none_or(|(_, b)| e > b) {
                best = Some((j, e));
            }
        }
        let Some((j, e)) = best else { break };
        eligible[j] = false;
        q.copy_from_slice(&cols[j * n..(j + 1) * n]);
        let qq = ww[j];
        let gj = dot(&q, &r) / qq;
        for (ri, qi) in r.iter_mut().zip(&q) {
            *ri -= gj * qi;
        }
        chosen.push(j);
        err.push(e);
        g.push(gj);
        for k in 0..m {
            if !eligible[k] {
                continue;
            }
            let w = &mut cols[k * n..(k + 1) * n];
            let a = dot(&q, w) / qq;
            c[s * m + k] = a;
            let (mut nn, mut nr) = (0.0, 0.0);
            for ((wi, qi), ri) in w.iter_mut().zip(&q).zip(&r) {
                *wi -= a * qi;
                nn += *wi * *wi;
                nr += *wi * ri;
            }
            ww[k] = nn;
            wr[k] = nr;
        }
        let rr = dot(&r, &r);
        sse.push(rr);
        if rr <= EXACT_RTOL * yy {
            break;
        }
    }
    let k = chosen.len();
    let mut a = vec![0.0; k * k];
    for (t, &j) in chosen.iter().enumerate() {
        a[t * k + t] = 1.0;
        for s in 0..t {
            a[s * k + t] = c[s * m + j];
        }
    }
    Selection {
        chosen,
        err,
        sse,
        a,
        g,
    }
}

/// Fit a sparse polynomial NARX model by FROLS on every experiment of `data` (one output).
///
/// Errors: an invalid configuration, more than one output, records no longer than the lag
/// window, no row without missing samples, no more rows than the terms that could be
/// selected, an output that does not vary over the rows.
pub fn fit_frols(data: &Dataset, config: &FrolsConfig) -> Result<FrolsFit> {
    config.validate()?;
    let p = data.output_channels().len();
    if p != 1 {
        return Err(BaselineError::Dimension {
            what: "output channels of a FROLS polynomial NARX",
            found: p,
            expected: 1,
        });
    }
    let o = config.orders;
    let rows = training_rows(data, &o)?;
    let m_in = data.input_channels().len();
    let len = o.regressor_len(p, m_in);
    let n = rows.inputs.ncols();
    let terms = if config.degree == 1 {
        structure_terms(&o, p, m_in, 1, 0)
    } else {
        structure_terms(&o, p, m_in, config.degree, config.nonlinear_lags)
    };
    let m = terms.len();
    let cap = config.max_terms.min(m);
    if n <= cap {
        return Err(BaselineError::TooFewRows {
            what: "FROLS rows (more than the terms that can be selected)",
            found: n,
            needed: cap + 1,
        });
    }
    let y: Vec<f64> = rows.targets.row(0).iter().copied().collect();
    let mean = y.iter().sum::<f64>() / n as f64;
    if !y
        .iter()
        .any(|v| (v - mean).abs() > 1e-12 * mean.abs().max(f64::MIN_POSITIVE))
    {
        return Err(BaselineError::NoVariation {
            what: "FROLS target output",
            rows: n,
        });
    }
    // Root-mean-square scale of each variable, not centred (a zero variable keeps 1: its
    // monomials are zero columns, never eligible).
    let scale: Vec<f64> = (0..len)
        .map(|i| {
            let ms = rows.inputs.row(i).iter().map(|v| v * v).sum::<f64>() / n as f64;
            if ms > 0.0 { ms.sqrt() } else { 1.0 }
        })
        .collect();
    let mut cols = vec![0.0; n * m];
    let mut z = vec![0.0; len];
    for r in 0..n {
        for (i, zi) in z.iter_mut().enumerate() {
            *zi = rows.inputs[(i, r)] / scale[i];
        }
        for (j, vars) in terms.iter().enumerate() {
            cols[j * n + r] = vars.iter().map(|&i| z[i]).product();
        }
    }
    let sel = select(&mut cols, n, &y, cap);
    drop(cols);
    if sel.chosen.is_empty() {
        return Err(BaselineError::TooFewRows {
            what: "FROLS candidate terms with a nonzero column",
            found: 0,
            needed: 1,
        });
    }
    let nf = n as f64;
    let factors = Factors {
        orders: o,
        scale,
        terms: sel.chosen.iter().map(|&j| terms[j].clone()).collect(),
        a: sel.a,
        g: sel.g,
        input_names: data.input_names(),
        output_names: data.output_names(),
        limits: divergence_limits(data, config.divergence_factor)?,
        record_lens: data.experiments().iter().map(|e| e.len()).collect(),
    };
    let names = factors.model(sel.chosen.len())?.term_names();
    let ranking: Vec<RankedTerm> = names
        .into_iter()
        .enumerate()
        .map(|(t, name)| {
            let sse = sel.sse[t];
            let ln = (sse / nf).ln();
            let k = (t + 1) as f64;
            RankedTerm {
                name,
                err: sel.err[t],
                sse,
                aic: nf * ln + 2.0 * k,
                bic: nf * ln + k * nf.ln(),
            }
        })
        .collect();
    let n_terms = choose_count(&ranking, config.count);
    let model = factors.model(n_terms)?;
    let coefficients = factors
        .solve(n_terms)
        .iter()
        .zip(&factors.terms)
        .map(|(th, vars)| th / vars.iter().map(|&i| factors.scale[i]).product::<f64>())
        .collect();
    Ok(FrolsFit {
        model,
        n_terms,
        one_step_rmse: (ranking[n_terms - 1].sse / nf).sqrt(),
        ranking,
        coefficients,
        candidates: m,
        rows: n,
        skipped_rows: rows.skipped,
        factors,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The triangular solve against a direct least-squares solve of the same columns.
    /// The smallest count within the tolerance of the best eligible one; failed runs are
    /// never chosen, whatever their position.
    #[test]
    fn the_free_run_count_is_the_smallest_within_the_tolerance() {
        let s = [
            (1, Some(3.0)),
            (2, None),
            (3, Some(1.015)),
            (4, Some(1.0)),
            (5, Some(f64::NAN)),
            (6, Some(0.99)),
        ];
        assert_eq!(count_by_free_run(&s, 0.02), Some((4, 1.0)));
        assert_eq!(count_by_free_run(&s, 0.03), Some((3, 1.015)));
        assert_eq!(count_by_free_run(&s, 0.0), Some((6, 0.99)));
        assert_eq!(
            count_by_free_run(&[(1, None), (2, Some(f64::INFINITY))], 0.02),
            None
        );
        assert_eq!(count_by_free_run(&[], 0.02), None);
    }

    #[test]
    fn prefix_coefficients_are_least_squares_on_the_chosen_columns() {
        let n = 50;
        let cols_of = |j: usize| -> Vec<f64> {
            (0..n)
                .map(|i| ((i * (j + 2)) as f64 * 0.37).sin() + 0.1 * j as f64)
                .collect()
        };
        let m = 6;
        let mut cols: Vec<f64> = (0..m).flat_map(cols_of).collect();
        let orig = cols.clone();
        let y: Vec<f64> = (0..n).map(|i| (i as f64 * 0.11).cos() + 0.3).collect();
        let sel = select(&mut cols, n, &y, 4);
        assert_eq!(sel.chosen.len(), 4);
        let k = 4;
        for used in 1..=k {
            let f = Factors {
                orders: NarxOrders::default(),
                scale: vec![],
                terms: vec![],
                a: sel.a.clone(),
                g: sel.g.clone(),
                input_names: vec![],
                output_names: vec![],
                limits: vec![],
                record_lens: vec![],
            };
            let theta = f.solve(used);
            let p = DMatrix::from_fn(n, used, |i, t| orig[sel.chosen[t] * n + i]);
            let yv = nalgebra::DVector::from_vec(y.clone());
            let ls = p.clone().svd(true, true).solve(&yv, 1e-14).unwrap();
            for (a, b) in theta.iter().zip(ls.iter()) {
                assert!((a - b).abs() < 1e-9 * b.abs().max(1.0), "{a} vs {b}");
            }
            let resid = (&p * &ls - &yv).norm_squared();
            assert!((resid - sel.sse[used - 1]).abs() < 1e-9 * resid.max(1.0));
        }
    }
}
