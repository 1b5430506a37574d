//! The free-run refinement of the linear state-space baseline: the output error after the
//! initialisation window as a least-squares problem in the sections' coefficients, the
//! feedthrough and (optionally) the input offset, solved by the workspace's
//! Levenberg–Marquardt; and the held-out RMSE that chooses the order.

use nalgebra::{DMatrix, DVector};
use sysid_core::SolveReport;

use super::LinearSsConfig;
use super::model::{LinearSsModel, Record, Section};
use crate::error::Result;
use crate::lsq::{self, LeastSquares, Linearised};

/// The free-run problem over one record with window-estimated `x0`.
struct Refine<'a> {
    template: LinearSsModel,
    record: Record<'a>,
    base_offset: f64,
    fit_offset: bool,
    /// Finite-difference step scale per parameter.
    typical: Vec<f64>,
    /// Relative finite-difference step per parameter.
    step: Vec<f64>,
}

impl Refine<'_> {
    fn model(&self, theta: &[f64]) -> LinearSsModel {
        let mut m = self.template.clone();
        let mut o = 0;
        for s in &mut m.sections {
            let k = s.params().len();
            *s = s.with_params(&theta[o..o + k]);
            o += k;
        }
        m.d = theta[o];
        m.input_offset = self.base_offset + if self.fit_offset { theta[o + 1] } else { 0.0 };
        m
    }

    fn errors(&self, theta: &[f64]) -> Option<DVector<f64>> {
        let m = self.model(theta);
        let sim = m.simulate_signal(self.record.u, self.record.y)?;
        let w = m.window;
        Some(DVector::from_iterator(
            sim.len() - w,
            sim[w..].iter().zip(&self.record.y[w..]).map(|(s, y)| s - y),
        ))
    }
}

impl LeastSquares for Refine<'_> {
    /// Residuals, and a central-difference Jacobian (steps `step_i·(|θ_i| + typical_i)`;
    /// one-sided where one side diverges).
    fn residuals(&self, theta: &[f64], jacobian: bool) -> Result<Option<Linearised>> {
        let Some(r) = self.errors(theta) else {
            return Ok(None);
        };
        if !jacobian {
            return Ok(Some((r, None)));
        }
        let mut j = DMatrix::zeros(r.len(), theta.len());
        let mut t = theta.to_vec();
        for i in 0..theta.len() {
            let h = self.step[i] * (theta[i].abs() + self.typical[i]);
            t[i] = theta[i] + h;
            let plus = self.errors(&t);
            t[i] = theta[i] - h;
            let minus = self.errors(&t);
            t[i] = theta[i];
            let col = match (plus, minus) {
                (Some(p), Some(m)) => (p - m) / (2.0 * h),
                (Some(p), None) => (p - &r) / h,
                (None, Some(m)) => (&r - m) / h,
                (None, None) => return Ok(None),
            };
            j.set_column(i, &col);
        }
        Ok(Some((r, Some(j))))
    }
}

/// Refine `start` by free-run output error on `rec`.
pub(super) fn refine(
    start: &LinearSsModel,
    rec: &Record<'_>,
    config: &LinearSsConfig,
    base_offset: f64,
) -> Result<(LinearSsModel, SolveReport)> {
    let mut theta: Vec<f64> = start.sections.iter().flat_map(|s| s.params()).collect();
    let n_sec = theta.len();
    theta.push(start.d);
    let u_scale = {
        let m = rec.u.iter().sum::<f64>() / rec.u.len() as f64;
        (rec.u.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / rec.u.len() as f64).sqrt()
    };
    if config.fit_input_offset {
        theta.push(start.input_offset - base_offset);
    }
    let b_scale = start
        .sections
        .iter()
        .flat_map(|s| match *s {
            Section::Second { b1, b2, .. } | Section::Integrating { b1, b2, .. } => {
                vec![b1.abs(), b2.abs()]
            }
            Section::First { b, .. } => vec![b.abs()],
        })
        .fold(start.d.abs(), f64::max)
        .max(1e-300);
    let mut typical = Vec::with_capacity(theta.len());
    for s in &start.sections {
        match s {
            Section::Second { .. } => typical.extend([1e-3, 1e-3, b_scale, b_scale]),
            Section::Integrating { .. } => typical.extend([1e-3, b_scale, b_scale]),
            Section::First { .. } => typical.extend([1e-3, b_scale]),
        }
    }
    typical.push(b_scale);
    if config.fit_input_offset {
        typical.push(1e-2 * u_scale.max(1e-300));
    }
    debug_assert_eq!(typical.len(), theta.len());
    // Denominator coefficients get much smaller steps: near the unit circle a pole moves
    // by δa/(p₁ − p₂) and a long record amplifies it k-fold, so a 1e-7 step leaves a
    // truncation error of ~1e-4 in those columns (enough to stall Gauss–Newton); 1e-9
    // keeps both truncation and round-off below 1e-6 on the benchmarks' records.
    let mut step = Vec::with_capacity(theta.len());
    for s in &start.sections {
        match s {
            Section::Second { .. } => step.extend([1e-9, 1e-9, 1e-7, 1e-7]),
            Section::Integrating { .. } => step.extend([1e-9, 1e-7, 1e-7]),
            Section::First { .. } => step.extend([1e-9, 1e-7]),
        }
    }
    step.push(1e-7);
    if config.fit_input_offset {
        step.push(1e-7);
    }
    let problem = Refine {
        template: start.clone(),
        record: Record { u: rec.u, y: rec.y },
        base_offset,
        fit_offset: config.fit_input_offset,
        typical,
        step,
    };
    let mut names: Vec<String> = Vec::new();
    for (i, s) in start.sections.iter().enumerate() {
        match s {
            Section::Second { .. } => {
                names.extend(["a1", "a2", "b1", "b2"].map(|p| format!("section {i} {p}")))
            }
            Section::Integrating { .. } => {
                names.extend(["p", "b1", "b2"].map(|p| format!("section {i} {p}")))
            }
            Section::First { .. } => {
                names.extend(["lambda", "b"].map(|p| format!("section {i} {p}")))
            }
        }
    }
    debug_assert_eq!(names.len(), n_sec);
    names.push("d".into());
    if config.fit_input_offset {
        names.push("input offset".into());
    }
    let (theta, report) = marquardt(&problem, theta, &names, config.max_iterations)?;
    Ok((problem.model(&theta), report))
}

/// The workspace's Levenberg–Marquardt (Marquardt's scaling by the current `diag(JᵀJ)`,
/// Nielsen's gain-ratio damping, through [`lsq::minimise`]; with MINPACK's remembered
/// column norms the held-out order choice on EMPS moved from n = 2 to n = 4) until an accepted step lowers the cost by less than `1e-12`
/// relative, no damping gives a descent, or `max_iterations` Jacobians. (argmin's trust
/// region, which the baselines used before, crept along the curved valley of
/// near-integrating models, hundreds of iterations for a 5-parameter problem.)
fn marquardt<P: LeastSquares>(
    problem: &P,
    theta0: Vec<f64>,
    names: &[String],
    max_iterations: u64,
) -> Result<(Vec<f64>, SolveReport)> {
    let settings = lsq::Settings {
        max_iterations,
        gtol: 0.0,
        ftol: 1e-12,
        exact_rtol: 0.0,
        data_norm: 0.0,
        scaling: sysid_core::Scaling::Current,
    };
    let outcome = lsq::minimise(
        problem,
        &theta0,
        names,
        "linear state-space model",
        settings,
    )?;
    Ok((outcome.theta, outcome.report))
}

pub(super) fn rmse_after(model: &LinearSsModel, rec: &Record<'_>) -> Option<f64> {
    let sim = model.simulate_signal(rec.u, rec.y)?;
    let w = model.window;
    let n = (sim.len() - w) as f64;
    let sse: f64 = sim[w..]
        .iter()
        .zip(&rec.y[w..])
        .map(|(s, y)| (s - y) * (s - y))
        .sum();
    Some((sse / n).sqrt())
}
