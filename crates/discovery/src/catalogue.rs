//! The catalogue of named physical effects: for each, its snake_case name, a label, which
//! variables it reads (by role), which equations it may enter, the term it adds (an
//! [`Expr`] text that the model file stores and re-parses), the smooth variant used for
//! integration where the true function jumps, the unit of the term and how the sign of its
//! coefficient reads.
//!
//! # How a term enters a model
//!
//! A named term adds `c·g(x, u)` to the right-hand side of a corrected state equation `i`,
//! so `unit(c) = unit(ẋ_i) / unit(g)` ([`coefficient_unit`]). Terms are written as the
//! part a linear (or linearised) assumed model *misses*, so that they are identifiable
//! next to the linear terms already in `A` and `B`:
//!
//! | effect | term `g` | coefficient reads as |
//! |---|---|---|
//! | `constant_bias` | `1` | constant force/flow or bias |
//! | `viscous_damping` | `v` (own velocity) | `−c/m`: negative = more damping than assumed |
//! | `linear_stiffness` | `x` (own position) | `−k/m` correction: negative = stiffer |
//! | `linear_coupling` | `x_j` | correction of `A[i, j]` |
//! | `input_gain` | `u` | correction of `B[i, j]` |
//! | `cubic_stiffness` | `x^3` | `−k₃/m`: **negative = hardening** (force `k₃x³`, `k₃ > 0`) |
//! | `quadratic_drag` | `v*abs(v)` | `−c₂/m`: negative = drag opposing motion |
//! | `coulomb_friction` | `sign(v)` | `−F_c/m`: negative = dry friction opposing motion |
//! | `stribeck_friction` | `sign(v)*exp(-(v/v_s)^2)` | `−(F_s − F_c)/m`: negative = breakaway |
//! | `amplitude_dependent_damping` | `x^2*v` | negative = damping grows with amplitude |
//! | `gravity_nonlinearity` | `sin(θ) - θ` | the gain of `sin θ` (`−g/l` for a hanging pendulum) |
//! | `input_coupling_cos` | `u*cos(θ) - u` | the gain of `u·cos θ` |
//! | `input_coupling_sin` | `u*sin(θ)` | the gain of `u·sin θ` |
//! | `orifice_outflow` | `sqrt(abs(h))` | `−α` (Torricelli) in its own tank, `+α` downstream |
//! | `input_saturation` | `sign(u)*max(abs(u) - L, 0)` | `−b` when the input is capped at `±L` |
//! | `dead_zone` | `sign(u)*min(abs(u), δ)` | `−b` when inputs below `δ` have no effect |
//! | `overflow` | `max(h - L, 0)` | `−a` loss above the rim `L` in its own tank, `+a` spill into the tank below |
//!
//! **Why the difference forms.** If the truth has `b'·u·cos θ` and the linearised model
//! `B·u`, the model error is `b'(u cos θ − u) + (b' − B)·u`: `u cos θ` itself would be
//! nearly collinear with `u` at small angles, whereas `u cos θ − u ≈ −u θ²/2` is not, so
//! the coefficient of `u*cos(θ) - u` is the true gain `b'` and an error in `B` shows up
//! separately as `input_gain`. The same holds for `sin(θ) - θ` next to the `θ` column of
//! `A`. Saturation and dead zone are likewise the *missing part* `b·(sat(u) − u)` and
//! `b·(dz(u) − u)` of a linear input `b·u`.
//!
//! `max` and `min` are written with `abs` (the expression language has no `max`):
//! `sign(u)*(abs(u) - L + abs(abs(u) - L))/2`, `u - sign(u)*(abs(u) - δ + abs(abs(u) - δ))/2`
//! and `(h - L + abs(h - L))/2`.
//!
//! **Overflow.** A tank whose level reaches its rim `L` loses what comes in above it: the
//! balance gains a sink that is zero below `L` and grows steeply above it. With a finite
//! coefficient `−a` the term is a stiff spring holding the level near `L` (`a` large) or a
//! partial spill; `+a` in the balance of a tank the model connects it to is the water that
//! falls into it. `L` is a shaping parameter, calibrated like a saturation limit.
//!
//! **Smooth variants.** `sign(v)` jumps at `v = 0`, which a fixed-step integrator turns
//! into chattering; the augmented model therefore integrates `coulomb_friction_smooth`
//! `tanh(v/ε)` (and `stribeck_friction_smooth`) with the same coefficient. `ε` is a small
//! fraction of the velocity's RMS over the data (see `candidates`), so the two agree except
//! for `|v| ≲ 3ε`. Levels use `sqrt(abs(h))` so that an estimate dipping below zero stays
//! finite.

use serde::{Deserialize, Serialize};
use sysid_core::{Expr, ExprError};

use crate::roles::{EquationKind, Role};

/// A named physical effect of the catalogue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[non_exhaustive]
pub enum Effect {
    /// `1`: a constant force, flow or bias.
    ConstantBias,
    /// `v` in the equation of `v` itself.
    ViscousDamping,
    /// `x` in the equation of `x`'s velocity.
    LinearStiffness,
    /// Any other state, linearly.
    LinearCoupling,
    /// An input, linearly.
    InputGain,
    /// `x^3` (position).
    CubicStiffness,
    /// `v*abs(v)` (velocity).
    QuadraticDrag,
    /// `sign(v)`.
    CoulombFriction,
    /// `tanh(v/ε)`: the integrable form of [`Effect::CoulombFriction`].
    CoulombFrictionSmooth,
    /// `(2/π)·atan(v/ε)`: a smooth Coulomb law with a slower approach to `±1` (a
    /// `1 − 2ε/(π|v|)` tail), the form many drives and simulators use; not a regression
    /// candidate (force-space discovery tries it as the shape of a named Coulomb term).
    CoulombFrictionAtan,
    /// `sign(v)*exp(-(v/v_s)^2)`.
    StribeckFriction,
    /// `tanh(v/ε)*exp(-(v/v_s)^2)`: the integrable form of [`Effect::StribeckFriction`].
    StribeckFrictionSmooth,
    /// `x^2*v` (position, its velocity).
    AmplitudeDependentDamping,
    /// `sin(θ) - θ` (angle).
    GravityNonlinearity,
    /// `u*cos(θ) - u` (input, angle).
    InputCouplingCos,
    /// `u*sin(θ)` (input, angle).
    InputCouplingSin,
    /// `sqrt(abs(h))` (level).
    OrificeOutflow,
    /// `sign(u)*max(abs(u) - L, 0)` (input, threshold `L`).
    InputSaturation,
    /// `sign(u)*min(abs(u), δ)` (input, threshold `δ`).
    DeadZone,
    /// `max(h - L, 0)` (level, rim `L`).
    Overflow,
}

/// What one variable slot of an effect accepts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slot {
    /// A state with one of these roles.
    State(&'static [Role]),
    /// Any state.
    AnyState,
    /// An input.
    Input,
}

const ALL_KINDS: &[EquationKind] = &[
    EquationKind::Acceleration,
    EquationKind::Flow,
    EquationKind::Other,
];
const MECHANICAL: &[EquationKind] = &[EquationKind::Acceleration];
const POSITION: &[Role] = &[Role::Position];
const ANGLE: &[Role] = &[Role::Angle];
const VELOCITY: &[Role] = &[Role::Velocity];
const LEVEL: &[Role] = &[Role::Level];

impl Effect {
    /// Every effect, in catalogue order (regression candidates first in this order, which
    /// also breaks ties between exactly equivalent candidates).
    pub const ALL: [Effect; 20] = [
        Effect::ConstantBias,
        Effect::ViscousDamping,
        Effect::LinearStiffness,
        Effect::LinearCoupling,
        Effect::InputGain,
        Effect::CubicStiffness,
        Effect::QuadraticDrag,
        Effect::CoulombFriction,
        Effect::CoulombFrictionSmooth,
        Effect::CoulombFrictionAtan,
        Effect::StribeckFriction,
        Effect::StribeckFrictionSmooth,
        Effect::AmplitudeDependentDamping,
        Effect::GravityNonlinearity,
        Effect::InputCouplingCos,
        Effect::InputCouplingSin,
        Effect::OrificeOutflow,
        Effect::InputSaturation,
        Effect::DeadZone,
        Effect::Overflow,
    ];

    /// The snake_case name used in model files and `discovery.json`.
    pub fn name(self) -> &'static str {
        match self {
            Effect::ConstantBias => "constant_bias",
            Effect::ViscousDamping => "viscous_damping",
            Effect::LinearStiffness => "linear_stiffness",
            Effect::LinearCoupling => "linear_coupling",
            Effect::InputGain => "input_gain",
            Effect::CubicStiffness => "cubic_stiffness",
            Effect::QuadraticDrag => "quadratic_drag",
            Effect::CoulombFriction => "coulomb_friction",
            Effect::CoulombFrictionSmooth => "coulomb_friction_smooth",
            Effect::CoulombFrictionAtan => "coulomb_friction_atan",
            Effect::StribeckFriction => "stribeck_friction",
            Effect::StribeckFrictionSmooth => "stribeck_friction_smooth",
            Effect::AmplitudeDependentDamping => "amplitude_dependent_damping",
            Effect::GravityNonlinearity => "gravity_nonlinearity",
            Effect::InputCouplingCos => "input_coupling_cos",
            Effect::InputCouplingSin => "input_coupling_sin",
            Effect::OrificeOutflow => "orifice_outflow",
            Effect::InputSaturation => "input_saturation",
            Effect::DeadZone => "dead_zone",
            Effect::Overflow => "overflow",
        }
    }

    /// The effect with this name, if any.
    pub fn from_name(name: &str) -> Option<Effect> {
        Self::ALL.into_iter().find(|e| e.name() == name)
    }

    /// A short human label.
    pub fn label(self) -> &'static str {
        match self {
            Effect::ConstantBias => "constant bias",
            Effect::ViscousDamping => "viscous damping",
            Effect::LinearStiffness => "linear stiffness",
            Effect::LinearCoupling => "linear coupling",
            Effect::InputGain => "input gain",
            Effect::CubicStiffness => "cubic stiffness",
            Effect::QuadraticDrag => "quadratic drag",
            Effect::CoulombFriction => "Coulomb friction",
            Effect::CoulombFrictionSmooth => "Coulomb friction (smoothed)",
            Effect::CoulombFrictionAtan => "Coulomb friction (smoothed by atan)",
            Effect::StribeckFriction => "Stribeck friction",
            Effect::StribeckFrictionSmooth => "Stribeck friction (smoothed)",
            Effect::AmplitudeDependentDamping => "amplitude-dependent damping",
            Effect::GravityNonlinearity => "gravity nonlinearity",
            Effect::InputCouplingCos => "input coupling through cos",
            Effect::InputCouplingSin => "input coupling through sin",
            Effect::OrificeOutflow => "orifice outflow",
            Effect::InputSaturation => "input saturation",
            Effect::DeadZone => "dead zone",
            Effect::Overflow => "overflow above a level",
        }
    }

    /// The variables the term reads, in template order.
    pub fn slots(self) -> &'static [Slot] {
        match self {
            Effect::ConstantBias => &[],
            Effect::ViscousDamping
            | Effect::QuadraticDrag
            | Effect::CoulombFriction
            | Effect::CoulombFrictionSmooth
            | Effect::CoulombFrictionAtan
            | Effect::StribeckFriction
            | Effect::StribeckFrictionSmooth => &[Slot::State(VELOCITY)],
            Effect::LinearStiffness => &[Slot::State(&[Role::Position, Role::Angle])],
            Effect::LinearCoupling => &[Slot::AnyState],
            Effect::InputGain | Effect::InputSaturation | Effect::DeadZone => &[Slot::Input],
            Effect::CubicStiffness => &[Slot::State(POSITION)],
            Effect::AmplitudeDependentDamping => &[Slot::State(POSITION), Slot::State(VELOCITY)],
            Effect::GravityNonlinearity => &[Slot::State(ANGLE)],
            Effect::InputCouplingCos | Effect::InputCouplingSin => {
                &[Slot::Input, Slot::State(ANGLE)]
            }
            Effect::OrificeOutflow | Effect::Overflow => &[Slot::State(LEVEL)],
        }
    }

    /// Names of the numeric parameters written into the term, in template order.
    pub fn parameters(self) -> &'static [&'static str] {
        match self {
            Effect::CoulombFrictionSmooth | Effect::CoulombFrictionAtan => &["eps"],
            Effect::StribeckFriction => &["v_s"],
            Effect::StribeckFrictionSmooth => &["v_s", "eps"],
            Effect::InputSaturation => &["limit"],
            Effect::DeadZone => &["width"],
            Effect::Overflow => &["level"],
            _ => &[],
        }
    }

    /// The equation kinds the effect may enter.
    pub fn enters(self) -> &'static [EquationKind] {
        match self {
            Effect::ConstantBias
            | Effect::LinearCoupling
            | Effect::InputGain
            | Effect::InputSaturation
            | Effect::DeadZone => ALL_KINDS,
            Effect::OrificeOutflow | Effect::Overflow => &[EquationKind::Flow],
            _ => MECHANICAL,
        }
    }

    /// The variant written into a model for integration (the effect itself when it is
    /// continuous).
    pub fn integration_form(self) -> Effect {
        match self {
            Effect::CoulombFriction => Effect::CoulombFrictionSmooth,
            Effect::StribeckFriction => Effect::StribeckFrictionSmooth,
            other => other,
        }
    }

    /// Whether the effect is a regression candidate (smooth variants are not: they exist
    /// for integration only).
    pub fn is_candidate(self) -> bool {
        !matches!(
            self,
            Effect::CoulombFrictionSmooth
                | Effect::CoulombFrictionAtan
                | Effect::StribeckFrictionSmooth
        )
    }

    /// The term's text over the variable names `vars` (one per [`Effect::slots`]) and
    /// parameter values `params` (one per [`Effect::parameters`]). Missing entries are
    /// written as `?`, which does not parse.
    pub fn template(self, vars: &[&str], params: &[f64]) -> String {
        let v = |i: usize| vars.get(i).copied().unwrap_or("?");
        let p = |i: usize| {
            params
                .get(i)
                .map_or_else(|| "?".to_string(), |x| number(*x))
        };
        let (a, b) = (v(0), v(1));
        match self {
            Effect::ConstantBias => "1".into(),
            Effect::ViscousDamping
            | Effect::LinearStiffness
            | Effect::LinearCoupling
            | Effect::InputGain => a.into(),
            Effect::CubicStiffness => format!("{a}^3"),
            Effect::QuadraticDrag => format!("{a}*abs({a})"),
            Effect::CoulombFriction => format!("sign({a})"),
            Effect::CoulombFrictionSmooth => format!("tanh({a}/{})", p(0)),
            Effect::CoulombFrictionAtan => format!("2/pi*atan({a}/{})", p(0)),
            Effect::StribeckFriction => format!("sign({a})*exp(-({a}/{})^2)", p(0)),
            Effect::StribeckFrictionSmooth => {
                format!("tanh({a}/{})*exp(-({a}/{})^2)", p(1), p(0))
            }
            Effect::AmplitudeDependentDamping => format!("{a}^2*{b}"),
            Effect::GravityNonlinearity => format!("sin({a}) - {a}"),
            Effect::InputCouplingCos => format!("{a}*cos({b}) - {a}"),
            Effect::InputCouplingSin => format!("{a}*sin({b})"),
            Effect::OrificeOutflow => format!("sqrt(abs({a}))"),
            Effect::InputSaturation => {
                let l = p(0);
                format!("sign({a})*(abs({a}) - {l} + abs(abs({a}) - {l}))/2")
            }
            Effect::DeadZone => {
                let d = p(0);
                format!("{a} - sign({a})*(abs({a}) - {d} + abs(abs({a}) - {d}))/2")
            }
            Effect::Overflow => {
                let l = p(0);
                format!("({a} - {l} + abs({a} - {l}))/2")
            }
        }
    }

    /// Parse the term over `variables` (a model's state names then input names).
    pub fn expression(
        self,
        vars: &[&str],
        params: &[f64],
        variables: &[&str],
    ) -> Result<Expr, ExprError> {
        Expr::parse(&self.template(vars, params), variables)
    }

    /// The unit of the term from the units of its variables (`None` where unknown).
    /// Angles in radians count as dimensionless inside `sin`/`cos`.
    pub fn term_unit(self, units: &[Option<&str>]) -> Option<String> {
        let u = |i: usize| units.get(i).copied().flatten();
        match self {
            Effect::ConstantBias
            | Effect::CoulombFriction
            | Effect::CoulombFrictionSmooth
            | Effect::CoulombFrictionAtan
            | Effect::StribeckFriction
            | Effect::StribeckFrictionSmooth
            | Effect::GravityNonlinearity => Some("1".into()),
            Effect::ViscousDamping
            | Effect::LinearStiffness
            | Effect::LinearCoupling
            | Effect::InputGain
            | Effect::InputSaturation
            | Effect::DeadZone
            | Effect::Overflow => u(0).map(str::to_string),
            Effect::CubicStiffness => u(0).map(|a| power(a, "3")),
            Effect::QuadraticDrag => u(0).map(|a| power(a, "2")),
            Effect::OrificeOutflow => u(0).map(|a| power(a, "0.5")),
            Effect::AmplitudeDependentDamping => {
                Some(format!("{}*{}", power(u(0)?, "2"), wrap(u(1)?)))
            }
            Effect::InputCouplingCos | Effect::InputCouplingSin => u(0).map(str::to_string),
        }
    }

    /// A one-line physical reading of a fitted coefficient's sign.
    pub fn reading(self, coefficient: f64) -> &'static str {
        let negative = coefficient < 0.0;
        match self {
            Effect::ConstantBias => "constant force, flow or offset the model lacks",
            Effect::ViscousDamping if negative => "more viscous damping than assumed",
            Effect::ViscousDamping => "less viscous damping than assumed",
            Effect::LinearStiffness if negative => "stiffer than assumed",
            Effect::LinearStiffness => "softer than assumed",
            Effect::LinearCoupling => "a linear coupling the A matrix lacks",
            Effect::InputGain => "the input gain differs from the B matrix",
            Effect::CubicStiffness if negative => "hardening (stiffening) cubic spring",
            Effect::CubicStiffness => "softening cubic spring",
            Effect::QuadraticDrag if negative => "quadratic drag opposing motion",
            Effect::QuadraticDrag => "negative quadratic drag (pushes with the motion)",
            Effect::CoulombFriction
            | Effect::CoulombFrictionSmooth
            | Effect::CoulombFrictionAtan
                if negative =>
            {
                "dry (Coulomb) friction opposing motion"
            }
            Effect::CoulombFriction
            | Effect::CoulombFrictionSmooth
            | Effect::CoulombFrictionAtan => "a constant push along the motion (not friction)",
            Effect::StribeckFriction | Effect::StribeckFrictionSmooth if negative => {
                "extra breakaway friction near rest (Stribeck)"
            }
            Effect::StribeckFriction | Effect::StribeckFrictionSmooth => {
                "friction lower near rest than at speed"
            }
            Effect::AmplitudeDependentDamping if negative => "damping that grows with amplitude",
            Effect::AmplitudeDependentDamping => "damping that falls with amplitude",
            Effect::GravityNonlinearity if negative => "restoring gravity through sin(angle)",
            Effect::GravityNonlinearity => "destabilising gravity through sin(angle) (inverted)",
            Effect::InputCouplingCos => "the input acts through cos(angle)",
            Effect::InputCouplingSin => "the input acts through sin(angle)",
            Effect::OrificeOutflow if negative => "outflow through an orifice (Torricelli)",
            Effect::OrificeOutflow => "inflow from an orifice upstream",
            Effect::InputSaturation => "the input's effect changes above the threshold",
            Effect::DeadZone => "the input's effect changes below the threshold",
            Effect::Overflow if negative => "a loss above a level (the tank overflows)",
            Effect::Overflow => "a spill from a tank above (it overflows into this one)",
        }
    }
}

/// The coefficient's unit from the unit of the state equation (`unit(ẋ_i)`) and of the
/// term: `unit(ẋ_i)/unit(g)`, kept as text (`"1"` means dimensionless).
pub fn coefficient_unit(equation_unit: &str, term_unit: &str) -> String {
    if term_unit == "1" {
        equation_unit.to_string()
    } else if term_unit == equation_unit {
        "1".to_string()
    } else {
        format!("{}/{}", wrap(equation_unit), wrap(term_unit))
    }
}

/// Parenthesise a compound unit.
fn wrap(unit: &str) -> String {
    if unit.contains(['*', '/', '^', ' ']) {
        format!("({unit})")
    } else {
        unit.to_string()
    }
}

fn power(unit: &str, exponent: &str) -> String {
    if unit == "1" {
        "1".into()
    } else {
        format!("{}^{exponent}", wrap(unit))
    }
}

/// A parameter written with 3 significant digits (readable model files; the value used
/// is the printed one, so a re-parsed model is the same function).
pub fn number(x: f64) -> String {
    format!("{:?}", round_significant(x, 3))
        .trim_end_matches(".0")
        .to_string()
}

/// `x` rounded to `digits` significant decimal digits.
pub fn round_significant(x: f64, digits: i32) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(digits - 1 - x.abs().log10().floor() as i32);
    let r = (x * scale).round() / scale;
    // Re-parse the shortest text so that printing and parsing agree exactly.
    format!("{r:.*e}", (digits - 1).max(0) as usize)
        .parse()
        .unwrap_or(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    const VARS: [&str; 5] = ["x", "v", "theta", "h", "u"];

    /// Variables and parameters that instantiate `effect` over [`VARS`].
    fn instance(effect: Effect) -> (Vec<&'static str>, Vec<f64>) {
        let vars = effect
            .slots()
            .iter()
            .map(|s| match s {
                Slot::Input => "u",
                Slot::AnyState => "h",
                Slot::State(roles) => match roles[0] {
                    Role::Position => "x",
                    Role::Angle => "theta",
                    Role::Velocity => "v",
                    Role::Level => "h",
                    Role::Other => "h",
                },
            })
            .collect();
        let params = effect
            .parameters()
            .iter()
            .enumerate()
            .map(|(i, _)| 0.37 + 0.21 * i as f64)
            .collect();
        (vars, params)
    }

    /// Every term's symbolic derivative against central differences at points away from
    /// kinks (|u| not near the thresholds 0.37 / 0.58, no zero crossings). Step h = 1e-5
    /// gives truncation error ~h²·f''' ≈ 1e-9 and round-off ~ε/h ≈ 1e-11 on O(1) values;
    /// the tolerance 1e-6·(1 + |f'|) leaves a wide margin.
    #[test]
    fn derivatives_match_finite_differences() {
        let points: [[f64; 5]; 4] = [
            [0.7, -1.3, 0.4, 0.25, 1.1],
            [-1.9, 0.8, -1.2, 1.7, -0.2],
            [0.3, 2.2, 2.5, 0.04, -2.6],
            [1.4, -0.05, -0.3, 3.1, 0.45],
        ];
        let h = 1e-5;
        for effect in Effect::ALL {
            let (vars, params) = instance(effect);
            let e = effect
                .expression(&vars, &params, &VARS)
                .unwrap_or_else(|err| panic!("{}: {err}", effect.name()));
            for var in 0..VARS.len() {
                let d = e.derivative(var).unwrap_or_else(|err| panic!("{err}"));
                for p in &points {
                    let (mut a, mut b) = (*p, *p);
                    a[var] += h;
                    b[var] -= h;
                    let fd = (e.eval(&a) - e.eval(&b)) / (2.0 * h);
                    let an = d.eval(p);
                    assert!(
                        (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
                        "{} d/d{}: analytic {an}, differences {fd} at {p:?}",
                        effect.name(),
                        VARS[var]
                    );
                }
            }
        }
    }

    /// The printed (canonical) term re-parses to the identical tree, and so does the raw
    /// template text, and both evaluate alike.
    #[test]
    fn printed_terms_reparse() {
        for effect in Effect::ALL {
            let (vars, params) = instance(effect);
            let e = effect
                .expression(&vars, &params, &VARS)
                .unwrap_or_else(|err| panic!("{}: {err}", effect.name()));
            let printed = e.to_string();
            let again = Expr::parse(&printed, &VARS).unwrap_or_else(|err| panic!("{err}"));
            assert_eq!(again, e, "{} printed as {printed}", effect.name());
            assert_eq!(Effect::from_name(effect.name()), Some(effect));
        }
    }

    /// Saturation and dead zone are what their doc says: `sign(u)·max(|u| − L, 0)` and
    /// `sign(u)·min(|u|, δ)`, checked against direct formulas on a grid.
    #[test]
    fn piecewise_terms_match_their_definitions() {
        let vars = ["u"];
        let sat = Effect::InputSaturation
            .expression(&["u"], &[0.5], &vars)
            .unwrap_or_else(|e| panic!("{e}"));
        let dz = Effect::DeadZone
            .expression(&["u"], &[0.5], &vars)
            .unwrap_or_else(|e| panic!("{e}"));
        let over = Effect::Overflow
            .expression(&["u"], &[0.5], &vars)
            .unwrap_or_else(|e| panic!("{e}"));
        for k in -40..=40 {
            let u = k as f64 * 0.05;
            let want_sat = u.signum() * (u.abs() - 0.5).max(0.0);
            let want_dz = u.signum() * u.abs().min(0.5);
            let want_over = (u - 0.5).max(0.0);
            assert!((sat.eval(&[u]) - want_sat).abs() < 1e-15, "sat at {u}");
            assert!((dz.eval(&[u]) - want_dz).abs() < 1e-15, "dz at {u}");
            assert!(
                (over.eval(&[u]) - want_over).abs() < 1e-15,
                "overflow at {u}"
            );
        }
    }

    #[test]
    fn units_follow_the_equation() {
        let cubic = Effect::CubicStiffness.term_unit(&[Some("m")]);
        assert_eq!(cubic.as_deref(), Some("m^3"));
        assert_eq!(coefficient_unit("m/s^2", "m^3"), "(m/s^2)/(m^3)");
        assert_eq!(coefficient_unit("rad/s^2", "1"), "rad/s^2");
        assert_eq!(coefficient_unit("m/s", "m/s"), "1");
        assert_eq!(
            Effect::AmplitudeDependentDamping
                .term_unit(&[Some("m"), Some("m/s")])
                .as_deref(),
            Some("m^2*(m/s)")
        );
        assert_eq!(Effect::OrificeOutflow.term_unit(&[None]), None);
    }

    #[test]
    fn numbers_print_with_three_digits_and_reparse() {
        assert_eq!(number(0.012345), "0.0123");
        assert_eq!(number(1234.5), "1230");
        assert_eq!(number(2.0), "2");
        let x = round_significant(0.0123456, 3);
        assert_eq!(number(x).parse::<f64>().map(f64::to_bits), Ok(x.to_bits()));
    }
}
