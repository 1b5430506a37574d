//! Mass–spring–damper with a cubic (hardening) spring, `m ẍ + c ẋ + k(x + x³) = u`
//! (thesis §2.5, eqs. 2.12–2.16 and §6.2), and its undamped linear assumed model.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use sysid_core::{Dynamics, LinearModel};

use crate::error::Result;
use crate::params::{ParamInfo, Parameters, non_negative, param_table, positive};
use crate::signals::{Excitation, Sine};
use crate::system::Recipe;
use crate::system::{RecipeSpec, TruthSystem, selection_model, unit_map};

/// Registry name.
pub const NAME: &str = "msd_cubic";

/// Damping coefficients (N·s/m) of the thesis's condition-monitoring classes (§6.2).
pub const MSD_DAMPING_CLASSES: [f64; 3] = [0.1, 0.15, 0.2];

/// Physical parameters of [`MsdCubic`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MsdCubicParams {
    /// Mass, kg.
    pub m: f64,
    /// Viscous damping, N·s/m (set from [`MSD_DAMPING_CLASSES`] for condition monitoring).
    pub c: f64,
    /// Spring stiffness, N/m; the restoring force is `k(x + x³)` with `x` in m (the cubic
    /// coefficient is `k` per m²).
    pub k: f64,
}

impl Default for MsdCubicParams {
    /// Thesis values: m = 1 kg, c = 0.1 N·s/m, k = 0.5 N/m.
    fn default() -> Self {
        Self {
            m: 1.0,
            c: 0.1,
            k: 0.5,
        }
    }
}

param_table!(MsdCubicParams, NAME, [(m, "kg"), (c, "N*s/m"), (k, "N/m")]);

/// Truth: `ẋ = v`, `v̇ = (u − c v − k(x + x³))/m`; state `[x, v]`, input `u` (force, N).
///
/// Assumed model (thesis eq. 6.2): `ẋ = v`, `v̇ = −(k/m) x + u/m` (no damping, no cubic
/// term); position measured, velocity equation corrected. Truth correction
/// `d = −(k/m) x³ − (c/m) v` (eq. 6.3).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MsdCubic {
    params: MsdCubicParams,
}

impl MsdCubic {
    /// Build from parameters: `m`, `k` positive, `c` non-negative.
    pub fn new(params: MsdCubicParams) -> Result<Self> {
        positive(NAME, "m", params.m)?;
        non_negative(NAME, "c", params.c)?;
        positive(NAME, "k", params.k)?;
        Ok(Self { params })
    }

    /// The parameters.
    pub fn params(&self) -> &MsdCubicParams {
        &self.params
    }
}

impl Dynamics for MsdCubic {
    fn n_states(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let MsdCubicParams { m, c, k } = self.params;
        dx[0] = x[1];
        dx[1] = (u[0] - c * x[1] - k * (x[0] + x[0].powi(3))) / m;
    }
    fn jacobians(
        &self,
        _t: f64,
        x: &[f64],
        _u: &[f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) {
        let MsdCubicParams { m, c, k } = self.params;
        a[(0, 0)] = 0.0;
        a[(0, 1)] = 1.0;
        a[(1, 0)] = -k * (1.0 + 3.0 * x[0] * x[0]) / m;
        a[(1, 1)] = -c / m;
        b[(0, 0)] = 0.0;
        b[(1, 0)] = 1.0 / m;
    }
}

impl TruthSystem for MsdCubic {
    fn name(&self) -> &'static str {
        NAME
    }
    fn description(&self) -> &'static str {
        "mass-spring-damper with cubic spring: m x'' + c x' + k(x + x^3) = u; position measured \
         (thesis 2.5)"
    }
    fn parameters(&self) -> Vec<ParamInfo> {
        self.params.list()
    }
    /// 100 Hz (period 0.01 s). The thesis's grid "t = 0, .?5, …, 10" lost its digits.
    fn default_fs(&self) -> f64 {
        100.0
    }
    /// 0.09 m² on position: the thesis's "variance of .9" read as 0.09 (digits lost).
    fn default_noise_variance(&self) -> Vec<f64> {
        vec![0.09]
    }
    fn assumed_model(&self) -> Result<LinearModel> {
        let MsdCubicParams { m, k, .. } = self.params;
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -k / m, 0.0]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0 / m]);
        selection_model(a, b, &["x", "v"], &["u"], &["x"], &["v"])
    }
    fn truth_correction(&self, x: &[f64], _u: &[f64], d: &mut [f64]) {
        let MsdCubicParams { m, c, k } = self.params;
        d[0] = -(k / m) * x[0].powi(3) - (c / m) * x[1];
    }
    fn units(&self) -> BTreeMap<String, String> {
        unit_map(&[("x", "m", "m/s"), ("v", "m/s", "m/s^2")], &[("u", "N")])
    }
    /// Train (thesis §2.5): `x(0) = 5 m`, `v(0) = 0`, `u = sin t` N, 10 s.
    /// Test (not in the thesis): `x(0) = −4 m`, `v(0) = 0`, `u = 2 sin(0.6 t)` N, 10 s.
    fn recipe(&self, recipe: Recipe) -> RecipeSpec {
        match recipe {
            Recipe::Train => RecipeSpec {
                x0: vec![5.0, 0.0],
                inputs: vec![Excitation::Sine(Sine::default())],
                duration: 10.0,
            },
            Recipe::Test => RecipeSpec {
                x0: vec![-4.0, 0.0],
                inputs: vec![Excitation::Sine(Sine {
                    amplitude: 2.0,
                    omega: 0.6,
                    ..Sine::default()
                })],
                duration: 10.0,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::check_jacobians;

    #[test]
    fn analytic_jacobians_match_differences() {
        check_jacobians(
            &MsdCubic::default(),
            &[(-6.0, 6.0), (-30.0, 30.0)],
            (-3.0, 3.0),
            11,
        );
    }

    #[test]
    fn invalid_parameters_are_named() {
        let r = MsdCubic::new(MsdCubicParams {
            c: -0.1,
            ..MsdCubicParams::default()
        });
        assert!(
            matches!(r, Err(crate::PlantError::InvalidParameter { ref name, .. }) if name == "c")
        );
    }
}
