//! Unit tests of `Expr`: precedence against hand-evaluated values, error classes and their
//! columns, canonical printing, and derivative forms at the documented special points.

// Expected values in these tests are exact in binary floating point (or exact IEEE
// results such as infinities), so they are compared with `==` on purpose.
#![allow(clippy::float_cmp)]

use super::*;

fn eval0(text: &str) -> f64 {
    match Expr::parse(text, &[]) {
        Ok(e) => e.eval(&[]),
        Err(err) => panic!("{text}: {err}"),
    }
}

fn parse(text: &str, vars: &[&str]) -> Expr {
    match Expr::parse(text, vars) {
        Ok(e) => e,
        Err(err) => panic!("{text}: {err}"),
    }
}

fn err(text: &str, vars: &[&str]) -> ExprError {
    match Expr::parse(text, vars) {
        Ok(e) => panic!("{text} parsed as {e}"),
        Err(err) => err,
    }
}

/// Every value below is exact in binary floating point, so equality is exact.
#[test]
fn precedence_and_associativity_match_hand_values() {
    let cases = [
        ("2^3^2", 512.0),      // right-associative: 2^(3^2)
        ("(2^3)^2", 64.0),     //
        ("-2^2", -4.0),        // ^ binds tighter than unary minus
        ("(-2)^2", 4.0),       //
        ("2^-1", 0.5),         // unary minus in an exponent
        ("-2^-2", -0.25),      // -(2^(-2))
        ("1-2-3", -4.0),       // left-associative
        ("1-(2-3)", 2.0),      //
        ("8/4/2", 1.0),        // left-associative
        ("8/(4/2)", 4.0),      //
        ("2+3*4", 14.0),       // * before +
        ("(2+3)*4", 20.0),     //
        ("2*3^2", 18.0),       // ^ before *
        ("-3*-2", 6.0),        // unary minus inside a product
        ("--3", 3.0),          // nested unary minus
        ("- - -3", -3.0),      //
        ("2 - -3", 5.0),       //
        ("1e-3*1E3", 1.0),     // exponent notation
        ("2.5e+1 - .5", 24.5), //
        ("12/3*2", 8.0),       // * and / at the same level, left to right
        ("4^0.5", 2.0),
        ("sqrt(16) + abs(-3) + sign(-7) + sign(0)", 6.0),
        ("exp(0) + log(1) + sin(0) + cos(0) + tan(0) + tanh(0)", 2.0),
    ];
    for (text, want) in cases {
        assert_eq!(eval0(text), want, "{text}");
    }
}

#[test]
fn sign_is_zero_at_zero_and_functions_follow_ieee_outside_their_domain() {
    assert_eq!(Func::Sign.apply(0.0).abs(), 0.0);
    assert!(Func::Sign.apply(f64::NAN).is_nan());
    assert!(Func::Sqrt.apply(-1.0).is_nan());
    assert!(Func::Log.apply(-1.0).is_nan());
    // Not folded (the value is not finite), evaluated at run time.
    let e = parse("log(0)", &[]);
    assert_eq!(e.to_string(), "log(0)");
    assert_eq!(e.eval(&[]), f64::NEG_INFINITY);
}

#[test]
fn variables_and_their_order() {
    let e = parse("u*cos(theta)", &["theta", "omega", "u"]);
    assert_eq!(e.variables_used(), vec![0, 2]);
    let v = e.eval(&[0.3, 99.0, 2.0]);
    assert!((v - 2.0 * 0.3_f64.cos()).abs() <= f64::EPSILON * 2.0);
    // Split evaluation reads the same variables across two slices.
    assert_eq!(e.eval_parts(&[0.3, 99.0], &[2.0]).to_bits(), v.to_bits());
    // A variable named like a function is a variable unless a '(' follows.
    let e = parse("sign*sign(sign)", &["sign"]);
    assert_eq!(e.eval(&[-2.0]), 2.0);
}

#[test]
fn printing_is_canonical_with_minimal_parentheses() {
    let vars = ["x", "y", "z"];
    let cases = [
        ("x + y*z", "x + y*z"),
        ("(x + y)*z", "(x + y)*z"),
        ("x - (y - z)", "x - (y - z)"),
        ("(x - y) - z", "x - y - z"),
        ("x*(y*z)", "x*(y*z)"),
        ("x/(y*z)", "x/(y*z)"),
        ("-x^2", "-x^2"),
        ("(-x)^2", "(-x)^2"),
        ("x^y^z", "x^y^z"),
        ("(x^y)^z", "(x^y)^z"),
        ("x^-y", "x^(-y)"),
        ("x*-y", "x*(-y)"),
        ("-x*y", "-x*y"),
        ("-(x*y)", "-(x*y)"),
        ("x - -y", "x + y"),
        ("x + -y", "x - y"),
        ("x + -2", "x - 2"),
        ("x - -2", "x + 2"),
        ("(-2)^x", "(-2)^x"),
        ("-2^x", "-2^x"),
        ("x^(-2)", "x^(-2)"),
        ("2*3*x", "6*x"),
        ("0*x + 1*y + z/1 + 0", "y + z"),
        ("- -x", "x"),
        ("-1*x", "-x"),
        ("x^1 + y^0", "x + 1"),
        ("1e-3*x", "0.001*x"),
        ("1e-7*x + 2.5e20", "1e-7*x + 2.5e20"),
        ("sin( x )-x", "sin(x) - x"),
        ("omega*abs(omega)", "omega*abs(omega)"),
    ];
    for (text, want) in cases {
        let vars: &[&str] = if text.contains("omega") {
            &["omega"]
        } else {
            &vars
        };
        let e = parse(text, vars);
        assert_eq!(e.to_string(), want, "{text}");
        assert_eq!(
            parse(want, vars),
            e,
            "{want} does not re-parse to the same tree"
        );
    }
}

#[test]
fn derivative_forms_and_special_points() {
    let vars = ["x", "y"];
    let cases = [
        ("x^3", 0, "3*x^2"),
        ("x*y", 0, "y"),
        ("x*y", 1, "x"),
        ("sin(x)", 0, "cos(x)"),
        ("cos(x)", 0, "-sin(x)"),
        ("abs(x)", 0, "sign(x)"),
        ("sign(x)", 0, "0"),
        ("exp(2*x)", 0, "exp(2*x)*2"),
        ("log(x)", 0, "1/x"),
        ("sqrt(x)", 0, "1/(2*sqrt(x))"),
        ("tanh(x)", 0, "1 - tanh(x)^2"),
        ("tan(x)", 0, "1/cos(x)^2"),
        ("2^x", 0, "2^x*0.6931471805599453"),
        ("x/y", 1, "-x/y^2"),
        ("y", 0, "0"),
    ];
    for (text, var, want) in cases {
        let d = parse(text, &vars)
            .derivative(var)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(d.to_string(), want, "d({text})/d{}", vars[var]);
    }
    // d sqrt(x)/dx at 0 is +inf, as documented.
    let d = parse("sqrt(x)", &vars)
        .derivative(0)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(d.eval(&[0.0, 0.0]), f64::INFINITY);
    // d abs(x)/dx at 0 is sign(0) = 0.
    let d = parse("abs(x)", &vars)
        .derivative(0)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(d.eval(&[0.0, 0.0]), 0.0);
    assert_eq!(d.constant(), None);
    assert_eq!(
        parse("x", &vars).derivative(2),
        Err(ExprError::VariableIndex {
            index: 2,
            n_variables: 2
        })
    );
}

#[test]
fn errors_carry_class_and_column() {
    let v = ["x", "theta"];
    let unexpected = |column, found: &str, expected| ExprError::UnexpectedToken {
        column,
        found: found.to_owned(),
        expected,
    };
    let known = vec!["x".to_owned(), "theta".to_owned()];
    let cases = [
        ("", ExprError::Empty { column: 0 }),
        ("   ", ExprError::Empty { column: 0 }),
        (
            "x + y",
            ExprError::UnknownName {
                column: 4,
                name: "y".into(),
                known: known.clone(),
            },
        ),
        (
            "θ + x",
            ExprError::UnknownName {
                column: 0,
                name: "θ".into(),
                known: known.clone(),
            },
        ),
        (
            "foo(x)",
            ExprError::UnknownFunction {
                column: 0,
                name: "foo".into(),
            },
        ),
        (
            "2*x(1)",
            ExprError::UnknownFunction {
                column: 2,
                name: "x".into(),
            },
        ),
        ("sin x", unexpected(4, "'x'", "'(' after a function name")),
        ("x + * x", unexpected(4, "'*'", super::parse::OPERAND)),
        ("x +", unexpected(3, "end of input", super::parse::OPERAND)),
        ("()", unexpected(1, "')'", super::parse::OPERAND)),
        ("(x x)", unexpected(3, "'x'", "')' or an operator")),
        ("+x", unexpected(0, "'+'", super::parse::OPERAND)),
        ("(x + 1", ExprError::UnclosedParenthesis { column: 0 }),
        ("sin(theta", ExprError::UnclosedParenthesis { column: 3 }),
        ("x + 1)", ExprError::UnmatchedParenthesis { column: 5 }),
        ("x + )", ExprError::UnmatchedParenthesis { column: 4 }),
        (
            "x theta",
            ExprError::TrailingInput {
                column: 2,
                found: "'theta'".into(),
            },
        ),
        (
            "2x",
            ExprError::TrailingInput {
                column: 1,
                found: "'x'".into(),
            },
        ),
        (
            "x # 2",
            ExprError::UnexpectedCharacter {
                column: 2,
                character: '#',
            },
        ),
        (
            "θ·x",
            ExprError::UnexpectedCharacter {
                column: 1,
                character: '·',
            },
        ),
        (
            "x + 1e",
            ExprError::InvalidNumber {
                column: 4,
                text: "1e".into(),
                reason: "the exponent has no digits",
            },
        ),
        (
            "x + .",
            ExprError::InvalidNumber {
                column: 4,
                text: ".".into(),
                reason: "a number needs at least one digit",
            },
        ),
        (
            "1e999",
            ExprError::InvalidNumber {
                column: 0,
                text: "1e999".into(),
                reason: "too large for a 64-bit float",
            },
        ),
    ];
    for (text, want) in cases {
        assert_eq!(err(text, &v), want, "{text}");
    }
    // Columns count characters, not bytes: 'θ' is two bytes.
    assert_eq!(
        err("θ + y", &["θ"]),
        ExprError::UnknownName {
            column: 4,
            name: "y".into(),
            known: vec!["θ".into()]
        }
    );
}

#[test]
fn nesting_limit_is_an_error_not_a_stack_overflow() {
    let deep = format!(
        "{}x{}",
        "(".repeat(MAX_DEPTH + 5),
        ")".repeat(MAX_DEPTH + 5)
    );
    assert!(matches!(
        err(&deep, &["x"]),
        ExprError::TooDeep {
            limit: MAX_DEPTH,
            ..
        }
    ));
    let long_chain = vec!["x"; MAX_DEPTH + 5].join(" - ");
    assert!(matches!(
        err(&long_chain, &["x"]),
        ExprError::TooDeep { .. }
    ));
    let minus = format!("{}x", "-".repeat(MAX_DEPTH + 5));
    assert!(matches!(err(&minus, &["x"]), ExprError::TooDeep { .. }));
    // Within the limit, deep nesting parses and evaluates.
    let ok = format!("{}x{}", "sin(".repeat(40), ")".repeat(40));
    let mut want = 0.5_f64;
    for _ in 0..40 {
        want = want.sin();
    }
    assert_eq!(parse(&ok, &["x"]).eval(&[0.5]).to_bits(), want.to_bits());
}

#[test]
fn declared_variables_are_checked() {
    assert_eq!(
        Expr::parse("x", &["x", "x"]),
        Err(ExprError::DuplicateVariable { name: "x".into() })
    );
    for bad in ["", "1x", "a b", "x-y"] {
        assert_eq!(
            Expr::parse("1", &[bad]),
            Err(ExprError::InvalidVariableName { name: bad.into() })
        );
    }
}

#[test]
fn rebinding_variables_by_name() {
    let e = parse("sign(omega)*u", &["omega", "u"]);
    let r = e
        .with_variables(&["theta", "omega", "h", "u"])
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(r.variables_used(), vec![1, 3]);
    assert_eq!(r.eval(&[9.0, -2.0, 9.0, 3.0]), -3.0);
    assert_eq!(r.to_string(), e.to_string());
    assert_eq!(
        e.with_variables(&["omega"]),
        Err(ExprError::MissingVariable { name: "u".into() })
    );
}

/// A right-nested chain of non-commutative operators is the worst case for a postfix
/// stack; with operands emitted deeper-first it still needs only 2 slots, and 1 when the
/// left operands are leaves (read in place).
#[test]
fn deep_right_nesting_fits_the_fixed_stack() {
    let n = MAX_DEPTH / 2 - 2;
    let nested = format!("{}x{}", "abs(x)/(".repeat(n / 2), ")".repeat(n / 2));
    let e = parse(&nested, &["x"]);
    assert_eq!(compile(&e.tree).1, 2);
    assert_eq!(
        e.eval(&[-3.0]).to_bits(),
        tree_value(&e.tree, &[-3.0]).to_bits()
    );
    let text = format!("{}x{}", "x/(".repeat(n), ")".repeat(n));
    let e = parse(&text, &["x"]);
    let (_, need) = compile(&e.tree);
    assert_eq!(need, 1);
    // x/(x/(x/…x)) alternates between x and 1: n divisions of x = 3 give 1 for even n.
    let want = if n.is_multiple_of(2) { 3.0 } else { 1.0 };
    assert!((e.eval(&[3.0]) - want).abs() <= 1e-15 * n as f64);
}

/// The functions added for physical models: values at points where they are exact or
/// known in closed form, aliases, and two-argument calls.
#[test]
fn inverse_hyperbolic_and_two_argument_functions() {
    let pi = std::f64::consts::PI;
    let cases = [
        ("atan(1)", pi / 4.0),
        ("asin(1)", pi / 2.0),
        ("acos(-1)", pi),
        ("sinh(0) + cosh(0)", 1.0),
        ("atan2(1, -1)", 3.0 * pi / 4.0),
        ("atan2(-1, 0)", -pi / 2.0),
        ("min(2, -3) + max(2, -3)", -1.0),
        ("sgn(-2) + ln(1)", -1.0),
        ("max(min(1, 2), 0.5)^2", 1.0),
        ("2*acos(0) - pi", 0.0),
    ];
    for (text, want) in cases {
        let got = eval0(text);
        assert!(
            (got - want).abs() <= 4.0 * f64::EPSILON,
            "{text}: {got} vs {want}"
        );
    }
    assert!(Func::Asin.apply(1.5).is_nan());
    // `pi` is π unless declared as a variable.
    assert_eq!(parse("pi", &["x"]).constant(), Some(std::f64::consts::PI));
    assert_eq!(parse("pi", &["pi"]).eval(&[2.0]), 2.0);
    let e = parse("min(x, y)", &["x", "y"]);
    assert!(e.eval(&[f64::NAN, 1.0]).is_nan() && e.eval(&[1.0, f64::NAN]).is_nan());
    // Printing keeps the call form and the canonical names.
    for (text, want) in [
        ("atan2(x,y)*2", "atan2(x, y)*2"),
        ("-min(x, -y)", "-min(x, -y)"),
        ("max(x + y, x*y)^2", "max(x + y, x*y)^2"),
        ("sgn(x) + ln(y)", "sign(x) + log(y)"),
        ("atan(x)/(1 + atan2(y, x))", "atan(x)/(1 + atan2(y, x))"),
    ] {
        let e = parse(text, &["x", "y"]);
        assert_eq!(e.to_string(), want, "{text}");
        assert_eq!(parse(want, &["x", "y"]), e, "{want}");
    }
    // Derivative forms.
    for (text, var, want) in [
        ("atan(x)", 0, "1/(1 + x^2)"),
        ("asin(x)", 0, "1/sqrt(1 - x^2)"),
        ("acos(x)", 0, "-1/sqrt(1 - x^2)"),
        ("sinh(x)", 0, "cosh(x)"),
        ("cosh(x)", 0, "sinh(x)"),
        ("atan2(x, y)", 0, "y/(x^2 + y^2)"),
        ("atan2(x, y)", 1, "-x/(x^2 + y^2)"),
        ("min(x, y)", 0, "0.5*(1 - sign(x - y))"),
        ("max(x, y)", 1, "0.5*(1 - sign(x - y))"),
    ] {
        let d = parse(text, &["x", "y"])
            .derivative(var)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(d.to_string(), want, "d({text})/d{var}");
    }
    // Errors in two-argument calls.
    assert_eq!(
        err("atan2(x)", &["x"]),
        ExprError::UnexpectedToken {
            column: 7,
            found: "')'".into(),
            expected: "',' between the two arguments",
        }
    );
    assert_eq!(
        err("min(x, x", &["x"]),
        ExprError::UnclosedParenthesis { column: 3 }
    );
    assert_eq!(
        err("sin(x, x)", &["x"]),
        ExprError::UnexpectedToken {
            column: 5,
            found: "','".into(),
            expected: "')' or an operator",
        }
    );
    assert!(matches!(
        err("max", &["x"]),
        ExprError::UnexpectedToken { .. }
    ));
}

/// `substitute` folds constants in and `eval3` reads states, inputs and parameters from
/// three slices like one concatenated buffer.
#[test]
fn substitution_and_three_slice_evaluation() {
    let vars = ["q", "v", "u", "m", "l"];
    let e = parse("m*l^2*v + u*cos(q) - m*9.81*l*sin(q)", &vars);
    let (x, u, p) = ([0.3, -1.2], [0.7], [0.5, 2.0]);
    let flat = [0.3, -1.2, 0.7, 0.5, 2.0];
    assert_eq!(e.eval3(&x, &u, &p).to_bits(), e.eval(&flat).to_bits());
    let bound = e.substitute(&[None, None, None, Some(0.5), Some(2.0)]);
    assert_eq!(bound.to_string(), "2*v + u*cos(q) - 9.81*sin(q)");
    let bound = bound
        .with_variables(&["q", "v", "u"])
        .unwrap_or_else(|e| panic!("{e}"));
    assert!((bound.eval(&flat[..3]) - e.eval(&flat)).abs() <= 1e-15);
    // Substituting every variable gives a constant; a non-finite fold stays a node.
    let all = e.substitute(&flat.map(Some));
    assert_eq!(
        all.constant().map(f64::to_bits),
        Some(e.eval(&flat).to_bits())
    );
    let log = parse("log(m)", &vars).substitute(&[None, None, None, Some(0.0), None]);
    assert_eq!(log.to_string(), "log(0)");
}

/// The same bits, or both NaN (a NaN's payload is not part of the semantics).
fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
}

/// Reference semantics, independent of the compiled program: the tree evaluated
/// recursively by the module doc's rules (`a^2` is `a·a`, a constant integer exponent up
/// to 16 `powi`, any other power `powf`).
fn tree_value(t: &Tree, v: &[f64]) -> f64 {
    match t {
        Tree::Const(c) => *c,
        Tree::Var(i) => v[*i],
        Tree::Neg(a) => -tree_value(a, v),
        Tree::Call(f, a) => f.apply(tree_value(a, v)),
        Tree::Bin(tree::BinOp::Pow, a, b) => match **b {
            Tree::Const(2.0) => {
                let x = tree_value(a, v);
                x * x
            }
            Tree::Const(c) if c.fract() == 0.0 && c.abs() <= 16.0 => {
                tree_value(a, v).powi(c as i32)
            }
            _ => tree::BinOp::Pow.apply(tree_value(a, v), tree_value(b, v)),
        },
        Tree::Bin(op, a, b) => op.apply(tree_value(a, v), tree_value(b, v)),
    }
}

/// The compiled program (every instruction form: operands pushed or read in place,
/// left or right, each operator) against the tree evaluated recursively, bit for bit, on
/// the terms of the real benchmarks' grey boxes and their derivatives, at points with
/// zeros, signs, infinities and NaN.
#[test]
fn programs_evaluate_exactly_as_the_tree() {
    let vars = ["y", "v", "w", "u"];
    let texts = [
        "sqrt((y + abs(y))/2)",
        "sqrt((v + abs(v))/2 + 0.0001)",
        "(v - 5)*sqrt((y + abs(y))/2)",
        "(y - 10 + abs(y - 10))/2",
        "(w - 5)*u",
        "tanh(v/0.0003)",
        "(v + abs(v))/2",
        "(v - abs(v))/2",
        "y^3",
        "y^5",
        "y^2*v",
        "v*abs(v)",
        "u*y^2",
        "u*y",
        "y*v*w",
        "3 - y",
        "y - 3",
        "3/y",
        "y/3",
        "1/(1 + y^2)",
        "atan2(y, v)",
        "atan2(2, v)",
        "atan2(y, 2)",
        "min(y, v) + max(1, w)",
        "y^0.5 + 2^y + y^v",
        "xmuly(y, v) + xdivy(v, y)",
        "exp(-y^2)*sin(3*v) - cos(w)/2",
        "-(y*v) + (w - u)*(y + v)",
    ];
    let values = [0.0, -0.0, 0.75, -2.25, 12.5, f64::INFINITY, f64::NAN];
    for text in texts {
        let e = parse(text, &vars);
        let mut all = vec![e.clone()];
        for var in 0..vars.len() {
            all.push(e.derivative(var).expect("differentiable"));
        }
        for f in &all {
            for &a in &values {
                for &b in &values {
                    for &c in &[0.0, -1.5] {
                        let point = [a, b, c, 0.3 - c];
                        let got = f.eval(&point);
                        let want = tree_value(&f.tree, &point);
                        assert!(same(got, want), "{f} at {point:?}: {got} vs {want}");
                    }
                }
            }
        }
    }
}

#[test]
fn shapes_evaluate_exactly_as_the_stack_program() {
    // Every shortcut shape, and expressions just outside each, against the postfix
    // program on the full stack: bit-identical at points that include 0, negatives,
    // infinities and NaN.
    let vars = ["x", "y", "z"];
    let texts = [
        "2.5",
        "x",
        "z",
        "x^2",
        "y^3",
        "x^-2",
        "x*y",
        "y*x",
        "x*x",
        "(x*y)*z",
        "x^2*y",
        "2*x",
        "x*2",
        "-x",
        "x + y",
        "x/y",
        "abs(x)*y",
        "x^0.5",
        "sqrt(x)",
        "x^2^2",
        "xmuly(x, y)",
        "xdivy(x, y)",
        "3*x^2",
        "x^2*3",
        "-2.5*y^4",
        "x^2*y",
        "y*x^2",
        "2*x*y",
        "(2*x)*y",
        "2*(x*y)",
        "y*abs(x)",
        "abs(x)*y",
        "y*sign(x)",
    ];
    let values = [0.0, -0.0, 1.5, -2.25, 1e300, -7.0, f64::INFINITY, f64::NAN];
    for text in texts {
        let e = parse(text, &vars);
        for &a in &values {
            for &b in &values {
                let point = [a, b, 0.75];
                let fast = e.eval(&point);
                let full = e.exec::<STACK>(|i| point[i]);
                let reference = tree_value(&e.tree, &point);
                for other in [full, reference] {
                    assert!(same(fast, other), "{text} at {point:?}: {fast} vs {other}");
                }
            }
        }
    }
    // The shapes are taken where they apply.
    type IsShape = fn(&Shape) -> bool;
    let taken: [(&str, IsShape); 12] = [
        ("y^3", |s| matches!(s, Shape::PowI(1, 3))),
        ("x*y", |s| matches!(s, Shape::Product(0, 1))),
        ("x^2", |s| matches!(s, Shape::Square(0))),
        ("4", |s| matches!(s, Shape::Const(_))),
        ("(x*y)*z", |s| matches!(s, Shape::Small)),
        ("2*x", |s| matches!(s, Shape::ConstTimes(_, 0))),
        ("3*x^2", |s| matches!(s, Shape::ConstTimesSquare(_, 0))),
        ("-2.5*y^4", |s| matches!(s, Shape::ConstTimesPowI(_, 1, 4))),
        ("x^2*y", |s| matches!(s, Shape::SquareTimes(0, 1))),
        ("y*x^2", |s| matches!(s, Shape::TimesSquare(0, 1))),
        ("2*x*y", |s| matches!(s, Shape::ConstProduct(_, 0, 1))),
        ("y*abs(x)", |s| matches!(s, Shape::TimesAbs(0, 1))),
    ];
    for (text, is) in taken {
        let shape = parse(text, &vars).shape;
        assert!(is(&shape), "{text}: {shape:?}");
    }
}

/// Central difference `∂e/∂v_var` with step `ε^(1/3)·max(1, |v_var|)`.
fn central(e: &Expr, v: &[f64], var: usize) -> f64 {
    let h = f64::EPSILON.cbrt() * v[var].abs().max(1.0);
    let (mut p, mut m) = (v.to_vec(), v.to_vec());
    p[var] += h;
    m[var] -= h;
    (e.eval(&p) - e.eval(&m)) / (2.0 * h)
}

/// The chain rule's strong zero: where a term's argument is held (its inner derivative is
/// exactly 0) the slope is exactly 0, although the outer slope there is infinite or NaN
/// (the plain rule gave 0/0 or 0·inf = NaN for every case but `log(max(x, 1))`, whose
/// argument is held at 1). Where the argument moves, the slope matches a central
/// difference, and every derivative prints to text that parses back to it.
#[test]
fn strong_zero_where_the_inner_derivative_vanishes() {
    let vars = ["x", "y"];
    // (text, variable, a point of the held region with x replaced, x values where the
    // argument moves): the held region is x < 0 unless the text says otherwise.
    let held = [-3.0, -0.5, -1e-3];
    let moving = [0.3, 1.7, 4.0];
    let cases: [(&str, usize, &[f64], &[f64]); 14] = [
        ("sqrt(max(x, 0))", 0, &held, &moving),
        ("sqrt((x + abs(x))/2)", 0, &held, &moving),
        ("(y - 5)*sqrt(max(x, 0))", 0, &held, &moving),
        ("(y - 5)*sqrt(max(x, 0))", 1, &held, &moving),
        ("log(max(x, 1))", 0, &[-3.0, 0.5, 0.999], &[1.3, 2.0, 4.0]),
        ("max(x, 0)^0.5", 0, &held, &moving),
        ("max(x, 0)^0.25*y", 0, &held, &moving),
        ("max(x, 0)^y", 0, &held, &moving),
        // d/dy of 0^y is 0 for y > 0 (the limit of a^y·log(a) as a → 0).
        ("max(x, 0)^y", 1, &held, &moving),
        ("asin(min(x, 1))", 0, &[1.001, 2.0, 5.0], &[-0.9, 0.2, 0.7]),
        (
            "acos(max(x, -1))",
            0,
            &[-1.001, -2.0, -5.0],
            &[-0.9, 0.2, 0.7],
        ),
        ("exp(log(max(x, 0)))", 0, &held, &moving),
        ("atan2(max(x, 0), max(y - 3, 0))", 0, &held, &moving),
        ("atan2(max(x, 0), max(y - 3, 0))", 1, &held, &moving),
    ];
    for (text, var, zero_at, slope_at) in cases {
        let e = parse(text, &vars);
        let d = e.derivative(var).unwrap_or_else(|e| panic!("{e}"));
        let printed = d.to_string();
        assert_eq!(parse(&printed, &vars), d, "d({text}) = {printed}");
        for &x in zero_at {
            let got = d.eval(&[x, 2.0]);
            assert!(
                got == 0.0,
                "d({text})/d{} = {printed} at x = {x}: {got}",
                vars[var]
            );
        }
        for &x in slope_at {
            let v = [x, 2.0];
            let (got, want) = (d.eval(&v), central(&e, &v, var));
            assert!(
                (got - want).abs() <= 1e-6 * (1.0 + got.abs()),
                "d({text})/d{} = {printed} at x = {x}: {got} vs {want}",
                vars[var]
            );
        }
    }
    // A second derivative keeps the strong zero too.
    let d2 = parse("sqrt(max(x, 0))", &vars)
        .derivative(0)
        .and_then(|d| d.derivative(0))
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(parse(&d2.to_string(), &vars), d2);
    assert!(d2.eval(&[-1.0, 0.0]) == 0.0, "{d2}");
    let want = -0.25 * 2.0_f64.powf(-1.5);
    assert!((d2.eval(&[2.0, 0.0]) - want).abs() <= 1e-15, "{d2}");
}

/// Only a zero inner derivative gives the strong zero: where the argument moves into the
/// singular point, the slope is still the infinite one of the plain rule, and a constant
/// inner derivative keeps the plain printed form.
#[test]
fn strong_zero_needs_a_zero_inner_derivative() {
    let vars = ["x", "y"];
    for (text, point, want) in [
        ("sqrt(max(x, 0))", [0.0, 0.0], f64::INFINITY),
        ("sqrt(x)", [0.0, 0.0], f64::INFINITY),
        ("sqrt(2*x)", [0.0, 0.0], f64::INFINITY),
        ("max(x, 0)^0.5", [0.0, 0.0], f64::INFINITY),
        ("log(abs(x) + x)", [0.0, 0.0], f64::INFINITY),
        ("asin(x)", [1.0, 0.0], f64::INFINITY),
        // A varying exponent: the slope of x^y at x = 0 is infinite for y < 1, y for
        // y = 1 and 0 for y > 1 (the old form a^b·b/a gave 0·inf = NaN for every y > 0).
        ("x^y", [0.0, 0.5], f64::INFINITY),
        ("x^y", [0.0, 1.0], 1.0),
        ("x^y", [0.0, 2.0], 0.0),
    ] {
        let d = parse(text, &vars)
            .derivative(0)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(d.eval(&point), want, "d({text}) = {d} at {point:?}");
    }
    // atan2 has no slope at the origin: NaN unless both arguments are held there.
    let d = parse("atan2(x, max(y, 0))", &vars)
        .derivative(0)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(d.eval(&[0.0, -1.0]).is_nan(), "{d}");
    // Printed forms: plain where the inner derivative is a constant, the strong products
    // where it varies.
    for (text, want) in [
        ("sqrt(2*x)", "2/(2*sqrt(2*x))"),
        ("(2*x)^0.5", "0.5*(2*x)^(-0.5)*2"),
        (
            "sqrt(max(x, 0))",
            "xdivy(0.5*(1 + sign(x)), 2*sqrt(max(x, 0)))",
        ),
        ("log(y*x)", "xdivy(y, y*x)"),
        ("log(x^2)", "xdivy(2*x, x^2)"),
        (
            "max(x, 0)^0.5",
            "xmuly(0.5*(1 + sign(x)), 0.5*max(x, 0)^(-0.5))",
        ),
        ("sin(x^2)", "cos(x^2)*(2*x)"),
        ("(x^2)^3", "3*(x^2)^2*(2*x)"),
        ("asin(x^2)", "xdivy(2*x, sqrt(1 - (x^2)^2))"),
        ("x^y", "y*x^(y - 1)"),
        ("y^x", "xmuly(y^x, log(y))"),
        ("atan2(x^2, y)", "xmuly(2*x, y/((x^2)^2 + y^2))"),
    ] {
        let d = parse(text, &vars)
            .derivative(0)
            .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(d.to_string(), want, "d({text})/dx");
        assert_eq!(parse(want, &vars), d, "{want}");
    }
}

/// `xmuly` and `xdivy`: the plain product and quotient bit for bit wherever those are
/// not NaN, 0 where the first argument is 0 and they are; their simplifications.
#[test]
fn strong_zero_products_evaluate_and_simplify() {
    let vars = ["x", "y"];
    let mul = parse("xmuly(x, y)", &vars);
    let div = parse("xdivy(x, y)", &vars);
    let values = [
        0.0,
        -0.0,
        1.5,
        -2.25,
        1e-320,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
    ];
    for &a in &values {
        for &b in &values {
            for (e, plain) in [(&mul, a * b), (&div, a / b)] {
                let got = e.eval(&[a, b]);
                if !plain.is_nan() {
                    assert_eq!(got.to_bits(), plain.to_bits(), "{e} at ({a}, {b})");
                } else if a == 0.0 {
                    assert_eq!(got.to_bits(), 0.0_f64.to_bits(), "{e} at ({a}, {b})");
                } else {
                    assert!(got.is_nan(), "{e} at ({a}, {b}): {got}");
                }
            }
        }
    }
    for (text, want) in [
        ("xmuly(x, y)", "xmuly(x, y)"),
        ("xdivy(x + 1, y)*2", "xdivy(x + 1, y)*2"),
        ("xmuly(0, y)", "0"),
        ("xdivy(0, y)", "0"),
        ("xmuly(2, y)", "2*y"),
        ("xdivy(-2, y)", "-2/y"),
        ("xmuly(x, 1) + xdivy(y, -1)", "x - y"),
        ("xmuly(x, 0)", "0"),
        ("xmuly(3, 2) + xdivy(1, 4)", "6.25"),
        ("-xdivy(x, y)^2", "-xdivy(x, y)^2"),
    ] {
        let e = parse(text, &vars);
        assert_eq!(e.to_string(), want, "{text}");
        assert_eq!(parse(want, &vars), e, "{want}");
    }
    // Their own derivatives keep the strong zero of the first argument.
    let e = parse("xdivy(max(x, 0), y) + xmuly(max(x, 0), log(y))", &vars);
    for var in 0..2 {
        let d = e.derivative(var).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(parse(&d.to_string(), &vars), d);
        assert!(d.eval(&[-1.0, 0.0]) == 0.0, "{d}");
        let v = [0.7, 1.3];
        let (got, want) = (d.eval(&v), central(&e, &v, var));
        assert!(
            (got - want).abs() <= 1e-6 * (1.0 + got.abs()),
            "{d}: {got} vs {want}"
        );
    }
    assert!(matches!(
        err("xmuly(x)", &vars),
        ExprError::UnexpectedToken { .. }
    ));
}
