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
}

impl Default for PolyNarxConfig {
    fn default() -> Self {
        Self {
            orders: NarxOrders::default(),
            degree: 3,
            nonlinear_lags: 2,
            divergence_factor: 100.0,
        }
    }
}

impl PolyNarxConfig {
    /// Check every field.
    pub fn validate(&self) -> Result<()> {
        self.orders.validate()?;
        check_config(
            "degree",
            self.degree as f64,
            "must be between 1 and 5",
            (1..=5).contains(&self.degree),
        )?;
        check_config(
            "nonlinear_lags",
            self.nonlinear_lags as f64,
            "must be ≥ 1 when degree ≥ 2",
            self.degree == 1 || self.nonlinear_lags >= 1,
        )?;
        check_config(
            "divergence_factor",
            self.divergence_factor,
            "must be finite and > 1",
            self.divergence_factor.is_finite() && self.divergence_factor > 1.0,
        )
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
        };
        model.validate()?;
        Ok(model)
    }
}

/// The terms of a structure: constant, the linear part, then the monomials.
fn structure_terms(
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
        out.fill(0.0);
        for (t, vars) in self.terms.iter().enumerate() {
            let phi: f64 = vars.iter().map(|&i| s.z[i]).product();
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
    /// One-step root-mean-square error per output on the training rows.
    pub one_step_rmse: Vec<f64>,
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
    for r in 0..n {
        for (i, zi) in z.iter_mut().enumerate() {
            *zi = (rows.inputs[(i, r)] - centre[i]) / scale[i];
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
    let model = PolyNarxModel {
        orders: o,
        centre,
        scale,
        terms: degree_terms,
        coefficients: theta.transpose(),
        input_names: data.input_names(),
        output_names: data.output_names(),
        limits: divergence_limits(data, config.divergence_factor)?,
    };
    model.validate()?;
    Ok(PolyNarxFit {
        model,
        rows: n,
        skipped_rows: rows.skipped,
        rank,
        one_step_rmse,
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
}
