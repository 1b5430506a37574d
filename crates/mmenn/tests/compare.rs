//! `mmenn compare` on the single pendulum (thesis §5.2): four models, one free-run table;
//! and its linear columns on a record whose inputs are linear between samples.

use mmenn::compare::{CompareOptions, run_compare};
use mmenn::fit::FitOptions;
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;
use mmenn::sysid_core::Horizon;

#[test]
fn four_models_on_one_free_run_table() {
    let dir = std::env::temp_dir().join(format!("mmenn-compare-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let req = |recipe| SimulationRequest {
        system: "pendulum".into(),
        recipe,
        seed: 3,
        ..Default::default()
    };
    let train = run_simulate(&req(Recipe::Train), &dir.join("train")).unwrap();
    let test = run_simulate(&req(Recipe::Test), &dir.join("test")).unwrap();
    let opts = CompareOptions {
        fit: FitOptions {
            max_hidden: 5,
            inits: 3,
            ..FitOptions::default()
        },
        narx_lags: Some(6),
        ..CompareOptions::default()
    };
    let s = run_compare(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &opts,
        &dir.join("cmp"),
    )
    .unwrap();
    let val = s.validation.as_ref().unwrap();
    assert_eq!(val.horizon(), Horizon::FreeRun);
    let r2 = |label: &str| {
        val.rows()
            .iter()
            .find(|r| r.label == label)
            .unwrap()
            .evaluation
            .channel("theta")
            .unwrap()
            .r2
    };
    // The linearised model cannot follow large swings; the hybrid model can (thesis
    // Table 5-1). With this noise (σ = 0.1 rad) the hybrid's test R² varies with the noise
    // realisation (0.93–1.00 seen over seeds), so the check is the thesis's ranking.
    assert!(r2("MME/NN") > 0.9, "MME/NN validation R² {}", r2("MME/NN"));
    assert!(r2("MME/NN") > r2("assumed model") && r2("MME/NN") > r2("linear OE"));
    for f in [
        "compare.json",
        "report.md",
        "compare_validation_theta.svg",
        "residual_acf_MME_NN_theta.svg",
    ] {
        assert!(dir.join("cmp").join(f).exists(), "missing {f}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A linear oscillator (the assumed model is the truth) driven by a band-limited input,
/// simulated with the input linear between samples: with `intersample = "foh"` the
/// "assumed model" and "linear OE" columns simulate it exactly, so their validation
/// RMSE is the measurement noise (σ = 0.01); with the hold they see the input half a
/// sample late. Measured: foh 0.0101 (assumed) / 0.0101 (OE); zoh 0.202 / 0.092 (the
/// OE fit absorbs part of the lag into its parameters). Bounds: the noise level within 3σ
/// of its estimate over 240 samples (+14 %), and the held columns at least twice as far
/// off as the interpolated ones (measured 20 times for the assumed model, 9 for OE).
#[test]
fn linear_columns_follow_the_first_order_hold() {
    use mmenn::sysid_core::{InterSample, TermModel};

    use crate::band_limited::{oscillator, record, write_spec};

    let dir = std::env::temp_dir().join(format!("mmenn-compare-foh-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let linear = oscillator();
    let truth = TermModel::new(linear.clone(), vec![]).unwrap();
    let (train, _) = record(&dir, &truth, "train", 480, 0.0, 1);
    let (val, _) = record(&dir, &truth, "val", 240, 0.8, 2);
    let run = |hold: InterSample| {
        let model = dir.join(format!("model_{hold:?}.toml"));
        write_spec(&model, &linear, hold);
        let opts = CompareOptions {
            fit: FitOptions {
                hidden: mmenn::fit::HiddenChoice::Fixed(2),
                inits: 2,
                ..FitOptions::default()
            },
            narx_lags: Some(4),
            ..CompareOptions::default()
        };
        let s = run_compare(
            std::slice::from_ref(&train),
            &model,
            std::slice::from_ref(&val),
            &opts,
            &dir.join(format!("cmp_{hold:?}")),
        )
        .unwrap();
        let val = s.validation.unwrap();
        let rmse = |label: &str| {
            val.rows()
                .iter()
                .find(|r| r.label == label)
                .unwrap()
                .evaluation
                .channel("x")
                .unwrap()
                .rmse
        };
        [rmse("assumed model"), rmse("linear OE")]
    };
    let foh = run(InterSample::Foh);
    let zoh = run(InterSample::Zoh);
    for (i, label) in ["assumed model", "linear OE"].iter().enumerate() {
        assert!(foh[i] < 0.0114, "{label}: foh RMSE {}", foh[i]);
        assert!(
            zoh[i] > 2.0 * foh[i],
            "{label}: zoh {} vs foh {}",
            zoh[i],
            foh[i]
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The polynomial NARX row on records mmenn did not make: the independent generator's
/// hardening Duffing oscillator (`fixtures/discovery_suite/cases/duffing_hardening`: the
/// assumed model is the linear part, the cubic spring is hidden). Scoring rule, fixed
/// before the first run: with compare's defaults for the baselines (the NARX delays
/// suggested, degree 3, the newest 2 lags in the monomials) the row is in both tables,
/// nothing fails, and its validation free-run fit % is higher than the linear OE row's
/// (the best the linear structure does). It is threaded through like NARX: its figure
/// legend, residual analysis, initial condition, `compare.json` and the report.
/// Measured (delays na = 8, nb = 10 suggested; 49 terms, rank 49): validation fit %
/// polynomial NARX 97.67, NARX 95.95, linear OE 27.82, assumed model −65.71, MME/NN 18.20
/// (with this test's small network settings).
#[test]
fn polynomial_narx_beats_linear_oe_on_an_independent_duffing_record() {
    use mmenn::compare::{POLY_NARX_ROW, PolyNarxChoice};
    use mmenn::fit::{HiddenChoice, TrajectoryChoice};

    let case = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/discovery_suite/cases/duffing_hardening");
    let dir = std::env::temp_dir().join(format!("mmenn-compare-poly-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let opts = CompareOptions {
        fit: FitOptions {
            hidden: HiddenChoice::Fixed(2),
            inits: 2,
            train_on_trajectories: TrajectoryChoice::None,
            ..FitOptions::default()
        },
        ..CompareOptions::default()
    };
    assert_eq!(opts.poly_narx, Some(PolyNarxChoice::default()));
    let s = run_compare(
        &[case.join("est.csv")],
        &case.join("model.toml"),
        &[case.join("val.csv")],
        &opts,
        &dir,
    )
    .unwrap();
    assert!(s.failures.is_empty(), "{:?}", s.failures);
    let poly = s.poly_narx.as_ref().unwrap();
    assert_eq!(poly.orders, s.narx_orders);
    assert_eq!((poly.choice.degree, poly.choice.nonlinear_lags), (3, 2));
    assert!(poly.terms.is_some() && poly.rank.is_some());
    let fit = |t: &mmenn::sysid_baselines::EvaluationTable, label: &str| {
        t.rows()
            .iter()
            .find(|r| r.label == label)
            .and_then(|r| r.evaluation.channel("y"))
            .map(|m| m.fit_percent)
    };
    assert!(fit(&s.estimation, POLY_NARX_ROW).is_some());
    let val = s.validation.as_ref().unwrap();
    let (poly_fit, oe_fit) = (
        fit(val, POLY_NARX_ROW).unwrap(),
        fit(val, "linear OE").unwrap(),
    );
    assert!(
        poly_fit > oe_fit,
        "validation fit: polynomial NARX {poly_fit} %, linear OE {oe_fit} %"
    );
    assert!(s.residuals.iter().any(|(l, _)| l == POLY_NARX_ROW));
    assert!(
        s.initialisation
            .iter()
            .any(|(l, how)| l == POLY_NARX_ROW && how.contains("first measured delay window"))
    );
    assert!(dir.join("residual_acf_polynomial_NARX_y.svg").exists());
    let figure = std::fs::read_to_string(dir.join("compare_validation_y.svg")).unwrap();
    assert!(figure.contains("polynomial NARX (fit"), "no legend entry");
    let json = std::fs::read_to_string(dir.join("compare.json")).unwrap();
    assert!(json.contains("\"poly_narx\"") && json.contains("\"label\": \"polynomial NARX\""));
    let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(report.contains("| polynomial NARX | y | "), "{report}");
    assert!(
        report.contains("Polynomial NARX: the same delays"),
        "{report}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A polynomial's free run can leave its divergence limits on an input wider than the
/// training one: that costs only its row in the validation table (a failure at the free
/// run, naming the dataset), not the comparison. The validation record here is the
/// Duffing case's with the input ten times as large (outputs as measured: only the free
/// runs matter).
#[test]
fn a_diverging_polynomial_free_run_costs_only_its_row() {
    use mmenn::compare::{FailedAt, POLY_NARX_ROW};
    use mmenn::fit::{HiddenChoice, TrajectoryChoice};

    let case = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/discovery_suite/cases/duffing_hardening");
    let dir = std::env::temp_dir().join(format!("mmenn-compare-poly-div-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string(case.join("val.csv")).unwrap();
    let mut wide = String::new();
    for (i, line) in text.lines().enumerate() {
        if i == 0 {
            wide.push_str(line);
        } else {
            let f: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
            wide.push_str(&format!("{},{},{}", f[0], 10.0 * f[1], f[2]));
        }
        wide.push('\n');
    }
    std::fs::write(dir.join("wide.csv"), wide).unwrap();
    let opts = CompareOptions {
        fit: FitOptions {
            hidden: HiddenChoice::Fixed(2),
            inits: 2,
            train_on_trajectories: TrajectoryChoice::None,
            ..FitOptions::default()
        },
        narx_lags: Some(3),
        ..CompareOptions::default()
    };
    let s = run_compare(
        &[case.join("est.csv")],
        &case.join("model.toml"),
        &[dir.join("wide.csv")],
        &opts,
        &dir.join("cmp"),
    )
    .unwrap();
    let has_row = |t: &mmenn::sysid_baselines::EvaluationTable| {
        t.rows().iter().any(|r| r.label == POLY_NARX_ROW)
    };
    assert!(has_row(&s.estimation));
    assert!(!has_row(s.validation.as_ref().unwrap()));
    assert_eq!(s.failures.len(), 1, "{:?}", s.failures);
    let f = &s.failures[0];
    assert_eq!((f.model.as_str(), f.at), (POLY_NARX_ROW, FailedAt::FreeRun));
    assert!(
        f.reason.contains("validation data") && f.reason.contains("diverged at sample"),
        "{}",
        f.reason
    );
    assert!(s.residuals.iter().all(|(l, _)| l != POLY_NARX_ROW));
    let report = std::fs::read_to_string(dir.join("cmp/report.md")).unwrap();
    assert!(
        report.contains("| polynomial NARX | — | free run failed: free run on the validation data"),
        "{report}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
