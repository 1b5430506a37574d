//! Forced Van der Pol oscillator `ẍ − μ(1 − x²) ẋ + x = u` (the earlier MME/NN study the
//! thesis's introduction cites) and its linear-oscillator assumed model.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use sysid_core::{Dynamics, LinearModel};

use crate::error::Result;
use crate::params::{ParamInfo, Parameters, non_negative, param_table};
use crate::signals::{Excitation, Sine};
use crate::system::Recipe;
use crate::system::{RecipeSpec, TruthSystem, selection_model, unit_map};

/// Registry name.
pub const NAME: &str = "van_der_pol";

/// Parameters of [`VanDerPol`] (the equation is in dimensionless time scaled by the
/// linear natural frequency, here 1 rad/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VanDerPolParams {
    /// Nonlinear damping strength μ, 1/s (0 gives the undamped linear oscillator).
    pub mu: f64,
}

impl Default for VanDerPolParams {
    /// μ = 1.
    fn default() -> Self {
        Self { mu: 1.0 }
    }
}

param_table!(VanDerPolParams, NAME, [(mu, "1/s")]);

/// Truth: `ẋ = v`, `v̇ = μ(1 − x²) v − x + u`; state `[x, v]`. Assumed model: the linear
/// oscillator `v̇ = −x + u`; `x` measured, `v` corrected; truth correction
/// `d = μ(1 − x²) v`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VanDerPol {
    params: VanDerPolParams,
}

impl VanDerPol {
    /// Build from parameters: `mu` non-negative.
    pub fn new(params: VanDerPolParams) -> Result<Self> {
        non_negative(NAME, "mu", params.mu)?;
        Ok(Self { params })
    }

    /// The parameters.
    pub fn params(&self) -> &VanDerPolParams {
        &self.params
    }
}

impl Dynamics for VanDerPol {
    fn n_states(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let mu = self.params.mu;
        dx[0] = x[1];
        dx[1] = mu * (1.0 - x[0] * x[0]) * x[1] - x[0] + u[0];
    }
    fn jacobians(
        &self,
        _t: f64,
        x: &[f64],
        _u: &[f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) {
        let mu = self.params.mu;
        a[(0, 0)] = 0.0;
        a[(0, 1)] = 1.0;
        a[(1, 0)] = -2.0 * mu * x[0] * x[1] - 1.0;
        a[(1, 1)] = mu * (1.0 - x[0] * x[0]);
        b[(0, 0)] = 0.0;
        b[(1, 0)] = 1.0;
    }
}

impl TruthSystem for VanDerPol {
    fn name(&self) -> &'static str {
        NAME
    }
    fn description(&self) -> &'static str {
        "forced Van der Pol oscillator: x'' - mu (1 - x^2) x' + x = u; x measured"
    }
    fn parameters(&self) -> Vec<ParamInfo> {
        self.params.list()
    }
    /// 20 Hz.
    fn default_fs(&self) -> f64 {
        20.0
    }
    /// 0.01 on `x` (σ = 0.1, 5 % of the limit-cycle amplitude 2).
    fn default_noise_variance(&self) -> Vec<f64> {
        vec![0.01]
    }
    fn assumed_model(&self) -> Result<LinearModel> {
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -1.0, 0.0]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0]);
        selection_model(a, b, &["x", "v"], &["u"], &["x"], &["v"])
    }
    fn truth_correction(&self, x: &[f64], _u: &[f64], d: &mut [f64]) {
        d[0] = self.params.mu * (1.0 - x[0] * x[0]) * x[1];
    }
    fn units(&self) -> BTreeMap<String, String> {
        unit_map(
            &[("x", "1", "1/s"), ("v", "1/s", "1/s^2")],
            &[("u", "1/s^2")],
        )
    }
    /// Train: `[x, v](0) = [1, 0]`, `u = 0.5 sin(1.3 t)`, 30 s. Test: `[−2, 1]`,
    /// `u = 0.8 sin(0.7 t)`, 30 s.
    fn recipe(&self, recipe: Recipe) -> RecipeSpec {
        let (x0, amplitude, omega) = match recipe {
            Recipe::Train => (vec![1.0, 0.0], 0.5, 1.3),
            Recipe::Test => (vec![-2.0, 1.0], 0.8, 0.7),
        };
        RecipeSpec {
            x0,
            inputs: vec![Excitation::Sine(Sine {
                amplitude,
                omega,
                ..Sine::default()
            })],
            duration: 30.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::check_jacobians;
    use sysid_core::integrate::DEFAULT_BLOW_UP;
    use sysid_core::{DpOptions, Integrator, simulate};

    #[test]
    fn analytic_jacobians_match_differences() {
        check_jacobians(
            &VanDerPol::default(),
            &[(-3.0, 3.0), (-5.0, 5.0)],
            (-2.0, 2.0),
            7,
        );
    }

    /// Unforced with small μ the limit cycle is `x ≈ 2 cos t`: by averaging, the
    /// amplitude obeys `ṙ = (μ/2) r (1 − r²/4)`, whose stable fixed point is r = 2 and which
    /// relaxes there with time constant 1/μ (20 s for μ = 0.05). The peak's next correction
    /// is +μ²/96 ≈ 2.6e-5 (perturbation series of the limit cycle), and sampling at 0.01 s
    /// can shave at most ½·|ẍ|·(0.005 s)² ≈ 2.5e-5 off a peak. Started inside (x = 1) and
    /// outside (x = 3), after 370 s (≥ 15 time constants, leaving < 1e-5 of the initial
    /// offset) the peak |x| over the last 30 s is 2 to 1e-4 (2.000026 measured).
    #[test]
    fn unforced_limit_cycle_has_amplitude_two() {
        let p = VanDerPol::new(VanDerPolParams { mu: 0.05 }).unwrap();
        let opts = DpOptions {
            rtol: 1e-10,
            atol: 1e-12,
            ..DpOptions::default()
        };
        let u = DMatrix::zeros(1, 40_001);
        for start in [1.0, 3.0] {
            let x = simulate(
                &p,
                &[start, 0.0],
                0.0,
                0.01,
                &u,
                &Integrator::DormandPrince(opts),
                DEFAULT_BLOW_UP,
            )
            .unwrap();
            let tail = x.row(0).columns(37_000, 3_001).amax();
            assert!((tail - 2.0).abs() < 1e-4, "start {start}: peak {tail}");
        }
    }
}
