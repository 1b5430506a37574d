//! One model, one judge: simulate → discover → predict on the discovered model → compare
//! with the discovered model as a row; the discovered model's free-run fit % on the test
//! record is the same number in `predict` and in `compare`. Also: every model mmenn writes
//! loads through one loader, and a data file given as a model is a typed error.

use std::path::PathBuf;

use mmenn::compare::{CompareOptions, GIVEN_MODEL_ROW, run_compare};
use mmenn::discover::{DiscoverOptions, WorkflowConfig, run_discover};
use mmenn::fit::{FitOptions, HiddenChoice, InitialChoice, TrajectoryChoice, run_predict};
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;
use mmenn::{LoadedModel, MmennError, ModelKind, ModelProblem};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mmenn-model-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

#[test]
fn discovered_model_gets_one_fit_in_predict_and_compare() {
    let dir = scratch("chain");
    // Small records: 20 Hz for 10 s (201 samples); initial states fitted to 50 samples.
    let req = |recipe| SimulationRequest {
        system: "msd_cubic".into(),
        recipe,
        seed: 2,
        fs: Some(20.0),
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test), &dir.join("test")).unwrap();
    let d = run_discover(
        std::slice::from_ref(&train.data),
        &train.model,
        &[],
        &DiscoverOptions {
            workflow: WorkflowConfig {
                max_rounds: 1,
                ..WorkflowConfig::default()
            },
            ..DiscoverOptions::default()
        },
        &dir.join("discover"),
    )
    .unwrap();
    let discovered = dir.join("discover").join(&d.model);
    let loaded = LoadedModel::read(&discovered).unwrap();
    let text = mmenn::show::show_model(&discovered).unwrap();
    assert!(text.contains("v' = "), "{text}");

    let p = run_predict(
        &discovered,
        &test.data,
        &InitialChoice::Fit,
        50,
        &dir.join("predict"),
    )
    .unwrap();
    assert!(dir.join("predict/prediction.json").exists());

    let opts = CompareOptions {
        fit: FitOptions {
            hidden: HiddenChoice::Fixed(1),
            max_hidden: 1,
            inits: 1,
            train_on_trajectories: TrajectoryChoice::None,
            x0_window: 50,
            ..FitOptions::default()
        },
        narx_lags: Some(2),
        ..CompareOptions::default()
    };
    let c = run_compare(
        std::slice::from_ref(&train.data),
        &discovered,
        std::slice::from_ref(&test.data),
        &opts,
        &dir.join("compare"),
    )
    .unwrap();
    let val = c.validation.as_ref().unwrap();
    // The discovered model names the cubic spring (and damping): it is more than its
    // linear part, so compare gives it its own row, judged as predict judges it.
    assert_eq!(loaded.kind, ModelKind::WithTerms, "{:?}", d.effects);
    assert_eq!(c.given_model, ModelKind::WithTerms);
    let row = val
        .rows()
        .iter()
        .find(|r| r.label == GIVEN_MODEL_ROW)
        .unwrap();
    assert!(!p.free_run.channels.is_empty());
    for (name, m) in &p.free_run.channels {
        let cm = row.evaluation.channel(name).unwrap();
        // Identical to the bit: one judge, one rule, one window.
        assert_eq!(
            cm.fit_percent.to_bits(),
            m.fit_percent.to_bits(),
            "{name}: compare {} vs predict {}",
            cm.fit_percent,
            m.fit_percent
        );
        assert_eq!(cm.rmse.to_bits(), m.rmse.to_bits());
    }
    // compare's own MME/NN row is judged the same way: predict on its model.json agrees.
    let ph = run_predict(
        &dir.join("compare/mme_nn/model.json"),
        &test.data,
        &InitialChoice::Fit,
        50,
        &dir.join("predict-hybrid"),
    )
    .unwrap();
    let hybrid_row = val.rows().iter().find(|r| r.label == "MME/NN").unwrap();
    let (a, b) = (
        hybrid_row.evaluation.channel("x").unwrap().fit_percent,
        ph.free_run.channels["x"].fit_percent,
    );
    assert!(
        (a - b).abs() <= 1e-9 * a.abs().max(1.0),
        "MME/NN: compare {a} vs predict {b}"
    );
    // On this 201-sample record the linear SS row's refinement on the whole record fails
    // (a numerator not identifiable): its model is the held-out stage's, and the row's
    // note says so (the input bias stays; there is no retry without it).
    let ss = &c.linear_ss;
    let why = ss.final_refinement_failure.as_deref().unwrap_or_default();
    assert!(why.contains("not identifiable"), "{}", ss.choice);
    assert!(ss.input_bias);
    assert!(
        ss.choice.contains(&format!("which failed ({why})"))
            && ss
                .choice
                .contains("the row's model is the held-out stage's"),
        "{}",
        ss.choice
    );
    assert!(val.rows().iter().any(|r| r.label == ss.label));
    // The discovered model beats its own linear part on the test record.
    let assumed = val
        .rows()
        .iter()
        .find(|r| r.label == "assumed model")
        .unwrap();
    assert!(
        row.evaluation.channel("x").unwrap().fit_percent
            > assumed.evaluation.channel("x").unwrap().fit_percent
    );
    // A baseline that cannot be fitted (a free parameter outside the model) has no row of
    // numbers, and the report and summary say so with the reason.
    // (Without the polynomial NARX row: on this short record its free run leaves its
    // limits on the test record, a second failure this check is not about.)
    let bad = CompareOptions {
        oe_free: Some(vec!["A[9,9]".into()]),
        poly_narx: None,
        ..opts.clone()
    };
    let c = run_compare(
        std::slice::from_ref(&train.data),
        &discovered,
        std::slice::from_ref(&test.data),
        &bad,
        &dir.join("compare-bad"),
    )
    .unwrap();
    assert_eq!(c.failures.len(), 1, "{:?}", c.failures);
    assert_eq!(c.failures[0].model, "linear OE");
    assert!(!c.failures[0].reason.is_empty());
    assert!(c.estimation.rows().iter().all(|r| r.label != "linear OE"));
    let report = std::fs::read_to_string(dir.join("compare-bad/report.md")).unwrap();
    assert!(
        report.contains("| linear OE | — | not fitted: "),
        "{report}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn one_loader_reads_every_model_and_names_what_is_not_one() {
    let dir = scratch("loader");
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("data.csv");
    std::fs::write(&csv, "t,u,x\n0,0,1\n0.1,0,1\n").unwrap();
    match LoadedModel::read(&csv) {
        Err(MmennError::Model {
            problem: ModelProblem::NotAModel { .. },
            path,
            ..
        }) => assert_eq!(path, csv),
        other => panic!("{other:?}"),
    }
    let json = dir.join("model.json");
    std::fs::write(&json, "{\"format\": \"something else\"}").unwrap();
    assert!(matches!(
        LoadedModel::read(&json),
        Err(MmennError::Model {
            problem: ModelProblem::Syntax { .. },
            ..
        })
    ));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A model whose output is a combination of states (`C` + `outputs`): `predict` writes the
/// output column, reports the channel, estimates the initial state from the new record
/// (the model stores none) and, on the model's own noise-free response, recovers it.
#[test]
fn predict_judges_a_general_output_and_estimates_x0_from_the_record() {
    use mmenn::data_file::{read_table, write_csv};
    use mmenn::fit::{PredictOptions, run_predict_with};
    use mmenn::sysid_core::Experiment;
    use nalgebra::DMatrix;

    let dir = scratch("outputs");
    std::fs::create_dir_all(&dir).unwrap();
    let model_path = dir.join("m.toml");
    std::fs::write(
        &model_path,
        r#"
states = ["x1", "x2"]
inputs = ["u"]
A = [[0.0, 1.0], [-2.0, -0.3]]
B = [[0.0], [1.0]]
C = [[1.0, 0.5]]
outputs = ["s"]
corrected = ["x2"]
noise_variance = [1e-4]
units = { x1 = "m", x2 = "m/s", u = "N", s = "m" }
"#,
    )
    .unwrap();
    let model = LoadedModel::read(&model_path).unwrap();
    let n = 301;
    let dt = 0.05;
    let u = DMatrix::from_fn(1, n, |_, k| (0.7 * k as f64 * dt).sin());
    let exp = Experiment::new(0.0, dt, u.clone(), DMatrix::zeros(1, n)).unwrap();
    let truth_x0 = [0.8, -0.4];
    let xs = model.simulate_states(&truth_x0, &exp).unwrap();
    let s: Vec<f64> = (0..n).map(|k| xs[(0, k)] + 0.5 * xs[(1, k)]).collect();
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let uu: Vec<f64> = u.row(0).iter().copied().collect();
    let data = dir.join("d.csv");
    write_csv(&data, &["t".into(), "u".into(), "s".into()], &[&t, &uu, &s]).unwrap();
    let p = run_predict_with(
        &model_path,
        &data,
        &PredictOptions {
            horizon: Some(3),
            score_from: None,
            ..PredictOptions::default()
        },
        &dir.join("p"),
    )
    .unwrap();
    assert_eq!(p.model_kind, ModelKind::Assumed);
    let m = p.free_run.channels["s"];
    assert!(m.fit_percent > 99.9, "{m:?}");
    for (a, b) in p.free_run.x0.iter().zip(truth_x0) {
        assert!((a - b).abs() < 1e-4, "x0 {:?}", p.free_run.x0);
    }
    let k = p.k_step.as_ref().unwrap();
    assert_eq!(k.horizon, mmenn::sysid_core::Horizon::Steps(3));
    assert_eq!(k.scored.first, 3);
    let table = read_table(&dir.join("p/prediction.csv")).unwrap();
    for col in ["x1", "x2", "s", "s_3step"] {
        assert!(table.column_index(col).is_some(), "no column {col}");
    }
    let json = std::fs::read_to_string(dir.join("p/prediction.json")).unwrap();
    assert!(json.contains("first 200 of 301 samples"), "{json}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--score-from N` scores samples N.. only (the benchmark protocols' "RMSE after the
/// initialisation window"): the reported RMSE equals the RMSE computed by hand from
/// `prediction.csv`'s measured and error columns over those rows, the scored window says
/// so, and a first sample beyond the record is a typed error.
#[test]
fn predict_scores_from_a_given_sample() {
    use mmenn::data_file::{read_table, write_csv};
    use mmenn::fit::{PredictOptions, run_predict_with};
    use mmenn::sysid_core::Experiment;
    use nalgebra::DMatrix;

    let dir = scratch("score-from");
    std::fs::create_dir_all(&dir).unwrap();
    let model_path = dir.join("m.toml");
    std::fs::write(
        &model_path,
        "states = [\"x\", \"v\"]\ninputs = [\"u\"]\nA = [[0.0, 1.0], [-2.0, -0.3]]\nB = [[0.0], [1.0]]\nmeasured = [\"x\"]\ncorrected = [\"v\"]\nnoise_variance = [1e-4]\n",
    )
    .unwrap();
    let model = LoadedModel::read(&model_path).unwrap();
    let (n, dt) = (301, 0.05);
    let u = DMatrix::from_fn(1, n, |_, k| (0.7 * k as f64 * dt).sin());
    let exp = Experiment::new(0.0, dt, u.clone(), DMatrix::zeros(1, n)).unwrap();
    let xs = model.simulate_states(&[0.5, 0.0], &exp).unwrap();
    // A deterministic disturbance the model cannot follow, larger late in the record.
    let x: Vec<f64> = (0..n)
        .map(|k| xs[(0, k)] + 0.002 * (k as f64) * 1e-2 * (1.3 * k as f64).sin())
        .collect();
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    let uu: Vec<f64> = u.row(0).iter().copied().collect();
    let data = dir.join("d.csv");
    write_csv(&data, &["t".into(), "u".into(), "x".into()], &[&t, &uu, &x]).unwrap();
    let opts = |score_from| PredictOptions {
        x0_window: Some(50),
        score_from,
        ..PredictOptions::default()
    };
    let all = run_predict_with(&model_path, &data, &opts(None), &dir.join("all")).unwrap();
    let after = run_predict_with(&model_path, &data, &opts(Some(50)), &dir.join("after")).unwrap();
    assert_eq!((after.scored.first, after.scored.end), (50, n));
    // Same model, same start: only the scored samples differ.
    assert_eq!(all.free_run.x0, after.free_run.x0);
    let table = read_table(&dir.join("after/prediction.csv")).unwrap();
    let col = |name: &str| table.columns[table.column_index(name).unwrap()].clone();
    let (err, measured, sim) = (col("x_error"), col("x_measured"), col("x"));
    for k in 0..n {
        assert!((measured[k] - sim[k] - err[k]).abs() < 1e-12);
        assert!((measured[k] - x[k]).abs() < 1e-12);
    }
    let by_hand =
        |from: usize| (err[from..].iter().map(|e| e * e).sum::<f64>() / (n - from) as f64).sqrt();
    let rmse = |p: &mmenn::fit::PredictSummary| p.free_run.channels["x"].rmse;
    assert!(
        (rmse(&after) - by_hand(50)).abs() <= 1e-12 * by_hand(50),
        "{} {}",
        rmse(&after),
        by_hand(50)
    );
    assert!((rmse(&all) - by_hand(0)).abs() <= 1e-12 * by_hand(0));
    assert!((rmse(&after) - rmse(&all)).abs() > 1e-6 * rmse(&all));
    let beyond = run_predict_with(&model_path, &data, &opts(Some(n)), &dir.join("beyond"));
    assert!(
        matches!(beyond, Err(MmennError::ScoreFromBeyondRecord { first, len }) if first == n && len == n),
        "{beyond:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The command line: `show` prints a model's equations; `predict` on a data file given as
/// the model fails with a message naming the file and what it is, without a backtrace.
#[test]
fn cli_show_and_a_data_file_as_model() {
    use std::process::Command;

    let dir = scratch("cli");
    std::fs::create_dir_all(&dir).unwrap();
    let model = dir.join("m.toml");
    std::fs::write(
        &model,
        "states = [\"x\", \"v\"]\ninputs = [\"u\"]\nA = [[0.0, 1.0], [-4.03, -0.2]]\nB = [[0.0], [1.01]]\nmeasured = [\"x\"]\ncorrected = [\"v\"]\nnoise_variance = [1e-4]\n\n[[terms]]\nstate = \"v\"\neffect = \"quadratic_drag\"\nterm = \"v*abs(v)\"\ncoefficient = -0.803\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mmenn"))
        .args(["show", model.to_str().unwrap()])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success());
    assert!(
        text.contains("v' = -4.03 x - 0.2 v + 1.01 u - 0.803 v*abs(v)"),
        "{text}"
    );
    let csv = dir.join("d.csv");
    std::fs::write(&csv, "t,u,x\n0,0,1\n0.1,0,1\n0.2,0,1\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mmenn"))
        .current_dir(&dir)
        .env_remove("MMENN_BACKTRACE")
        .args([
            "predict", "--model", "d.csv", "--data", "d.csv", "--out", "p",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("d.csv") && err.contains("not a model mmenn reads"),
        "{err}"
    );
    assert!(!err.contains("backtrace"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The issue's "done when": simulate → discover (the test record as validation) →
/// predict on the discovered model → compare with the discovered model as a row; the
/// discovered model's free-run fit % on the test record is one number in `predict`,
/// `compare` and `discover` (its validation gap after the discovered terms), all with the
/// initial state fitted to the first 50 samples.
#[test]
// Measured on bfa0e7e: predict and compare 87.30277999699857 %, discover 87.30277977566405 %.
fn one_fit_percent_in_predict_compare_and_discover() {
    let dir = scratch("done-when");
    let req = |recipe| SimulationRequest {
        system: "msd_cubic".into(),
        recipe,
        seed: 2,
        fs: Some(20.0),
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test), &dir.join("test")).unwrap();
    let d = run_discover(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &DiscoverOptions {
            workflow: WorkflowConfig {
                max_rounds: 1,
                x0_window: 50,
                ..WorkflowConfig::default()
            },
            ..DiscoverOptions::default()
        },
        &dir.join("discover"),
    )
    .unwrap();
    let discovered = dir.join("discover").join(&d.model);
    assert_eq!(
        LoadedModel::read(&discovered).unwrap().kind,
        ModelKind::WithTerms
    );
    let p = run_predict(
        &discovered,
        &test.data,
        &InitialChoice::Fit,
        50,
        &dir.join("predict"),
    )
    .unwrap();
    let c = run_compare(
        std::slice::from_ref(&train.data),
        &discovered,
        std::slice::from_ref(&test.data),
        &CompareOptions {
            fit: FitOptions {
                hidden: HiddenChoice::Fixed(1),
                inits: 1,
                train_on_trajectories: TrajectoryChoice::None,
                x0_window: 50,
                ..FitOptions::default()
            },
            narx_lags: Some(2),
            ..CompareOptions::default()
        },
        &dir.join("compare"),
    )
    .unwrap();
    let row = c
        .validation
        .as_ref()
        .unwrap()
        .rows()
        .iter()
        .find(|r| r.label == GIVEN_MODEL_ROW)
        .unwrap()
        .evaluation
        .clone();
    let discover_after = &d.validation_gap.as_ref().unwrap().after.fit_percent;
    assert!(!p.free_run.channels.is_empty());
    for (name, m) in &p.free_run.channels {
        let in_compare = row.channel(name).unwrap().fit_percent;
        let in_discover = discover_after[name];
        assert_eq!(
            (in_compare.to_bits(), in_discover.to_bits()),
            (m.fit_percent.to_bits(), m.fit_percent.to_bits()),
            "{name}: predict {} %, compare {in_compare} %, discover {in_discover} %",
            m.fit_percent
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
