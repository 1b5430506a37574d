//! Polynomial NARX: `y(k) = Σ θ_t φ_t(k)`, a linear-in-parameters model whose terms are a
//! constant, every output lag and input tap of [`NarxOrders`] (the linear part), and
//! every monomial of total degree `2..=degree` in the newest `nonlinear_lags` output lags
//! and input taps (the nonlinear part). Each variable is centred and scaled by its
//! training mean and standard deviation before the monomials are formed, so the columns
//! of the least-squares problem are of one size. Coefficients minimise the one-step error
//! (Householder QR of the regressor matrix, then a truncated SVD of its triangle, so a
//! term the data cannot tell from the others gets the minimum-norm share and the fit
//! reports its rank). Nothing here is random. The free run and k-step prediction are
//! those of the network NARX (`narx_sim`).

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use sysid_core::{Dataset, Experiment, Model, Prediction};

use crate::error::{BaselineError, Result, check_config};
use crate::lsq::{self, LeastSquares, Linearised};
use crate::narx::divergence_limits;
use crate::narx_sim::{self, OneStep};
use crate::regressors::{NarxOrders, training_rows};

/// Relative singular-value threshold below which a direction of the regressor matrix
/// counts as not determined by the data.
const RANK_RTOL: f64 = 1e-10;

/// Settings of [`fit_poly_narx`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PolyNarxConfig {
    /// Tapped delays of the linear part. Default `na = nb = 2`, `nk = 1`.
    pub orders: NarxOrders,
    /// Highest total degree of a monomial (1: a linear ARX model with a constant).
    /// Default 3.
    pub degree: usize,
    /// How many of the newest output lags and input taps (each channel) enter the
    /// monomials of degree ≥ 2 (at most `na` resp. `nb`). Default 2.
    pub nonlinear_lags: usize,
    /// A simulated output more than this many half-ranges of the training data away from
    /// the data's centre counts as diverged. Default 100.
    pub divergence_factor: f64,
    /// What the coefficients minimise. Default [`Focus::Prediction`].
    pub focus: Focus,
    /// Hold the monomials at the training box: every monomial of degree ≥ 2 is evaluated
    /// at the scaled variables clamped to the range they spanned over the fitted rows
    /// (the constant and the linear part see the variables as they are), so an input or a
    /// simulated output beyond the training range cannot drive a cubic without bound.
    /// Default false (the plain polynomial).
    pub hold: bool,
}

/// What the coefficients minimise (the "focus" of MATLAB's `nlarx`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Focus {
    /// One-step prediction error: one linear least-squares solve.
    Prediction,
    /// Free-run simulation error over every training record (each run from its first
    /// measured delay window, outputs weighted by their standard deviations), from the
    /// one-step solution: Levenberg–Marquardt with exact sensitivities of the recursion,
    /// at most `max_iterations` Jacobians. A one-step solution whose free run leaves the
    /// divergence limits cannot start it: the fit fails with the divergence.
    Simulation {
        /// Jacobian evaluations at most (≥ 1).
        max_iterations: usize,
    },
}

impl Focus {
    /// A simulation focus needs at least one Jacobian (`focus.max_iterations` ≥ 1).
    pub(crate) fn validate(&self) -> Result<()> {
        if let Focus::Simulation { max_iterations } = *self {
            check_config(
                "focus.max_iterations",
                max_iterations as f64,
                "must be ≥ 1",
                max_iterations >= 1,
            )?;
        }
        Ok(())
    }
}

impl Default for PolyNarxConfig {
    fn default() -> Self {
        Self {
            orders: NarxOrders::default(),
            degree: 3,
            nonlinear_lags: 2,
            divergence_factor: 100.0,
            focus: Focus::Prediction,
            hold: false,
        }
    }
}

/// Check the candidate dictionary's settings (orders, degree, nonlinear lags), shared by
/// the dense fit and FROLS.
pub(crate) fn check_dictionary(
    orders: &NarxOrders,
    degree: usize,
    nonlinear_lags: usize,
) -> Result<()> {
    orders.validate()?;
    check_config(
        "degree",
        degree as f64,
        "must be between 1 and 5",
        (1..=5).contains(&degree),
    )?;
    check_config(
        "nonlinear_lags",
        nonlinear_lags as f64,
        "must be ≥ 1 when degree ≥ 2",
        degree == 1 || nonlinear_lags >= 1,
    )
}

impl PolyNarxConfig {
    /// Check every field.
    pub fn validate(&self) -> Result<()> {
        check_dictionary(&self.orders, self.degree, self.nonlinear_lags)?;
        check_config(
            "divergence_factor",
            self.divergence_factor,
            "must be finite and > 1",
            self.divergence_factor.is_finite() && self.divergence_factor > 1.0,
        )?;
        self.focus.validate()
    }
}

/// A fitted polynomial NARX model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "PolyNarxRaw")]
pub struct PolyNarxModel {
    orders: NarxOrders,
    /// Per regressor variable (layout of the tapped-delay regressor): mean and scale.
    centre: Vec<f64>,
    scale: Vec<f64>,
    /// Each term as the regressor variables it multiplies (empty: the constant).
    terms: Vec<Vec<usize>>,
    /// `p × terms` coefficients, in the outputs' units.
    coefficients: DMatrix<f64>,
    input_names: Vec<String>,
    output_names: Vec<String>,
    limits: Vec<(f64, f64)>,
    /// Per regressor variable, the range of its scaled values over the fitted rows, when
    /// the monomials are held there ([`PolyNarxConfig::hold`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    held: Option<Vec<(f64, f64)>>,
}

#[derive(Deserialize)]
struct PolyNarxRaw {
    orders: NarxOrders,
    centre: Vec<f64>,
    scale: Vec<f64>,
    terms: Vec<Vec<usize>>,
    coefficients: DMatrix<f64>,
    input_names: Vec<String>,
    output_names: Vec<String>,
    limits: Vec<(f64, f64)>,
    #[serde(default)]
    held: Option<Vec<(f64, f64)>>,
}

impl TryFrom<PolyNarxRaw> for PolyNarxModel {
    type Error = BaselineError;
    fn try_from(r: PolyNarxRaw) -> Result<Self> {
        let model = PolyNarxModel {
            orders: r.orders,
            centre: r.centre,
            scale: r.scale,
            terms: r.terms,
            coefficients: r.coefficients,
            input_names: r.input_names,
            output_names: r.output_names,
            limits: r.limits,
            held: r.held,
        };
        model.validate()?;
        Ok(model)
    }
}

/// The terms of a structure: constant, the linear part, then the monomials (also the
/// candidate dictionary of [`crate::frols`]).
pub(crate) fn structure_terms(
    o: &NarxOrders,
    p: usize,
    m: usize,
    degree: usize,
    nl: usize,
) -> Vec<Vec<usize>> {
    let len = o.regressor_len(p, m);
    let mut terms: Vec<Vec<usize>> = vec![Vec::new()];
    terms.extend((0..len).map(|i| vec![i]));
    // The regressor holds each output's `na` lags, then each input's `nb` taps, newest
    // first; the nonlinear variables are the newest `nl` of each.
    let mut vars = Vec::new();
    for ch in 0..p {
        vars.extend((0..nl.min(o.na)).map(|l| ch * o.na + l));
    }
    for ch in 0..m {
        vars.extend((0..nl.min(o.nb)).map(|l| p * o.na + ch * o.nb + l));
    }
    for d in 2..=degree {
        // Multisets of size d from `vars`, as non-decreasing index sequences.
        let mut idx = vec![0usize; d];
        'outer: loop {
            terms.push(idx.iter().map(|&i| vars[i]).collect());
            let mut pos = d;
            while pos > 0 {
                pos -= 1;
                if idx[pos] + 1 < vars.len() {
                    let v = idx[pos] + 1;
                    for slot in &mut idx[pos..] {
                        *slot = v;
                    }
                    continue 'outer;
                }
            }
            break;
        }
    }
    terms
}

impl PolyNarxModel {
    /// A model from its parts (checked as a model file is), with nothing held.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn from_parts(
        orders: NarxOrders,
        centre: Vec<f64>,
        scale: Vec<f64>,
        terms: Vec<Vec<usize>>,
        coefficients: DMatrix<f64>,
        input_names: Vec<String>,
        output_names: Vec<String>,
        limits: Vec<(f64, f64)>,
    ) -> Result<Self> {
        let model = PolyNarxModel {
            orders,
            centre,
            scale,
            terms,
            coefficients,
            input_names,
            output_names,
            limits,
            held: None,
        };
        model.validate()?;
        Ok(model)
    }

    fn validate(&self) -> Result<()> {
        self.orders.validate()?;
        let len = self
            .orders
            .regressor_len(self.output_names.len(), self.input_names.len());
        for (what, found) in [
            ("scaling centres vs regressor length", self.centre.len()),
            ("scaling factors vs regressor length", self.scale.len()),
        ] {
            if found != len {
                return Err(BaselineError::Dimension {
                    what,
                    found,
                    expected: len,
                });
            }
        }
        if let Some(bad) = self.terms.iter().flatten().copied().find(|&i| i >= len) {
            return Err(BaselineError::Dimension {
                what: "a polynomial term's variable vs regressor length",
                found: bad,
                expected: len,
            });
        }
        if self.coefficients.shape() != (self.output_names.len(), self.terms.len()) {
            return Err(BaselineError::Dimension {
                what: "coefficient columns vs polynomial terms",
                found: self.coefficients.ncols(),
                expected: self.terms.len(),
            });
        }
        if let Some(held) = &self.held {
            if held.len() != len {
                return Err(BaselineError::Dimension {
                    what: "held ranges vs regressor length",
                    found: held.len(),
                    expected: len,
                });
            }
            check_config(
                "polynomial NARX held ranges",
                f64::NAN,
                "must be finite with low ≤ high",
                held.iter()
                    .all(|(lo, hi)| lo.is_finite() && hi.is_finite() && lo <= hi),
            )?;
        }
        if self.limits.len() != self.output_names.len() {
            return Err(BaselineError::Dimension {
                what: "divergence limits vs NARX output channels",
                found: self.limits.len(),
                expected: self.output_names.len(),
            });
        }
        let finite = self
            .centre
            .iter()
            .chain(&self.coefficients)
            .all(|v| v.is_finite())
            && self.scale.iter().all(|s| s.is_finite() && *s > 0.0)
            && self
                .limits
                .iter()
                .all(|(lo, hi)| lo.is_finite() && hi.is_finite() && lo < hi);
        check_config(
            "polynomial NARX model",
            f64::NAN,
            "centres, coefficients and limits must be finite, scales positive, limits increasing",
            finite,
        )
    }

    /// The tapped delays.
    pub fn orders(&self) -> NarxOrders {
        self.orders
    }

    /// Per regressor variable, the range (scaled) at which the monomials are held, when
    /// they are ([`PolyNarxConfig::hold`]).
    pub fn held(&self) -> Option<&[(f64, f64)]> {
        self.held.as_deref()
    }

    /// The value of term `vars` at the scaled regressor `z` (`zc`: `z` clamped to the
    /// held ranges, or `z` itself): a monomial of degree ≥ 2 is evaluated at `zc`.
    fn term_value(vars: &[usize], z: &[f64], zc: &[f64]) -> f64 {
        let v = if vars.len() >= 2 { zc } else { z };
        vars.iter().map(|&i| v[i]).product()
    }

    /// Whether scaled variable `i` at `zi` lies outside its held range (never when
    /// nothing is held).
    fn beyond(&self, i: usize, zi: f64) -> bool {
        self.held
            .as_ref()
            .is_some_and(|h| zi < h[i].0 || zi > h[i].1)
    }

    /// `zc = z` clamped to the held ranges (a copy of `z` when nothing is held).
    fn clamp_into(&self, z: &[f64], zc: &mut [f64]) {
        match &self.held {
            Some(held) => {
                for ((c, v), (lo, hi)) in zc.iter_mut().zip(z).zip(held) {
                    *c = v.clamp(*lo, *hi);
                }
            }
            None => zc.copy_from_slice(z),
        }
    }

    /// Number of terms (constant included).
    pub fn n_terms(&self) -> usize {
        self.terms.len()
    }

    /// `p × terms` coefficients, in the order of [`PolyNarxModel::term_names`].
    pub fn coefficients(&self) -> &DMatrix<f64> {
        &self.coefficients
    }

    /// Each term written out, e.g. `1`, `y(k-1)`, `y(k-1)^2*u(k-1)`; the variables are
    /// the scaled ones, `(x − mean)/std` of the training record.
    pub fn term_names(&self) -> Vec<String> {
        let names = self.variable_names();
        self.terms
            .iter()
            .map(|t| {
                if t.is_empty() {
                    return "1".to_string();
                }
                let mut parts: Vec<String> = Vec::new();
                let mut i = 0;
                while i < t.len() {
                    let run = t[i..].iter().take_while(|&&v| v == t[i]).count();
                    parts.push(if run == 1 {
                        names[t[i]].clone()
                    } else {
                        format!("{}^{run}", names[t[i]])
                    });
                    i += run;
                }
                parts.join("*")
            })
            .collect()
    }

    fn variable_names(&self) -> Vec<String> {
        let o = self.orders;
        let mut names = Vec::new();
        for y in &self.output_names {
            names.extend((1..=o.na).map(|l| format!("{y}(k-{l})")));
        }
        for u in &self.input_names {
            names.extend((0..o.nb).map(|t| match o.nk + t {
                0 => format!("{u}(k)"),
                d => format!("{u}(k-{d})"),
            }));
        }
        names
    }
}

/// Scratch of one step: the scaled regressor.
pub(crate) struct PolyScratch {
    z: Vec<f64>,
    /// `z` clamped to the held ranges.
    zc: Vec<f64>,
}

impl OneStep for PolyNarxModel {
    type Scratch = PolyScratch;

    fn orders(&self) -> NarxOrders {
        self.orders
    }

    fn input_names(&self) -> &[String] {
        &self.input_names
    }

    fn output_names(&self) -> &[String] {
        &self.output_names
    }

    fn limits(&self) -> &[(f64, f64)] {
        &self.limits
    }

    fn scratch(&self) -> PolyScratch {
        PolyScratch {
            z: vec![0.0; self.centre.len()],
            zc: vec![0.0; self.centre.len()],
        }
    }

    fn map(&self, reg: &[f64], s: &mut PolyScratch, out: &mut [f64]) -> Result<()> {
        for ((z, r), (c, sc)) in
            s.z.iter_mut()
                .zip(reg)
                .zip(self.centre.iter().zip(&self.scale))
        {
            *z = (r - c) / sc;
        }
        self.clamp_into(&s.z, &mut s.zc);
        out.fill(0.0);
        for (t, vars) in self.terms.iter().enumerate() {
            let phi = Self::term_value(vars, &s.z, &s.zc);
            for (c, o) in out.iter_mut().enumerate() {
                *o += self.coefficients[(c, t)] * phi;
            }
        }
        Ok(())
    }
}

impl Model for PolyNarxModel {
    type Error = BaselineError;

    fn output_names(&self) -> Vec<String> {
        self.output_names.clone()
    }

    /// Free-run simulation from the first `max_lag` measured samples (as the network
    /// NARX's [`Model::simulate`](crate::NarxModel)); columns before the start are NaN.
    fn simulate(&self, experiment: &Experiment) -> Result<Prediction> {
        narx_sim::simulate(self, experiment)
    }

    /// k-step prediction (as the network NARX's).
    fn predict(&self, experiment: &Experiment, k: usize) -> Result<Prediction> {
        narx_sim::predict(self, experiment, k)
    }
}

/// What [`fit_poly_narx`] returns.
#[derive(Debug, Clone)]
pub struct PolyNarxFit {
    /// The model.
    pub model: PolyNarxModel,
    /// Training rows used (rows touching a missing sample are skipped).
    pub rows: usize,
    /// Rows skipped for missing samples.
    pub skipped_rows: usize,
    /// Numerical rank of the regressor matrix (equal to the number of terms when every
    /// term is determined by the data).
    pub rank: usize,
    /// One-step root-mean-square error per output on the training rows (of the one-step
    /// solution).
    pub one_step_rmse: Vec<f64>,
    /// The simulation-error refinement, when [`Focus::Simulation`] asked for it.
    pub refinement: Option<Refinement>,
}

/// What the simulation-error refinement did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Refinement {
    /// Jacobian evaluations.
    pub iterations: usize,
    /// Free-run RMSE per output over the training records, from the one-step solution.
    pub start_rmse: Vec<f64>,
    /// The same after the refinement.
    pub final_rmse: Vec<f64>,
}

/// Fit a polynomial NARX model by one-step least squares on every experiment of `data`.
///
/// Errors: an invalid configuration, records no longer than the lag window, no row
/// without missing samples, fewer rows than terms.
pub fn fit_poly_narx(data: &Dataset, config: &PolyNarxConfig) -> Result<PolyNarxFit> {
    config.validate()?;
    let o = config.orders;
    let rows = training_rows(data, &o)?;
    let (p, m) = (data.output_channels().len(), data.input_channels().len());
    let len = o.regressor_len(p, m);
    let n = rows.inputs.ncols();
    // Centre and scale of each variable over the training rows.
    let mut centre = vec![0.0; len];
    let mut scale = vec![1.0; len];
    for i in 0..len {
        let r = rows.inputs.row(i);
        let mean = r.mean();
        let var = r.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
        centre[i] = mean;
        // A constant variable keeps scale 1 (its column is then the constant's).
        scale[i] = if var > 0.0 { var.sqrt() } else { 1.0 };
    }
    let degree_terms = if config.degree == 1 {
        structure_terms(&o, p, m, 1, 0)
    } else {
        structure_terms(&o, p, m, config.degree, config.nonlinear_lags)
    };
    let t = degree_terms.len();
    if n < t {
        return Err(BaselineError::TooFewRows {
            what: "polynomial NARX training rows (one per term at least)",
            found: n,
            needed: t,
        });
    }
    let mut phi = DMatrix::zeros(n, t);
    let mut z = vec![0.0; len];
    // The range of each scaled variable over the fitted rows (where a held monomial is
    // evaluated as it is).
    let mut range = vec![(f64::INFINITY, f64::NEG_INFINITY); len];
    for r in 0..n {
        for (i, zi) in z.iter_mut().enumerate() {
            *zi = (rows.inputs[(i, r)] - centre[i]) / scale[i];
            range[i] = (range[i].0.min(*zi), range[i].1.max(*zi));
        }
        for (j, vars) in degree_terms.iter().enumerate() {
            phi[(r, j)] = vars.iter().map(|&i| z[i]).product();
        }
    }
    let (theta, rank) = least_squares(phi.clone(), &rows.targets.transpose())?;
    let resid = &phi * &theta - rows.targets.transpose();
    let one_step_rmse = (0..p)
        .map(|c| (resid.column(c).norm_squared() / n as f64).sqrt())
        .collect();
    let mut model = PolyNarxModel {
        orders: o,
        centre,
        scale,
        terms: degree_terms,
        coefficients: theta.transpose(),
        input_names: data.input_names(),
        output_names: data.output_names(),
        limits: divergence_limits(data, config.divergence_factor)?,
        held: config.hold.then_some(range),
    };
    model.validate()?;
    let refinement = match config.focus {
        Focus::Prediction => None,
        Focus::Simulation { max_iterations } => Some(refine(&mut model, data, max_iterations)?),
    };
    Ok(PolyNarxFit {
        model,
        rows: n,
        skipped_rows: rows.skipped,
        rank,
        one_step_rmse,
        refinement,
    })
}

/// Minimum-norm least squares `min ‖Φθ − Y‖` through a QR of `Φ` and a truncated SVD of
/// its triangle; returns `θ` (`terms × p`) and the numerical rank.
fn least_squares(phi: DMatrix<f64>, y: &DMatrix<f64>) -> Result<(DMatrix<f64>, usize)> {
    let t = phi.ncols();
    let qr = phi.qr();
    let mut qty = y.clone();
    qr.q_tr_mul(&mut qty);
    let r = qr.r();
    let top = qty.rows(0, t).into_owned();
    let svd = r.svd(true, true);
    let smax = svd.singular_values.max();
    if !(smax.is_finite() && smax > 0.0) {
        return Err(BaselineError::TooFewRows {
            what: "polynomial NARX regressor directions with a finite nonzero spread",
            found: 0,
            needed: 1,
        });
    }
    let tol = RANK_RTOL * smax;
    let rank = svd.singular_values.iter().filter(|&&s| s > tol).count();
    let theta = svd
        .solve(&top, tol)
        .map_err(|_| BaselineError::TooFewRows {
            what: "polynomial NARX least-squares solution",
            found: rank,
            needed: t,
        })?;
    Ok((theta, rank))
}

/// The derivative of each term with respect to each output-lag variable it holds:
/// `(variable, multiplicity, the term with one factor of it removed)`.
type TermDerivatives = Vec<Vec<(usize, f64, Vec<usize>)>>;

fn term_derivatives(terms: &[Vec<usize>], n_output_vars: usize) -> TermDerivatives {
    terms
        .iter()
        .map(|vars| {
            let mut out: Vec<(usize, f64, Vec<usize>)> = Vec::new();
            for (i, &v) in vars.iter().enumerate() {
                if v >= n_output_vars || (i > 0 && vars[i - 1] == v) {
                    continue;
                }
                let mult = vars.iter().filter(|&&w| w == v).count() as f64;
                let mut rest = vars.clone();
                rest.remove(i);
                out.push((v, mult, rest));
            }
            out
        })
        .collect()
}

/// The free-run (simulation) error of a polynomial NARX structure as a function of its
/// coefficients (row-major `p × terms`).
struct SimulationError<'a> {
    model: &'a PolyNarxModel,
    data: &'a Dataset,
    /// 1 / standard deviation of each output over the training records.
    weight: Vec<f64>,
    derivatives: TermDerivatives,
}

impl SimulationError<'_> {
    /// Residuals `w·(ŷ − y)` of every measured sample after each record's start, with
    /// their Jacobian when asked; `None` when a free run leaves the limits.
    fn run(&self, theta: &[f64], jacobian: bool) -> Result<Option<Linearised>> {
        let m = self.model;
        let o = m.orders;
        let (p, q) = (m.output_names.len(), m.input_names.len());
        let t_count = m.terms.len();
        let n_par = p * t_count;
        let len = o.regressor_len(p, q);
        let n_out_vars = p * o.na;
        let mut reg = vec![0.0; len];
        let mut z = vec![0.0; len];
        let mut zc = vec![0.0; len];
        let mut phi = vec![0.0; t_count];
        let mut grad = vec![0.0; p * n_out_vars];
        let mut row = vec![0.0; n_par];
        let mut sens = narx_sim::Sensitivities::new(o, p, n_par, jacobian);
        for exp in self.data.experiments() {
            narx_sim::check(m, exp)?;
            let s = narx_sim::first_complete_window(m, exp)?;
            let mut yhat = exp.outputs().clone();
            let (u, y) = (exp.inputs(), exp.outputs());
            sens.start_record();
            for k in s..exp.len() {
                crate::regressors::fill_regressor(
                    |c, j| yhat[(c, j)],
                    |c, j| u[(c, j)],
                    (p, q),
                    k,
                    &o,
                    &mut reg,
                );
                for i in 0..len {
                    z[i] = (reg[i] - m.centre[i]) / m.scale[i];
                }
                m.clamp_into(&z, &mut zc);
                for (f, vars) in phi.iter_mut().zip(&m.terms) {
                    *f = PolyNarxModel::term_value(vars, &z, &zc);
                }
                for c in 0..p {
                    let th = &theta[c * t_count..(c + 1) * t_count];
                    let v: f64 = th.iter().zip(&phi).map(|(a, b)| a * b).sum();
                    let (lo, hi) = m.limits[c];
                    if !(v.is_finite() && v >= lo && v <= hi) {
                        return Ok(None);
                    }
                    yhat[(c, k)] = v;
                }
                if sens.with_jacobian() {
                    grad.fill(0.0);
                    for c in 0..p {
                        let th = &theta[c * t_count..(c + 1) * t_count];
                        for (t, ders) in self.derivatives.iter().enumerate() {
                            let monomial = m.terms[t].len() >= 2;
                            for (v, mult, rest) in ders {
                                // A held monomial is flat in a variable outside its range.
                                if monomial && m.beyond(*v, z[*v]) {
                                    continue;
                                }
                                let d: f64 = if monomial {
                                    rest.iter().map(|&i| zc[i]).product()
                                } else {
                                    rest.iter().map(|&i| z[i]).product()
                                };
                                grad[c * n_out_vars + v] += th[t] * mult * d;
                            }
                        }
                    }
                    for c in 0..p {
                        row.fill(0.0);
                        row[c * t_count..(c + 1) * t_count].copy_from_slice(&phi);
                        sens.chain(k, c, &mut row, |v| grad[c * n_out_vars + v] / m.scale[v]);
                    }
                }
                for c in 0..p {
                    if !y[(c, k)].is_nan() {
                        sens.push(k, c, self.weight[c], yhat[(c, k)], y[(c, k)]);
                    }
                }
            }
        }
        Ok(Some(sens.finish()))
    }

    /// Free-run RMSE per output (unweighted) at `theta`.
    fn rmse(&self, theta: &[f64]) -> Result<Vec<f64>> {
        let Some((r, _)) = self.run(theta, false)? else {
            return Err(BaselineError::Diverged {
                sample: 0,
                channel: "polynomial NARX free run over the training records".into(),
                value: f64::INFINITY,
            });
        };
        narx_sim::rmse_per_output(self.model, self.data, &r, &self.weight)
    }
}

impl LeastSquares for SimulationError<'_> {
    fn residuals(&self, theta: &[f64], jacobian: bool) -> Result<Option<Linearised>> {
        self.run(theta, jacobian)
    }
}

/// Refine `model`'s coefficients by free-run error over `data` (see [`Focus::Simulation`]).
fn refine(model: &mut PolyNarxModel, data: &Dataset, max_iterations: usize) -> Result<Refinement> {
    // The start must run free over every record (its divergence, with the sample, is the
    // error).
    for exp in data.experiments() {
        narx_sim::simulate(model, exp)?;
    }
    let p = model.output_names.len();
    let weight = narx_sim::output_weights(data, p);
    let theta0: Vec<f64> = (0..p)
        .flat_map(|c| {
            model
                .coefficients
                .row(c)
                .iter()
                .copied()
                .collect::<Vec<_>>()
        })
        .collect();
    let problem = SimulationError {
        model,
        data,
        weight,
        derivatives: term_derivatives(&model.terms, p * model.orders.na),
    };
    let start_rmse = problem.rmse(&theta0)?;
    let settings = lsq::Settings {
        max_iterations: max_iterations as u64,
        gtol: 0.0,
        ftol: 1e-10,
        exact_rtol: 0.0,
        data_norm: 0.0,
        scaling: sysid_core::Scaling::Current,
    };
    let outcome = lsq::minimise_damped(&problem, &theta0, "polynomial NARX", settings)?;
    let final_rmse = problem.rmse(&outcome.theta)?;
    let t = model.terms.len();
    let coefficients = DMatrix::from_row_slice(p, t, &outcome.theta);
    model.coefficients = coefficients;
    model.validate()?;
    Ok(Refinement {
        iterations: outcome.report.iterations.len(),
        start_rmse,
        final_rmse,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use sysid_core::{Channel, Experiment};

    #[test]
    fn structure_counts_every_monomial_once() {
        let o = NarxOrders {
            na: 3,
            nb: 3,
            nk: 1,
        };
        // Linear: 1 + 6. Nonlinear variables: 2 output lags + 2 input taps = 4;
        // degree 2: C(5, 2) = 10, degree 3: C(6, 3) = 20.
        let t = structure_terms(&o, 1, 1, 3, 2);
        assert_eq!(t.len(), 1 + 6 + 10 + 20);
        let mut sorted = t.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), t.len());
        // The variables of the nonlinear part are y(k-1), y(k-2), u(k-1), u(k-2).
        let nl: std::collections::BTreeSet<usize> = t
            .iter()
            .filter(|v| v.len() > 1)
            .flatten()
            .copied()
            .collect();
        assert_eq!(nl.into_iter().collect::<Vec<_>>(), vec![0, 1, 3, 4]);
    }

    #[test]
    fn configuration_errors_name_the_field() {
        let bad = PolyNarxConfig {
            degree: 0,
            ..PolyNarxConfig::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("degree"), "{e}");
        let bad = PolyNarxConfig {
            nonlinear_lags: 0,
            ..PolyNarxConfig::default()
        };
        assert!(
            bad.validate()
                .unwrap_err()
                .to_string()
                .contains("nonlinear_lags")
        );
    }

    impl PolyNarxModel {
        /// The range of scaled regressor variable `i` over `data`'s training rows.
        fn held_range_of(&self, i: usize, data: &Dataset) -> (f64, f64) {
            let rows = training_rows(data, &self.orders).unwrap();
            rows.inputs
                .row(i)
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                    let z = (v - self.centre[i]) / self.scale[i];
                    (a.min(z), b.max(z))
                })
        }
    }

    /// A cubic in the input, fitted on |u| ≤ 1: run on an input 30 times larger, the plain
    /// polynomial leaves its divergence limits and the held one stays bounded; on the
    /// fitted record's own regressors (one-step prediction) the two agree to the bit.
    #[test]
    fn held_monomials_stay_bounded_beyond_the_training_range() {
        let n = 400;
        let wave = |a: f64| -> Vec<f64> {
            (0..n)
                .map(|k| a * ((0.37 * k as f64).sin() * 0.7 + 0.3 * (0.11 * k as f64).cos()))
                .collect()
        };
        let truth = |u: &[f64]| -> Vec<f64> {
            let mut y = vec![0.0; u.len()];
            for k in 1..u.len() {
                y[k] = 0.5 * y[k - 1] + u[k - 1] + 0.3 * u[k - 1].powi(3);
            }
            y
        };
        let u = wave(1.0);
        let train = dataset(u.clone(), truth(&u));
        let config = |hold| PolyNarxConfig {
            orders: NarxOrders {
                na: 1,
                nb: 1,
                nk: 1,
            },
            degree: 3,
            nonlinear_lags: 1,
            hold,
            ..PolyNarxConfig::default()
        };
        let plain = fit_poly_narx(&train, &config(false)).unwrap().model;
        let held = fit_poly_narx(&train, &config(true)).unwrap().model;
        assert!(plain.held().is_none());
        assert_eq!(held.held().map(<[_]>::len), Some(2));
        let e = &train.experiments()[0];
        let (a, b) = (plain.predict(e, 1).unwrap(), held.predict(e, 1).unwrap());
        for (x, y) in a.outputs.iter().zip(b.outputs.iter()) {
            assert!(x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()));
        }
        let big = wave(30.0);
        let far = dataset(big.clone(), truth(&big));
        let e = &far.experiments()[0];
        assert!(matches!(
            plain.simulate(e),
            Err(BaselineError::Diverged { .. })
        ));
        let sim = held.simulate(e).unwrap();
        let peak = sim
            .outputs
            .iter()
            .filter(|v| v.is_finite())
            .fold(0.0_f64, |m, v| m.max(v.abs()));
        // The linear part alone: |y| ≤ 2·30 + the held cubic's edge value (< 1).
        assert!(peak < 70.0, "peak {peak}");
    }

    fn dataset(u: Vec<f64>, y: Vec<f64>) -> Dataset {
        let n = u.len();
        Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("y")],
            vec![
                Experiment::new(
                    0.0,
                    1.0,
                    DMatrix::from_vec(1, n, u),
                    DMatrix::from_vec(1, n, y),
                )
                .unwrap(),
            ],
        )
        .unwrap()
    }

    #[test]
    fn too_few_rows_and_missing_rows_are_errors_not_panics() {
        let d = dataset(vec![0.1, 0.2, 0.3, 0.4], vec![0.0, 0.1, 0.2, 0.3]);
        let e = fit_poly_narx(&d, &PolyNarxConfig::default()).unwrap_err();
        assert!(matches!(e, BaselineError::TooFewRows { .. }), "{e}");
        let d = dataset(vec![0.0; 40], vec![f64::NAN; 40]);
        assert!(fit_poly_narx(&d, &PolyNarxConfig::default()).is_err());
    }

    /// The exact sensitivities of the free run against central differences.
    #[test]
    fn simulation_jacobian_matches_finite_differences() {
        jacobian_check(None);
    }

    /// The same with the monomials held at ranges narrower than the data's (60 % of each
    /// width about its middle), so that many samples evaluate clamped monomials.
    #[test]
    fn held_simulation_jacobian_matches_finite_differences() {
        jacobian_check(Some(0.6));
    }

    fn jacobian_check(held: Option<f64>) {
        let n = 120;
        let u: Vec<f64> = (0..n)
            .map(|k| (0.21 * k as f64).sin() + 0.3 * (0.05 * k as f64).cos())
            .collect();
        let mut y = vec![0.0; n];
        for k in 2..n {
            y[k] = 1.2 * y[k - 1] - 0.5 * y[k - 2] + 0.3 * u[k - 1] - 0.1 * y[k - 1].powi(3)
                + 0.05 * y[k - 2] * y[k - 1] * u[k - 1];
        }
        let data = dataset(u, y);
        let fit = fit_poly_narx(
            &data,
            &PolyNarxConfig {
                orders: NarxOrders {
                    na: 2,
                    nb: 2,
                    nk: 1,
                },
                degree: 3,
                nonlinear_lags: 2,
                ..PolyNarxConfig::default()
            },
        )
        .unwrap();
        let mut model = fit.model.clone();
        if let Some(share) = held {
            let ranges = (0..model.centre.len())
                .map(|i| {
                    let (lo, hi) = fit.model.held_range_of(i, &data);
                    let (mid, half) = (0.5 * (lo + hi), 0.5 * share * (hi - lo));
                    (mid - half, mid + half)
                })
                .collect();
            model.held = Some(ranges);
        }
        let model = &model;
        let problem = SimulationError {
            model,
            data: &data,
            weight: vec![2.0],
            derivatives: term_derivatives(&model.terms, model.orders.na),
        };
        // Move away from the exact solution so every sensitivity is exercised.
        let theta: Vec<f64> = model
            .coefficients
            .iter()
            .enumerate()
            .map(|(i, v)| v * 0.97 + 1e-3 * (i as f64 % 3.0))
            .collect();
        let (_, j) = problem.run(&theta, true).unwrap().unwrap();
        let j = j.unwrap();
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for col in 0..theta.len() {
            let (mut a, mut b) = (theta.clone(), theta.clone());
            a[col] += h;
            b[col] -= h;
            let (ra, _) = problem.run(&a, false).unwrap().unwrap();
            let (rb, _) = problem.run(&b, false).unwrap().unwrap();
            let fd = (ra - rb) / (2.0 * h);
            let scale = fd.amax().max(1e-3);
            worst = worst.max((j.column(col) - fd).amax() / scale);
        }
        assert!(worst < 1e-6, "largest relative Jacobian error {worst:e}");
    }
}
