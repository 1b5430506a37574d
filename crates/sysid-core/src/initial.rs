//! Initial-state estimation for free-run simulation: the `x0` whose free response best
//! fits the measured outputs over a window (as MATLAB's `compare` with an estimated
//! initial condition). The workspace's Levenberg–Marquardt on the `n` entries of `x0`
//! with a finite-difference sensitivity of the simulated outputs.

use nalgebra::DMatrix;

use crate::dataset::Experiment;
use crate::dynamics::Dynamics;
use crate::error::{CoreError, Result};
use crate::integrate::{Integrator, simulate_experiment};
use crate::least_squares::{
    LeastSquaresProblem, LmSettings, forward_difference, levenberg_marquardt,
};

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

/// The free-response fit as a least-squares problem in `x0`.
struct FreeResponse<'a, D: ?Sized> {
    f: &'a D,
    c: &'a DMatrix<f64>,
    exp: &'a Experiment,
    opt: &'a InitialStateFit,
    /// Measured (non-missing) values in the window.
    count: usize,
}

impl<D: Dynamics + ?Sized> FreeResponse<'_, D> {
    /// `ỹ − C x(t_k; x0)` over the window, missing samples skipped.
    fn residuals_into(&self, x0: &[f64], r: &mut [f64]) -> Result<()> {
        let len = self.opt.window.min(self.exp.len());
        let xs = simulate_experiment(
            self.f,
            x0,
            self.exp,
            0..len,
            &self.opt.integrator,
            self.opt.blow_up,
        )?;
        let ys = self.c * xs;
        let mut at = 0;
        for k in 0..len {
            for (i, y) in self.exp.output(k).iter().enumerate() {
                if !y.is_nan() {
                    r[at] = y - ys[(i, k)];
                    at += 1;
                }
            }
        }
        Ok(())
    }
}

impl<D: Dynamics + ?Sized> LeastSquaresProblem for FreeResponse<'_, D> {
    type Error = CoreError;

    fn residual_count(&self) -> usize {
        self.count
    }

    fn residuals(&mut self, x0: &[f64], r: &mut [f64]) -> Result<bool> {
        match self.residuals_into(x0, r) {
            Ok(()) => Ok(true),
            Err(CoreError::Diverged { .. }) => Ok(false),
            Err(e) => Err(e),
        }
    }

    /// Forward differences, step `√ε·max(1, |x_j|)`.
    fn jacobian(&mut self, x0: &[f64], r: &[f64], jac: &mut DMatrix<f64>) -> Result<()> {
        forward_difference(
            |x, out| self.residuals_into(x, out).map(|()| true),
            x0,
            r,
            (f64::EPSILON.sqrt(), 1.0),
            jac,
        )
    }
}

/// The initial state minimising `Σ_k ‖ỹ_k − C x(t_k; x0)‖²` over the first `window`
/// samples (missing samples skipped), started from `guess`, by the workspace's
/// Levenberg–Marquardt ([`crate::least_squares`]; relative cost decrease `1e-12`). A
/// diverging trial simulation is treated as a rejected step; a diverging start (or a
/// diverging perturbed simulation of the Jacobian) is an error.
pub fn fit_initial_state<D: Dynamics + ?Sized>(
    f: &D,
    c: &DMatrix<f64>,
    exp: &Experiment,
    guess: &[f64],
    opt: &InitialStateFit,
) -> Result<Vec<f64>> {
    let n = f.n_states();
    CoreError::check_len("initial-state guess", guess.len(), n)?;
    if c.ncols() != n || c.nrows() != exp.n_outputs() {
        return Err(CoreError::Shape {
            matrix: "C",
            rows: c.nrows(),
            cols: c.ncols(),
            expected_rows: exp.n_outputs(),
            expected_cols: n,
        });
    }
    let len = opt.window.min(exp.len());
    let count = (0..len)
        .map(|k| exp.output(k).iter().filter(|v| !v.is_nan()).count())
        .sum();
    let mut problem = FreeResponse {
        f,
        c,
        exp,
        opt,
        count,
    };
    // A diverging start is an error naming where it diverged.
    problem.residuals_into(guess, &mut vec![0.0; count])?;
    let settings = LmSettings {
        max_iterations: opt.max_iterations,
        ftol: 1e-12,
        ..LmSettings::default()
    };
    Ok(levenberg_marquardt(&mut problem, guess, &settings)?.theta)
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
