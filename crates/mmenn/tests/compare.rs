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

/// Noise σ of [`second_order_csv`].
const SS_SIGMA: f64 = 0.02;

/// A continuous oscillator near [`second_order_csv`]'s truth, with its velocity corrected
/// (the MME/NN row needs an assumed model).
const NEAR_OSCILLATOR: &str = r#"
states = ["y", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [-20.0, -2.2]]
B = [[0.0], [50.0]]
measured = ["y"]
corrected = ["v"]
noise_variance = [0.0004]
"#;

/// Compare options that keep the MME/NN row small (one hidden unit, one initialisation,
/// no trajectory training), the NARX at two delays and no polynomial NARX row.
fn light_options() -> CompareOptions {
    use mmenn::fit::{HiddenChoice, TrajectoryChoice};
    CompareOptions {
        fit: FitOptions {
            hidden: HiddenChoice::Fixed(1),
            inits: 1,
            train_on_trajectories: TrajectoryChoice::None,
            ..FitOptions::default()
        },
        narx_lags: Some(2),
        poly_narx: None,
        ..CompareOptions::default()
    }
}

/// A record of a discrete second-order system written here, independent of every mmenn
/// simulator: `y_k = x_k + e_k` with `X(z) = (0.3 z + 0.2)/(z² − 1.6 z + 0.8) U(z)` (poles
/// 0.8 ± 0.4i, steady-state gain 2.5), the input a random ±1 sequence held 3 to 18
/// samples, `e` white Gaussian noise of σ = [`SS_SIGMA`], sample time 0.1 s. A small
/// linear congruential generator and Box–Muller draw both (`seed` picks the stream).
fn second_order_csv(samples: usize, seed: u64) -> String {
    let mut state = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    let mut uniform = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let (a1, a2, b1, b2) = (-1.6, 0.8, 0.3, 0.2);
    // Observer form: x⁺ = [[−a1, 1], [−a2, 0]] x + [b1, b2]ᵀ u, output x₁.
    let (mut x1, mut x2) = (0.0_f64, 0.0_f64);
    let (mut u, mut hold) = (1.0_f64, 0usize);
    let mut csv = String::from("t,u,y\n");
    for k in 0..samples {
        if hold == 0 {
            u = if uniform() < 0.5 { -1.0 } else { 1.0 };
            hold = 3 + (uniform() * 16.0) as usize;
        }
        hold -= 1;
        let e = SS_SIGMA
            * (-2.0 * uniform().ln()).sqrt()
            * (2.0 * std::f64::consts::PI * uniform()).cos();
        csv.push_str(&format!("{},{u},{}\n", k as f64 * 0.1, x1 + e));
        let n1 = -a1 * x1 + x2 + b1 * u;
        let n2 = -a2 * x1 + b2 * u;
        x1 = n1;
        x2 = n2;
    }
    csv
}

/// The linear state-space row (subspace + free-run OE) on [`second_order_csv`]'s records:
/// it keeps the true order 2, and its validation free-run RMSE is the noise level (the
/// model class holds the truth; every sample scored, state fitted to the first 200). The
/// row is threaded through like the other rows (figure legend, residual analysis,
/// initial condition, `compare.json`, the report); the same options give the same bits;
/// and the bound bites: the order held to 1 leaves the RMSE far above the noise.
/// The assumed model is a continuous oscillator near the truth (the MME/NN row needs one).
/// Measured: order 2 (held-out RMSE n = 1: 1.29, n = 2: 0.02027, best n = 6: 0.02025),
/// poles 0.80005 ± 0.40009i; validation RMSE 0.02022 (fit 99.31 %), estimation 0.01972;
/// order held to 1: validation RMSE 1.237. Bounds: σ within ±15 % (600 samples give about
/// ±3 % for the noise alone), order 1 at least 3σ.
#[test]
fn linear_ss_row_finds_the_order_and_noise_level_of_an_independent_record() {
    use mmenn::compare::{LINEAR_SS_ROW, compute_compare};
    use mmenn::model::LoadedModel;

    let dir = std::env::temp_dir().join(format!("mmenn-compare-ss-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("est.csv"), second_order_csv(1000, 1)).unwrap();
    std::fs::write(dir.join("val.csv"), second_order_csv(600, 2)).unwrap();
    std::fs::write(dir.join("model.toml"), NEAR_OSCILLATOR).unwrap();
    let opts = light_options();
    assert_eq!(opts.ss_max_order, 6);
    let s = run_compare(
        &[dir.join("est.csv")],
        &dir.join("model.toml"),
        &[dir.join("val.csv")],
        &opts,
        &dir.join("cmp"),
    )
    .unwrap();
    assert!(s.failures.is_empty(), "{:?}", s.failures);
    let ss = &s.linear_ss;
    assert_eq!(ss.order, Some(2), "{}", ss.choice);
    assert_eq!(ss.label, format!("{LINEAR_SS_ROW}, n = 2)"));
    assert_eq!(ss.label, "linear SS (subspace + OE, n = 2)");
    let metrics = |t: &mmenn::sysid_baselines::EvaluationTable, label: &str| {
        *t.rows()
            .iter()
            .find(|r| r.label == label)
            .and_then(|r| r.evaluation.channel("y"))
            .unwrap_or_else(|| panic!("no {label} row in {}", t.title()))
    };
    let val = s.validation.as_ref().unwrap();
    let (est_m, val_m) = (metrics(&s.estimation, &ss.label), metrics(val, &ss.label));
    assert!(
        val_m.rmse < 1.15 * SS_SIGMA && val_m.rmse > 0.85 * SS_SIGMA,
        "validation RMSE {} vs σ {SS_SIGMA}",
        val_m.rmse
    );
    assert!(
        est_m.rmse < 1.15 * SS_SIGMA,
        "estimation RMSE {}",
        est_m.rmse
    );
    assert!(val_m.fit_percent > 95.0, "fit {} %", val_m.fit_percent);
    // The order choice: order 1 is far off on the held-out part, order 2 at the noise.
    let held = |n: usize| {
        ss.candidates
            .iter()
            .find(|c| c.order == n)
            .and_then(|c| c.refined_rmse)
            .unwrap()
    };
    assert!(held(1) > 3.0 * held(2), "{}", ss.choice);
    assert!(
        ss.choice.starts_with("n = 2: the smallest order"),
        "{}",
        ss.choice
    );
    // Threaded through like the other rows.
    assert!(s.residuals.iter().any(|(l, _)| l == &ss.label));
    assert!(
        s.initialisation
            .iter()
            .any(|(l, how)| l == &ss.label && how.contains("first 200 measured outputs"))
    );
    let out = dir.join("cmp");
    assert!(
        out.join("residual_acf_linear_SS_subspace_OE_n_2_y.svg")
            .exists()
    );
    let figure = std::fs::read_to_string(out.join("compare_validation_y.svg")).unwrap();
    assert!(
        figure.contains("linear SS (subspace + OE, n = 2) (fit"),
        "no legend entry"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("compare.json")).unwrap()).unwrap();
    assert_eq!(json["linear_ss"]["order"], 2);
    assert_eq!(json["linear_ss"]["max_order"], 6);
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("| linear SS (subspace + OE, n = 2) | y | "),
        "{report}"
    );
    assert!(report.contains("Linear SS (black box"), "{report}");

    // The same options on the same records: the same bits.
    let loaded = LoadedModel::read(&dir.join("model.toml")).unwrap();
    let read = |f: &str| {
        let spec = &loaded.spec;
        mmenn::data_file::read_with_validation(&[dir.join(f)], &[], spec)
            .unwrap()
            .0
    };
    let (est_d, val_d) = (read("est.csv"), read("val.csv"));
    let again = compute_compare(&est_d, &loaded, Some(&val_d), &opts)
        .unwrap()
        .summary;
    let again_val = metrics(again.validation.as_ref().unwrap(), &ss.label);
    assert_eq!(again.linear_ss, s.linear_ss);
    assert_eq!(
        (again_val.rmse.to_bits(), again_val.fit_percent.to_bits()),
        (val_m.rmse.to_bits(), val_m.fit_percent.to_bits())
    );

    // Held to order 1, the same row is far from the noise level: the bound above bites.
    let first = compute_compare(
        &est_d,
        &loaded,
        Some(&val_d),
        &CompareOptions {
            ss_max_order: 1,
            ..opts.clone()
        },
    )
    .unwrap()
    .summary;
    assert_eq!(first.linear_ss.order, Some(1));
    let low = metrics(first.validation.as_ref().unwrap(), &first.linear_ss.label);
    assert!(low.rmse > 3.0 * SS_SIGMA, "order-1 RMSE {}", low.rmse);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `CompareOptions::narx_focus`: with [`Focus::Simulation`] the NARX network is refined by
/// free-run error over the estimation data, and `compare.json` and the report say how
/// (iterations, training free-run RMSE before → after); with the default it is trained
/// one-step alone and carries no refinement. On [`second_order_csv`]'s record (one
/// estimation record, no validation) the refinement's RMSEs are the NARX row's own
/// estimation free-run RMSE: the one-step network's (the default run, the same seed and
/// so the same network) before, the refined network's after; and the refinement lowers it.
#[test]
fn narx_simulation_focus_is_refined_and_reported() {
    use mmenn::compare::Focus;

    let dir = std::env::temp_dir().join(format!("mmenn-compare-narx-focus-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("est.csv"), second_order_csv(300, 3)).unwrap();
    std::fs::write(dir.join("model.toml"), NEAR_OSCILLATOR).unwrap();
    let base = CompareOptions {
        ss_max_order: 2,
        ..light_options()
    };
    assert_eq!(base.narx_focus, Focus::Prediction);
    let run = |focus: Focus, out: &str| {
        let s = run_compare(
            &[dir.join("est.csv")],
            &dir.join("model.toml"),
            &[],
            &CompareOptions {
                narx_focus: focus,
                ..base.clone()
            },
            &dir.join(out),
        )
        .unwrap();
        let narx_rmse = s
            .estimation
            .rows()
            .iter()
            .find(|r| r.label == "NARX")
            .and_then(|r| r.evaluation.channel("y"))
            .unwrap_or_else(|| panic!("no NARX row: {:?}", s.failures))
            .rmse;
        let report = std::fs::read_to_string(dir.join(out).join("report.md")).unwrap();
        let json: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(dir.join(out).join("compare.json")).unwrap(),
        )
        .unwrap();
        (s, narx_rmse, report, json)
    };

    let (one_step, one_step_rmse, report, json) = run(Focus::Prediction, "prediction");
    assert_eq!(one_step.narx_focus, Focus::Prediction);
    assert!(one_step.narx_refinement.is_none());
    assert!(
        json["narx_refinement"].is_null(),
        "{}",
        json["narx_refinement"]
    );
    assert_eq!(json["narx_focus"], "prediction");
    assert!(
        report.contains("trained one-step") && !report.contains("then refined by free-run error"),
        "{report}"
    );

    let focus = Focus::Simulation { max_iterations: 30 };
    let (refined, refined_rmse, report, json) = run(focus, "simulation");
    assert_eq!(refined.narx_focus, focus);
    let r = refined
        .narx_refinement
        .as_ref()
        .expect("a refinement with the simulation focus");
    assert!((1..=30).contains(&r.iterations), "{r:?}");
    assert_eq!((r.start_rmse.len(), r.final_rmse.len()), (1, 1), "{r:?}");
    assert!(r.final_rmse[0] < r.start_rmse[0], "{r:?}");
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1e-300);
    assert!(
        close(r.start_rmse[0], one_step_rmse),
        "start {} vs the one-step NARX row {one_step_rmse}",
        r.start_rmse[0]
    );
    assert!(
        close(r.final_rmse[0], refined_rmse),
        "final {} vs the refined NARX row {refined_rmse}",
        r.final_rmse[0]
    );
    let sentence = format!(
        "then refined by free-run error over the estimation data: {} Levenberg–Marquardt \
         iteration{} (at most 30), training free-run RMSE y {:.4e} → {:.4e}",
        r.iterations,
        if r.iterations == 1 { "" } else { "s" },
        r.start_rmse[0],
        r.final_rmse[0]
    );
    assert!(report.contains(&sentence), "{sentence}\n{report}");
    assert_eq!(json["narx_focus"]["simulation"]["max_iterations"], 30);
    assert_eq!(
        json["narx_refinement"]["iterations"].as_u64(),
        Some(r.iterations as u64)
    );
    assert_eq!(
        json["narx_refinement"]["final_rmse"][0].as_f64(),
        Some(r.final_rmse[0])
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
