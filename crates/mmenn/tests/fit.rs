//! MME/NN hybrid model end to end (thesis ch. 4): simulate, fit on the training recipe,
//! predict free-run on the test recipe (a different input), judge against the truth.
//! Sweeps are reduced (sizes 1–5 × 3 initialisations) to keep CI short; the full
//! 1–10 × 10 sweep runs in `cargo xtask reproduce`.

use std::path::{Path, PathBuf};

use mmenn::fit::{FitOptions, InitialChoice, ModelUpdateChoice, Training, run_fit, run_predict};
use mmenn::plants::{Recipe, SimulationRequest};
use mmenn::simulate::run_simulate;

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mmenn-fit-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn sim(
    dir: &Path,
    system: &str,
    recipe: Recipe,
    noise: Option<f64>,
    fs: Option<f64>,
) -> mmenn::simulate::SimulateOutput {
    let req = SimulationRequest {
        system: system.into(),
        recipe,
        noise_variance: noise,
        fs,
        seed: 5,
        ..Default::default()
    };
    run_simulate(&req, dir).unwrap()
}

fn quick(update: ModelUpdateChoice) -> FitOptions {
    FitOptions {
        max_hidden: 5,
        inits: 3,
        update,
        ..FitOptions::default()
    }
}

/// Free-run prediction on the test recipe's truth, from the true initial state.
fn predict_truth(
    fit_dir: &Path,
    test: &mmenn::simulate::SimulateOutput,
    out: &Path,
) -> mmenn::fit::PredictSummary {
    let truth = mmenn::data_file::read_table(&test.truth).unwrap();
    let spec = mmenn::read_model(&test.model).unwrap();
    let x0: Vec<f64> = spec
        .linear
        .state_names()
        .iter()
        .map(|s| truth.columns[truth.column_index(s).unwrap()][0])
        .collect();
    run_predict(
        &fit_dir.join("model.json"),
        &test.truth,
        &InitialChoice::Given(x0),
        200,
        out,
    )
    .unwrap()
}

/// The noise-free pendulum's training and test recipes, simulated under `dir`.
fn clean_pendulum(
    dir: &Path,
) -> (
    mmenn::simulate::SimulateOutput,
    mmenn::simulate::SimulateOutput,
) {
    let train = sim(
        &dir.join("train"),
        "pendulum",
        Recipe::Train,
        Some(0.0),
        None,
    );
    let test = sim(&dir.join("test"), "pendulum", Recipe::Test, Some(0.0), None);
    (train, test)
}

#[test]
fn clean_single_pendulum_predicts_the_test_input() {
    let dir = scratch("pend-clean");
    let (train, test) = clean_pendulum(&dir);
    // The thesis bound holds with `trainlm` and with the accelerated training too.
    for training in [Training::Trainlm, Training::Accelerated] {
        let fit_dir = dir.join(format!("fit-{training:?}"));
        let s = run_fit(
            std::slice::from_ref(&train.data),
            &train.model,
            std::slice::from_ref(&test.data),
            &FitOptions {
                training,
                ..quick(ModelUpdateChoice::None)
            },
            &fit_dir,
        )
        .unwrap();
        assert_eq!(s.training, training);
        let p = predict_truth(&fit_dir, &test, &dir.join("pred"));
        for state in ["theta", "omega"] {
            let r2 = p.free_run.channels[state].r2;
            assert!(
                r2 >= 0.999,
                "{training:?} {state}: free-run R² {r2} on the test input"
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn noisy_single_pendulum_predicts_the_truth_better_than_the_noise() {
    // Thesis §4.1 with measurement noise (variance 0.01 rad²): the hybrid model's error
    // against the truth must be smaller than its error against the noisy measurements
    // (which carry the noise on top) — i.e. it learned the system, not the noise.
    let dir = scratch("pend-noisy");
    let train = sim(
        &dir.join("train"),
        "pendulum",
        Recipe::Train,
        Some(0.01),
        None,
    );
    let test = sim(
        &dir.join("test"),
        "pendulum",
        Recipe::Test,
        Some(0.01),
        None,
    );
    run_fit(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &quick(ModelUpdateChoice::None),
        &dir.join("fit"),
    )
    .unwrap();
    let vs_truth = predict_truth(&dir.join("fit"), &test, &dir.join("pred_truth"));
    let spec = mmenn::read_model(&test.model).unwrap();
    let vs_meas = run_predict(
        &dir.join("fit/model.json"),
        &test.data,
        &InitialChoice::Given(vs_truth.free_run.x0.clone()),
        200,
        &dir.join("pred_meas"),
    )
    .unwrap();
    for name in spec.linear.output_names() {
        let (t, m) = (
            vs_truth.free_run.channels[name].error_variance,
            vs_meas.free_run.channels[name].error_variance,
        );
        assert!(
            t < m,
            "{name}: error variance vs truth {t} not below vs measurements {m}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The thesis's protocol (§4.5): its validation record chooses the network
/// (`ValidationUse::Select`) and is the record predicted, so these R² are optimistic. With
/// the validation record scored only (the default since `ValidationUse` exists) the 10-Hz
/// h2 fell to 0.943 (the one rate measured that way before this doc was written);
/// `cargo xtask reproduce`'s sample-rate table fits without validation data.
#[test]
fn two_tank_at_every_thesis_sample_rate() {
    for fs in [10.0, 5.0, 1.0, 0.5] {
        let dir = scratch(&format!("tank-{fs}"));
        let train = sim(
            &dir.join("train"),
            "two_tank",
            Recipe::Train,
            None,
            Some(fs),
        );
        let test = sim(&dir.join("test"), "two_tank", Recipe::Test, None, Some(fs));
        run_fit(
            std::slice::from_ref(&train.data),
            &train.model,
            std::slice::from_ref(&test.data),
            &FitOptions {
                validation_use: mmenn::fit::ValidationUse::Select,
                ..quick(ModelUpdateChoice::None)
            },
            &dir.join("fit"),
        )
        .unwrap();
        let p = predict_truth(&dir.join("fit"), &test, &dir.join("pred"));
        for (state, m) in &p.free_run.channels {
            assert!(m.r2 >= 0.95, "fs {fs} Hz, {state}: free-run R² {}", m.r2);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[test]
fn double_pendulum_with_regression_updated_model() {
    let dir = scratch("dpend");
    let train = sim(
        &dir.join("train"),
        "double_pendulum",
        Recipe::Train,
        None,
        None,
    );
    let test = sim(
        &dir.join("test"),
        "double_pendulum",
        Recipe::Test,
        None,
        None,
    );
    // The corrections of the double pendulum need larger networks than the single
    // pendulum's: the full size range, with 2 initialisations per size to keep CI short.
    let opts = FitOptions {
        max_hidden: 10,
        inits: 2,
        update: ModelUpdateChoice::Regression,
        ..FitOptions::default()
    };
    let s = run_fit(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &opts,
        &dir.join("fit"),
    )
    .unwrap();
    assert!(s.model_update.is_some());
    let p = predict_truth(&dir.join("fit"), &test, &dir.join("pred"));
    assert_eq!(p.free_run.channels.len(), 4);
    for (state, m) in &p.free_run.channels {
        assert!(
            m.r2 >= 0.95,
            "{state}: free-run R² {} on the test input",
            m.r2
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn trajectory_refinement_removes_the_bias_of_a_shrunk_correction() {
    // Thesis §7.1: training on trajectories. With W = 3e8 (the covariance constraint picks
    // W ≈ 1.8e4 on this record) MME's cost penalises d so heavily that d̂ is shrunk towards
    // 0, and a network trained on d̂ inherits the bias: its free-run fit on the test input
    // drops to ~87 %. Refining the weights on the training record's output trajectories
    // must remove much of that bias. No validation data is given, so the test input is
    // never seen by the fit (early stopping uses held-out training windows); the judge is
    // the noise-free truth on the test input from the true initial state.
    use mmenn::estimate::{EstimateOptions, WeightChoice};
    use mmenn::fit::{HiddenChoice, TrajectoryChoice};
    let dir = scratch("refine-bias");
    let (train, test) = clean_pendulum(&dir);
    let fit = |refine, name: &str| {
        let opts = FitOptions {
            estimate: EstimateOptions {
                w: WeightChoice::Value(3e8),
                substeps: None,
                ..EstimateOptions::default()
            },
            hidden: HiddenChoice::Fixed(4),
            inits: 2,
            train_on_trajectories: refine,
            ..FitOptions::default()
        };
        let s = run_fit(
            std::slice::from_ref(&train.data),
            &train.model,
            &[],
            &opts,
            &dir.join(name),
        )
        .unwrap();
        let p = predict_truth(&dir.join(name), &test, &dir.join(format!("{name}-pred")));
        (s, p)
    };
    let (plain, before) = fit(TrajectoryChoice::None, "plain");
    let (refined, after) = fit(TrajectoryChoice::Trajectory, "refined");
    assert!(plain.refinement.is_none());
    let r = refined.refinement.as_ref().unwrap();
    assert!(r.report.final_train_objective() <= r.report.initial_train_objective());
    assert!(r.report.best_iteration >= 1, "{r:?}");
    // Same data, seed and sweep: the refinement starts from the very network `plain` kept.
    assert_eq!(plain.chosen, refined.chosen);
    // Measured: RMSE 0.085 → 0.037 rad on θ and 0.37 → 0.16 rad/s on ω (a factor 2.3);
    // require at least a 40 % reduction on both states.
    for state in ["theta", "omega"] {
        let (b, a) = (
            before.free_run.channels[state].rmse,
            after.free_run.channels[state].rmse,
        );
        assert!(a < 0.6 * b, "{state}: test free-run RMSE {b} → {a}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A band-limited input sampled coarsely: an oscillator `ẍ = −4x − 0.4ẋ + u` whose assumed
/// model misses a cubic spring `−x³` (the correction the network learns), driven by four
/// tones of 0.7–2.6 rad/s sampled every 0.25 s (10–36 samples per period), the records
/// simulated finely (20 RK4 sub-steps) with the input linear between samples, `x`
/// measured with noise variance 1e-4. `fit` and `predict` with `intersample = "foh"` must
/// follow the record; with `"zoh"` every step (MME, the network's training pairs, the
/// refinement and the free run) sees the input half a sample late, which the network
/// of `(x, v, u)` cannot undo.
#[test]
fn band_limited_input_is_fitted_and_predicted_with_the_first_order_hold() {
    use mmenn::fit::{FitSummary, HiddenChoice, PredictSummary};
    use mmenn::sysid_core::{InterSample, TermModel};

    use crate::band_limited::{oscillator, record, write_spec};

    let linear = oscillator();
    let truth =
        TermModel::from_specs(linear.clone(), [("v", "cubic_stiffness", "x^3", -1.0)]).unwrap();
    let dir = scratch("foh");
    std::fs::create_dir_all(&dir).unwrap();
    // The measured record, and the noise-free states of the same run (x and v) to judge
    // `predict` against.
    let record = |name: &str, len: usize, phase: f64, seed: u64| {
        record(&dir, &truth, name, len, phase, seed)
    };
    let (train, _) = record("train", 480, 0.0, 1);
    let (val, val_truth) = record("val", 240, 0.8, 2);
    let run = |hold: InterSample| -> (FitSummary, PredictSummary) {
        let model = dir.join(format!("model_{hold:?}.toml"));
        write_spec(&model, &linear, hold);
        let out = dir.join(format!("fit_{hold:?}"));
        let opts = FitOptions {
            hidden: HiddenChoice::Fixed(3),
            inits: 2,
            ..FitOptions::default()
        };
        let fit = run_fit(
            std::slice::from_ref(&train),
            &model,
            std::slice::from_ref(&val),
            &opts,
            &out,
        )
        .unwrap();
        // The validation run starts at rest: the true initial state.
        let pred = run_predict(
            &out.join("model.json"),
            &val_truth,
            &InitialChoice::Given(vec![0.0, 0.0]),
            200,
            &dir.join(format!("pred_{hold:?}")),
        )
        .unwrap();
        (fit, pred)
    };
    let (foh_fit, foh) = run(InterSample::Foh);
    let (zoh_fit, zoh) = run(InterSample::Zoh);
    // `model.json` carries the hold, so `predict` simulates as the model was fitted.
    let text = std::fs::read_to_string(dir.join("fit_Foh/model.json")).unwrap();
    let file: mmenn::fit::HybridFile = serde_json::from_str(&text).unwrap();
    assert_eq!(file.spec().unwrap().intersample, InterSample::Foh);
    // Measured (free-run RMSE against the noise-free validation states from the true
    // start): foh x 3.9e-3, v 8.7e-3; zoh x 0.125, v 0.279 — a factor 32 on both. The
    // interpolated model must predict x better than the measurement noise (σ = 0.01;
    // measured 2.6 times better), and the held one must be at least 5 times worse on both
    // states (over 6 times below the measured factor).
    let rmse = |p: &PredictSummary, s: &str| p.free_run.channels[s].rmse;
    assert!(rmse(&foh, "x") < 0.01, "foh x RMSE {}", rmse(&foh, "x"));
    for state in ["x", "v"] {
        assert!(
            rmse(&zoh, state) > 5.0 * rmse(&foh, state),
            "{state}: zoh {} vs foh {}",
            rmse(&zoh, state),
            rmse(&foh, state)
        );
    }
    // `fit`'s own validation report (against the noisy record, initial state fitted):
    // measured foh 0.01057, the noise σ = 0.01 plus the model error above in quadrature
    // (0.0107); zoh 0.118. Bound: the noise level within 3σ of its estimate over 240
    // samples (+14 %) and the model error in quadrature, √(0.0114² + 0.0039²) ≈ 0.0120,
    // rounded up.
    let val_rmse = |s: &FitSummary| s.validation.as_ref().unwrap().channels["x"].rmse;
    assert!(val_rmse(&foh_fit) < 0.0122, "foh {}", val_rmse(&foh_fit));
    assert!(
        val_rmse(&zoh_fit) > 5.0 * val_rmse(&foh_fit),
        "zoh {} vs foh {}",
        val_rmse(&zoh_fit),
        val_rmse(&foh_fit)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `ensemble: band` averages every sweep network inside the sizing rule's band into one
/// network: its width is the members' total, the rows it lists are exactly the band of
/// the sweep it ran (validation data given), and the averaged model predicts the clean
/// pendulum's test input (R² ≥ 0.999, the bound of the single-network test).
#[test]
fn band_ensemble_is_one_network_of_the_equally_good_ones() {
    let dir = scratch("pend-band");
    let (train, test) = clean_pendulum(&dir);
    let s = run_fit(
        std::slice::from_ref(&train.data),
        &train.model,
        std::slice::from_ref(&test.data),
        &FitOptions {
            ensemble: mmenn::fit::NetworkEnsemble::Band,
            ..quick(ModelUpdateChoice::None)
        },
        &dir.join("fit"),
    )
    .unwrap();
    // The band, recomputed from sweep.csv by hand: test MSE within 10 % of the best.
    let sweep = mmenn::data_file::read_table(&dir.join("fit/sweep.csv")).unwrap();
    let col = |name: &str| sweep.columns[sweep.column_index(name).unwrap()].clone();
    let (hidden, test_mse) = (col("hidden"), col("test_mse"));
    let best = test_mse.iter().copied().fold(f64::INFINITY, f64::min);
    let band: Vec<usize> = (0..test_mse.len())
        .filter(|&i| test_mse[i] <= best * 1.1)
        .collect();
    assert_eq!(s.ensemble_rows, band);
    // On this record two restarts land inside the band (rows 7 and 11 on 2026-11-26), so
    // the merge is exercised.
    assert!(band.len() >= 2, "band {band:?}");
    let width = band.iter().map(|&i| hidden[i] as usize).sum::<usize>();
    assert_eq!(s.hidden, width);
    let file: mmenn::fit::HybridFile =
        serde_json::from_str(&std::fs::read_to_string(dir.join("fit/model.json")).unwrap())
            .unwrap();
    assert_eq!(file.network.hidden(), &[width]);
    let p = predict_truth(&dir.join("fit"), &test, &dir.join("pred"));
    for state in ["theta", "omega"] {
        let r2 = p.free_run.channels[state].r2;
        assert!(r2 >= 0.999, "{state}: free-run R² {r2} on the test input");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `FitOptions::network_domain = Hold` is saved in `model.json`, and `predict` counts the
/// free-run samples at which the network's inputs leave the box of its training pairs —
/// checked by brute force from `prediction.csv`'s states, the record's input and the
/// saved network's scaler. The test recipe's input is another signal than the training
/// one, and some of its samples leave the box; with the saved domain switched to
/// `extrapolate` the prediction changes (its count checked the same way).
#[test]
fn held_network_domain_is_saved_and_reported() {
    let dir = scratch("pend-hold");
    let (train, test) = clean_pendulum(&dir);
    let fit_dir = dir.join("fit");
    let summary = run_fit(
        std::slice::from_ref(&train.data),
        &train.model,
        &[],
        &FitOptions {
            network_domain: mmenn::fit::DomainPolicy::Hold,
            max_hidden: 2,
            inits: 2,
            ..FitOptions::default()
        },
        &fit_dir,
    )
    .unwrap();
    // The summary names the box (states, then inputs) and what the network does outside.
    assert_eq!(summary.network_domain, mmenn::nn::Domain::Hold);
    let names: Vec<&str> = summary.network_box.iter().map(|b| b.0.as_str()).collect();
    assert_eq!(names, ["theta", "omega", "u"]);
    assert!(summary.network_box.iter().all(|(_, lo, hi)| lo < hi));
    let report = std::fs::read_to_string(fit_dir.join("report.md")).unwrap();
    assert!(report.contains("theta ∈ ["), "{report}");
    assert!(report.contains("(held)"));
    let json = std::fs::read_to_string(fit_dir.join("model.json")).unwrap();
    let file: mmenn::fit::HybridFile = serde_json::from_str(&json).unwrap();
    assert_eq!(file.domain, mmenn::nn::Domain::Hold);
    let held = predict_truth(&fit_dir, &test, &dir.join("pred-hold"));
    let report = held.network_domain.expect("a hybrid's report");
    assert_eq!(report.domain, mmenn::nn::Domain::Hold);
    let md = std::fs::read_to_string(dir.join("pred-hold").join("report.md")).unwrap();
    assert!(
        md.contains(&format!(
            "at {} of {} samples",
            report.outside, report.samples
        )) && md.contains("held at the box's edge"),
        "{md}"
    );
    // Brute force: every sample's [x; u] against the saved scaler's box.
    let pred = mmenn::data_file::read_table(&dir.join("pred-hold").join("prediction.csv")).unwrap();
    let rec = mmenn::data_file::read_table(&test.truth).unwrap();
    let col = |t: &mmenn::data_file::Table, n: &str| t.columns[t.column_index(n).unwrap()].clone();
    let (theta, omega, u) = (col(&pred, "theta"), col(&pred, "omega"), col(&rec, "u"));
    let s = file.network.input_scaler().clone();
    // Samples within rounding of the box's faces may fall either way: bounds.
    let (surely, maybe) = outside_bounds(&[&theta, &omega, &u], &s);
    assert_eq!(report.samples, theta.len());
    assert!(
        (surely..=maybe).contains(&report.outside),
        "{} outside, brute force {surely}..={maybe}",
        report.outside
    );
    assert!(surely > 0, "the test record never left the training box");
    let outside = report.outside;
    // The same network extrapolating: same count, another prediction.
    let free = mmenn::fit::HybridFile {
        domain: mmenn::nn::Domain::Extrapolate,
        ..file
    };
    let free_dir = dir.join("fit-free");
    std::fs::create_dir_all(&free_dir).unwrap();
    std::fs::write(
        free_dir.join("model.json"),
        serde_json::to_string(&free).unwrap(),
    )
    .unwrap();
    let other = predict_truth(&free_dir, &test, &dir.join("pred-free"));
    let r = other.network_domain.unwrap();
    assert_eq!(r.domain, mmenn::nn::Domain::Extrapolate);
    // Its own trajectory leaves the box elsewhere: brute force on its states.
    let pred_free =
        mmenn::data_file::read_table(&dir.join("pred-free").join("prediction.csv")).unwrap();
    let (th, om) = (col(&pred_free, "theta"), col(&pred_free, "omega"));
    let (lo, hi) = outside_bounds(&[&th, &om, &u], &s);
    assert!((lo..=hi).contains(&r.outside));
    assert!(r.outside > 0 && outside > 0);
    let omega_free = col(
        &mmenn::data_file::read_table(&dir.join("pred-free").join("prediction.csv")).unwrap(),
        "omega",
    );
    assert!(
        omega
            .iter()
            .zip(&omega_free)
            .any(|(a, b)| (a - b).abs() > 1e-9)
    );
    // A network that is zero everywhere (the guard's physics alone) has nothing to report.
    let net = &free.network;
    let zero = mmenn::nn::Mlp::from_parts(
        net.architecture().clone(),
        vec![0.0; net.n_weights()],
        net.input_scaler().clone(),
        mmenn::nn::Scaler::new(vec![0.0; net.n_outputs()], vec![1.0; net.n_outputs()]).unwrap(),
    )
    .unwrap();
    let physics = mmenn::fit::HybridFile {
        network: zero,
        ..free
    };
    std::fs::write(
        free_dir.join("model.json"),
        serde_json::to_string(&physics).unwrap(),
    )
    .unwrap();
    let alone = predict_truth(&free_dir, &test, &dir.join("pred-physics"));
    assert!(alone.network_domain.is_none());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `FitOptions::network_inputs = States`: the network is trained on `(x̂, d̂)` pairs and
/// saved with as many inputs as the model has states; the summary's box and the report
/// name the states only; no figure plots `d̂` against the input. The two-tank system's
/// missing effect (Torricelli outflows in place of linear ones) is a function of the
/// levels alone, the pump's flow being in the assumed model: the states-only hybrid
/// predicts the test recipe (another input signal, whose free run leaves the training
/// box) at R² ≥ 0.98 on both levels, better on average than the thesis's network on
/// `(x̂, u)`, which extrapolates along the input too. On the pendulum, whose missing
/// effect carries the input (`−(u/l)(cos θ − 1)`, the base acceleration's torque), the
/// states-only network cannot represent it and predicts the test recipe worse.
#[test]
fn states_only_network_fits_a_state_function() {
    let dir = scratch("tank-states");
    // Fit with the network reading `inputs`, then predict the test recipe's truth.
    let fit_predict = |train: &mmenn::simulate::SimulateOutput,
                       test: &mmenn::simulate::SimulateOutput,
                       inputs,
                       tag: &str| {
        let fit_dir = dir.join(format!("fit-{tag}-{inputs:?}"));
        let opts = FitOptions {
            network_inputs: inputs,
            max_hidden: 5,
            inits: 3,
            ..FitOptions::default()
        };
        let summary = run_fit(
            std::slice::from_ref(&train.data),
            &train.model,
            &[],
            &opts,
            &fit_dir,
        )
        .unwrap();
        let p = predict_truth(&fit_dir, test, &dir.join(format!("pred-{tag}-{inputs:?}")));
        (fit_dir, summary, p)
    };
    let train = sim(&dir.join("train"), "two_tank", Recipe::Train, None, None);
    let test = sim(&dir.join("test"), "two_tank", Recipe::Test, None, None);
    let mut mean_r2 = Vec::new();
    for inputs in [
        mmenn::fit::NetworkInputs::States,
        mmenn::fit::NetworkInputs::StatesAndInputs,
    ] {
        let (fit_dir, summary, p) = fit_predict(&train, &test, inputs, "tank");
        assert_eq!(summary.network_inputs, inputs);
        let names: Vec<&str> = summary.network_box.iter().map(|b| b.0.as_str()).collect();
        let file: mmenn::fit::HybridFile =
            serde_json::from_str(&std::fs::read_to_string(fit_dir.join("model.json")).unwrap())
                .unwrap();
        let report = std::fs::read_to_string(fit_dir.join("report.md")).unwrap();
        let r2: Vec<f64> = ["h1", "h2"]
            .iter()
            .map(|s| p.free_run.channels[*s].r2)
            .collect();
        if inputs == mmenn::fit::NetworkInputs::States {
            assert_eq!(names, ["h1", "h2"]);
            assert!(report.contains("the states alone"), "{report}");
            assert!(summary.files.iter().all(|f| !f.ends_with("_vs_u.svg")));
            assert!(fit_dir.join("nn_d_h2_vs_h1.svg").exists());
            assert_eq!(file.network.n_inputs(), 2);
            assert!(r2.iter().all(|&r| r >= 0.98), "states-only R² {r2:?}");
        } else {
            assert_eq!(names, ["h1", "h2", "u"]);
            assert_eq!(file.network.n_inputs(), 3);
        }
        mean_r2.push((r2[0] + r2[1]) / 2.0);
    }
    assert!(mean_r2[0] > mean_r2[1], "mean R² {mean_r2:?}");
    // The pendulum: the input is part of what is missing.
    let (train, test) = clean_pendulum(&dir.join("pend"));
    let mut r2 = Vec::new();
    for inputs in [
        mmenn::fit::NetworkInputs::StatesAndInputs,
        mmenn::fit::NetworkInputs::States,
    ] {
        let (_, _, p) = fit_predict(&train, &test, inputs, "pend");
        r2.push(p.free_run.channels["theta"].r2);
    }
    assert!(r2[0] >= 0.999 && r2[1] < r2[0], "pendulum theta R²: {r2:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Samples at which some column lies outside the scaler's box by more than 1e-9 of its
/// half-range, and by more than −1e-9 (a sample on a face may count either way).
fn outside_bounds(columns: &[&Vec<f64>], s: &mmenn::nn::Scaler) -> (usize, usize) {
    let count = |edge: f64| {
        (0..columns[0].len())
            .filter(|&k| {
                columns
                    .iter()
                    .zip(s.centre().iter().zip(s.half_range()))
                    .any(|(col, (c, h))| ((col[k] - c) / h).abs() > edge)
            })
            .count()
    };
    (count(1.0 + 1e-9), count(1.0 - 1e-9))
}

/// `intersample = "bl"` end to end: a model file saying it is read, shown and used by
/// `predict`. The record: the oscillator of the test above (`ẍ = −4x − 0.4ẋ + u`, exact
/// model) driven by tones at 3–8 samples per period (0.12–0.33 of the sampling rate),
/// integrated by a hand-written RK4 at 64 steps per sample on the *continuous* tones (no
/// code of the crates), noise-free. Bound chosen before the run: the band-limited reading's
/// free run is at least 5 times closer to the truth than the linear one's, which loses
/// 31 % of a component at a third of the sampling rate.
#[test]
fn band_limited_model_file_is_read_shown_and_predicted() {
    use mmenn::predict::{InitialChoice, run_predict};
    use mmenn::sysid_core::InterSample;

    use crate::band_limited::{DT, oscillator, write_spec};

    const TONES: [(f64, f64); 3] = [(0.12, 0.4), (0.22, 1.7), (0.33, 2.9)];
    let u = |t: f64| -> f64 {
        TONES
            .iter()
            .map(|(nu, p)| (2.0 * std::f64::consts::PI * nu / DT * t + p).sin())
            .sum()
    };
    let f = |t: f64, x: [f64; 2]| [x[1], -4.0 * x[0] - 0.4 * x[1] + u(t)];
    let (len, sub) = (400, 64);
    let states = crate::truth::rk4_samples(f, [0.0, 0.0], DT, len, sub);
    let t_col: Vec<f64> = (0..len).map(|k| k as f64 * DT).collect();
    let u_col: Vec<f64> = t_col.iter().map(|&t| u(t)).collect();
    let x_col: Vec<f64> = states.iter().map(|x| x[0]).collect();
    let v_col: Vec<f64> = states.iter().map(|x| x[1]).collect();
    let dir = scratch("bl");
    std::fs::create_dir_all(&dir).unwrap();
    let data = dir.join("truth.csv");
    let header = ["t", "u", "x", "v"].map(String::from);
    mmenn::data_file::write_csv(&data, &header, &[&t_col, &u_col, &x_col, &v_col]).unwrap();
    let linear = oscillator();
    let run = |hold: InterSample| {
        let model = dir.join(format!("model_{hold:?}.toml"));
        write_spec(&model, &linear, hold);
        let spec = mmenn::model_file::read_model(&model).unwrap();
        assert_eq!(spec.intersample, hold);
        let shown = mmenn::show::show_model(&model).unwrap();
        let pred = run_predict(
            &model,
            &data,
            &InitialChoice::Given(vec![0.0, 0.0]),
            200,
            &dir.join(format!("pred_{hold:?}")),
        )
        .unwrap();
        (shown, pred.free_run.channels["x"].rmse)
    };
    let (shown, bl) = run(InterSample::Bl);
    assert!(shown.contains("band-limited"), "{shown}");
    let (_, foh) = run(InterSample::Foh);
    assert!(bl.is_finite() && 5.0 * bl < foh, "bl {bl} vs foh {foh}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--val-use score` (the default): the validation records are only judged. The model a
/// fit writes is byte-for-byte the one it writes without validation data, whichever
/// record is given, and its training numbers are the same; `--val-use select` makes its
/// choices on them, and its model differs (which shows the comparison can tell).
#[test]
fn validation_records_scored_only_do_not_change_the_model() {
    use mmenn::fit::ValidationUse;
    let dir = scratch("val-use");
    let train = sim(&dir.join("train"), "msd_cubic", Recipe::Train, None, None);
    let test = sim(&dir.join("test"), "msd_cubic", Recipe::Test, None, None);
    let other = run_simulate(
        &SimulationRequest {
            system: "msd_cubic".into(),
            recipe: Recipe::Test,
            seed: 9,
            ..Default::default()
        },
        &dir.join("other"),
    )
    .unwrap();
    let fit = |val: &[PathBuf], use_: ValidationUse, name: &str| {
        let out = dir.join(name);
        let opts = FitOptions {
            max_hidden: 3,
            inits: 2,
            validation_use: use_,
            ..FitOptions::default()
        };
        let s = run_fit(
            std::slice::from_ref(&train.data),
            &train.model,
            val,
            &opts,
            &out,
        )
        .unwrap();
        (s, std::fs::read(out.join("model.json")).unwrap())
    };
    let (none, model_none) = fit(&[], ValidationUse::Score, "none");
    assert_eq!(none.validation_use, None);
    for (val, name) in [(&test.data, "score-test"), (&other.data, "score-other")] {
        let (s, model) = fit(std::slice::from_ref(val), ValidationUse::Score, name);
        assert!(model == model_none, "{name}: the model depends on --val");
        assert_eq!(s.train, none.train, "{name}");
        assert_eq!(s.guard.held_out, none.guard.held_out, "{name}");
        assert_eq!(s.validation_use, Some(ValidationUse::Score));
        assert!(
            s.validation.is_some(),
            "{name}: the validation record is still judged"
        );
        assert!(
            s.test_source.contains("validation data scored only"),
            "{}",
            s.test_source
        );
    }
    let (sel, model_sel) = fit(
        std::slice::from_ref(&test.data),
        ValidationUse::Select,
        "select",
    );
    assert!(
        model_sel != model_none,
        "select: the validation record chose nothing"
    );
    assert!(
        sel.guard.held_out.contains("validation"),
        "{}",
        sel.guard.held_out
    );
    assert!(
        sel.test_source.contains("validation"),
        "{}",
        sel.test_source
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
