//! A mass–spring–damper with switchable hidden effects — the test bench of the discovery
//! workflow. The assumed model is always the linear oscillator `m ẍ + c ẋ + k x = u`; the
//! truth adds any of: cubic stiffness (hardening `k3 > 0` or softening `k3 < 0`),
//! quadratic drag `cq·v|v|`, Coulomb friction `fc·tanh(v/eps)`, and a one-sided contact
//! spring `kc·max(0, x − gap)` (an effect no catalogue of smooth named terms holds), and
//! an actuator that saturates at `u_max` or has a dead zone of half-width `u_dead`.
//! With every hidden parameter at its default 0 the assumed model is the truth.

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use sysid_core::{Dynamics, LinearModel};

use crate::error::{PlantError, Result};
use crate::params::{ParamInfo, Parameters, non_negative, param_table, positive};
use crate::signals::{Excitation, Multisine};
use crate::system::Recipe;
use crate::system::{RecipeSpec, TruthSystem, selection_model, unit_map};

/// Registry name.
pub const NAME: &str = "oscillator";

/// Parameters of [`Oscillator`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OscillatorParams {
    /// Mass, kg.
    pub m: f64,
    /// Viscous damping (known), N·s/m.
    pub c: f64,
    /// Linear stiffness (known), N/m.
    pub k: f64,
    /// Hidden cubic stiffness, N/m³ (negative: softening).
    pub k3: f64,
    /// Hidden quadratic drag, N·s²/m².
    pub cq: f64,
    /// Hidden Coulomb friction level, N.
    pub fc: f64,
    /// Velocity scale of the Coulomb friction's tanh, m/s.
    pub eps: f64,
    /// Hidden one-sided contact stiffness, N/m.
    pub kc: f64,
    /// Gap before the contact spring engages, m.
    pub gap: f64,
    /// Actuator limit: the force applied is `u` clipped to `±u_max`, N (0: no limit).
    pub u_max: f64,
    /// Actuator dead zone: no force for `|u| ≤ u_dead`, `u ∓ u_dead` beyond, N (0: none).
    pub u_dead: f64,
}

impl Default for OscillatorParams {
    /// `m = 1`, `c = 0.2`, `k = 4` (natural frequency 2 rad/s, damping ratio 0.05), no
    /// hidden effect, `eps = 0.001`, `gap = 0.3`, `u_max = u_dead = 0` (an ideal actuator).
    fn default() -> Self {
        Self {
            m: 1.0,
            c: 0.2,
            k: 4.0,
            k3: 0.0,
            cq: 0.0,
            fc: 0.0,
            eps: 0.001,
            kc: 0.0,
            gap: 0.3,
            u_max: 0.0,
            u_dead: 0.0,
        }
    }
}

param_table!(
    OscillatorParams,
    NAME,
    [
        (m, "kg"),
        (c, "N*s/m"),
        (k, "N/m"),
        (k3, "N/m^3"),
        (cq, "N*s^2/m^2"),
        (fc, "N"),
        (eps, "m/s"),
        (kc, "N/m"),
        (gap, "m"),
        (u_max, "N"),
        (u_dead, "N")
    ]
);

/// Truth: `ẋ = v`, `m v̇ = sat(u) − c v − k x − k3 x³ − cq v|v| − fc tanh(v/eps) −
/// kc max(0, x − gap)` with `sat(u)` the actuator's force: `u` with a dead zone of
/// half-width `u_dead` removed, then clipped to `±u_max` (either off at 0); state
/// `[x, v]`. Assumed model: the linear part; `x` measured, `v`
/// corrected.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Oscillator {
    params: OscillatorParams,
}

impl Oscillator {
    /// Build from parameters: `m`, `k`, `eps` positive; `c`, `cq`, `fc`, `kc`, `gap`,
    /// `u_max`, `u_dead` non-negative (and `u_dead < u_max` when both are set); `k3` finite, and if negative soft enough only that the spring's
    /// tangent stiffness stays positive up to |x| = 1.5 m (`k + 3·k3·1.5² > 0`).
    pub fn new(params: OscillatorParams) -> Result<Self> {
        positive(NAME, "m", params.m)?;
        positive(NAME, "k", params.k)?;
        positive(NAME, "eps", params.eps)?;
        for (name, v) in [
            ("c", params.c),
            ("cq", params.cq),
            ("fc", params.fc),
            ("kc", params.kc),
            ("gap", params.gap),
            ("u_max", params.u_max),
            ("u_dead", params.u_dead),
        ] {
            non_negative(NAME, name, v)?;
        }
        if params.u_max > 0.0 && params.u_dead >= params.u_max {
            return Err(PlantError::InvalidParameter {
                system: NAME,
                name: "u_dead".into(),
                value: params.u_dead,
                reason: "must be below u_max when both are set",
            });
        }
        if !params.k3.is_finite() || params.k + 3.0 * params.k3 * 2.25 <= 0.0 {
            return Err(PlantError::InvalidParameter {
                system: NAME,
                name: "k3".into(),
                value: params.k3,
                reason: "must be finite, and k + 3·k3·1.5² > 0 (the spring stays stable)",
            });
        }
        Ok(Self { params })
    }

    /// The parameters.
    pub fn params(&self) -> &OscillatorParams {
        &self.params
    }

    /// The force the actuator does not deliver: `u − sat(u)`, N.
    fn clipped(&self, u: f64) -> f64 {
        let (l, w) = (self.params.u_max, self.params.u_dead);
        let after_dead = u.signum() * (u.abs() - w).max(0.0);
        let applied = if l > 0.0 {
            after_dead.clamp(-l, l)
        } else {
            after_dead
        };
        u - applied
    }

    /// The hidden force on the mass (N), truth minus assumed model, times `1/m`.
    fn hidden(&self, x: f64, v: f64, u: f64) -> f64 {
        let p = &self.params;
        -(p.k3 * x * x * x
            + p.cq * v * v.abs()
            + p.fc * (v / p.eps).tanh()
            + p.kc * (x - p.gap).max(0.0)
            + self.clipped(u))
            / p.m
    }
}

impl Dynamics for Oscillator {
    fn n_states(&self) -> usize {
        2
    }
    fn n_inputs(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let p = &self.params;
        dx[0] = x[1];
        dx[1] = (u[0] - p.c * x[1] - p.k * x[0]) / p.m + self.hidden(x[0], x[1], u[0]);
    }
    fn jacobians(&self, _t: f64, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        let p = &self.params;
        let contact = if x[0] > p.gap { p.kc } else { 0.0 };
        let sech2 = 1.0 - (x[1] / p.eps).tanh().powi(2);
        a[(0, 0)] = 0.0;
        a[(0, 1)] = 1.0;
        a[(1, 0)] = -(p.k + 3.0 * p.k3 * x[0] * x[0] + contact) / p.m;
        a[(1, 1)] = -(p.c + 2.0 * p.cq * x[1].abs() + p.fc * sech2 / p.eps) / p.m;
        b[(0, 0)] = 0.0;
        let after_dead = u[0].abs() - p.u_dead;
        let limited = p.u_max > 0.0 && after_dead > p.u_max;
        let dead = after_dead <= 0.0 && p.u_dead > 0.0;
        b[(1, 0)] = if limited || dead { 0.0 } else { 1.0 / p.m };
    }
}

impl TruthSystem for Oscillator {
    fn name(&self) -> &'static str {
        NAME
    }
    fn description(&self) -> &'static str {
        "mass-spring-damper with switchable hidden effects: m x'' + c x' + k x = u - k3 x^3 \
         - cq x'|x'| - fc tanh(x'/eps) - kc max(0, x - gap), actuator dead zone u_dead and limit u_max; assumed model linear; x measured \
         (discovery test bench; all hidden effects 0 by default)"
    }
    fn parameters(&self) -> Vec<ParamInfo> {
        self.params.list()
    }
    /// 50 Hz.
    fn default_fs(&self) -> f64 {
        50.0
    }
    /// 1e-4 m² on `x` (σ = 1 cm, about 2 % of the response's RMS).
    fn default_noise_variance(&self) -> Vec<f64> {
        vec![1e-4]
    }
    fn assumed_model(&self) -> Result<LinearModel> {
        let p = &self.params;
        let a = DMatrix::from_row_slice(2, 2, &[0.0, 1.0, -p.k / p.m, -p.c / p.m]);
        let b = DMatrix::from_row_slice(2, 1, &[0.0, 1.0 / p.m]);
        selection_model(a, b, &["x", "v"], &["u"], &["x"], &["v"])
    }
    fn truth_correction(&self, x: &[f64], u: &[f64], d: &mut [f64]) {
        d[0] = self.hidden(x[0], x[1], u[0]);
    }
    fn units(&self) -> BTreeMap<String, String> {
        unit_map(&[("x", "m", "m/s"), ("v", "m/s", "m/s^2")], &[("u", "N")])
    }
    /// Train: at rest, multisine force (RMS 0.75 N, 0.05–0.6 Hz, 12 lines, phase seed 11),
    /// 60 s. Test: from `x = 0.3`, multisine (RMS 0.6 N, 0.1–0.5 Hz, 9 lines, seed 23), 40 s.
    fn recipe(&self, recipe: Recipe) -> RecipeSpec {
        let (x0, rms, f_min, f_max, lines, seed, duration) = match recipe {
            Recipe::Train => (vec![0.0, 0.0], 0.75, 0.05, 0.6, 12, 11, 60.0),
            Recipe::Test => (vec![0.3, 0.0], 0.6, 0.1, 0.5, 9, 23, 40.0),
        };
        RecipeSpec {
            x0,
            inputs: vec![Excitation::Multisine(Multisine {
                rms,
                f_min,
                f_max,
                lines,
                seed,
                offset: 0.0,
            })],
            duration,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::check_jacobians;

    #[test]
    fn analytic_jacobians_match_differences() {
        let p = OscillatorParams {
            k3: 1.0,
            cq: 0.3,
            fc: 0.2,
            eps: 0.5,
            kc: 10.0,
            ..OscillatorParams::default()
        };
        check_jacobians(
            &Oscillator::new(p).unwrap(),
            &[(-1.0, 1.0), (-2.0, 2.0)],
            (-2.0, 2.0),
            7,
        );
    }

    /// With no hidden effect the truth is the assumed model: identical right-hand sides.
    #[test]
    fn default_truth_is_the_assumed_model() {
        let o = Oscillator::default();
        let lin = o.assumed_model().unwrap();
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        for &(x, v, u) in &[(0.3, -1.0, 2.0), (-1.2, 0.4, -1.0)] {
            o.rhs(0.0, &[x, v], &[u], &mut a);
            lin.rhs(0.0, &[x, v], &[u], &mut b);
            assert!((a[0] - b[0]).abs() < 1e-15 && (a[1] - b[1]).abs() < 1e-15);
        }
    }

    /// An actuator limit clips the force: beyond `u_max` the response is that of
    /// `±u_max`, below it that of the linear model; the truth correction is the clipped
    /// part `−(u − sat(u))/m`.
    #[test]
    fn actuator_limit_clips_the_force() {
        let o = Oscillator::new(OscillatorParams {
            u_max: 1.0,
            m: 2.0,
            ..OscillatorParams::default()
        })
        .unwrap();
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        o.rhs(0.0, &[0.1, 0.2], &[2.5], &mut a);
        o.rhs(0.0, &[0.1, 0.2], &[1.0], &mut b);
        assert!((a[1] - b[1]).abs() < 1e-15);
        o.rhs(0.0, &[0.1, 0.2], &[-0.5], &mut a);
        let lin = o.assumed_model().unwrap();
        lin.rhs(0.0, &[0.1, 0.2], &[-0.5], &mut b);
        assert!((a[1] - b[1]).abs() < 1e-15);
        let mut d = [0.0];
        o.truth_correction(&[0.1, 0.2], &[-3.0], &mut d);
        assert!((d[0] - 1.0).abs() < 1e-15, "{}", d[0]);
    }

    /// A dead zone removes `u_dead` from the force's magnitude: inside it the force is
    /// zero, beyond it `u ∓ u_dead`.
    #[test]
    fn actuator_dead_zone_removes_small_forces() {
        let o = Oscillator::new(OscillatorParams {
            u_dead: 0.3,
            ..OscillatorParams::default()
        })
        .unwrap();
        let mut d = [0.0];
        for (u, applied) in [(0.2, 0.0), (-0.25, 0.0), (1.0, 0.7), (-2.0, -1.7)] {
            o.truth_correction(&[0.0, 0.0], &[u], &mut d);
            assert!((d[0] - (applied - u)).abs() < 1e-15, "u = {u}: {}", d[0]);
        }
        assert!(
            Oscillator::new(OscillatorParams {
                u_dead: 1.0,
                u_max: 0.5,
                ..OscillatorParams::default()
            })
            .is_err()
        );
    }

    #[test]
    fn unstable_softening_is_refused() {
        let p = OscillatorParams {
            k3: -1.0,
            ..OscillatorParams::default()
        };
        assert!(Oscillator::new(p).is_err());
    }
}
