//! Physical roles of a model's states (position, angle, velocity, level, other), inferred
//! from the structure of `A`, the units and the names, so that catalogue effects are only
//! tried where they make physical sense.
//!
//! # Inference rules
//!
//! 1. **Kinematic pairs.** A state equation `ẋ_i = a·x_j`, `a > 0` (row `i` of `A` has its
//!    only nonzero entry at `j ≠ i`, and row `i` of `B` is zero) makes `x_i` position-like and
//!    `x_j` its velocity (they are *partners*). Each state joins at most one pair.
//! 2. **Angles.** A position-like state is an angle when its unit is `rad` or `deg`; with
//!    no unit given, when its name (lower case, trailing digits and `_` dropped) is one of
//!    `theta th phi psi alpha beta gamma angle`.
//! 3. **Levels.** A state outside every pair is a level when its unit is a length
//!    (`m cm mm`); with no unit, when its name (as above) is `h`, `level` or `height`.
//! 4. Everything else is [`Role::Other`].
//!
//! Explicit overrides replace the inferred role of a named state (pairs still come from
//! rule 1).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use sysid_core::LinearModel;

use crate::error::{DiscoveryError, Result};

/// The physical role of a state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// A translational position (enters `ẋ = v`).
    Position,
    /// An angle in radians (enters `θ̇ = ω`).
    Angle,
    /// A velocity: the derivative of a position or angle; its equation is an acceleration.
    Velocity,
    /// A fluid level (non-negative, first-order dynamics).
    Level,
    /// Anything else.
    Other,
}

/// The kind of a state equation, from the role of its state: which effects may enter it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EquationKind {
    /// The equation of a velocity (forces and torques act here).
    Acceleration,
    /// The equation of a level (flows act here).
    Flow,
    /// Any other equation (generic effects only).
    Other,
}

/// Roles of every state of a model, with kinematic partners.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct StateRoles {
    /// Role of each state, in the model's state order.
    pub roles: Vec<Role>,
    /// For a position/angle its velocity, for a velocity its position/angle.
    pub partners: Vec<Option<usize>>,
}

const ANGLE_NAMES: [&str; 8] = [
    "theta", "th", "phi", "psi", "alpha", "beta", "gamma", "angle",
];
const LEVEL_NAMES: [&str; 3] = ["h", "level", "height"];

/// The name in lower case without trailing digits and underscores (`theta_2` → `theta`).
fn stem(name: &str) -> String {
    name.to_lowercase()
        .trim_end_matches(|c: char| c.is_ascii_digit() || c == '_')
        .to_string()
}

impl StateRoles {
    /// Infer roles from `model` (structure of `A` and `B`), `units` (state name → unit;
    /// may be empty) and explicit `overrides` (state name, role).
    ///
    /// Errors: an override naming a state the model does not have.
    pub fn infer(
        model: &LinearModel,
        units: &BTreeMap<String, String>,
        overrides: &[(String, Role)],
    ) -> Result<Self> {
        let n = model.n_states();
        let (a, b) = (model.a(), model.b());
        let mut partners: Vec<Option<usize>> = vec![None; n];
        let mut is_position = vec![false; n];
        for i in 0..n {
            let nonzero: Vec<usize> = (0..n).filter(|&j| a[(i, j)] != 0.0).collect();
            let b_zero = (0..b.ncols()).all(|j| b[(i, j)] == 0.0);
            if let [j] = nonzero[..]
                && j != i
                && a[(i, j)] > 0.0
                && b_zero
                && partners[i].is_none()
                && partners[j].is_none()
            {
                partners[i] = Some(j);
                partners[j] = Some(i);
                is_position[i] = true;
            }
        }
        let mut roles = vec![Role::Other; n];
        let names = model.state_names();
        for i in 0..n {
            let unit = units.get(&names[i]).map(|u| u.trim());
            roles[i] = match partners[i] {
                Some(_) if is_position[i] => {
                    let angle = match unit {
                        Some(u) => matches!(u, "rad" | "deg"),
                        None => ANGLE_NAMES.contains(&stem(&names[i]).as_str()),
                    };
                    if angle { Role::Angle } else { Role::Position }
                }
                Some(_) => Role::Velocity,
                None => {
                    let level = match unit {
                        Some(u) => matches!(u, "m" | "cm" | "mm"),
                        None => LEVEL_NAMES.contains(&stem(&names[i]).as_str()),
                    };
                    if level { Role::Level } else { Role::Other }
                }
            };
        }
        for (name, role) in overrides {
            let i = names.iter().position(|s| s == name).ok_or_else(|| {
                DiscoveryError::UnknownName {
                    kind: "state",
                    name: name.clone(),
                }
            })?;
            roles[i] = *role;
        }
        Ok(Self { roles, partners })
    }

    /// States whose name alone would make them a level or an angle but whose unit makes
    /// them something else (and that `overrides` does not name): `(state, role by its
    /// unit, role by its name)`. A level sensor read in volts is the usual case; the caller
    /// can tell the user to give the role.
    ///
    /// Errors: as [`StateRoles::infer`].
    pub fn unit_overrules_name(
        model: &LinearModel,
        units: &BTreeMap<String, String>,
        overrides: &[(String, Role)],
    ) -> Result<Vec<(String, Role, Role)>> {
        let with = Self::infer(model, units, overrides)?;
        let by_name = Self::infer(model, &BTreeMap::new(), overrides)?;
        Ok(model
            .state_names()
            .iter()
            .zip(with.roles.iter().zip(&by_name.roles))
            .filter(|&(_, (w, n))| w != n && matches!(n, Role::Level | Role::Angle))
            .map(|(name, (&w, &n))| (name.clone(), w, n))
            .collect())
    }

    /// The kind of state equation `i`.
    pub fn equation_kind(&self, i: usize) -> EquationKind {
        match self.roles.get(i) {
            Some(Role::Velocity) => EquationKind::Acceleration,
            Some(Role::Level) => EquationKind::Flow,
            _ => EquationKind::Other,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::DMatrix;
    use sysid_core::ModelNames;

    fn model(a: &[f64], b: &[f64], states: &[&str]) -> LinearModel {
        let n = states.len();
        let names = ModelNames {
            states: states.iter().map(|s| s.to_string()).collect(),
            inputs: vec!["u".into()],
            outputs: vec!["y".into()],
            corrections: vec!["d".into()],
        };
        let mut c = DMatrix::zeros(1, n);
        c[(0, 0)] = 1.0;
        let mut e = DMatrix::zeros(n, 1);
        e[(n - 1, 0)] = 1.0;
        LinearModel::with_names(
            DMatrix::from_row_slice(n, n, a),
            DMatrix::from_row_slice(n, 1, b),
            c,
            e,
            names,
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn kinematic_pairs_angles_and_levels() {
        let none = BTreeMap::new();
        // Mass-spring: x position, v velocity.
        let r = StateRoles::infer(
            &model(&[0.0, 1.0, -1.0, 0.0], &[0.0, 1.0], &["x", "v"]),
            &none,
            &[],
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.roles, [Role::Position, Role::Velocity]);
        assert_eq!(r.partners, [Some(1), Some(0)]);
        assert_eq!(r.equation_kind(1), EquationKind::Acceleration);
        // Pendulum by name, then by unit (a unit beats the name).
        let p = model(&[0.0, 1.0, -9.0, -0.1], &[0.0, -2.0], &["theta", "omega"]);
        let r = StateRoles::infer(&p, &none, &[]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.roles, [Role::Angle, Role::Velocity]);
        let units = BTreeMap::from([("theta".to_string(), "m".to_string())]);
        let r = StateRoles::infer(&p, &units, &[]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.roles[0], Role::Position);
        // Tanks: first-order, names h1 h2.
        let t = model(&[-0.1, 0.0, 0.1, -0.2], &[0.003, 0.0], &["h1", "h2"]);
        let r = StateRoles::infer(&t, &none, &[]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.roles, [Role::Level, Role::Level]);
        // Read in volts, they are `Other`, and the names say what the unit hid; a given
        // role silences it, and a unit that agrees with the name is no case.
        let volts = BTreeMap::from([
            ("h1".to_string(), "V".to_string()),
            ("h2".to_string(), "V".to_string()),
        ]);
        let hidden =
            StateRoles::unit_overrules_name(&t, &volts, &[]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            hidden,
            [
                ("h1".to_string(), Role::Other, Role::Level),
                ("h2".to_string(), Role::Other, Role::Level)
            ]
        );
        let given = [("h1".to_string(), Role::Level)];
        let hidden =
            StateRoles::unit_overrules_name(&t, &volts, &given).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(hidden, [("h2".to_string(), Role::Other, Role::Level)]);
        let metres = BTreeMap::from([("h1".to_string(), "m".to_string())]);
        assert!(
            StateRoles::unit_overrules_name(&t, &metres, &[])
                .unwrap_or_else(|e| panic!("{e}"))
                .is_empty()
        );
        assert_eq!(r.equation_kind(0), EquationKind::Flow);
        // Overrides, and an unknown name.
        let r = StateRoles::infer(&t, &none, &[("h2".into(), Role::Other)])
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(r.roles, [Role::Level, Role::Other]);
        assert!(matches!(
            StateRoles::infer(&t, &none, &[("h3".into(), Role::Other)]),
            Err(DiscoveryError::UnknownName { .. })
        ));
    }
}
