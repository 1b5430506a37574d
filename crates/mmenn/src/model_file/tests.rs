//! Unit tests of the model-file reader and writer.

use super::*;

const SPEC_EXAMPLE: &str = r#"
states = ["theta", "omega"]          # state names, in order
inputs = ["u"]
A = [[0.0, 1.0], [-9.81, 0.0]]       # n×n
B = [[0.0], [-1.0]]                  # n×m
measured = ["theta"]
corrected = ["omega"]
noise_variance = [1e-4]
units = { theta = "rad", omega = "rad/s", u = "m/s^2" }

[[terms]]
state = "omega"
effect = "coulomb_friction"
term = "sign(omega)"
coefficient = -0.3
"#;

fn problem(text: &str) -> ModelProblem {
    match parse_model(Path::new("m.toml"), text) {
        Err(MmennError::Model { problem, .. }) => problem,
        other => panic!("expected a model error, got {other:?}"),
    }
}

#[test]
fn spec_example_parses_and_round_trips() {
    let spec = parse_model(Path::new("m.toml"), SPEC_EXAMPLE).unwrap();
    assert!((spec.linear.a()[(1, 0)] + 9.81).abs() < 1e-15);
    assert_eq!(spec.linear.c(), &DMatrix::from_row_slice(1, 2, &[1.0, 0.0]));
    assert_eq!(spec.linear.e(), &DMatrix::from_row_slice(2, 1, &[0.0, 1.0]));
    assert_eq!(spec.linear.correction_names(), &["omega".to_string()]);
    assert_eq!(spec.noise_variance, NoiseVariance::Given(vec![1e-4]));
    assert_eq!(spec.terms[0].term, "sign(omega)");
    let again = parse_model(Path::new("m.toml"), &format_model(&spec).unwrap()).unwrap();
    assert_eq!(spec, again);
    assert_eq!(spec.terms[0].into, None);
    // A transfer term keeps its receiving equation through a round trip, and the
    // model it builds subtracts the term there.
    let text = SPEC_EXAMPLE.replace("state = \"omega\"", "state = \"omega\"\ninto = \"theta\"");
    let spec = parse_model(Path::new("m.toml"), &text).unwrap();
    assert_eq!(spec.terms[0].into.as_deref(), Some("theta"));
    let again = parse_model(Path::new("m.toml"), &format_model(&spec).unwrap()).unwrap();
    assert_eq!(spec, again);
    let model = spec.term_model().unwrap();
    let mut dx = [0.0; 2];
    sysid_core::Dynamics::rhs(&model, 0.0, &[0.0, 1.0], &[0.0], &mut dx);
    // theta' = omega + 0.3·sign(omega) (the transfer), omega' = −0.3 (the term).
    assert!(
        (dx[0] - 1.3).abs() < 1e-15 && (dx[1] + 0.3).abs() < 1e-15,
        "{dx:?}"
    );
}

/// `intersample` defaults to the hold, survives a round trip when set, is not written
/// when it is the default, and an unknown value is a syntax error naming it.
#[test]
fn intersample_key() {
    let spec = parse_model(Path::new("m.toml"), SPEC_EXAMPLE).unwrap();
    assert_eq!(spec.intersample, InterSample::Zoh);
    assert!(!format_model(&spec).unwrap().contains("intersample"));
    let text = SPEC_EXAMPLE.replace("noise_variance", "intersample = \"foh\"\nnoise_variance");
    let spec = parse_model(Path::new("m.toml"), &text).unwrap();
    assert_eq!(spec.intersample, InterSample::Foh);
    let again = parse_model(Path::new("m.toml"), &format_model(&spec).unwrap()).unwrap();
    assert_eq!(spec, again);
    let bad = SPEC_EXAMPLE.replace("noise_variance", "intersample = \"spline\"\nnoise_variance");
    match problem(&bad) {
        ModelProblem::Syntax { message } => assert!(message.contains("spline"), "{message}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn correction_units_follow_their_state() {
    let mut spec = parse_model(Path::new("m.toml"), SPEC_EXAMPLE).unwrap();
    spec.units = [("x", "m"), ("v", "m/s"), ("w", "rad/s^2"), ("d_x", "given")]
        .into_iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    assert_eq!(spec.unit_of("v").as_deref(), Some("m/s"));
    assert_eq!(spec.unit_of("d_v").as_deref(), Some("m/s^2"));
    assert_eq!(spec.unit_of("d_w").as_deref(), Some("rad/s^3"));
    assert_eq!(spec.unit_of("d_x").as_deref(), Some("given"));
    assert_eq!(spec.unit_of("d_q"), None);
    assert_eq!(spec.unit_of("u"), None);
    assert_eq!(per_second("N"), "N/s");
}

#[test]
fn general_c_and_auto_noise_round_trip() {
    let text = r#"
states = ["x1", "x2"]
A = [[0.0, 1.0], [-1.0, -0.1]]
C = [[1.0, 1.0]]
outputs = ["s"]
corrected = ["x2"]
noise_variance = "auto"
"#;
    let spec = parse_model(Path::new("m.toml"), text).unwrap();
    assert_eq!(spec.noise_variance, NoiseVariance::Auto);
    assert_eq!(spec.linear.n_inputs(), 0);
    // Leaving the key out means the same.
    let omitted = text.replace("noise_variance = \"auto\"\n", "");
    assert_eq!(parse_model(Path::new("m.toml"), &omitted).unwrap(), spec);
    let again = parse_model(Path::new("m.toml"), &format_model(&spec).unwrap()).unwrap();
    assert_eq!(spec, again);
}

#[test]
fn every_bad_input_class_is_typed() {
    let base = |a: &str, b: &str| {
        SPEC_EXAMPLE
            .replace("A = [[0.0, 1.0], [-9.81, 0.0]]", a)
            .replace("noise_variance = [1e-4]", b)
    };
    assert!(matches!(
        problem(&base(
            "A = [[0.0, 1.0, 2.0], [-9.81, 0.0, 1.0]]",
            "noise_variance = [1e-4]"
        )),
        ModelProblem::RaggedRow {
            matrix: "A",
            row: 0,
            ..
        }
    ));
    assert!(matches!(
        problem(&base("A = [[0.0, 1.0]]", "noise_variance = [1e-4]")),
        ModelProblem::Rows { matrix: "A", .. }
    ));
    assert!(matches!(
        problem(&base(
            "A = [[0.0, 1.0], [-9.81, 0.0]]",
            "noise_variance = [0.0]"
        )),
        ModelProblem::NonPositiveVariance { index: 0, .. }
    ));
    assert!(matches!(
        problem(&base(
            "A = [[0.0, 1.0], [-9.81, 0.0]]",
            "noise_variance = [-1.0]"
        )),
        ModelProblem::NonPositiveVariance { .. }
    ));
    assert!(matches!(
        problem(&base(
            "A = [[0.0, 1.0], [-9.81, 0.0]]",
            "noise_variance = [1.0, 2.0]"
        )),
        ModelProblem::NoiseLength {
            found: 2,
            expected: 1
        }
    ));
    assert!(matches!(
        problem(&base(
            "A = [[0.0, 1.0], [-9.81, 0.0]]",
            "noise_variance = \"guess\""
        )),
        ModelProblem::NoiseWord(_)
    ));
    assert!(matches!(
        problem(&SPEC_EXAMPLE.replace("B = [[0.0], [-1.0]]", "B = [[0.0, 1.0], [-1.0, 1.0]]")),
        ModelProblem::RaggedRow { matrix: "B", .. }
    ));
    assert!(matches!(
        problem(&SPEC_EXAMPLE.replace("measured = [\"theta\"]", "measured = [\"phi\"]")),
        ModelProblem::UnknownName {
            key: "measured",
            ..
        }
    ));
    assert!(matches!(
        problem(&SPEC_EXAMPLE.replace("corrected = [\"omega\"]", "corrected = [\"w\"]")),
        ModelProblem::UnknownName {
            key: "corrected",
            ..
        }
    ));
    assert!(matches!(
        problem(&SPEC_EXAMPLE.replace("state = \"omega\"", "state = \"w\"")),
        ModelProblem::UnknownName {
            key: "terms.state",
            ..
        }
    ));
    for into in ["into = \"w\"", "into = \"omega\""] {
        let text = SPEC_EXAMPLE.replace("state = \"omega\"", &format!("state = \"omega\"\n{into}"));
        assert!(
            matches!(
                problem(&text),
                ModelProblem::UnknownName {
                    key: "terms.into",
                    ..
                }
            ),
            "{into}"
        );
    }
    // A and B left out are zero.
    let bare = SPEC_EXAMPLE
        .replace("B = [[0.0], [-1.0]]", "")
        .replace("A = [[0.0, 1.0], [-9.81, 0.0]]", "");
    let spec = parse_model(Path::new("m.toml"), &bare).unwrap();
    assert_eq!(spec.linear.a(), &DMatrix::zeros(2, 2));
    assert_eq!(spec.linear.b(), &DMatrix::zeros(2, 1));
    assert!(matches!(
        problem(&SPEC_EXAMPLE.replace(
            "measured = [\"theta\"]",
            "measured = [\"theta\"]\nC = [[1.0, 0.0]]"
        )),
        ModelProblem::Conflict { .. }
    ));
    let dup = "states = [\"x\", \"x\"]\nA = [[0.0, 1.0], [0.0, 0.0]]\nmeasured = [\"x\"]\nnoise_variance = [1.0]\n";
    assert!(matches!(
        problem(&SPEC_EXAMPLE.replace("sign(omega)", "sign(omega")),
        ModelProblem::Term(e) if matches!(*e, sysid_core::TermError::Expression { .. })
    ));
    assert!(matches!(
        problem(&SPEC_EXAMPLE.replace("sign(omega)", "sign(phi)")),
        ModelProblem::Term(_)
    ));
    assert!(matches!(
        problem(dup),
        ModelProblem::Model(sysid_core::CoreError::DuplicateName { .. })
    ));
}

#[test]
fn syntax_errors_carry_line_and_column() {
    let text = SPEC_EXAMPLE.replace("inputs = [\"u\"]", "inputs = [\"u\"\nmesured = 3");
    match parse_model(Path::new("m.toml"), &text) {
        Err(MmennError::Model {
            line: Some(l),
            column: Some(_),
            problem: ModelProblem::Syntax { .. },
            ..
        }) => assert!(l >= 3),
        other => panic!("expected a located syntax error, got {other:?}"),
    }
    match parse_model(
        Path::new("m.toml"),
        &format!("{SPEC_EXAMPLE}\nmesured = 1\n"),
    ) {
        Err(MmennError::Model {
            problem: ModelProblem::Syntax { message },
            ..
        }) => assert!(message.contains("mesured"), "{message}"),
        other => panic!("expected unknown key error, got {other:?}"),
    }
}

/// `[acquisition]`: parsed into the filter with its numbers exactly, written back and read
/// again unchanged, absent when the model has none; every malformed table is a typed error
/// naming the key and, for a band, the row.
#[test]
fn acquisition_table_round_trips_and_malformed_ones_name_key_and_row() {
    let with = |table: &str| format!("{SPEC_EXAMPLE}\n[acquisition]\n{table}\n");
    let good = with(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.90, -0.46], [207.5, 0.72, -0.55]]   # centre Hz, re, im",
    );
    let spec = parse_model(Path::new("m.toml"), &good).unwrap();
    let f = spec.acquisition.as_ref().expect("the filter is read");
    assert_eq!(f.pass_below_hz().to_bits(), 190.0_f64.to_bits());
    let expected = [(202.5, 0.90, -0.46), (207.5, 0.72, -0.55)];
    assert_eq!(f.bands().len(), 2);
    for (&(c, g), &(ec, er, ei)) in f.bands().iter().zip(&expected) {
        assert_eq!(
            [c.to_bits(), g.re.to_bits(), g.im.to_bits()],
            [f64::to_bits(ec), f64::to_bits(er), f64::to_bits(ei)]
        );
    }
    assert_eq!(f.standard_errors(), &[None, None]);
    let written = format_model(&spec).unwrap();
    assert!(written.contains("[acquisition]"), "{written}");
    let again = parse_model(Path::new("m.toml"), &written).unwrap();
    assert_eq!(spec, again);
    // A band's fourth number is its standard error, read and written back exactly; a band
    // without one has none.
    let with_se =
        with("pass_below_hz = 190.0\nbands = [[202.5, 0.90, -0.46, 0.013], [207.5, 0.72, -0.55]]");
    let spec = parse_model(Path::new("m.toml"), &with_se).unwrap();
    let f = spec.acquisition.as_ref().expect("the filter is read");
    assert_eq!(f.standard_errors(), &[Some(0.013), None]);
    let again = parse_model(Path::new("m.toml"), &format_model(&spec).unwrap()).unwrap();
    assert_eq!(spec, again);
    // No table: none read, none written.
    let plain = parse_model(Path::new("m.toml"), SPEC_EXAMPLE).unwrap();
    assert!(plain.acquisition.is_none());
    assert!(!format_model(&plain).unwrap().contains("acquisition"));

    let expect =
        |table: &str, key: &str, row: Option<usize>, words: &str| match problem(&with(table)) {
            ModelProblem::Acquisition {
                key: k,
                row: r,
                reason,
            } => {
                assert_eq!((k, r), (key, row), "{table}: {reason}");
                assert!(reason.contains(words), "{table}: {reason}");
            }
            other => panic!("{table}: {other:?}"),
        };
    let bands = "acquisition.bands";
    expect(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46], [202.5, 0.7, -0.5]]",
        bands,
        Some(1),
        "previous row",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[210.0, 0.9, -0.46], [205.0, 0.7, -0.5]]",
        bands,
        Some(1),
        "previous row",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[190.0, 0.9, -0.46]]",
        bands,
        Some(0),
        "pass_below_hz",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[180.0, 0.9, -0.46]]",
        bands,
        Some(0),
        "pass_below_hz",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46], [207.5, nan, -0.5]]",
        bands,
        Some(1),
        "finite",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[inf, 0.9, -0.46]]",
        bands,
        Some(0),
        "finite",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46], [207.5, 0.7]]",
        bands,
        Some(1),
        "expected 3",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46, 1.0, 2.0]]",
        bands,
        Some(0),
        "expected 3",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46, -0.01]]",
        bands,
        Some(0),
        "negative",
    );
    expect(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46], [207.5, 0.7, -0.5, nan]]",
        bands,
        Some(1),
        "finite",
    );
    // A response through zero (here from one at the pass band to −1) has no inverse.
    expect(
        "pass_below_hz = 190.0\nbands = [[202.5, -1.0, 0.0]]",
        bands,
        Some(0),
        "zero",
    );
    expect(
        "pass_below_hz = nan\nbands = [[202.5, 0.9, -0.46]]",
        "acquisition.pass_below_hz",
        None,
        "finite",
    );
    expect(
        "pass_below_hz = -1.0\nbands = [[202.5, 0.9, -0.46]]",
        "acquisition.pass_below_hz",
        None,
        "non-negative",
    );
    // An unknown key, and a missing one, are syntax errors naming them, with the line.
    for (table, word) in [
        (
            "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46]]\ngain = 1.0",
            "gain",
        ),
        ("bands = [[202.5, 0.9, -0.46]]", "pass_below_hz"),
    ] {
        match parse_model(Path::new("m.toml"), &with(table)) {
            Err(MmennError::Model {
                problem: ModelProblem::Syntax { message },
                line,
                ..
            }) => {
                assert!(message.contains(word), "{message}");
                assert!(line.is_some(), "{message}");
            }
            other => panic!("{table}: {other:?}"),
        }
    }
    // The message names the key and row.
    let text = problem(&with(
        "pass_below_hz = 190.0\nbands = [[202.5, 0.9, -0.46], [207.5, 0.7]]",
    ))
    .to_string();
    assert!(text.contains("acquisition.bands, row 1"), "{text}");
}

/// `[x0_prior]` is read in the states' order, checked (unknown state, NaN mean, negative
/// or missing std, unknown field are typed errors naming the state or key), and not part
/// of the spec: `parse_model` drops it and `format_model` does not write it.
#[test]
fn x0_prior_table_is_read_checked_and_not_written() {
    let with = |table: &str| format!("{SPEC_EXAMPLE}\n[x0_prior]\n{table}\n");
    let path = Path::new("m.toml");
    let (spec, prior) = parse_model_and_prior(
        path,
        &with("omega = { mean = 0.5, std = 2.0 }\ntheta = { mean = -1.0, std = 0.1 }"),
    )
    .unwrap();
    assert_eq!(
        prior,
        vec![
            StatePrior::new("theta", -1.0, 0.1),
            StatePrior::new("omega", 0.5, 2.0)
        ]
    );
    assert_eq!(spec, parse_model(path, SPEC_EXAMPLE).unwrap());
    assert!(!format_model(&spec).unwrap().contains("x0_prior"));
    let (_, none) = parse_model_and_prior(path, SPEC_EXAMPLE).unwrap();
    assert!(none.is_empty());
    let prior_problem = |table: &str| match parse_model_and_prior(path, &with(table)) {
        Err(MmennError::Model { problem, .. }) => problem,
        other => panic!("expected a model error, got {other:?}"),
    };
    assert!(matches!(
        prior_problem("h9 = { mean = 1.0, std = 1.0 }"),
        ModelProblem::UnknownName { key: "x0_prior", ref name, .. } if name == "h9"
    ));
    assert!(matches!(
        prior_problem("omega = { mean = nan, std = 1.0 }"),
        ModelProblem::Prior { ref state, field: "mean", .. } if state == "omega"
    ));
    assert!(matches!(
        prior_problem("theta = { mean = 0.0, std = -0.5 }"),
        ModelProblem::Prior { ref state, field: "std", value, .. } if state == "theta" && (value + 0.5).abs() < 1e-15
    ));
    assert!(matches!(
        prior_problem("theta = { mean = 0.0, std = 0.0 }"),
        ModelProblem::Prior { field: "std", .. }
    ));
    let msg = prior_problem("theta = { mean = 0.0, std = inf }").to_string();
    assert!(
        msg.contains("x0_prior.theta.std") && msg.contains("positive and finite"),
        "{msg}"
    );
    assert!(matches!(
        prior_problem("theta = { mean = 0.0 }"),
        ModelProblem::Syntax { .. }
    ));
    assert!(matches!(
        prior_problem("theta = { mean = 0.0, std = 1.0, sd = 2.0 }"),
        ModelProblem::Syntax { .. }
    ));
}

/// `[roles]`: read by state name, written back, and refused when it names no state or an
/// unknown role (a syntax error naming the value, with its line).
#[test]
fn roles_table_round_trips_and_bad_entries_are_typed() {
    let text = format!("{TWO_TANKS_IN_VOLTS}\n[roles]\nh1 = \"level\"\nh2 = \"level\"\n");
    let text = text.as_str();
    let spec = parse_model(Path::new("m.toml"), text).unwrap();
    assert_eq!(
        spec.roles.iter().collect::<Vec<_>>(),
        vec![
            (&"h1".to_string(), &discovery::Role::Level),
            (&"h2".to_string(), &discovery::Role::Level)
        ]
    );
    let written = format_model(&spec).unwrap();
    assert!(written.contains("[roles]"), "{written}");
    assert_eq!(parse_model(Path::new("m.toml"), &written).unwrap(), spec);
    // Without the table there are none, and none are written.
    let plain = text.replace("[roles]\nh1 = \"level\"\nh2 = \"level\"\n", "");
    let spec = parse_model(Path::new("m.toml"), &plain).unwrap();
    assert!(spec.roles.is_empty());
    assert!(!format_model(&spec).unwrap().contains("roles"));
    // A name that is no state (an output here).
    assert!(matches!(
        problem(&text.replace("h2 = \"level\"\n", "y = \"level\"\n")),
        ModelProblem::UnknownName { key: "roles", name, kind: "state" } if name == "y"
    ));
    // A role discover does not know.
    match parse_model(
        Path::new("m.toml"),
        &text.replace("h1 = \"level\"", "h1 = \"tank\""),
    ) {
        Err(MmennError::Model {
            line: Some(12),
            problem: ModelProblem::Syntax { message },
            ..
        }) => assert!(
            message.contains("tank") && message.contains("level"),
            "{message}"
        ),
        other => panic!("expected a syntax error on line 12, got {other:?}"),
    }
}
