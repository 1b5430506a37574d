//! Issue 21: every reproducer of the reliability report ends in a typed error (or a correct
//! result) in bounded time and memory, through the library and through the `mmenn` binary.

#![allow(clippy::result_large_err)] // errors carry paths and context; tests only

use std::path::{Path, PathBuf};
use std::process::Command;

use mmenn::error::{CsvProblem, MmennError, ModelProblem};
use mmenn::mme_core::{self, MmeConfig, MmeError, NoiseSpec, WeightSpec};
use mmenn::model_file::parse_model;
use mmenn::sysid_core::{Dataset, Experiment, LinearModel};
use nalgebra::DMatrix;

fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mmenn-rel-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn model_problem(text: &str) -> ModelProblem {
    match parse_model(Path::new("m.toml"), text) {
        Err(MmennError::Model { problem, .. }) => problem,
        other => panic!("expected a model error, got {other:?}"),
    }
}

/// Pendulum-like data: 400 samples at 0.02 s of a damped oscillation, position measured.
fn oscillation_csv() -> String {
    let mut s = String::from("t,u,theta\n");
    for k in 0..400 {
        let t = k as f64 * 0.02;
        let u = (0.7 * t).sin();
        let y = (-(0.1 * t)).exp() * (4.4 * t).cos();
        s.push_str(&format!("{t},{u},{y}\n"));
    }
    s
}

const PENDULUM: &str = r#"
states = ["theta", "omega"]
inputs = ["u"]
A = [[0.0, 1.0], [-19.62, -0.2]]
B = [[0.0], [-2.0]]
measured = ["theta"]
corrected = ["omega"]
noise_variance = [0.01]
"#;

#[test]
fn empty_state_list_is_a_typed_error() {
    let text = "states = []\nA = []\nmeasured = []\nnoise_variance = []\n";
    assert_eq!(model_problem(text), ModelProblem::NoStates);
    // And mme-core refuses a model without states before any decomposition.
    let Ok(model) = LinearModel::new(
        DMatrix::zeros(0, 0),
        DMatrix::zeros(0, 0),
        DMatrix::zeros(0, 0),
        DMatrix::zeros(0, 0),
    ) else {
        return; // refused even earlier: also fine
    };
    let exp = Experiment::new(0.0, 0.1, DMatrix::zeros(0, 5), DMatrix::zeros(0, 5)).unwrap();
    let data = Dataset::new(vec![], vec![], vec![exp]).unwrap();
    for substeps in [None, Some(1)] {
        let config = MmeConfig {
            substeps,
            ..MmeConfig::default()
        };
        assert_eq!(
            mme_core::estimate(&model, &data, &config).unwrap_err(),
            MmeError::NoStates
        );
    }
}

/// `term = "theta/q"` on an unmeasured state `q` is infinite at the data-based start: an
/// error naming the equation, the time and the term, quickly (it used to hang in the
/// eigenvalue routine).
#[test]
fn a_term_undefined_at_the_start_is_named_not_a_hang() {
    let dir = scratch("nanterm");
    let data = dir.join("d.csv");
    std::fs::write(&data, oscillation_csv()).unwrap();
    let text = r#"
states = ["theta", "omega", "q"]
inputs = ["u"]
A = [[0.0, 1.0, 0.0], [-19.62, -0.2, 0.0], [0.0, 0.0, -1.0]]
B = [[0.0], [-2.0], [0.0]]
measured = ["theta"]
corrected = ["omega"]
noise_variance = [0.01]
[[terms]]
state = "omega"
effect = "ratio"
term = "theta/q"
coefficient = 1.0
"#;
    let model = dir.join("m.toml");
    std::fs::write(&model, text).unwrap();
    for substeps in [None, Some(1)] {
        let opts = mmenn::estimate::EstimateOptions {
            substeps,
            ..Default::default()
        };
        let err = mmenn::estimate::run_estimate(
            std::slice::from_ref(&data),
            &model,
            &opts,
            &dir.join("out"),
        )
        .unwrap_err();
        match &err {
            MmennError::MmeTerms { source, terms } => {
                assert!(terms.contains("theta/q"), "{terms}");
                match source {
                    MmeError::NonFiniteModel {
                        experiment,
                        state,
                        time,
                        ..
                    } => {
                        assert_eq!(*experiment, 0);
                        assert_eq!(state, "omega");
                        assert!(time.abs() < 1e-12, "{time}");
                    }
                    other => panic!("{other:?}"),
                }
            }
            other => panic!("expected a named non-finite term, got {other:?}"),
        }
        let msg = err.to_string();
        assert!(
            msg.contains("experiment 0") && msg.contains("t = 0 s") && msg.contains("'omega'"),
            "{msg}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn substeps_are_capped_before_allocating() {
    let spec = parse_model(Path::new("m.toml"), PENDULUM).unwrap();
    let table =
        mmenn::data_file::parse_table(Path::new("d.csv"), oscillation_csv().as_bytes()).unwrap();
    let exp = mmenn::data_file::table_to_experiment(
        &table,
        spec.linear.input_names(),
        spec.linear.output_names(),
    )
    .unwrap();
    let data = Dataset::new(
        vec![mmenn::sysid_core::Channel::new("u")],
        vec![mmenn::sysid_core::Channel::new("theta")],
        vec![exp],
    )
    .unwrap();
    for s in [
        4_294_967_296usize,
        100_000,
        mme_core::discretize::MAX_SUBSTEPS + 1,
    ] {
        let config = MmeConfig {
            substeps: Some(s),
            w: WeightSpec::Scalar(1.0),
            noise_variance: NoiseSpec::Given(vec![0.01]),
            ..MmeConfig::default()
        };
        let err = mme_core::estimate(&spec.linear, &data, &config).unwrap_err();
        assert!(
            matches!(
                err,
                MmeError::InvalidSetting {
                    name: "substeps",
                    ..
                }
            ),
            "{err:?}"
        );
    }
}

fn csv_problem(text: &str) -> CsvProblem {
    let r = mmenn::data_file::parse_table(Path::new("d.csv"), text.as_bytes()).and_then(|t| {
        mmenn::data_file::table_to_experiment(&t, &["u".to_string()], &["y".to_string()])
    });
    match r {
        Err(MmennError::Csv { problem, .. }) => problem,
        other => panic!("expected a CSV error, got {other:?}"),
    }
}

/// A missing row is caught at any |t|: at 1e9 as a non-uniform step; at 1e12 and 1e15,
/// where `f64` cannot resolve a 0.01 s step, the file is refused as such.
#[test]
fn uniform_time_check_is_exact_at_large_times() {
    let rows = |base: f64, skip: usize| {
        let mut s = String::from("t,u,y\n");
        for k in (0..8).filter(|&k| k != skip) {
            s.push_str(&format!("{},1,2\n", base + k as f64 * 0.01));
        }
        s
    };
    assert!(matches!(
        csv_problem(&rows(1e9, 4)),
        CsvProblem::NonUniformTime { .. }
    ));
    for base in [1e12, 1e15] {
        let p = csv_problem(&rows(base, 4));
        assert!(
            matches!(
                p,
                CsvProblem::TimeResolution { .. } | CsvProblem::NonIncreasingTime { .. }
            ),
            "{p:?}"
        );
    }
    // Complete files at large t with a resolvable step are fine.
    let ok =
        mmenn::data_file::parse_table(Path::new("d.csv"), rows(1e9, 99).as_bytes()).and_then(|t| {
            mmenn::data_file::table_to_experiment(&t, &["u".to_string()], &["y".to_string()])
        });
    assert!(ok.is_ok(), "{ok:?}");
}

#[test]
fn names_that_break_csv_or_paths_are_refused() {
    let bad = [
        "t",
        "",
        "a,b",
        "a\"b",
        "a\nb",
        "x/../../../escaped",
        "..",
        "a\\b",
        " x",
    ];
    for name in bad {
        let quoted = serde_json::to_string(name).unwrap();
        // As a state (also measured).
        let text = PENDULUM
            .replace("\"theta\"", &quoted)
            .replace("measured = [\"theta\"]", &format!("measured = [{quoted}]"));
        assert!(
            matches!(
                model_problem(&text),
                ModelProblem::BadName { key: "states", .. }
            ),
            "state {name:?}: {:?}",
            model_problem(&text)
        );
        // As an input.
        let text = PENDULUM.replace("inputs = [\"u\"]", &format!("inputs = [{quoted}]"));
        assert!(
            matches!(
                model_problem(&text),
                ModelProblem::BadName { key: "inputs", .. }
            ),
            "input {name:?}"
        );
        // As an output of C.
        let text = PENDULUM.replace(
            "measured = [\"theta\"]",
            &format!("C = [[1.0, 0.0]]\noutputs = [{quoted}]"),
        );
        assert!(
            matches!(
                model_problem(&text),
                ModelProblem::BadName { key: "outputs", .. }
            ),
            "output {name:?}"
        );
    }
    assert!(parse_model(Path::new("m.toml"), PENDULUM).is_ok());
}

#[test]
fn model_json_with_a_bad_period_is_refused() {
    let spec = parse_model(Path::new("m.toml"), PENDULUM).unwrap();
    let file = mmenn::fit::HybridFile {
        format: mmenn::fit::HYBRID_FORMAT.into(),
        model_toml: mmenn::model_file::format_model(&spec).unwrap(),
        network: mmenn::nn::Mlp::new(&mmenn::nn::Architecture::single(3, 2, 1), 1).unwrap(),
        x0: vec![0.0, 0.0],
        dt: 0.01,
        substeps: 4,
        domain: mmenn::nn::Domain::Extrapolate,
    };
    let good = serde_json::to_string(&file).unwrap();
    assert!(mmenn::fit::HybridFile::parse(Path::new("model.json"), &good).is_ok());
    for (dt, substeps, x0) in [
        (0.0, 4, vec![0.0, 0.0]),
        (-1.0, 4, vec![0.0, 0.0]),
        (0.01, 0, vec![0.0, 0.0]),
        (0.01, 4, vec![0.0]),
    ] {
        let bad = mmenn::fit::HybridFile {
            dt,
            substeps,
            x0,
            ..file.clone()
        };
        let text = serde_json::to_string(&bad).unwrap();
        assert!(matches!(
            mmenn::fit::HybridFile::parse(Path::new("model.json"), &text),
            Err(MmennError::Model { .. })
        ));
    }
    // NaN cannot be written in JSON; a text with `null` is a syntax error, not a panic.
    let text = good.replace("\"dt\":0.01", "\"dt\":null");
    assert!(mmenn::fit::HybridFile::parse(Path::new("model.json"), &text).is_err());
}

#[test]
fn max_samples_message_names_the_value() {
    let request = mmenn::plants::SimulationRequest {
        system: "pendulum".into(),
        recipe: mmenn::plants::Recipe::Train,
        noise_variance: None,
        fs: Some(1000.0),
        seed: 1,
        params: vec![],
        duration: Some(1e5),
    };
    let err = mmenn::plants::simulate_system(&request).unwrap_err();
    assert!(err.to_string().contains("10,000,000"), "{err}");
}

/// The trajectory training of a 1,000,000-sample record used to abort allocating
/// 102 GB; it is refused with a typed error before allocating.
#[test]
fn trajectory_refinement_of_a_huge_record_is_refused_before_allocating() {
    use mmenn::nn::{
        Architecture, Mlp, NetCorrection, NnError, ShootingRecord, TrajectoryConfig,
        train_on_trajectories,
    };
    let lin = parse_model(Path::new("m.toml"), PENDULUM).unwrap().linear;
    let n = 1_000_000;
    let exp = Experiment::new(
        0.0,
        0.01,
        DMatrix::zeros(1, n),
        DMatrix::from_element(1, n, 0.1),
    )
    .unwrap();
    let states = DMatrix::zeros(2, n);
    let net = Mlp::new(&Architecture::single(3, 3, 1), 1).unwrap();
    let mut model = mmenn::sysid_core::CorrectedModel::new(
        &lin,
        NetCorrection::new(net, 2).unwrap(),
        lin.e().clone(),
        lin.c().clone(),
        lin.output_names().to_vec(),
    )
    .unwrap();
    let records = [ShootingRecord {
        experiment: &exp,
        states: &states,
    }];
    let err = train_on_trajectories(
        &mut model,
        &records,
        &[],
        &TrajectoryConfig::default(),
        None,
    )
    .unwrap_err();
    assert!(matches!(err, NnError::TooLarge { .. }), "{err:?}");
}

// ---- through the binary ----

fn mmenn(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> (i32, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mmenn"));
    cmd.current_dir(dir).args(args);
    cmd.env_remove("MMENN_BACKTRACE");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Empty and NaN cells of a measured column are missing samples that MME skips, and
/// `estimate` counts them per channel (`summary.json`'s `missing`; the terminal prints a
/// line per channel with any) instead of saying nothing.
#[test]
fn estimate_counts_missing_samples() {
    let dir = scratch("missing-count");
    let mut rows: Vec<String> = oscillation_csv().lines().map(str::to_string).collect();
    // Rows 10 and 20 (samples 9 and 19): an empty cell; row 30: the text NaN.
    for (row, cell) in [(10, ""), (20, ""), (30, "NaN")] {
        let mut parts: Vec<String> = rows[row].split(',').map(str::to_string).collect();
        parts[2] = cell.to_string();
        rows[row] = parts.join(",");
    }
    std::fs::write(dir.join("d.csv"), rows.join("\n") + "\n").unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    let s = mmenn::estimate::run_estimate(
        &[dir.join("d.csv")],
        &dir.join("m.toml"),
        &mmenn::estimate::EstimateOptions::default(),
        &dir.join("out"),
    )
    .unwrap();
    assert_eq!(s.samples, 400);
    assert_eq!(s.missing.get("theta"), Some(&3), "{:?}", s.missing);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Standard output closed before the command prints (as `mmenn simulate --list | head -0`
/// or a reader that quits) ends the command quietly with success: no panic, no backtrace
/// (`println!` panics with "failed printing to stdout: Broken pipe").
#[test]
fn closed_stdout_is_not_a_panic() {
    use std::process::Stdio;
    let dir = scratch("closed-stdout");
    for _ in 0..3 {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mmenn"))
            .current_dir(&dir)
            .args(["simulate", "--list"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Close the read end at once: the listing (a few hundred bytes) then meets a
        // closed pipe rather than a buffer.
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cli_rejects_bad_arguments_and_prints_no_backtrace() {
    let dir = scratch("cli");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    let base = ["--data", "d.csv", "--model", "m.toml", "--out", "o"];
    for (cmd, extra) in [
        ("discover", ["--holdout-fraction", "2"]),
        ("discover", ["--holdout-fraction", "NaN"]),
        ("discover", ["--holdout-fraction", "1"]),
        ("fit", ["--max-hidden", "0"]),
        ("compare", ["--max-hidden", "0"]),
        ("estimate", ["--substeps", "4294967296"]),
        ("estimate", ["--substeps", "0"]),
    ] {
        let mut args = vec![cmd];
        args.extend(base);
        args.extend(extra);
        let (code, err) = mmenn(&dir, &args, &[]);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains("invalid value"), "{err}");
    }
    let (code, err) = mmenn(
        &dir,
        &[
            "predict",
            "--model",
            "model.json",
            "--data",
            "d.csv",
            "--out",
            "p",
            "--x0-window",
            "0",
        ],
        &[],
    );
    assert_eq!(code, 2, "{err}");
    // An ordinary user error with RUST_BACKTRACE=1: one line, no backtrace.
    let mut args = vec!["estimate"];
    args.extend(["--data", "missing.csv", "--model", "m.toml", "--out", "o"]);
    let (code, err) = mmenn(&dir, &args, &[("RUST_BACKTRACE", "1")]);
    assert_eq!(code, 1);
    assert!(
        err.starts_with("error: ") && err.contains("missing.csv"),
        "{err}"
    );
    assert!(!err.to_lowercase().contains("backtrace"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        !dir.join("o").exists(),
        "a failed run left its output folder"
    );
    // Asked for (--debug, or MMENN_BACKTRACE), the same error prints its whole chain in
    // the multi-line debug form, still with status 1.
    for (flag, env) in [
        (true, ("MMENN_BACKTRACE", "0")),
        (false, ("MMENN_BACKTRACE", "1")),
    ] {
        let mut debug_args = if flag { vec!["--debug"] } else { vec![] };
        debug_args.extend(&args);
        let (code, err) = mmenn(&dir, &debug_args, &[("RUST_BACKTRACE", "1"), env]);
        assert_eq!(code, 1, "{err}");
        assert!(
            err.starts_with("error: ") && err.contains("missing.csv"),
            "{err}"
        );
        assert!(err.trim_end().lines().count() > 1, "{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A noise variance far above the data's makes the covariance constraint unreachable: the
/// W search cannot bracket, the results are written for inspection, and the exit status is
/// 3 with the reason on the terminal.
#[test]
fn an_unconverged_w_search_exits_non_zero() {
    let dir = scratch("wsearch");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(
        dir.join("m.toml"),
        PENDULUM.replace("noise_variance = [0.01]", "noise_variance = [100.0]"),
    )
    .unwrap();
    let (code, err) = mmenn(
        &dir,
        &[
            "estimate", "--data", "d.csv", "--model", "m.toml", "--out", "o",
        ],
        &[],
    );
    assert_eq!(code, 3, "{err}");
    assert!(err.contains("did not converge"), "{err}");
    assert!(dir.join("o").join("report.md").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 20, item 5: a spent `--budget` stops `estimate` of a nonlinear (mass-matrix)
/// model with exit status 4 and a message naming the stage that ran out and how far it
/// got; nothing is written. A budget of 0 s is spent before the first iteration, so the
/// test does not depend on the machine's speed.
#[test]
fn a_spent_budget_exits_4_naming_the_stage() {
    let dir = scratch("budget");
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/two_link");
    let (data, model) = (fixture.join("est.csv"), fixture.join("model.toml"));
    let (code, err) = mmenn(
        &dir,
        &[
            "estimate",
            "--data",
            data.to_str().unwrap(),
            "--model",
            model.to_str().unwrap(),
            "--budget",
            "0",
            "--out",
            "o",
        ],
        &[],
    );
    assert_eq!(code, 4, "{err}");
    assert!(
        err.contains("budget of 0 s ran out during nonlinear MME iteration (0 of 50 done"),
        "{err}"
    );
    assert!(!dir.join("o").exists());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 19: `fit --train-on-trajectories yes|no` is the flag, and the old spellings
/// `--refine trajectory|none` and `--refine-window` still parse (hidden aliases): with a
/// missing model file each run gets as far as reading it (exit 1, the input error), while
/// a value neither spelling knows is a command-line error (exit 2).
#[test]
fn trajectory_training_flag_and_its_old_spelling_both_parse() {
    let dir = scratch("refine-alias");
    let base = [
        "fit",
        "--data",
        "missing.csv",
        "--model",
        "m.toml",
        "--out",
        "o",
    ];
    for extra in [
        &["--train-on-trajectories", "no"][..],
        &[
            "--train-on-trajectories",
            "yes",
            "--trajectory-window",
            "50",
        ],
        &["--refine", "none"],
        &["--refine", "trajectory", "--refine-window", "50"],
    ] {
        let args: Vec<&str> = base.iter().chain(extra).copied().collect();
        let (code, err) = mmenn(&dir, &args, &[]);
        assert_eq!(code, 1, "{extra:?}: {err}");
        assert!(err.contains("m.toml"), "{extra:?}: {err}");
    }
    let args: Vec<&str> = base
        .iter()
        .chain(&["--refine", "sometimes"])
        .copied()
        .collect();
    let (code, err) = mmenn(&dir, &args, &[]);
    assert_eq!(code, 2, "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `fit --guard` reads `last-fifth` and `K-fold` (K ≥ 2): such runs get as far as reading
/// the missing model file (exit 1); anything else is a command-line error (exit 2) that
/// names the accepted spellings.
#[test]
fn fit_guard_flag_reads_last_fifth_and_k_fold_only() {
    let dir = scratch("guard-flag");
    let base = [
        "fit",
        "--data",
        "missing.csv",
        "--model",
        "m.toml",
        "--out",
        "o",
        "--guard",
    ];
    for good in ["last-fifth", "last-fifth-retrained", "5-fold", "2-fold"] {
        let args: Vec<&str> = base.iter().copied().chain([good]).collect();
        let (code, err) = mmenn(&dir, &args, &[]);
        assert_eq!(code, 1, "{good}: {err}");
        assert!(err.contains("m.toml"), "{good}: {err}");
    }
    for bad in ["1-fold", "fold", "5", "last"] {
        let args: Vec<&str> = base.iter().copied().chain([bad]).collect();
        let (code, err) = mmenn(&dir, &args, &[]);
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(err.contains("K-fold with K ≥ 2"), "{bad}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 21: `fit` and `discover` on the same unreachable covariance constraint write
/// their results and exit with status 3 (not 0, not the input-error status 1), naming the
/// W search; on data with noise of the stated variance the same runs exit 0.
#[test]
fn fit_and_discover_exit_3_when_the_w_search_does_not_converge() {
    let dir = scratch("wsearch-fit");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(
        dir.join("m.toml"),
        PENDULUM.replace("noise_variance = [0.01]", "noise_variance = [100.0]"),
    )
    .unwrap();
    std::fs::write(dir.join("ok.toml"), PENDULUM).unwrap();
    // The same oscillation with noise of σ = 0.1 (variance 0.01, as PENDULUM states):
    // a sum of twelve uniforms from a fixed xorshift sequence.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut uniform = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let noisy: String = oscillation_csv()
        .lines()
        .enumerate()
        .map(|(k, line)| {
            if k == 0 {
                return format!("{line}\n");
            }
            let (head, y) = line.rsplit_once(',').unwrap();
            let e: f64 = (0..12).map(|_| uniform()).sum::<f64>() - 6.0;
            format!("{head},{}\n", y.parse::<f64>().unwrap() + 0.1 * e)
        })
        .collect();
    std::fs::write(dir.join("noisy.csv"), noisy).unwrap();
    let fit = [
        "--quiet", "fit", "--data", "d.csv", "--model", "m.toml", "--hidden", "2", "--inits", "1",
    ];
    let discover = [
        "--quiet",
        "discover",
        "--data",
        "d.csv",
        "--model",
        "m.toml",
        "--max-rounds",
        "1",
        "--stand-in-draws",
        "0",
    ];
    for (args, out) in [(&fit[..], "fit"), (&discover[..], "discover")] {
        let mut a = args.to_vec();
        a.extend(["--out", out]);
        let (code, err) = mmenn(&dir, &a, &[]);
        assert_eq!(code, 3, "{out}: {err}");
        assert!(
            err.contains("W search") && err.contains("did not converge"),
            "{out}: {err}"
        );
        assert!(dir.join(out).join("report.md").exists(), "{out}");
        // Noise of the variance the model states makes the constraint reachable.
        let ok: Vec<&str> = a
            .iter()
            .map(|s| match *s {
                "m.toml" => "ok.toml",
                "d.csv" => "noisy.csv",
                other => other,
            })
            .chain(["--force"])
            .collect();
        let (code, err) = mmenn(&dir, &ok, &[]);
        assert_eq!(code, 0, "{out} on noise of the stated variance: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Output folders are all-or-nothing: a re-run replaces the whole folder (a stale
/// `estimate_1.csv` goes), leftovers of killed runs are removed, a folder of someone
/// else's files is refused without --force, `simulate` never silently replaces a
/// different data file, and a failed run leaves the previous folder untouched.
#[test]
fn output_folders_are_all_or_nothing() {
    let dir = scratch("outdir");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    let est = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "estimate", "--data", "d.csv", "--model", "m.toml", "--w", "1", "--out", out,
        ];
        args.extend(extra);
        mmenn(&dir, &args, &[])
    };
    let (code, err) = est("o", &[]);
    assert_eq!(code, 0, "{err}");
    let o = dir.join("o");
    let manifest = mmenn::atomic::read_manifest(&o).unwrap();
    assert_eq!(manifest.command, "estimate");
    assert!(manifest.files.contains(&"estimate.csv".to_string()));
    // Stale files: one of an old run, one temp file of a killed writer, one staging
    // folder of a killed run beside the folder (PID far above any pid_max).
    std::fs::write(o.join("estimate_1.csv"), "stale").unwrap();
    std::fs::write(o.join(".estimate.csv.4000000000.tmp"), "partial").unwrap();
    std::fs::create_dir(dir.join(".o.4000000001.staging")).unwrap();
    let (code, err) = est("o", &[]);
    assert_eq!(code, 0, "{err}");
    assert!(!o.join("estimate_1.csv").exists());
    assert!(!o.join(".estimate.csv.4000000000.tmp").exists());
    assert!(!dir.join(".o.4000000001.staging").exists());
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
    // A failed run (bad W) leaves the previous results in place.
    let before = std::fs::read(o.join("estimate.csv")).unwrap();
    let (code, _) = est("o", &["--substeps", "1000", "--w", "-1"]);
    assert_ne!(code, 0);
    assert_eq!(std::fs::read(o.join("estimate.csv")).unwrap(), before);
    // A folder of the user's files: refused, then replaced with --force.
    let mine = dir.join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("notes.txt"), "mine").unwrap();
    let (code, err) = est("mine", &[]);
    assert_eq!(code, 1);
    assert!(err.contains("--force"), "{err}");
    assert!(mine.join("notes.txt").exists());
    let (code, err) = est("mine", &["--force"]);
    assert_eq!(code, 0, "{err}");
    assert!(!mine.join("notes.txt").exists());
    // Another command's folder is refused too.
    let (code, err) = mmenn(
        &dir,
        &["simulate", "--system", "pendulum", "--out", "o"],
        &[],
    );
    assert_eq!(code, 1);
    assert!(err.contains("mmenn estimate"), "{err}");
    // Never into a folder holding an input, even with --force.
    let (code, err) = mmenn(
        &dir,
        &[
            "estimate", "--data", "d.csv", "--model", "m.toml", "--out", ".", "--force",
        ],
        &[],
    );
    assert_eq!(code, 1, "{err}");
    assert!(dir.join("d.csv").exists());
    // simulate: the same request again is fine (same bytes), a different one is refused.
    let sim = |extra: &[&str]| {
        let mut args = vec!["simulate", "--system", "pendulum", "--out", "sim"];
        args.extend(extra);
        mmenn(&dir, &args, &[])
    };
    assert_eq!(sim(&[]).0, 0);
    assert_eq!(sim(&[]).0, 0);
    let data = std::fs::read(dir.join("sim").join("data.csv")).unwrap();
    let (code, err) = sim(&["--seed", "2"]);
    assert_eq!(code, 1);
    assert!(err.contains("data.csv"), "{err}");
    assert_eq!(
        std::fs::read(dir.join("sim").join("data.csv")).unwrap(),
        data
    );
    assert_eq!(sim(&["--seed", "2", "--force"]).0, 0);
    assert_ne!(
        std::fs::read(dir.join("sim").join("data.csv")).unwrap(),
        data
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--network-inputs states` saves a network on the states alone (as many inputs as the
/// model has states); the default reads the input too; a misspelt value is refused.
#[test]
fn cli_network_inputs_reach_the_saved_network() {
    let dir = scratch("netin");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    for (value, want) in [(Some("states"), 2), (None, 3)] {
        let out = format!("o-{want}");
        let mut args = vec![
            "--quiet", "fit", "--data", "d.csv", "--model", "m.toml", "--hidden", "2", "--inits",
            "1", "--w", "100", "--out", &out,
        ];
        if let Some(v) = value {
            args.extend(["--network-inputs", v]);
        }
        let (code, err) = mmenn(&dir, &args, &[]);
        assert_eq!(code, 0, "{err}");
        let text = std::fs::read_to_string(dir.join(&out).join("model.json")).unwrap();
        let file = mmenn::fit::HybridFile::parse(Path::new("model.json"), &text).unwrap();
        assert_eq!(file.network.n_inputs(), want);
    }
    let (code, err) = mmenn(
        &dir,
        &[
            "--quiet",
            "fit",
            "--data",
            "d.csv",
            "--model",
            "m.toml",
            "--network-inputs",
            "inputs",
            "--out",
            "bad",
        ],
        &[],
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("states-and-inputs"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--network-domain` (and its shorthand `--hold-network-domain`) reaches the saved model
/// (fit and compare share the flags' meaning); without either the guard's stress check
/// decides, and `summary.json` and the terminal say how; the two flags together, or a
/// misspelt policy, are refused.
#[test]
fn cli_network_domain_is_saved() {
    let dir = scratch("hold");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    let fit = |out: &str, flags: &[&str]| {
        let mut args = vec![
            "fit", "--data", "d.csv", "--model", "m.toml", "--hidden", "2", "--inits", "1", "--w",
            "100", "--out", out,
        ];
        args.extend(flags);
        let out_dir = dir.join(out);
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_mmenn"))
            .current_dir(&dir)
            .args(&args)
            .output()
            .unwrap();
        (output, out_dir)
    };
    let read = |out_dir: &Path| {
        let text = std::fs::read_to_string(out_dir.join("model.json")).unwrap();
        let file = mmenn::fit::HybridFile::parse(Path::new("model.json"), &text).unwrap();
        let summary: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap())
                .unwrap();
        (file.domain, summary)
    };
    for (flags, want, policy) in [
        (
            &["--hold-network-domain"][..],
            mmenn::nn::Domain::Hold,
            "hold",
        ),
        (
            &["--network-domain", "hold"][..],
            mmenn::nn::Domain::Hold,
            "hold",
        ),
        (
            &["--network-domain", "extrapolate"][..],
            mmenn::nn::Domain::Extrapolate,
            "extrapolate",
        ),
    ] {
        let (output, out_dir) = fit(&format!("o-{}", flags.join("")), flags);
        assert!(output.status.success(), "{output:?}");
        let (domain, summary) = read(&out_dir);
        assert_eq!(domain, want);
        assert_eq!(summary["guard"]["domain"]["policy"], policy);
        assert_eq!(summary["guard"]["domain"]["checks"], serde_json::json!([]));
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            stdout.contains(&format!("network domain: {policy}, as asked")),
            "{stdout}"
        );
    }
    // The default: the stress check decides each network candidate's domain, and the
    // saved one is the kept candidate's.
    let (output, out_dir) = fit("o-default", &[]);
    assert!(output.status.success(), "{output:?}");
    let (domain, summary) = read(&out_dir);
    let guard = &summary["guard"];
    assert_eq!(guard["domain"]["policy"], "checked");
    let checks = guard["domain"]["checks"].as_array().unwrap();
    assert!(!checks.is_empty());
    let stdout = String::from_utf8_lossy(&output.stdout);
    for c in checks {
        assert!(
            ["passed", "failed"].contains(&c["verdict"].as_str().unwrap()),
            "{c}"
        );
        let line = format!(
            "stress check, {}",
            match c["candidate"].as_str().unwrap() {
                "network" => "network before trajectory training",
                _ => "network after trajectory training",
            }
        );
        assert!(stdout.contains(&line), "{stdout}");
    }
    let kept = guard["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["candidate"] == guard["chosen"])
        .unwrap();
    if guard["chosen"] != "physics_alone" {
        assert_eq!(kept["domain"], serde_json::to_value(domain).unwrap());
    }
    // Both flags, or a misspelt policy: a command-line error.
    for flags in [
        &["--hold-network-domain", "--network-domain", "extrapolate"][..],
        &["--network-domain", "held"][..],
    ] {
        let (output, _) = fit("o-refused", flags);
        assert_eq!(output.status.code(), Some(2), "{flags:?}: {output:?}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `compare` on the oscillation record with `flag value`, which must be refused as a
/// command-line error (exit status 2); its standard error.
fn compare_refuses(dir: &Path, flag: &str, value: &str) -> String {
    let args = [
        "compare", "--data", "d.csv", "--model", "m.toml", flag, value,
    ];
    let (code, err) = mmenn(dir, &args, &[]);
    assert_eq!(code, 2, "{flag} {value}: {err}");
    err
}

/// `compare` on the oscillation record with small settings and one extra flag; its
/// `compare.json`.
fn compare_json_with(dir: &Path, out: &str, flag: &str, value: &str) -> serde_json::Value {
    let args = [
        "--quiet",
        "compare",
        "--data",
        "d.csv",
        "--model",
        "m.toml",
        "--max-hidden",
        "1",
        "--inits",
        "1",
        "--narx-lags",
        "2",
        flag,
        value,
        "--out",
        out,
    ];
    let (code, err) = mmenn(dir, &args, &[]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(dir.join(out).join("compare.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// `compare --poly-degree N` reaches the polynomial NARX row (`compare.json` records the
/// degree, the tables have the row); `--poly-degree 0` removes the row (no failure either).
#[test]
fn cli_poly_degree_reaches_compare_and_zero_removes_the_row() {
    let dir = scratch("poly-degree");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    for (degree, row) in [("2", true), ("0", false)] {
        let json = compare_json_with(&dir, &format!("o-{degree}"), "--poly-degree", degree);
        let labels: Vec<&str> = json["estimation"]["rows"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|r| r["label"].as_str())
            .collect();
        assert_eq!(labels.contains(&"polynomial NARX"), row, "{labels:?}");
        let failures = json["failures"].as_array().unwrap();
        assert!(failures.is_empty(), "{failures:?}");
        if row {
            assert_eq!(json["poly_narx"]["degree"], 2, "{}", json["poly_narx"]);
            assert_eq!(json["poly_narx"]["orders"]["na"], 2);
        } else {
            assert!(json["poly_narx"].is_null(), "{}", json["poly_narx"]);
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A `--poly-degree` outside 0..=5, or not a number, is a command-line error (exit 2)
/// naming the flag and the accepted values, before any file is read; a misspelt flag
/// is refused naming the right one.
#[test]
fn cli_poly_degree_out_of_range_or_misspelt_is_refused() {
    let dir = scratch("poly-degree-bad");
    let base = [
        "compare",
        "--data",
        "missing.csv",
        "--model",
        "m.toml",
        "--out",
        "o",
        "--poly-degree",
    ];
    for bad in ["6", "three", "-1", "2.5", ""] {
        let args: Vec<&str> = base.iter().copied().chain([bad]).collect();
        let (code, err) = mmenn(&dir, &args, &[]);
        assert_eq!(code, 2, "{bad}: {err}");
        assert!(err.contains("--poly-degree"), "{bad}: {err}");
        assert!(
            err.contains("0 (no polynomial NARX row) or 1 to 5"),
            "{bad}: {err}"
        );
    }
    // A misspelt flag: clap names the one that exists.
    let mut args: Vec<&str> = base[..base.len() - 1].to_vec();
    args.extend(["--poly-degre", "2"]);
    let (code, err) = mmenn(&dir, &args, &[]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("'--poly-degree'"), "{err}");
    // A valid degree gets as far as reading the missing model file (exit 1).
    let args: Vec<&str> = base.iter().copied().chain(["5"]).collect();
    let (code, err) = mmenn(&dir, &args, &[]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("m.toml"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A model whose physics lives mostly in its terms, with a linear part whose `omega` the
/// measured `theta` cannot see (`A = [[0, 0], [0, −0.1]]`, `B = 0`), has an assumed-model
/// row whose state the output cannot observe over the observer window: its residual
/// analysis fails, and `compare` still writes every table (before, the whole comparison
/// stopped with "baseline model: … not observable"), listing the failure in
/// `compare.json`, the report and on the terminal. (With `A = 0` and `B = 0` there is no
/// assumed-model row at all: `compare_takes_a_mass_matrix_model` and the terms-only tanks
/// test.)
#[test]
fn compare_goes_on_when_a_residual_analysis_fails() {
    let dir = scratch("residual-failure");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    let model = r#"
states = ["theta", "omega"]
inputs = ["u"]
A = [[0.0, 0.0], [0.0, -0.1]]
B = [[0.0], [0.0]]
measured = ["theta"]
corrected = ["omega"]
noise_variance = [0.01]

[[terms]]
state = "theta"
effect = "kinematics"
term = "omega"
coefficient = 1.0

[[terms]]
state = "omega"
effect = "pendulum"
term = "-19.62*theta - 0.2*omega - 2*u"
coefficient = 1.0
"#;
    std::fs::write(dir.join("m.toml"), model).unwrap();
    // The default degree, stated: any flag will do for the shared helper.
    let json = compare_json_with(&dir, "o", "--poly-degree", "3");
    let failed = json["residual_failures"].as_array().unwrap();
    assert!(
        failed
            .iter()
            .any(|f| f["model"] == "assumed model" && f["at"] == "residuals"),
        "{failed:?}"
    );
    // The assumed model's table row stands; the residual analyses that ran are there.
    let labels: Vec<&str> = json["estimation"]["rows"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|r| r["label"].as_str())
        .collect();
    assert!(labels.contains(&"assumed model"), "{labels:?}");
    assert!(labels.contains(&"given model"), "{labels:?}");
    let analysed: Vec<&str> = json["residuals"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|r| r[0].as_str())
        .collect();
    assert!(analysed.contains(&"MME/NN"), "{analysed:?}");
    assert!(!analysed.contains(&"assumed model"), "{analysed:?}");
    let report = std::fs::read_to_string(dir.join("o/report.md")).unwrap();
    assert!(
        report.contains("## Residual analyses that failed") && report.contains("not observable"),
        "{report}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--poly-nonlinear-lags N` reaches the polynomial NARX (`compare.json` records it, and
/// with one nonlinear lag per channel the model has fewer terms than with two: degree 3
/// in 2 variables has 7 monomials of degree 2–3, in 4 variables 30); 0 or a non-number is
/// refused naming the flag.
#[test]
fn cli_poly_nonlinear_lags_reach_compare_and_zero_is_refused() {
    let dir = scratch("poly-nl");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    let mut terms = Vec::new();
    for nl in ["1", "2"] {
        let json = compare_json_with(&dir, &format!("o-{nl}"), "--poly-nonlinear-lags", nl);
        let p = &json["poly_narx"];
        assert_eq!(p["nonlinear_lags"].as_u64(), nl.parse().ok(), "{p}");
        terms.push(p["terms"].as_u64().unwrap());
    }
    // Both runs share the delays, so the linear part is the same and only the monomials
    // of degree 2..=3 differ: C(2+3, 3) - 1 - 2 = 7 against C(4+3, 3) - 1 - 4 = 30.
    assert_eq!(terms[1] - terms[0], 30 - 7, "terms {terms:?}");
    for bad in ["0", "two"] {
        let err = compare_refuses(&dir, "--poly-nonlinear-lags", bad);
        assert!(err.contains("--poly-nonlinear-lags"), "{bad}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `compare --ss-max-order N` reaches the linear SS row (`compare.json` records the
/// largest order, and no candidate is above it); 0 or a non-number is refused naming the
/// flag.
#[test]
fn cli_ss_max_order_reaches_compare_and_zero_is_refused() {
    let dir = scratch("ss-max-order");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    for max in [1_u64, 3] {
        let json = compare_json_with(
            &dir,
            &format!("o-{max}"),
            "--ss-max-order",
            &max.to_string(),
        );
        let ss = &json["linear_ss"];
        assert_eq!(ss["max_order"].as_u64(), Some(max), "{ss}");
        let orders: Vec<u64> = ss["candidates"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|c| c["order"].as_u64())
            .collect();
        assert_eq!(orders, (1..=max).collect::<Vec<_>>(), "{ss}");
    }
    for bad in ["0", "two"] {
        let err = compare_refuses(&dir, "--ss-max-order", bad);
        assert!(err.contains("--ss-max-order"), "{bad}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--poly-focus simulation` refines the polynomial NARX by free-run error and
/// `compare.json` records it, with an estimation free-run fit no worse than the one-step
/// solution's; anything but `prediction` or `simulation` is refused naming the flag.
#[test]
fn cli_poly_focus_reaches_compare_and_a_bad_value_is_refused() {
    let dir = scratch("poly-focus");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    let mut fit = Vec::new();
    for focus in ["prediction", "simulation"] {
        let json = compare_json_with(&dir, &format!("o-{focus}"), "--poly-focus", focus);
        let row = json["estimation"]["rows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["label"] == "polynomial NARX")
            .unwrap_or_else(|| panic!("no polynomial NARX row: {}", json["estimation"]))
            .clone();
        fit.push(
            row["evaluation"]["channels"][0]["metrics"]["fit_percent"]
                .as_f64()
                .unwrap(),
        );
        if focus == "simulation" {
            assert_eq!(
                json["poly_narx"]["focus"]["simulation"]["max_iterations"], 30,
                "{}",
                json["poly_narx"]
            );
        } else {
            assert_eq!(
                json["poly_narx"]["focus"], "prediction",
                "{}",
                json["poly_narx"]
            );
        }
    }
    assert!(
        fit[1] >= fit[0] - 1e-9,
        "fit % prediction {}, simulation {}",
        fit[0],
        fit[1]
    );
    let err = compare_refuses(&dir, "--poly-focus", "sim");
    assert!(
        err.contains("--poly-focus") && err.contains("prediction or simulation"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--narx-focus simulation` reaches the NARX network: `compare.json` records the focus
/// and a refinement whose training free-run RMSE fell; anything but `prediction` or
/// `simulation` is refused naming the flag and the value.
#[test]
fn cli_narx_focus_reaches_compare_and_a_bad_value_is_refused() {
    let dir = scratch("narx-focus");
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(dir.join("m.toml"), PENDULUM).unwrap();
    let json = compare_json_with(&dir, "o", "--narx-focus", "simulation");
    assert_eq!(
        json["narx_focus"]["simulation"]["max_iterations"], 30,
        "{}",
        json["narx_focus"]
    );
    let r = &json["narx_refinement"];
    let (start, end) = (
        r["start_rmse"][0].as_f64().unwrap(),
        r["final_rmse"][0].as_f64().unwrap(),
    );
    assert!(end < start, "{r}");
    assert!((1..=30).contains(&r["iterations"].as_u64().unwrap()), "{r}");
    let err = compare_refuses(&dir, "--narx-focus", "bogus");
    assert!(
        err.contains("--narx-focus")
            && err.contains("'bogus'")
            && err.contains("prediction or simulation"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A model file that corrects no equation (`corrected` missing, or written empty by
/// `greyest` for a `[mechanics]` model) makes MME's `d̂` zero by construction. Every
/// command built on it refuses the file, naming it and suggesting the equations to
/// correct, before any estimate runs, instead of reporting "nothing missing" after
/// minutes.
#[test]
fn commands_built_on_mme_refuse_a_model_that_corrects_nothing() {
    let dir = scratch("uncorrected");
    let linear = PENDULUM.replace("corrected = [\"omega\"]\n", "");
    assert_ne!(linear, PENDULUM);
    std::fs::write(dir.join("linear.toml"), &linear).unwrap();
    std::fs::write(dir.join("d.csv"), oscillation_csv()).unwrap();
    std::fs::write(
        dir.join("mech.csv"),
        oscillation_csv().replace("t,u,theta", "t,u,y"),
    )
    .unwrap();
    std::fs::write(
        dir.join("mech.toml"),
        r#"
states = ["y", "v"]
inputs = ["u"]
measured = ["y"]
corrected = []
noise_variance = [1e-4]

[parameters]
m = { value = 1.0, fixed = true }
k = { value = 4.0 }

[mechanics]
q = ["y"]
qdot = ["v"]
mass = [["m"]]
forces = ["u - k*y"]
"#,
    )
    .unwrap();
    for (model, suggestion) in [
        ("linear.toml", "corrected = [\"theta\", \"omega\"]"),
        ("mech.toml", "corrected = [\"v\"]"),
    ] {
        for cmd in ["estimate", "discover", "fit", "compare", "monitor"] {
            let data = if model == "mech.toml" {
                "mech.csv"
            } else {
                "d.csv"
            };
            let class = format!("healthy={data}");
            let mut args = vec![cmd, "--model", model, "--out", "out"];
            if cmd == "monitor" {
                args.splice(0..1, ["monitor", "train"]);
                args.extend(["--class", &class]);
            } else {
                args.extend(["--data", data]);
            }
            let (code, err) = mmenn(&dir, &args, &[]);
            assert_ne!(code, 0, "{cmd} {model}: {err}");
            assert!(err.contains(model), "{cmd} {model}: {err}");
            assert!(err.contains("corrects none"), "{cmd} {model}: {err}");
            assert!(err.contains(suggestion), "{cmd} {model}: {err}");
            assert!(!dir.join("out").exists(), "{cmd} {model} wrote its output");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
