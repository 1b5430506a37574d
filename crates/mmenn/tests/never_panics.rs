//! Issue 21: the readers never panic. Arbitrary text and mutations of valid files go into
//! the CSV reader, the TOML model reader, the term-expression parser (with its
//! derivative, canonical printing and evaluation) and the model.json reader; each returns
//! `Ok` or a typed error.

use std::path::Path;

use mmenn::data_file::{parse_table, table_to_experiment};
use mmenn::model_file::parse_model;
use mmenn::sysid_core::Expr;
use proptest::prelude::*;

const MODEL: &str = r#"
states = ["theta", "omega"]
inputs = ["u"]
A = [[0.0, 1.0], [-19.62, -0.2]]
B = [[0.0], [-2.0]]
measured = ["theta"]
corrected = ["omega"]
noise_variance = [0.01]
units = { theta = "rad" }
[[terms]]
state = "omega"
effect = "friction"
term = "sign(omega) * exp(-theta^2) / (1 + u)"
coefficient = -0.3
"#;

const CSV: &str = "t,u,theta\n0,1,0.5\n0.1,1,\n0.2,0.5,0.25\n0.3,NaN,1e308\n";

/// Characters that matter to the grammars, plus anything.
fn text() -> impl Strategy<Value = String> {
    prop_oneof![
        "[-+*/^(),.0-9a-zeEtxuq_ \n\"=\\[\\]{}#:;'NaIinf]{0,80}",
        any::<String>(),
    ]
}

/// `base` with `edits` applied: delete, insert or replace a few characters.
fn mutate(base: &str, edits: &[(usize, u8, char)]) -> String {
    let mut chars: Vec<char> = base.chars().collect();
    for &(pos, op, c) in edits {
        if chars.is_empty() {
            chars.push(c);
            continue;
        }
        let i = pos % chars.len();
        match op % 3 {
            0 => {
                chars.remove(i);
            }
            1 => chars.insert(i, c),
            _ => chars[i] = c,
        }
    }
    chars.into_iter().collect()
}

fn edits() -> impl Strategy<Value = Vec<(usize, u8, char)>> {
    prop::collection::vec(
        (
            0usize..10_000,
            any::<u8>(),
            prop_oneof![
                Just(','),
                Just('\n'),
                Just('"'),
                Just('['),
                Just(']'),
                Just('='),
                Just('-'),
                Just('e'),
                Just('0'),
                Just('.'),
                any::<char>()
            ],
        ),
        1..6,
    )
}

fn read_csv(bytes: &[u8]) {
    if let Ok(t) = parse_table(Path::new("d.csv"), bytes) {
        let _ = table_to_experiment(&t, &["u".to_string()], &["theta".to_string()]);
        let _ = table_to_experiment(&t, &[], &[]);
    }
}

fn use_expr(text: &str) {
    let vars = ["x", "v", "u", "q"];
    if let Ok(e) = Expr::parse(text, &vars) {
        let _ = e.eval(&[0.5, -1.0, 0.0, 2.0]);
        let _ = e.eval(&[0.0, 0.0, 0.0, 0.0]);
        let _ = e.to_string();
        for var in 0..vars.len() {
            if let Ok(d) = e.derivative(var) {
                let _ = d.eval(&[1e300, -1e-300, f64::NAN, 0.0]);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    #[test]
    fn csv_reader_never_panics(s in text(), bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        read_csv(s.as_bytes());
        read_csv(&bytes);
    }

    #[test]
    fn csv_reader_survives_mutations(e in edits()) {
        read_csv(mutate(CSV, &e).as_bytes());
    }

    #[test]
    fn model_reader_never_panics(s in text(), e in edits()) {
        let _ = parse_model(Path::new("m.toml"), &s);
        if let Ok(spec) = parse_model(Path::new("m.toml"), &mutate(MODEL, &e)) {
            let _ = spec.term_model();
            let _ = mmenn::model_file::format_model(&spec);
        }
    }

    #[test]
    fn expression_parser_never_panics(s in text(), e in edits()) {
        use_expr(&s);
        use_expr(&mutate("sign(v) * exp(-x^2) / (1 + u) - 3.5e-2*q^3", &e));
    }

    #[test]
    fn model_json_reader_never_panics(s in text(), e in edits()) {
        let _ = mmenn::fit::HybridFile::parse(Path::new("model.json"), &s);
        let _ = mmenn::fit::HybridFile::parse(Path::new("model.json"), &mutate(&model_json(), &e));
    }
}

fn model_json() -> String {
    let spec = parse_model(Path::new("m.toml"), MODEL).unwrap();
    let file = mmenn::fit::HybridFile {
        format: mmenn::fit::HYBRID_FORMAT.into(),
        model_toml: mmenn::model_file::format_model(&spec).unwrap(),
        network: mmenn::nn::Mlp::new(&mmenn::nn::Architecture::single(3, 2, 1), 1).unwrap(),
        x0: vec![0.0, 0.0],
        dt: 0.01,
        substeps: 4,
        domain: mmenn::nn::Domain::Extrapolate,
    };
    serde_json::to_string(&file).unwrap()
}

#[test]
fn the_seed_files_are_valid() {
    assert!(parse_model(Path::new("m.toml"), MODEL).is_ok());
    assert!(mmenn::fit::HybridFile::parse(Path::new("model.json"), &model_json()).is_ok());
    let t = parse_table(Path::new("d.csv"), CSV.as_bytes()).unwrap();
    assert!(table_to_experiment(&t, &["u".to_string()], &["theta".to_string()]).is_err());
}
