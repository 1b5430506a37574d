//! Simulation-error refinement of a network NARX ([`crate::Focus::Simulation`] in
//! [`crate::NarxConfig`]): the network's weights minimise the free-run error over the
//! training records, with the sensitivities of the recursion computed exactly.
//!
//! At sample `k` the network reads `z(k) = P(φ(k))` (the regressor projection, or `φ`
//! itself), and `φ(k)` holds the model's own outputs `ŷ(k−1…k−na)`. So
//! `dŷ(k)/dw = ∂F/∂w + Σ_v ∂F/∂z · ∂z/∂φ_v · dŷ(k − lag_v)/dw` over the output-lag entries
//! `v` of the regressor. The weight and input Jacobians of the network at each sample
//! come from one forward and `p` backward passes ([`nn::Mlp::gradients_into`]); the
//! sensitivities of the last `na` samples live in a ring, so memory is the Jacobian's
//! own (`rows × weights`) plus `(na + 1)·p·weights`.

use nalgebra::DMatrix;
use nn::Workspace;
use sysid_core::Dataset;

use crate::error::{BaselineError, Result};
use crate::lsq::{self, LeastSquares, Linearised};
use crate::narx_model::NarxModel;
use crate::narx_sim::{self, OneStep};
use crate::poly_narx::Refinement;
use crate::regressors::fill_regressor;

/// The free-run error of a network NARX as a function of its flat weight vector.
struct NetSimulationError<'a> {
    model: &'a NarxModel,
    data: &'a Dataset,
    /// 1 / standard deviation of each output over the training records.
    weight: Vec<f64>,
    /// `∂z/∂φ_v` for the output-lag entries `v` of the regressor (`n_z × p·na`).
    dz: DMatrix<f64>,
}

impl NetSimulationError<'_> {
    /// Residuals `w·(ŷ − y)` of every measured sample after each record's start, with
    /// their Jacobian when asked; `None` when a free run leaves the limits.
    fn run(&self, theta: &[f64], jacobian: bool) -> Result<Option<Linearised>> {
        let m = self.model;
        let mut net = m.network().clone();
        net.set_weights(theta)?;
        let o = m.orders();
        let (p, q) = (m.output_names().len(), m.input_names().len());
        let n_w = net.n_weights();
        let n_z = net.n_inputs();
        let len = o.regressor_len(p, q);
        let mut reg = vec![0.0; len];
        let mut tmp = vec![0.0; len];
        let mut z = vec![0.0; n_z];
        let mut out = vec![0.0; p];
        let mut dw = DMatrix::zeros(p, n_w);
        let mut dx = DMatrix::zeros(p, n_z);
        let mut row = vec![0.0; n_w];
        let mut ws = Workspace::new();
        let mut sens = narx_sim::Sensitivities::new(o, p, n_w, jacobian);
        for exp in self.data.experiments() {
            narx_sim::check(m, exp)?;
            let s = narx_sim::first_complete_window(m, exp)?;
            let mut yhat = exp.outputs().clone();
            let (u, y) = (exp.inputs(), exp.outputs());
            sens.start_record();
            for k in s..exp.len() {
                fill_regressor(
                    |c, j| yhat[(c, j)],
                    |c, j| u[(c, j)],
                    (p, q),
                    k,
                    &o,
                    &mut reg,
                );
                let x: &[f64] = match m.projection() {
                    Some(proj) => {
                        proj.apply(&reg, &mut tmp, &mut z);
                        &z
                    }
                    None => &reg,
                };
                if jacobian {
                    net.gradients_into(x, &mut out, &mut dw, &mut dx, &mut ws)?;
                } else {
                    net.forward(x, &mut out, &mut ws)?;
                }
                for (c, v) in out.iter().enumerate() {
                    let (lo, hi) = m.limits()[c];
                    if !(v.is_finite() && *v >= lo && *v <= hi) {
                        return Ok(None);
                    }
                    yhat[(c, k)] = *v;
                }
                if jacobian {
                    for c in 0..p {
                        for (i, r) in row.iter_mut().enumerate() {
                            *r = dw[(c, i)];
                        }
                        // ∂ŷ_c/∂φ_v = Σ_i ∂ŷ_c/∂z_i · ∂z_i/∂φ_v.
                        sens.chain(k, c, &mut row, |v| {
                            (0..n_z).map(|i| dx[(c, i)] * self.dz[(i, v)]).sum()
                        });
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
                channel: "network NARX free run over the training records".into(),
                value: f64::INFINITY,
            });
        };
        narx_sim::rmse_per_output(self.model, self.data, &r, &self.weight)
    }
}

impl LeastSquares for NetSimulationError<'_> {
    fn residuals(&self, theta: &[f64], jacobian: bool) -> Result<Option<Linearised>> {
        self.run(theta, jacobian)
    }
}

/// `∂z/∂φ_v` of the network's input `z` for the regressor's output-lag entries `v`
/// (`n_z × p·na`): the projection's Jacobian columns, or the identity's without one.
fn lag_jacobian(model: &NarxModel) -> DMatrix<f64> {
    let n_out_vars = model.output_names().len() * model.orders().na;
    let n_z = model.network().n_inputs();
    match model.projection() {
        Some(proj) => proj.jacobian().columns(0, n_out_vars).into_owned(),
        None => DMatrix::identity(n_z, n_z)
            .columns(0, n_out_vars)
            .into_owned(),
    }
}

/// Refine `model`'s weights by free-run error over `data`, at most `max_iterations`
/// Jacobians. The start must run free over every record (its divergence, with the
/// sample, is the error).
pub(crate) fn refine(
    model: &mut NarxModel,
    data: &Dataset,
    max_iterations: usize,
) -> Result<Refinement> {
    for exp in data.experiments() {
        narx_sim::simulate(model, exp)?;
    }
    let p = model.output_names().len();
    let weight = narx_sim::output_weights(data, p);
    let dz = lag_jacobian(model);
    let theta0 = model.network().weights().to_vec();
    let problem = NetSimulationError {
        model,
        data,
        weight,
        dz,
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
    let outcome = lsq::minimise_damped(&problem, &theta0, "network NARX", settings)?;
    let final_rmse = problem.rmse(&outcome.theta)?;
    let iterations = outcome.report.iterations.len();
    model.set_network_weights(&outcome.theta)?;
    Ok(Refinement {
        iterations,
        start_rmse,
        final_rmse,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::narx::{NarxConfig, NetworkChoice, Projection, fit_narx};
    use crate::regressors::NarxOrders;
    use sysid_core::{Channel, Experiment};

    /// A small nonlinear record: `y(k) = 0.6 y(k−1) − 0.1 y(k−2) + tanh(u(k−1)) + 0.1 u(k−2)²`.
    fn record(n: usize) -> Dataset {
        let u: Vec<f64> = (0..n)
            .map(|k| (0.31 * k as f64).sin() + 0.5 * (0.057 * k as f64).cos())
            .collect();
        let mut y = vec![0.0; n];
        for k in 2..n {
            y[k] = 0.6 * y[k - 1] - 0.1 * y[k - 2] + u[k - 1].tanh() + 0.1 * u[k - 2].powi(2);
        }
        let e = Experiment::new(
            0.0,
            1.0,
            DMatrix::from_row_slice(1, n, &u),
            DMatrix::from_row_slice(1, n, &y),
        )
        .unwrap();
        Dataset::new(vec![Channel::new("u")], vec![Channel::new("y")], vec![e]).unwrap()
    }

    /// The Jacobian of the free-run residuals, chained through the fed-back lags and the
    /// projection, against central differences of the residuals themselves.
    #[test]
    fn sensitivities_match_central_differences_of_the_free_run() {
        let data = record(120);
        for projection in [Projection::None, Projection::Pca { rtol: 1e-3 }] {
            let config = NarxConfig {
                orders: NarxOrders {
                    na: 3,
                    nb: 2,
                    nk: 1,
                },
                network: NetworkChoice::Hidden {
                    units: 3,
                    restarts: 1,
                },
                projection,
                ..NarxConfig::default()
            };
            let model = fit_narx(&data, &config).unwrap().model;
            let dz = lag_jacobian(&model);
            let problem = NetSimulationError {
                model: &model,
                data: &data,
                weight: vec![1.0],
                dz,
            };
            let theta = model.network().weights().to_vec();
            let (r0, j) = problem.run(&theta, true).unwrap().unwrap();
            let j = j.unwrap();
            assert_eq!(j.nrows(), r0.len());
            let h = 1e-6;
            for i in 0..theta.len() {
                let at = |d: f64| {
                    let mut t = theta.clone();
                    t[i] += d;
                    problem.run(&t, false).unwrap().unwrap().0
                };
                let fd = (at(h) - at(-h)) / (2.0 * h);
                for k in 0..r0.len() {
                    let tol = 1e-6 * (1.0 + fd[k].abs());
                    assert!(
                        (j[(k, i)] - fd[k]).abs() <= tol,
                        "{projection:?} weight {i} row {k}: {} vs {}",
                        j[(k, i)],
                        fd[k]
                    );
                }
            }
        }
    }
}
