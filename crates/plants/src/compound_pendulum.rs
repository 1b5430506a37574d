//! Compound pendulum (a solid uniform rod) driven by pivot acceleration, with viscous
//! pivot damping and smoothed Coulomb pivot friction: the simulated stand-in for the
//! thesis's §4.2 hardware rig. Assumed model: the linearised rod without Coulomb friction.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use sysid_core::{Dynamics, LinearModel};

use crate::error::Result;
use crate::params::{ParamInfo, Parameters, non_negative, param_table, positive};
use crate::signals::{Chirp, Excitation, Multisine, Sweep};
use crate::system::Recipe;
use crate::system::{RecipeSpec, TruthSystem, selection_model, unit_map};

/// Registry name.
pub const NAME: &str = "compound_pendulum";

/// Physical parameters of [`CompoundPendulum`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CompoundPendulumParams {
    /// Rod length, m (pivot at one end; centre of mass at `l/2`).
    pub l: f64,
    /// Rod mass, kg (uniform; inertia about the pivot `m l²/3`).
    pub m: f64,
    /// Viscous pivot damping, N·m·s/rad.
    pub b: f64,
    /// Coulomb pivot friction torque, N·m.
    pub tau_c: f64,
    /// Velocity scale of the smoothed friction `tau_c·tanh(ω/eps)`, rad/s.
    pub eps: f64,
    /// Gravitational acceleration, m/s².
    pub g: f64,
}

impl Default for CompoundPendulumParams {
    /// A bench-top rod: l = 0.4 m, m = 0.25 kg (I = 0.0133 kg·m², natural frequency
    /// √(3g/2l) = 6.07 rad/s), b = 2e-3 N·m·s/rad (damping ratio 0.012),
    /// tau_c = 5e-3 N·m (1 % of the largest gravity torque m g l/2; it removes about
    /// 2·tau_c/(m g l/2) = 0.02 rad of amplitude per half swing), eps = 1e-3 rad/s.
    fn default() -> Self {
        Self {
            l: 0.4,
            m: 0.25,
            b: 2e-3,
            tau_c: 5e-3,
            eps: 1e-3,
            g: 9.81,
        }
    }
}

param_table!(
    CompoundPendulumParams,
    NAME,
    [
        (l, "m"),
        (m, "kg"),
        (b, "N*m*s/rad"),
        (tau_c, "N*m"),
        (eps, "rad/s"),
        (g, "m/s^2")
    ]
);

/// Truth: with `I = m l²/3` about the pivot,
/// `I ω̇ = −m g (l/2) sin θ − m (l/2) cos θ · u − b ω − tau_c·tanh(ω/eps)`, `θ̇ = ω`.
///
/// Coulomb friction `tau_c·sign(ω)` is integrated in the smooth-but-steep form
/// `tau_c·tanh(ω/eps)` (eps = 1e-3 rad/s by default): above ~3·eps it is Coulomb friction
/// to 0.5 %, and near rest it acts as a stiff viscous term of slope `tau_c/(I·eps)`
/// (≈ 375 s⁻¹ by default), which the adaptive integrator resolves with small steps. It
/// does not model true sticking (a rod held by static friction creeps at ω ~ eps).
///
/// Assumed model: the linearised rod without Coulomb friction (viscous damping kept, as
/// in the point-mass pendulum's eq. 4.12): `ω̇ = −(3g/2l) θ − (3b/(m l²)) ω − (3/2l) u`;
/// angle measured, `omega` corrected. Truth correction
/// `d = (3g/2l)(θ − sin θ) + (3/2l)(1 − cos θ) u − (3 tau_c/(m l²)) tanh(ω/eps)`.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CompoundPendulum {
    params: CompoundPendulumParams,
}

impl CompoundPendulum {
    /// Build from parameters: `l`, `m`, `eps`, `g` positive, `b`, `tau_c` non-negative.
    pub fn new(params: CompoundPendulumParams) -> Result<Self> {
        positive(NAME, "l", params.l)?;
        positive(NAME, "m", params.m)?;
        non_negative(NAME, "b", params.b)?;
        non_negative(NAME, "tau_c", params.tau_c)?;
        positive(NAME, "eps", params.eps)?;
        positive(NAME, "g", params.g)?;
        Ok(Self { params })
    }

    /// The parameters.
    pub fn params(&self) -> &CompoundPendulumParams {
        &self.params
    }

    /// Moment of inertia about the pivot, `m l²/3`, kg·m².
    pub fn inertia(&self) -> f64 {
        self.params.m * self.params.l * self.params.l / 3.0
    }

    /// `(gravity, input, viscous, friction)` coefficients of `ω̇`:
    /// `3g/2l`, `3/2l`, `b/I`, `tau_c/I`.
    fn coefficients(&self) -> (f64, f64, f64, f64) {
        let CompoundPendulumParams { l, b, tau_c, g, .. } = self.params;
        let i = self.inertia();
        (1.5 * g / l, 1.5 / l, b / i, tau_c / i)
    }
}

impl Dynamics for CompoundPendulum {
    fn n_states(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let (kg, ku, kb, kc) = self.coefficients();
        dx[0] = x[1];
        dx[1] = -kg * x[0].sin()
            - ku * x[0].cos() * u[0]
            - kb * x[1]
            - kc * (x[1] / self.params.eps).tanh();
    }
    fn jacobians(&self, _t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        let (kg, ku, kb, kc) = self.coefficients();
        let eps = self.params.eps;
        let th = (x[1] / eps).tanh();
        a[(0, 0)] = 0.0;
        a[(0, 1)] = 1.0;
        a[(1, 0)] = -kg * x[0].cos() + ku * x[0].sin() * u[0];
        a[(1, 1)] = -kb - kc * (1.0 - th * th) / eps;
        b[(0, 0)] = 0.0;
        b[(1, 0)] = -ku * x[0].cos();
    }
}

impl TruthSystem for CompoundPendulum {
    fn name(&self) -> &'static str {
        NAME
    }
    fn description(&self) -> &'static str {
        "compound (rod) pendulum, pivot acceleration input, viscous + Coulomb pivot friction \
         (tanh-smoothed), sensor noise; stand-in for the thesis 4.2 rig"
    }
    fn parameters(&self) -> Vec<ParamInfo> {
        self.params.list()
    }
    /// 200 Hz (the rig's rate printed as "2 Hz" with digits lost; 200 Hz assumed).
    fn default_fs(&self) -> f64 {
        200.0
    }
    /// 1e-5 rad² (σ ≈ 3.2 mrad), an encoder-like angle sensor.
    fn default_noise_variance(&self) -> Vec<f64> {
        vec![1e-5]
    }
    fn assumed_model(&self) -> Result<LinearModel> {
        let (kg, ku, kb, _) = self.coefficients();
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -kg, -kb]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, -ku]);
        selection_model(a, b, &["theta", "omega"], &["u"], &["theta"], &["omega"])
    }
    fn truth_correction(&self, x: &[f64], u: &[f64], d: &mut [f64]) {
        let (kg, ku, _, kc) = self.coefficients();
        d[0] = kg * (x[0] - x[0].sin()) + ku * (1.0 - x[0].cos()) * u[0]
            - kc * (x[1] / self.params.eps).tanh();
    }
    fn units(&self) -> BTreeMap<String, String> {
        unit_map(
            &[("theta", "rad", "rad/s"), ("omega", "rad/s", "rad/s^2")],
            &[("u", "m/s^2")],
        )
    }
    /// Train: `θ(0) = 0.898 rad` (the rig's training start, thesis §4.2), a random-phase
    /// multisine of 1.2 m/s² RMS with 20 lines over 0.1–2 Hz (seed 11), 18 s (the rig's
    /// record length). Test: `θ(0) = 0.3 rad`, a linear chirp of 1.5 m/s² from 0.2 to
    /// 1.8 Hz over 18 s.
    fn recipe(&self, recipe: Recipe) -> RecipeSpec {
        match recipe {
            Recipe::Train => RecipeSpec {
                x0: vec![0.898, 0.0],
                inputs: vec![Excitation::Multisine(Multisine {
                    rms: 1.2,
                    f_min: 0.1,
                    f_max: 2.0,
                    lines: 20,
                    seed: 11,
                    offset: 0.0,
                })],
                duration: 18.0,
            },
            Recipe::Test => RecipeSpec {
                x0: vec![0.3, 0.0],
                inputs: vec![Excitation::Chirp(Chirp {
                    amplitude: 1.5,
                    f0: 0.2,
                    f1: 1.8,
                    duration: 18.0,
                    sweep: Sweep::Linear,
                    offset: 0.0,
                })],
                duration: 18.0,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::check_jacobians;
    use sysid_core::integrate::DEFAULT_BLOW_UP;
    use sysid_core::{DpOptions, Integrator, simulate};

    /// With eps = 0.1 rad/s the tanh corner is smooth on the difference step (1e-5), so the
    /// check can sample velocities right across it.
    #[test]
    fn analytic_jacobians_match_differences() {
        let p = CompoundPendulum::new(CompoundPendulumParams {
            eps: 0.1,
            ..CompoundPendulumParams::default()
        })
        .unwrap();
        check_jacobians(&p, &[(-3.0, 3.0), (-1.0, 1.0)], (-5.0, 5.0), 5);
        check_jacobians(&p, &[(-3.0, 3.0), (-8.0, 8.0)], (-5.0, 5.0), 6);
    }

    /// Free decay with Coulomb friction only (b = 0, u = 0): in the small-angle range each
    /// half swing loses `2·tau_c/(m g l/2)` of amplitude (the classical linear decrement of
    /// a Coulomb-damped oscillator, here with the sin θ nonlinearity kept small by a
    /// 0.2 rad start). Checked on the first four peaks to 3 % of the decrement, which
    /// absorbs the tanh smoothing and the sin θ ≠ θ effect.
    #[test]
    fn coulomb_friction_gives_linear_amplitude_decay() {
        let p = CompoundPendulum::new(CompoundPendulumParams {
            b: 0.0,
            ..CompoundPendulumParams::default()
        })
        .unwrap();
        let opts = DpOptions {
            rtol: 1e-10,
            atol: 1e-12,
            ..DpOptions::default()
        };
        let dt = 1e-3;
        let u = DMatrix::zeros(1, 5001);
        let x = simulate(
            &p,
            &[0.2, 0.0],
            0.0,
            dt,
            &u,
            &Integrator::DormandPrince(opts),
            DEFAULT_BLOW_UP,
        )
        .unwrap();
        let th: Vec<f64> = x.row(0).iter().copied().collect();
        let peaks: Vec<f64> = (1..th.len() - 1)
            .filter(|&k| {
                th[k].abs() >= th[k - 1].abs()
                    && th[k].abs() > th[k + 1].abs()
                    && th[k].abs() > 0.05
            })
            .map(|k| th[k].abs())
            .collect();
        let pp = p.params;
        let dec = 2.0 * pp.tau_c / (pp.m * pp.g * pp.l / 2.0);
        assert!(peaks.len() >= 4, "peaks {peaks:?}");
        let mut prev = 0.2;
        for pk in &peaks[..4] {
            assert!(
                ((prev - pk) - dec).abs() < 0.03 * dec,
                "decrement {} vs {dec}",
                prev - pk
            );
            prev = *pk;
        }
    }
}
