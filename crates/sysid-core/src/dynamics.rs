//! The `Dynamics` trait (a continuous-time right-hand side `ẋ = f(t, x, u)`), the
//! `Correction` trait (a learned or named model-error term `d = g(x, u)`), and the
//! `Model` trait separating free-run simulation from k-step prediction.

use nalgebra::DMatrix;

use crate::dataset::Experiment;

/// A continuous-time system `ẋ = f(t, x, u)`.
///
/// Slices keep the hot path allocation-free; implementors write into `dx`.
pub trait Dynamics: Send + Sync {
    /// Number of states `n`.
    fn n_states(&self) -> usize;
    /// Number of inputs `m`.
    fn n_inputs(&self) -> usize;
    /// Evaluate `dx = f(t, x, u)`. `x.len() == n`, `u.len() == m`, `dx.len() == n`.
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]);

    /// Jacobians `∂f/∂x` (`n × n`) and `∂f/∂u` (`n × m`) at `(t, x, u)`, written into `a`
    /// and `b` (already sized). The default uses central differences with step
    /// `ε^(1/3)·max(1, |x_i|)` (truncation and round-off errors balanced, error ~ε^(2/3));
    /// override with the analytic form when it is known.
    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        let n = self.n_states();
        let m = self.n_inputs();
        let mut xp = x.to_vec();
        let mut up = u.to_vec();
        let mut fp = vec![0.0; n];
        let mut fm = vec![0.0; n];
        let eps = f64::EPSILON.cbrt();
        for j in 0..n {
            let h = eps * x[j].abs().max(1.0);
            xp[j] = x[j] + h;
            self.rhs(t, &xp, u, &mut fp);
            xp[j] = x[j] - h;
            self.rhs(t, &xp, u, &mut fm);
            xp[j] = x[j];
            for i in 0..n {
                a[(i, j)] = (fp[i] - fm[i]) / (2.0 * h);
            }
        }
        for j in 0..m {
            let h = eps * u[j].abs().max(1.0);
            up[j] = u[j] + h;
            self.rhs(t, x, &up, &mut fp);
            up[j] = u[j] - h;
            self.rhs(t, x, &up, &mut fm);
            up[j] = u[j];
            for i in 0..n {
                b[(i, j)] = (fp[i] - fm[i]) / (2.0 * h);
            }
        }
    }
}

impl<D: Dynamics + ?Sized> Dynamics for &D {
    fn n_states(&self) -> usize {
        (**self).n_states()
    }
    fn n_inputs(&self) -> usize {
        (**self).n_inputs()
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        (**self).rhs(t, x, u, dx)
    }
    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        (**self).jacobians(t, x, u, a, b)
    }
}

impl<D: Dynamics + ?Sized> Dynamics for Box<D> {
    fn n_states(&self) -> usize {
        (**self).n_states()
    }
    fn n_inputs(&self) -> usize {
        (**self).n_inputs()
    }
    fn rhs(&self, t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        (**self).rhs(t, x, u, dx)
    }
    fn jacobians(&self, t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        (**self).jacobians(t, x, u, a, b)
    }
}

/// A model-error term `d = g(x, u)` with `q` components (a network trained on MME's `d̂`,
/// or a sum of named physical effects). It enters a model as `ẋ = f(x, u) + E·g(x, u)`.
pub trait Correction: Send + Sync {
    /// Number of states it reads.
    fn n_states(&self) -> usize;
    /// Number of inputs it reads.
    fn n_inputs(&self) -> usize;
    /// Number of correction components `q`.
    fn n_outputs(&self) -> usize;
    /// Evaluate `d = g(x, u)` into `d` (`q` long).
    fn eval(&self, x: &[f64], u: &[f64], d: &mut [f64]);
}

/// Whether a prediction was made by free-run simulation (inputs only after the initial
/// condition) or by k-step-ahead prediction (measured outputs used up to `k` steps back).
///
/// Every number a report prints carries one of these, so free-run and k-step results
/// cannot be mixed silently.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Horizon {
    /// Free-run simulation.
    FreeRun,
    /// k-step-ahead prediction.
    Steps(usize),
}

impl std::fmt::Display for Horizon {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Horizon::FreeRun => write!(f, "free-run simulation"),
            Horizon::Steps(k) => write!(f, "{k}-step prediction"),
        }
    }
}

/// Predicted outputs of a model on one experiment.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    /// How the prediction was made.
    pub horizon: Horizon,
    /// Predicted outputs, `p × N` (same sample grid as the experiment).
    pub outputs: DMatrix<f64>,
    /// Samples at the start that the model consumed to initialise itself (e.g. a NARX
    /// model's delay window); metrics should skip them.
    pub initial_samples: usize,
}

/// An identified or assumed model that can be judged on data.
pub trait Model {
    /// Error type of the model's family.
    type Error: std::error::Error + Send + Sync + 'static;
    /// Names of the outputs it predicts, matching dataset output channels.
    fn output_names(&self) -> Vec<String>;
    /// Free-run simulation over the experiment's inputs.
    fn simulate(&self, experiment: &Experiment) -> Result<Prediction, Self::Error>;
    /// k-step-ahead prediction using the experiment's measured outputs.
    fn predict(&self, experiment: &Experiment, k: usize) -> Result<Prediction, Self::Error>;
}
