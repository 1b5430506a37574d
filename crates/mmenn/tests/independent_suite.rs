//! The independent discovery suite: `mmenn discover` on records that mmenn did not make
//! (`fixtures/discovery_suite`, written by a Python/scipy RK45 generator with its own
//! inputs and noise), scored by the rule written in that folder's README before the
//! first run:
//!
//! (a) the verdict is the expected one; (b) for `found`, every hidden effect is claimed
//! (in `effects`) under its catalogue name, in its equation, reading its variables, with
//! coefficient relative error ≤ 10 % (a transfer between tanks as one transfer term or
//! as the pair of terms); (c) no other nonlinear catalogue name is claimed — linear
//! corrections (`viscous_damping`, `linear_stiffness`, `linear_coupling`, `input_gain`)
//! and `constant_bias` are allowed; (d) outside-catalogue cases claim no nonlinear name.
//!
//! Every case runs with default `DiscoverOptions`, estimation and validation records,
//! cases in parallel on plain threads. One line per case, then the pass count.
//! `MMENN_SUITE=case1,case2` restricts the run (the count assertions then do not apply).
#![allow(clippy::print_stderr)]

use std::collections::{BTreeMap, BTreeSet};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use mmenn::discover::{DiscoverOptions, run_discover};
use serde_json::Value;

/// Regression floor: the number of cases that passed on the code when it was last set
/// (`fixtures/discovery_suite/README.md`, session 8: 41 of 41; one case of margin). Issue 15's target
/// is ≥ 90 % of the cases; the lead raises this floor as the verdicts improve.
const PASS_FLOOR: usize = 40;

/// The suite must not pass vacuously.
const MIN_CASES: usize = 24;

/// Largest relative coefficient error of a claimed hidden effect.
const REL_TOL: f64 = 0.10;

/// Catalogue names that are linear corrections of `A`/`B` or an affine offset: allowed
/// in every case and never counted as extra names.
const LINEAR: [&str; 5] = [
    "viscous_damping",
    "linear_stiffness",
    "linear_coupling",
    "input_gain",
    "constant_bias",
];

/// Function names of the expression language (not variables).
const FUNCTIONS: [&str; 12] = [
    "sqrt", "abs", "sign", "tanh", "exp", "sin", "cos", "tan", "log", "max", "min", "pow",
];

fn suite_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/discovery_suite")
}

/// A hidden effect as `answers.json` states it.
#[derive(Debug, Clone)]
struct Hidden {
    effect: String,
    state: String,
    into: Option<String>,
    variables: BTreeSet<String>,
    coefficient: f64,
    parameters: BTreeMap<String, f64>,
}

#[derive(Debug, Clone)]
struct Case {
    name: String,
    expected: String,
    hidden: Vec<Hidden>,
}

/// A claimed (or unconfirmed) term as `discovery.json` reports it.
#[derive(Debug, Clone)]
struct Claim {
    name: String,
    state: String,
    into: Option<String>,
    variables: BTreeSet<String>,
    coefficient: f64,
    parameters: BTreeMap<String, f64>,
}

#[derive(Debug)]
struct Outcome {
    verdict: String,
    effects: Vec<Claim>,
    unconfirmed: Vec<Claim>,
    pass: bool,
    reason: String,
    seconds: f64,
}

fn numbers(v: Option<&Value>) -> BTreeMap<String, f64> {
    v.and_then(Value::as_object)
        .map(|m| {
            m.iter()
                .filter_map(|(k, x)| x.as_f64().map(|x| (k.clone(), x)))
                .collect()
        })
        .unwrap_or_default()
}

fn text(v: &Value, key: &str) -> String {
    v[key]
        .as_str()
        .unwrap_or_else(|| panic!("`{key}` missing in {v}"))
        .to_string()
}

fn read_cases() -> Vec<Case> {
    let path = suite_dir().join("answers.json");
    let raw = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    let answers: Value = serde_json::from_str(&raw).unwrap();
    answers["cases"]
        .as_array()
        .expect("answers.json: cases")
        .iter()
        .map(|c| Case {
            name: text(c, "name"),
            expected: text(c, "expected_verdict"),
            hidden: c["hidden_effects"]
                .as_array()
                .expect("hidden_effects")
                .iter()
                .map(|h| Hidden {
                    effect: text(h, "effect"),
                    state: text(h, "state"),
                    into: h["into"].as_str().map(str::to_string),
                    variables: h["variables"]
                        .as_array()
                        .expect("variables")
                        .iter()
                        .map(|v| v.as_str().unwrap().to_string())
                        .collect(),
                    coefficient: h["coefficient"].as_f64().expect("coefficient"),
                    parameters: numbers(h.get("parameters")),
                })
                .collect(),
        })
        .collect()
}

/// The variables an expression reads: identifiers that are not function names (numbers,
/// including exponents such as `1e-3`, start with a digit or a point and are skipped).
fn identifiers(term: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    let mut word = String::new();
    for ch in term.chars().chain(std::iter::once(' ')) {
        if ch.is_ascii_alphanumeric() || ch == '_' || ch == '.' {
            word.push(ch);
            continue;
        }
        let starts_alpha = word
            .chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_');
        if starts_alpha && !FUNCTIONS.contains(&word.as_str()) {
            out.insert(word.clone());
        }
        word.clear();
    }
    out
}

/// One name for an effect and its integration form.
fn canonical(name: &str) -> &str {
    name.strip_suffix("_smooth").unwrap_or(name)
}

fn claims(v: &Value) -> Vec<Claim> {
    v.as_array()
        .map(|a| {
            a.iter()
                .map(|e| Claim {
                    name: text(e, "name"),
                    state: text(e, "state"),
                    into: e["into"].as_str().map(str::to_string),
                    variables: identifiers(&text(e, "term")),
                    coefficient: e["coefficient"].as_f64().unwrap_or(f64::NAN),
                    parameters: numbers(e.get("parameters")),
                })
                .collect()
        })
        .unwrap_or_default()
}

fn rel_err(got: f64, truth: f64) -> f64 {
    (got - truth).abs() / truth.abs()
}

/// Whether `c` is `h` (name, equation, variables), ignoring the transfer target.
fn same_law(c: &Claim, h: &Hidden, state: &str) -> bool {
    canonical(&c.name) == canonical(&h.effect) && c.state == state && c.variables == h.variables
}

/// Score one case by the README's rule: `Ok(())` or the reasons it fails.
fn score(case: &Case, verdict: &str, effects: &[Claim]) -> Result<(), String> {
    let mut reasons = Vec::new();
    if verdict != case.expected {
        reasons.push(format!("verdict {verdict} (expected {})", case.expected));
    }
    // Claimed terms that are one of the hidden laws (whatever their coefficient).
    let mut accounted = vec![false; effects.len()];
    for h in &case.hidden {
        // One transfer term, or an ordinary term (no transfer target).
        let direct: Vec<usize> = (0..effects.len())
            .filter(|&i| same_law(&effects[i], h, &h.state) && effects[i].into == h.into)
            .collect();
        // A transfer written as the pair of terms: c in `state`, −c in `into`.
        let (own, other): (Vec<usize>, Vec<usize>) = match &h.into {
            Some(into) => (
                (0..effects.len())
                    .filter(|&i| same_law(&effects[i], h, &h.state) && effects[i].into.is_none())
                    .collect(),
                (0..effects.len())
                    .filter(|&i| same_law(&effects[i], h, into) && effects[i].into.is_none())
                    .collect(),
            ),
            None => (Vec::new(), Vec::new()),
        };
        for &i in direct.iter().chain(&own).chain(&other) {
            accounted[i] = true;
        }
        let direct_ok = direct
            .iter()
            .any(|&i| rel_err(effects[i].coefficient, h.coefficient) <= REL_TOL);
        let pair_ok = own
            .iter()
            .any(|&i| rel_err(effects[i].coefficient, h.coefficient) <= REL_TOL)
            && other
                .iter()
                .any(|&i| rel_err(effects[i].coefficient, -h.coefficient) <= REL_TOL);
        if case.expected == "found" && !(direct_ok || pair_ok) {
            let named: Vec<String> = direct
                .iter()
                .chain(&own)
                .chain(&other)
                .map(|&i| format!("{:.4}", effects[i].coefficient))
                .collect();
            if named.is_empty() {
                reasons.push(format!("{} in d({}) not claimed", h.effect, h.state));
            } else {
                reasons.push(format!(
                    "{} in d({}) coefficient off: {} vs truth {:.4}",
                    h.effect,
                    h.state,
                    named.join("/"),
                    h.coefficient
                ));
            }
        }
    }
    for (i, e) in effects.iter().enumerate() {
        if !accounted[i] && !LINEAR.contains(&canonical(&e.name)) {
            reasons.push(format!(
                "passenger {} in d({}) = {:.4}",
                e.name, e.state, e.coefficient
            ));
        }
    }
    if reasons.is_empty() {
        Ok(())
    } else {
        Err(reasons.join("; "))
    }
}

fn run_case(case: &Case) -> Outcome {
    let model = suite_dir()
        .join("cases")
        .join(&case.name)
        .join("model.toml");
    run_case_with(case, &model, "")
}

/// [`run_case`] with another model file (`tag` keeps its output folder apart).
fn run_case_with(case: &Case, model: &Path, tag: &str) -> Outcome {
    let dir = suite_dir().join("cases").join(&case.name);
    let out = std::env::temp_dir().join(format!(
        "mmenn-independent-suite-{}-{}{tag}",
        std::process::id(),
        case.name
    ));
    let _ = std::fs::remove_dir_all(&out);
    let start = Instant::now();
    let result = catch_unwind(AssertUnwindSafe(|| {
        run_discover(
            &[dir.join("est.csv")],
            model,
            &[dir.join("val.csv")],
            &DiscoverOptions::default(),
            &out,
        )
        .map_err(|e| e.to_string())
    }));
    let seconds = start.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&out);
    let failed = |reason: String| Outcome {
        verdict: "error".into(),
        effects: Vec::new(),
        unconfirmed: Vec::new(),
        pass: false,
        reason,
        seconds,
    };
    let summary = match result {
        Ok(Ok(s)) => s,
        Ok(Err(e)) => return failed(format!("error: {e}")),
        Err(_) => return failed("panicked".into()),
    };
    let v = serde_json::to_value(&summary).expect("summary serialises");
    let verdict = v["verdict"].as_str().unwrap_or("?").to_string();
    let effects = claims(&v["effects"]);
    let unconfirmed = claims(&v["unconfirmed"]);
    let (pass, mut reason) = match score(case, &verdict, &effects) {
        Ok(()) => (true, String::new()),
        Err(r) => (false, r),
    };
    // What decided, for the log: the judged cost and the stand-in against their
    // thresholds.
    let judged = |key: &str| {
        let j = &v[key];
        match (j["statistic"].as_f64(), j["threshold"].as_f64()) {
            (Some(s), Some(t)) => format!(" {key} {s:.3}/{t:.3}"),
            _ => String::new(),
        }
    };
    reason.push_str(&judged("judgement"));
    reason.push_str(&judged("stand_in"));
    Outcome {
        verdict,
        effects,
        unconfirmed,
        pass,
        reason,
        seconds,
    }
}

fn show(claims: &[Claim]) -> String {
    if claims.is_empty() {
        return "-".into();
    }
    claims
        .iter()
        .map(|c| {
            let into = c.into.as_ref().map_or(String::new(), |r| format!("→{r}"));
            let params: Vec<String> = c
                .parameters
                .iter()
                .map(|(k, v)| format!("{k}={v:.3}"))
                .collect();
            let params = if params.is_empty() {
                String::new()
            } else {
                format!("[{}]", params.join(","))
            };
            format!("{}({}{into})={:.4}{params}", c.name, c.state, c.coefficient)
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn line(case: &Case, o: &Outcome) -> String {
    let truth: Vec<String> = case
        .hidden
        .iter()
        .map(|h| {
            let params: Vec<String> = h
                .parameters
                .iter()
                .map(|(k, v)| format!("{k}={v}"))
                .collect();
            format!(
                "{}({})={}{}",
                h.effect,
                h.state,
                h.coefficient,
                if params.is_empty() {
                    String::new()
                } else {
                    format!("[{}]", params.join(","))
                }
            )
        })
        .collect();
    format!(
        "{:<28} exp {:<11} got {:<11} {:<4} {:>6.1}s | claimed: {} | unconfirmed: {} | truth: {} | {}",
        case.name,
        case.expected,
        o.verdict,
        if o.pass { "PASS" } else { "FAIL" },
        o.seconds,
        show(&o.effects),
        show(&o.unconfirmed),
        if truth.is_empty() {
            "-".into()
        } else {
            truth.join(" ")
        },
        o.reason
    )
}

/// A `[roles]` table stands in for a level's unit, on the generator's records: the suite's
/// two-tank case with both levels read in volts instead of metres fails the suite's rule
/// (the unit hides the orifice law from the search), and passes it again when the model
/// file names both as levels.
#[test]
fn a_roles_table_restores_the_level_laws_on_independent_records() {
    let case = read_cases()
        .into_iter()
        .find(|c| c.name == "tanks_orifices_1pct")
        .expect("the suite has its two-tank orifice case");
    let dir = suite_dir().join("cases").join(&case.name);
    let text = std::fs::read_to_string(dir.join("model.toml")).expect("case model");
    let volts = text.replace(
        r#"units = { h1 = "m", h2 = "m", u = "V" }"#,
        r#"units = { h1 = "V", h2 = "V", u = "V" }"#,
    );
    assert_ne!(
        volts, text,
        "the case's units line changed; update this test"
    );
    let tmp = std::env::temp_dir().join(format!("mmenn-roles-suite-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).expect("temp dir");
    let plain = tmp.join("volts.toml");
    let given = tmp.join("volts_roles.toml");
    std::fs::write(&plain, &volts).expect("write");
    std::fs::write(
        &given,
        format!("{volts}\n[roles]\nh1 = \"level\"\nh2 = \"level\"\n"),
    )
    .expect("write");
    let without = run_case_with(&case, &plain, "-volts");
    let with = run_case_with(&case, &given, "-roles");
    let _ = std::fs::remove_dir_all(&tmp);
    assert!(
        !without.pass && !without.effects.iter().any(|c| c.name == "orifice_outflow"),
        "{}",
        line(&case, &without)
    );
    assert!(with.pass, "{}", line(&case, &with));
}

#[test]
fn independent_discovery_suite() {
    let all = read_cases();
    let filter: Option<Vec<String>> = std::env::var("MMENN_SUITE").ok().map(|s| {
        s.split(',')
            .map(|x| x.trim().to_string())
            .filter(|x| !x.is_empty())
            .collect()
    });
    let cases: Vec<Case> = match &filter {
        Some(names) => {
            for n in names {
                assert!(
                    all.iter().any(|c| &c.name == n),
                    "MMENN_SUITE names an unknown case {n}"
                );
            }
            all.iter()
                .filter(|c| names.contains(&c.name))
                .cloned()
                .collect()
        }
        None => all.clone(),
    };
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(cases.len())
        .max(1);
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Outcome>>> = Mutex::new((0..cases.len()).map(|_| None).collect());
    let start = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(case) = cases.get(i) else { break };
                    let o = run_case(case);
                    eprintln!("done {}", line(case, &o));
                    results.lock().unwrap()[i] = Some(o);
                }
            });
        }
    });
    let total = start.elapsed().as_secs_f64();
    let results: Vec<Outcome> = results
        .into_inner()
        .unwrap()
        .into_iter()
        .map(|o| o.expect("every case ran"))
        .collect();
    eprintln!("\nindependent discovery suite ({workers} threads, {total:.0} s)");
    for (case, o) in cases.iter().zip(&results) {
        eprintln!("{}", line(case, o));
    }
    let passed = results.iter().filter(|o| o.pass).count();
    eprintln!(
        "passed {passed} of {} (floor {PASS_FLOOR}; target ≥ 90 %)",
        cases.len()
    );
    if filter.is_none() {
        assert!(
            cases.len() >= MIN_CASES,
            "only {} cases read from answers.json",
            cases.len()
        );
        assert!(
            passed >= PASS_FLOOR,
            "{passed} cases pass, below the floor {PASS_FLOOR}"
        );
    }
}

#[test]
fn scoring_rule_on_hand_made_claims() {
    let hidden = |effect: &str, state: &str, into: Option<&str>, var: &str, c: f64| Hidden {
        effect: effect.into(),
        state: state.into(),
        into: into.map(str::to_string),
        variables: [var.to_string()].into(),
        coefficient: c,
        parameters: BTreeMap::new(),
    };
    let claim = |name: &str, state: &str, into: Option<&str>, term: &str, c: f64| Claim {
        name: name.into(),
        state: state.into(),
        into: into.map(str::to_string),
        variables: identifiers(term),
        coefficient: c,
        parameters: BTreeMap::new(),
    };
    assert_eq!(
        identifiers("sign(u)*(abs(u) - 1.5e-3 + abs(abs(u) - 2))/2"),
        ["u".to_string()].into()
    );
    assert_eq!(
        identifiers("u*cos(theta) - u"),
        ["theta".to_string(), "u".to_string()].into()
    );
    let tanks = Case {
        name: "t".into(),
        expected: "found".into(),
        hidden: vec![
            hidden("orifice_outflow", "h1", Some("h2"), "h1", -0.03),
            hidden("orifice_outflow", "h2", None, "h2", -0.035),
        ],
    };
    // As one transfer, with linear cancellations and a bias.
    let transfer = [
        claim("orifice_outflow", "h1", Some("h2"), "sqrt(abs(h1))", -0.031),
        claim("linear_coupling", "h1", Some("h2"), "h1", 0.06),
        claim("orifice_outflow", "h2", None, "sqrt(abs(h2))", -0.034),
        claim("constant_bias", "h2", None, "1", 1e-4),
    ];
    assert_eq!(score(&tanks, "found", &transfer), Ok(()));
    // As a pair of terms.
    let pair = [
        claim("orifice_outflow", "h1", None, "sqrt(abs(h1))", -0.029),
        claim("orifice_outflow", "h2", None, "sqrt(abs(h1))", 0.0305),
        claim("orifice_outflow", "h2", None, "sqrt(abs(h2))", -0.036),
    ];
    assert_eq!(score(&tanks, "found", &pair), Ok(()));
    // Coefficient off by more than 10 %, a wrong verdict, a passenger.
    let off = [
        claim("orifice_outflow", "h1", Some("h2"), "sqrt(abs(h1))", -0.04),
        claim("orifice_outflow", "h2", None, "sqrt(abs(h2))", -0.035),
        claim("quadratic_drag", "h2", None, "h2*abs(h2)", 0.1),
    ];
    let why = score(&tanks, "unexplained", &off).unwrap_err();
    assert!(why.contains("verdict"), "{why}");
    assert!(why.contains("coefficient off"), "{why}");
    assert!(why.contains("passenger quadratic_drag"), "{why}");
    // Coulomb's integration form counts as Coulomb; an outside-catalogue case may claim
    // linear terms but no nonlinear name.
    let coulomb = Case {
        name: "c".into(),
        expected: "found".into(),
        hidden: vec![hidden("coulomb_friction", "v", None, "v", -0.3)],
    };
    let smooth = [claim(
        "coulomb_friction_smooth",
        "v",
        None,
        "tanh(v/0.01)",
        -0.29,
    )];
    assert_eq!(score(&coulomb, "found", &smooth), Ok(()));
    let outside = Case {
        name: "o".into(),
        expected: "unexplained".into(),
        hidden: vec![],
    };
    let linear = [claim("viscous_damping", "v", None, "v", -0.1)];
    assert_eq!(score(&outside, "unexplained", &linear), Ok(()));
    assert!(score(&outside, "unexplained", &smooth).is_err());
}
