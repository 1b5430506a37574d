//! Initial-state estimation for free-run simulation: the `x0` whose free response best
//! fits the measured outputs over a window (as MATLAB's `compare` with an estimated
//! initial condition). Levenberg–Marquardt on the `n` entries of `x0` with a
//! finite-difference sensitivity of the simulated outputs.

use nalgebra::{DMatrix, DVector};

use crate::dataset::Experiment;
use crate::dynamics::Dynamics;
use crate::error::{CoreError, Result};
use crate::integrate::{Integrator, simulate_with};

/// Settings of [`fit_initial_state`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialStateFit {
    /// Samples from the start of the experiment used in the fit (clipped to its length).
    pub window: usize,
    /// Most Levenberg–Marquardt iterations.
    pub max_iterations: usize,
    /// Integrator for the free response.
    pub integrator: Integrator,
    /// Blow-up bound of the simulation.
    pub blow_up: f64,
}

impl Default for InitialStateFit {
    fn default() -> Self {
        Self {
            window: 200,
            max_iterations: 30,
            integrator: Integrator::Rk4 { substeps: 4 },
            blow_up: 1e12,
        }
    }
}

fn residuals<D: Dynamics + ?Sized>(
    f: &D,
    c: &DMatrix<f64>,
    exp: &Experiment,
    x0: &[f64],
    opt: &InitialStateFit,
) -> Result<DVector<f64>> {
    let len = opt.window.min(exp.len());
    let u = exp.inputs().columns(0, len).into_owned();
    let xs = simulate_with(
        f,
        x0,
        exp.t0(),
        exp.dt(),
        &u,
        exp.intersample(),
        &opt.integrator,
        opt.blow_up,
    )?;
    let ys = c * xs;
    let p = c.nrows();
    let mut r = Vec::with_capacity(p * len);
    for k in 0..len {
        let y = exp.output(k);
        for i in 0..p {
            if !y[i].is_nan() {
                r.push(y[i] - ys[(i, k)]);
            }
        }
    }
    Ok(DVector::from_vec(r))
}

/// The initial state minimising `Σ_k ‖ỹ_k − C x(t_k; x0)‖²` over the first `window`
/// samples (missing samples skipped), started from `guess`. A diverging trial simulation
/// is treated as a rejected step; a diverging start is an error.
pub fn fit_initial_state<D: Dynamics + ?Sized>(
    f: &D,
    c: &DMatrix<f64>,
    exp: &Experiment,
    guess: &[f64],
    opt: &InitialStateFit,
) -> Result<Vec<f64>> {
    let n = f.n_states();
    if guess.len() != n {
        return Err(CoreError::Length {
            what: "initial-state guess",
            found: guess.len(),
            expected: n,
        });
    }
    if c.ncols() != n || c.nrows() != exp.n_outputs() {
        return Err(CoreError::Shape {
            matrix: "C",
            rows: c.nrows(),
            cols: c.ncols(),
            expected_rows: exp.n_outputs(),
            expected_cols: n,
        });
    }
    let mut x = guess.to_vec();
    let mut r = residuals(f, c, exp, &x, opt)?;
    let mut cost = r.norm_squared();
    let mut mu = 1e-3;
    for _ in 0..opt.max_iterations {
        // Forward-difference sensitivity, step ~√ε·max(1,|x_j|).
        let mut jac = DMatrix::zeros(r.len(), n);
        for j in 0..n {
            let h = f64::EPSILON.sqrt() * x[j].abs().max(1.0);
            let mut xp = x.clone();
            xp[j] += h;
            let rp = residuals(f, c, exp, &xp, opt)?;
            // r = y − ŷ, so ∂r/∂x = −∂ŷ/∂x.
            jac.set_column(j, &((&rp - &r) / h));
        }
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * &r;
        let mut improved = false;
        for _ in 0..12 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[(i, i)] += mu * jtj[(i, i)].max(1e-12);
            }
            let Some(step) = a.cholesky().map(|ch| ch.solve(&g)) else {
                mu *= 10.0;
                continue;
            };
            let trial: Vec<f64> = x.iter().zip(step.iter()).map(|(xi, s)| xi - s).collect();
            match residuals(f, c, exp, &trial, opt) {
                Ok(rt) if rt.norm_squared() < cost => {
                    let rel = (cost - rt.norm_squared()) / cost.max(f64::MIN_POSITIVE);
                    x = trial;
                    r = rt;
                    cost = r.norm_squared();
                    mu = (mu / 10.0).max(1e-12);
                    improved = rel > 1e-12;
                    break;
                }
                _ => mu *= 10.0,
            }
        }
        if !improved {
            break;
        }
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LinearModel;
    use crate::integrate::simulate;

    #[test]
    fn recovers_the_unmeasured_velocity_of_an_oscillator() {
        // ẍ = −4x − 0.2ẋ + u, position measured: x0 = (0.7, −1.3) must be recovered
        // from noise-free position samples starting from zero.
        let model = LinearModel::new(
            DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -4.0, -0.2]),
            DMatrix::from_row_slice(2, 1, &[0.0, 1.0]),
            DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
            DMatrix::zeros(2, 0),
        )
        .unwrap();
        let u = DMatrix::from_fn(1, 300, |_, k| (0.05 * k as f64).sin());
        let xs = simulate(
            &model,
            &[0.7, -1.3],
            0.0,
            0.01,
            &u,
            &Integrator::Rk4 { substeps: 4 },
            1e12,
        )
        .unwrap();
        let exp = Experiment::new(0.0, 0.01, u, model.c() * xs).unwrap();
        let x0 = fit_initial_state(
            &model,
            model.c(),
            &exp,
            &[0.0, 0.0],
            &InitialStateFit::default(),
        )
        .unwrap();
        assert!(
            (x0[0] - 0.7).abs() < 1e-7 && (x0[1] + 1.3).abs() < 1e-6,
            "{x0:?}"
        );
    }
}
