//! Expression properties: random trees parse to their independent evaluation, print to a
//! canonical text that re-parses to the same tree, and the SPEC examples and every
//! function's symbolic derivative agree with direct formulas and finite differences.

use proptest::prelude::*;
use sysid_core::{Expr, Func};

use crate::{config, same};

const NAMES: [&str; 4] = ["x", "y", "u_1", "θ"];

/// A test-side expression tree, printed fully parenthesised and evaluated directly.
#[derive(Debug, Clone)]
enum T {
    /// A positive literal, and whether to write it in exponent notation.
    C(f64, bool),
    V(usize),
    Neg(Box<T>),
    Bin(char, Box<T>, Box<T>),
    F(Func, Box<T>),
}

fn text(t: &T) -> String {
    match t {
        T::C(c, true) => format!("{c:e}"),
        T::C(c, false) => format!("{c}"),
        T::V(i) => NAMES[*i].to_owned(),
        // Leaves and nested minus signs without parentheses ("-x", "--x"), the rest with.
        T::Neg(a) => match **a {
            T::C(..) | T::V(_) | T::Neg(_) => format!("-{}", text(a)),
            _ => format!("-({})", text(a)),
        },
        T::Bin('a', a, b) => format!("atan2({}, {})", text(a), text(b)),
        T::Bin('m', a, b) => format!("min({}, {})", text(a), text(b)),
        T::Bin('M', a, b) => format!("max({}, {})", text(a), text(b)),
        T::Bin(op, a, b) => format!("({}){op}({})", text(a), text(b)),
        T::F(f, a) => format!("{}({})", f.name(), text(a)),
    }
}

/// Whether a subtree uses no variable (the parser folds it to a constant).
fn constant(t: &T) -> bool {
    match t {
        T::C(..) => true,
        T::V(_) => false,
        T::Neg(a) | T::F(_, a) => constant(a),
        T::Bin(_, a, b) => constant(a) && constant(b),
    }
}

/// Direct evaluation with the documented semantics: `^` is `a·a` for an exponent of
/// exactly 2, `powi` for a constant integer exponent up to 16 in magnitude and `powf`
/// otherwise, `log` is natural, `sign(0) = 0`.
#[allow(clippy::float_cmp)]
fn value(t: &T, v: &[f64]) -> f64 {
    match t {
        T::C(c, _) => *c,
        T::V(i) => v[*i],
        T::Neg(a) => -value(a, v),
        T::Bin(op, ta, tb) => {
            let (a, b) = (value(ta, v), value(tb, v));
            match op {
                '+' => a + b,
                '-' => a - b,
                '*' => a * b,
                '/' => a / b,
                'a' => a.atan2(b),
                'm' | 'M' if a.is_nan() || b.is_nan() => f64::NAN,
                'm' => a.min(b),
                'M' => a.max(b),
                _ if b == 2.0 => a * a,
                _ if constant(tb) && b.fract() == 0.0 && b.abs() <= 16.0 => a.powi(b as i32),
                _ => a.powf(b),
            }
        }
        T::F(f, a) => {
            let a = value(a, v);
            match f {
                Func::Sin => a.sin(),
                Func::Cos => a.cos(),
                Func::Tan => a.tan(),
                Func::Exp => a.exp(),
                Func::Log => a.ln(),
                Func::Sqrt => a.sqrt(),
                Func::Abs => a.abs(),
                Func::Sign if a.is_nan() => a,
                Func::Sign if a == 0.0 => 0.0,
                Func::Sign => a.signum(),
                Func::Tanh => a.tanh(),
                Func::Atan => a.atan(),
                Func::Asin => a.asin(),
                Func::Acos => a.acos(),
                Func::Sinh => a.sinh(),
                Func::Cosh => a.cosh(),
            }
        }
    }
}

fn tree() -> impl Strategy<Value = T> {
    let literals = vec![0.0, 1.0, 2.0, 3.0, 0.5, 0.25, 1.5, 10.0, 1e-3, 2.5e3];
    let leaf = prop_oneof![
        (proptest::sample::select(literals), any::<bool>()).prop_map(|(c, e)| T::C(c, e)),
        (0..NAMES.len()).prop_map(T::V),
    ];
    leaf.prop_recursive(6, 48, 2, |inner| {
        prop_oneof![
            inner.clone().prop_map(|a| T::Neg(Box::new(a))),
            (
                proptest::sample::select(vec!['+', '-', '*', '/', '^', 'a', 'm', 'M']),
                inner.clone(),
                inner.clone()
            )
                .prop_map(|(op, a, b)| T::Bin(op, Box::new(a), Box::new(b))),
            (proptest::sample::select(Func::ALL.to_vec()), inner)
                .prop_map(|(f, a)| T::F(f, Box::new(a))),
        ]
    })
}

fn point() -> impl Strategy<Value = Vec<f64>> {
    proptest::collection::vec(-3.0..3.0_f64, NAMES.len())
}

proptest! {
    #![proptest_config(config(1024))]

    /// Parsing is faithful: wherever the direct evaluation is finite the parsed expression
    /// gives the same bits (simplification only changes results that are NaN or infinite,
    /// and reordering independent operands changes nothing).
    #[test]
    fn parsed_random_trees_evaluate_like_the_direct_formula(t in tree(), v in point()) {
        let written = text(&t);
        let e = Expr::parse(&written, &NAMES).map_err(|e| TestCaseError::fail(format!("{written}: {e}")))?;
        let want = value(&t, &v);
        if want.is_finite() {
            let got = e.eval(&v);
            prop_assert!(same(got, want), "{written} -> {e}: {got} vs {want}");
        }
    }

    /// Printing is canonical: the printed text re-parses to the identical tree, prints the
    /// same again, and evaluates to the same bits; the same holds for derivatives.
    #[test]
    fn printing_round_trips(t in tree(), v in point(), var in 0..NAMES.len()) {
        let written = text(&t);
        let e = Expr::parse(&written, &NAMES).map_err(|e| TestCaseError::fail(format!("{written}: {e}")))?;
        let printed = e.to_string();
        let again = Expr::parse(&printed, &NAMES).map_err(|err| TestCaseError::fail(format!("{written} printed as {printed}: {err}")))?;
        prop_assert_eq!(&again, &e, "{} printed as {}", written, printed);
        prop_assert_eq!(again.to_string(), printed.clone());
        prop_assert!(same(again.eval(&v), e.eval(&v)), "{printed}");

        let d = e.derivative(var).map_err(|err| TestCaseError::fail(err.to_string()))?;
        let d_printed = d.to_string();
        let d_again = Expr::parse(&d_printed, &NAMES).map_err(|err| TestCaseError::fail(format!("d {printed} = {d_printed}: {err}")))?;
        prop_assert_eq!(&d_again, &d, "d({})/d{} printed as {}", printed, NAMES[var], d_printed);
        prop_assert!(same(d_again.eval(&v), d.eval(&v)), "{d_printed}");
        // A derivative only uses variables the expression uses.
        let used = e.variables_used();
        prop_assert!(d.variables_used().iter().all(|i| used.contains(i)));
        if !used.contains(&var) {
            prop_assert_eq!(d.constant().map(f64::abs), Some(0.0));
        }
    }
}

/// Central difference `∂f/∂v_i` with step `h = ε^(1/3)·max(1, |v_i|)`.
fn central(e: &Expr, v: &[f64], i: usize) -> f64 {
    let h = f64::EPSILON.cbrt() * v[i].abs().max(1.0);
    let (mut p, mut m) = (v.to_vec(), v.to_vec());
    p[i] += h;
    m[i] -= h;
    (e.eval(&p) - e.eval(&m)) / (2.0 * h)
}

/// One expression per function (and per operator), over x, y ∈ [-2, 2], each with the
/// points it must avoid: a kink or jump (`abs`, `sign`) closer than 1e-3, far wider than
/// the finite-difference step (≈ 1e-5).
type Kink = fn(f64, f64) -> bool;
const SMOOTH: Kink = |_, _| false;
const CASES: [(&str, Kink); 22] = [
    ("sin(x*y) + x", SMOOTH),
    ("cos(x^2 - y)", SMOOTH),
    ("tan(x/3)*y", SMOOTH),
    ("exp(-x^2)*y + exp(y/2)", SMOOTH),
    ("log(1 + x^2) - log(3 + y)", SMOOTH),
    ("sqrt(4.5 + x*y)", SMOOTH),
    ("x*abs(x) + abs(x - y)", |x, y| {
        x.abs() < 1e-3 || (x - y).abs() < 1e-3
    }),
    ("sign(x)*y^2 + sign(y - 1)", |x, y| {
        x.abs() < 1e-3 || (y - 1.0).abs() < 1e-3
    }),
    ("tanh(2*x - y)", SMOOTH),
    ("x^3 - 2*x*y^2 + y/(1 + x^2)", SMOOTH),
    ("(1 + x^2)^y", SMOOTH),
    ("2^(x*y) - 1e-3*x", SMOOTH),
    ("(x^2 + 1)^-1.5 - -x/(3 + y)^3", SMOOTH),
    ("sin(x) - x + y*cos(x)", SMOOTH),
    ("atan(3*x*y) - atan(x)", SMOOTH),
    ("asin(x/2.5)*y + acos(y/2.5 - 0.1)", SMOOTH),
    ("sinh(x - y) + cosh(x*y/2)", SMOOTH),
    ("atan2(y + 3, x)", SMOOTH),
    ("atan2(x*y - 0.5, 1 + y^2)*x", SMOOTH),
    ("min(x, y^2)*x + max(x*y, 0.5)", |x, y| {
        (x - y * y).abs() < 1e-3 || (x * y - 0.5).abs() < 1e-3
    }),
    ("0.3*atan(100*x) + 0.1*y", SMOOTH),
    ("sgn(x - 0.5)*ln(2 + y)", |x, _| (x - 0.5).abs() < 1e-3),
];

proptest! {
    #![proptest_config(config(256))]

    /// Symbolic derivatives match central differences. Error of the difference: truncation
    /// `h²·|f'''|/6` plus round-off `≈ ε·|f|/h`; with `h ≈ 6e-6` both factors are ≈ 4e-11,
    /// and `|f|, |f'''| ≤ ~1e2` on these domains, so the error is below ~1e-8. The
    /// tolerance 1e-6·(1 + |f'|) leaves a margin of 100.
    #[test]
    fn derivatives_match_central_differences(case in 0..CASES.len(), x in -2.0..2.0_f64, y in -2.0..2.0_f64) {
        let (text, kink) = CASES[case];
        prop_assume!(!kink(x, y));
        let e = Expr::parse(text, &["x", "y"]).map_err(|err| TestCaseError::fail(err.to_string()))?;
        let v = [x, y];
        for i in 0..2 {
            let d = e.derivative(i).map_err(|err| TestCaseError::fail(err.to_string()))?;
            let (analytic, numeric) = (d.eval(&v), central(&e, &v, i));
            let tol = 1e-6 * (1.0 + analytic.abs());
            prop_assert!((analytic - numeric).abs() <= tol,
                "d({text})/d{} = {d} at {v:?}: {analytic} vs {numeric}", ["x", "y"][i]);
        }
    }

    /// The SPEC §5 examples evaluate like the same formulas written in Rust.
    #[test]
    fn spec_examples_match_rust_formulas(
        theta in -3.0..3.0_f64, omega in -5.0..5.0_f64, x in -3.0..3.0_f64,
        h1 in 0.0..2.0_f64, u in -2.0..2.0_f64,
    ) {
        let vars = ["theta", "omega", "x", "h1", "u"];
        let v = [theta, omega, x, h1, u];
        let sign = |a: f64| if a > 0.0 { 1.0 } else if a < 0.0 { -1.0 } else { 0.0 };
        let cases: [(&str, f64, f64); 7] = [
            // (text, direct value, tolerance): exact where the operations are the same;
            // powf(x, 3) is within 1 ulp of the exact cube and x·x·x within 2, so they
            // differ by at most 3 ulps ≤ 3ε·|x³|; the last case adds a few more roundings.
            ("omega*abs(omega)", omega * omega.abs(), 0.0),
            ("x^3", x * x * x, 4.0 * f64::EPSILON * x.abs().powi(3)),
            ("sqrt(h1)", h1.sqrt(), 0.0),
            ("sin(theta) - theta", theta.sin() - theta, 0.0),
            ("u*cos(theta)", u * theta.cos(), 0.0),
            ("sign(omega)", sign(omega), 0.0),
            ("1e-3*x^3 - 2.5E2*u", 1e-3 * x * x * x - 250.0 * u,
                8.0 * f64::EPSILON * (1e-3 * x.abs().powi(3) + 250.0 * u.abs())),
        ];
        for (text, want, tol) in cases {
            let e = Expr::parse(text, &vars).map_err(|err| TestCaseError::fail(err.to_string()))?;
            let got = e.eval(&v);
            prop_assert!((got - want).abs() <= tol, "{text}: {got} vs {want}");
        }
    }
}
