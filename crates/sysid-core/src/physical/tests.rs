//! `PhysicalModel` against hand-written closed forms: the double pendulum's mass-matrix
//! form against Cramer's rule, every analytic Jacobian (states, inputs, parameters)
//! against central differences, terms as generalized forces, and typed errors.

use nalgebra::DMatrix;

use super::*;
use crate::linear::ModelNames;

fn linear(states: &[&str], inputs: &[&str], measured: &[&str]) -> LinearModel {
    let n = states.len();
    let names = ModelNames {
        states: states.iter().map(|s| (*s).to_owned()).collect(),
        inputs: inputs.iter().map(|s| (*s).to_owned()).collect(),
        outputs: measured.iter().map(|s| (*s).to_owned()).collect(),
        corrections: Vec::new(),
    };
    let mut c = DMatrix::zeros(measured.len(), n);
    for (k, m) in measured.iter().enumerate() {
        let i = states.iter().position(|s| s == m).unwrap_or(0);
        c[(k, i)] = 1.0;
    }
    LinearModel::with_names(
        DMatrix::zeros(n, n),
        DMatrix::zeros(n, inputs.len()),
        c,
        DMatrix::zeros(n, 0),
        names,
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| (*s).to_owned()).collect()
}

/// Parameters of the double compound pendulum on an accelerated pivot.
const PARAMS: [(&str, f64); 9] = [
    ("m1", 0.4),
    ("l1", 0.3),
    ("m2", 0.3),
    ("l2", 0.25),
    ("c1", 0.01),
    ("c2", 0.03),
    ("tc", 0.02),
    ("vs", 0.05),
    ("g", 9.81),
];

const J1: &str = "m1*l1^2/3 + m2*l1^2";
const K: &str = "m2*l1*l2/2*cos(theta1 - theta2)";
const J2: &str = "m2*l2^2/3";
const F1: &str = "-m2*l1*l2/2*sin(theta1 - theta2)*omega2^2 - (m1/2 + m2)*l1*(g*sin(theta1) \
                  + cos(theta1)*u) - c1*omega1";
const F2: &str = "m2*l1*l2/2*sin(theta1 - theta2)*omega1^2 - m2*l2/2*(g*sin(theta2) + \
                  cos(theta2)*u)";

/// The double pendulum: rigid body in `[mechanics]`, the joint friction (viscous and a
/// smooth Coulomb law) as a transfer term between the two rate equations.
fn double_pendulum() -> PhysicalModel {
    let lin = linear(
        &["theta1", "theta2", "omega1", "omega2"],
        &["u"],
        &["theta1", "theta2"],
    );
    let params = PARAMS.iter().map(|(n, v)| Parameter::new(n, *v)).collect();
    let (q, qdot) = (
        strings(&["theta1", "theta2"]),
        strings(&["omega1", "omega2"]),
    );
    let mass = vec![strings(&[J1, K]), strings(&[K, J2])];
    let forces = strings(&[F1, F2]);
    // Joint torque τ = c2·(ω2 − ω1) + tc·atan((ω2 − ω1)/vs) acts +τ on rod 1, −τ on rod 2.
    let joint = PhysicalTerm {
        state: 2,
        into: Some(3),
        effect: "joint_friction",
        term: "c2*(omega2 - omega1) + tc*atan((omega2 - omega1)/vs)",
        coefficient: 1.0,
    };
    PhysicalModel::new(
        lin,
        params,
        &[joint],
        Some(MechanicsSpec {
            q: &q,
            qdot: &qdot,
            mass: &mass,
            forces: &forces,
        }),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// Cramer's rule on the same Lagrangian, written out by hand.
fn closed_form(p: &[f64; 9], x: &[f64], u: f64) -> [f64; 2] {
    let [m1, l1, m2, l2, c1, c2, tc, vs, g] = *p;
    let (t1, t2, w1, w2) = (x[0], x[1], x[2], x[3]);
    let j1 = m1 * l1 * l1 / 3.0 + m2 * l1 * l1;
    let j2 = m2 * l2 * l2 / 3.0;
    let k = m2 * l1 * l2 / 2.0;
    let (s, c) = (t1 - t2).sin_cos();
    let tau = c2 * (w2 - w1) + tc * ((w2 - w1) / vs).atan();
    let r1 =
        -k * s * w2 * w2 - (m1 / 2.0 + m2) * l1 * (g * t1.sin() + t1.cos() * u) - c1 * w1 + tau;
    let r2 = k * s * w1 * w1 - m2 * l2 / 2.0 * (g * t2.sin() + t2.cos() * u) - tau;
    let det = j1 * j2 - k * k * c * c;
    [(j2 * r1 - k * c * r2) / det, (j1 * r2 - k * c * r1) / det]
}

/// Deterministic points in a box (xorshift; no dependency on a random crate).
fn points(count: usize) -> Vec<([f64; 4], f64)> {
    let mut s = 0x2545_F491_4F6C_DD1D_u64;
    let mut next = move |lo: f64, hi: f64| {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64)
    };
    (0..count)
        .map(|_| {
            let pi = std::f64::consts::PI;
            (
                [
                    next(-pi, pi),
                    next(-pi, pi),
                    next(-8.0, 8.0),
                    next(-8.0, 8.0),
                ],
                next(-5.0, 5.0),
            )
        })
        .collect()
}

fn values() -> [f64; 9] {
    PARAMS.map(|(_, v)| v)
}

/// 200 points over the full angle range: the numerically solved mass-matrix form equals
/// Cramer's rule to round-off (both exact; ~1e-12 relative to accelerations of O(100)).
#[test]
fn mass_matrix_form_matches_cramers_rule() {
    let model = double_pendulum();
    assert!(model.is_mechanical());
    assert!(model.term_model().is_none());
    for (x, u) in points(200) {
        let mut dx = [0.0; 4];
        model.rhs(0.0, &x, &[u], &mut dx);
        let want = closed_form(&values(), &x, u);
        assert_eq!(dx[0].to_bits(), x[2].to_bits());
        assert_eq!(dx[1].to_bits(), x[3].to_bits());
        for i in 0..2 {
            let scale = 1.0 + want[i].abs();
            assert!(
                (dx[2 + i] - want[i]).abs() < 1e-12 * scale,
                "{x:?} {u}: {} vs {}",
                dx[2 + i],
                want[i]
            );
        }
    }
}

/// `mass_matrix` gives the hand-written `M(q)` (row-major) and the coordinate states;
/// too short a buffer and a model without mechanics give `None`.
#[test]
fn mass_matrix_is_the_written_one() {
    let model = double_pendulum();
    let [m1, l1, m2, l2, ..] = values();
    assert_eq!(model.mechanics_states(), Some((&[0, 1][..], &[2, 3][..])));
    for (x, u) in points(20) {
        let mut m = [f64::NAN; 4];
        assert_eq!(model.mass_matrix(&x, &[u], &mut m), Some(2));
        let k = m2 * l1 * l2 / 2.0 * (x[0] - x[1]).cos();
        let want = [m1 * l1 * l1 / 3.0 + m2 * l1 * l1, k, k, m2 * l2 * l2 / 3.0];
        for (got, want) in m.iter().zip(want) {
            assert!((got - want).abs() <= 1e-15, "{x:?}: {m:?}");
        }
    }
    assert_eq!(model.mass_matrix(&[0.0; 4], &[0.0], &mut [0.0; 3]), None);
    let plain = PhysicalModel::new(linear(&["x"], &[], &["x"]), Vec::new(), &[], None)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(plain.mass_matrix(&[0.0], &[], &mut [0.0; 4]), None);
    assert_eq!(plain.mechanics_states(), None);
}

/// Central difference of `f` along one coordinate, step `h = ε^(1/3)·max(1, |z|)`:
/// truncation `h²|f'''|/6` and round-off `ε|f|/h` are both ~1e-10·|f| here.
fn central(f: impl Fn(f64) -> [f64; 4], z: f64) -> [f64; 4] {
    let h = f64::EPSILON.cbrt() * z.abs().max(1.0);
    let (p, m) = (f(z + h), f(z - h));
    std::array::from_fn(|i| (p[i] - m[i]) / (2.0 * h))
}

fn check(analytic: f64, numeric: f64, what: &str) {
    // Accelerations are O(100) with third derivatives of the same order (atan's steepest
    // part is scaled by 1/vs = 20, so up to ~1e4·|f|): the tolerance 1e-5·(1 + |∂f|)
    // covers the ~1e-6 worst case of the difference with a margin of 10.
    let tol = 1e-5 * (1.0 + analytic.abs());
    assert!(
        (analytic - numeric).abs() <= tol,
        "{what}: {analytic} vs {numeric}"
    );
}

/// `∂f/∂x` and `∂f/∂u` (analytic, through `M⁻¹(∂F/∂z − ∂M/∂z·a)`) match central
/// differences at 50 points, every entry.
#[test]
fn state_and_input_jacobians_match_central_differences() {
    let model = double_pendulum();
    let mut a = DMatrix::zeros(4, 4);
    let mut b = DMatrix::zeros(4, 1);
    for (x, u) in points(50) {
        model.jacobians(0.0, &x, &[u], &mut a, &mut b);
        for j in 0..4 {
            let fd = central(
                |z| {
                    let mut xz = x;
                    xz[j] = z;
                    let mut dx = [0.0; 4];
                    model.rhs(0.0, &xz, &[u], &mut dx);
                    dx
                },
                x[j],
            );
            for i in 0..4 {
                check(a[(i, j)], fd[i], &format!("df{i}/dx{j} at {x:?}"));
            }
        }
        let fd = central(
            |z| {
                let mut dx = [0.0; 4];
                model.rhs(0.0, &x, &[z], &mut dx);
                dx
            },
            u,
        );
        for i in 0..4 {
            check(b[(i, 0)], fd[i], &format!("df{i}/du at {x:?}"));
        }
    }
}

/// `∂f/∂p` (the grey-box interface) matches central differences through
/// `with_parameters` for every parameter at 30 points, including the mass-matrix
/// parameters that enter through `M⁻¹`.
#[test]
fn parameter_jacobian_matches_central_differences() {
    let model = double_pendulum();
    let p0 = values();
    let mut jp = DMatrix::zeros(4, p0.len());
    for (x, u) in points(30) {
        model.parameter_jacobian(0.0, &x, &[u], &mut jp);
        for k in 0..p0.len() {
            let fd = central(
                |z| {
                    let mut p = p0;
                    p[k] = z;
                    let m = model.with_parameters(&p).unwrap_or_else(|e| panic!("{e}"));
                    let mut dx = [0.0; 4];
                    m.rhs(0.0, &x, &[u], &mut dx);
                    dx
                },
                p0[k],
            );
            for i in 0..4 {
                check(
                    jp[(i, k)],
                    fd[i],
                    &format!("df{i}/d{} at {x:?}", PARAMS[k].0),
                );
            }
        }
        // The kinematic rows do not depend on the parameters.
        assert!(jp.row(0).iter().chain(jp.row(1).iter()).all(|v| *v == 0.0));
    }
}

/// A term on a rate equation is a generalized force (divided by the mass), a term on a
/// coordinate equation adds to `ẋ` directly; `with_parameters` checks length and bounds.
#[test]
fn terms_on_rates_are_forces_and_parameters_are_checked() {
    let lin = linear(&["x", "v"], &["F"], &["x"]);
    let mut m = Parameter::new("m", 2.0);
    m.lower = 0.5;
    let params = vec![m, Parameter::new("c", 0.4), Parameter::new("k", 3.0)];
    let (q, qdot) = (strings(&["x"]), strings(&["v"]));
    let mass = vec![strings(&["m"])];
    let forces = strings(&["F - k*x"]);
    let terms = [
        PhysicalTerm {
            state: 1,
            into: None,
            effect: "viscous",
            term: "c*v",
            coefficient: -1.0,
        },
        PhysicalTerm {
            state: 0,
            into: None,
            effect: "drift",
            term: "0.1*k",
            coefficient: 1.0,
        },
    ];
    let spec = MechanicsSpec {
        q: &q,
        qdot: &qdot,
        mass: &mass,
        forces: &forces,
    };
    let model = PhysicalModel::new(lin.clone(), params.clone(), &terms, Some(spec))
        .unwrap_or_else(|e| panic!("{e}"));
    let mut dx = [0.0; 2];
    model.rhs(0.0, &[0.5, -1.0], &[1.0], &mut dx);
    // ẋ = v + 0.1·k = −1 + 0.3; v̇ = (F − k x − c v)/m = (1 − 1.5 + 0.4)/2.
    assert!(
        (dx[0] + 0.7).abs() < 1e-15 && (dx[1] + 0.05).abs() < 1e-15,
        "{dx:?}"
    );
    let mut jp = DMatrix::zeros(2, 3);
    model.parameter_jacobian(0.0, &[0.5, -1.0], &[1.0], &mut jp);
    // ∂v̇/∂m = −v̇/m, ∂v̇/∂c = −v/m, ∂v̇/∂k = −x/m; ∂ẋ/∂k = 0.1.
    let want = [0.0, 0.0, 0.1, 0.025, 0.5, -0.25];
    for (k, w) in want.iter().enumerate() {
        let (i, j) = (k / 3, k % 3);
        assert!(
            (jp[(i, j)] - w).abs() < 1e-15,
            "({i},{j}) {} vs {w}",
            jp[(i, j)]
        );
    }
    assert!(matches!(
        model.with_parameters(&[1.0, 2.0]),
        Err(PhysicalError::ParameterCount {
            found: 2,
            expected: 3
        })
    ));
    assert!(matches!(
        model.with_parameters(&[0.1, 0.4, 3.0]),
        Err(PhysicalError::BadParameter { ref name, .. }) if name == "m"
    ));
    // Without mechanics the same terms give a TermModel with the values substituted.
    let plain = PhysicalModel::new(lin, params, &terms, None).unwrap_or_else(|e| panic!("{e}"));
    let tm = plain
        .term_model()
        .unwrap_or_else(|| panic!("no mechanics"))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(tm.terms()[0].expr.to_string(), "0.4*v");
    let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
    plain.rhs(0.0, &[0.5, -1.0], &[1.0], &mut a);
    tm.rhs(0.0, &[0.5, -1.0], &[1.0], &mut b);
    assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits));
}

#[test]
fn construction_errors_say_what_and_where() {
    let lin = linear(&["x", "v"], &["F"], &["x"]);
    let (q, qdot) = (strings(&["x"]), strings(&["v"]));
    let build = |params: Vec<Parameter>, mass: &[Vec<String>], forces: &[String]| {
        PhysicalModel::new(
            lin.clone(),
            params,
            &[],
            Some(MechanicsSpec {
                q: &q,
                qdot: &qdot,
                mass,
                forces,
            }),
        )
    };
    let ok_mass = vec![strings(&["m"])];
    let ok_forces = strings(&["F"]);
    let r = build(vec![Parameter::new("v", 1.0)], &ok_mass, &ok_forces);
    assert!(matches!(
        r,
        Err(PhysicalError::NameClash { with: "state", .. })
    ));
    let r = build(
        vec![Parameter::new("m", 1.0), Parameter::new("m", 2.0)],
        &ok_mass,
        &ok_forces,
    );
    assert!(matches!(
        r,
        Err(PhysicalError::NameClash {
            with: "parameter",
            ..
        })
    ));
    let r = build(vec![Parameter::new("m", f64::NAN)], &ok_mass, &ok_forces);
    assert!(matches!(r, Err(PhysicalError::BadParameter { .. })));
    let r = build(
        vec![Parameter::new("m", 1.0)],
        &[strings(&["mm"])],
        &ok_forces,
    );
    match r {
        Err(PhysicalError::Expression { place, source, .. }) => {
            assert_eq!(place, "mechanics.mass[0][0]");
            assert!(matches!(source, ExprError::UnknownName { column: 0, .. }));
        }
        other => panic!("{other:?}"),
    }
    let r = build(
        vec![Parameter::new("m", 1.0)],
        &ok_mass,
        &strings(&["F", "F"]),
    );
    assert!(matches!(r, Err(PhysicalError::Shape { key: "forces", .. })));
    let lin2 = linear(&["a", "b", "va", "vb"], &[], &["a"]);
    let (q2, v2) = (strings(&["a", "b"]), strings(&["va", "vb"]));
    let mass = vec![strings(&["1", "a"]), strings(&["b", "1"])];
    let forces = strings(&["0", "0"]);
    let r = PhysicalModel::new(
        lin2.clone(),
        vec![],
        &[],
        Some(MechanicsSpec {
            q: &q2,
            qdot: &v2,
            mass: &mass,
            forces: &forces,
        }),
    );
    assert!(matches!(
        r,
        Err(PhysicalError::Asymmetric { row: 1, col: 0, .. })
    ));
    let bad_q = strings(&["a", "va"]);
    let r = PhysicalModel::new(
        lin2,
        vec![],
        &[],
        Some(MechanicsSpec {
            q: &bad_q,
            qdot: &v2,
            mass: &[strings(&["1", "0"]), strings(&["0", "1"])],
            forces: &forces,
        }),
    );
    assert!(matches!(
        r,
        Err(PhysicalError::Coordinate { key: "qdot", .. })
    ));
}
