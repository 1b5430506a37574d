//! `mmenn estimate`, `mmenn fit` and `mmenn predict` on measured data (Cascaded Tanks
//! benchmark, read in place from `../shared/data` or `MMENN_DATA_DIR`).

use std::path::{Path, PathBuf};

use mmenn::benchmarks::{Benchmark, DataDirSearch, load, test_rmse};
use mmenn::data_file::{read_table, write_experiment};
use mmenn::estimate::{EstimateOptions, run_estimate};
use mmenn::fit::{FitOptions, InitialChoice, run_fit, run_predict};
use mmenn::sysid_core::{Dataset, Experiment, InitialStateFit, fit_initial_state};

const MODEL: &str = r#"
states = ["x1", "y"]
inputs = ["u"]
A = [[-0.01, 0.0], [0.01, -0.01]]
B = [[0.01], [0.0]]
measured = ["y"]
corrected = ["x1", "y"]
noise_variance = "auto"
units = { y = "V", u = "V" }
"#;

#[test]
fn cascaded_tanks_with_estimated_noise() {
    let Some(folder) = tanks_folder() else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("mmenn-real-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("model.toml"), MODEL).unwrap();
    let s = run_estimate(
        &[folder.join("estimation.csv")],
        &dir.join("model.toml"),
        &EstimateOptions::default(),
        &dir.join("est"),
    )
    .unwrap();
    // The benchmark states an output SNR near 40 dB on a level of a few volts: the noise
    // variance must be positive and below (0.1 V)², and the covariance constraint met.
    let nv = s.noise_variance["y"];
    assert!(nv > 0.0 && nv < 1e-2, "noise variance {nv}");
    assert!(
        (s.residual_to_noise["y"] - 1.0).abs() < 0.1,
        "ratio {}",
        s.residual_to_noise["y"]
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The benchmark folder, or `None` (with a note) when it is absent — except under CI
/// (`CI` set), where the data are provisioned and a missing folder is a failure.
#[allow(clippy::print_stderr)]
fn folder(benchmark: Benchmark) -> Option<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    match DataDirSearch::from_env(None, Some(root)).locate(benchmark) {
        Ok(folder) => Some(folder),
        Err(e) if std::env::var_os("CI").is_some() => panic!("CI must provide the data: {e}"),
        Err(_) => {
            eprintln!(
                "SKIPPED: the {benchmark} data folder is absent (set MMENN_DATA_DIR or provide ../shared/data)"
            );
            None
        }
    }
}

pub(crate) fn tanks_folder() -> Option<PathBuf> {
    folder(Benchmark::CascadedTanks)
}

/// EMPS's recorded times are single-precision sums (steps of 0.99998 and 1.00002 ms): the
/// CSV reader takes them as the 1-ms clock they stamp, with the mean step, where it used to
/// refuse the official files (a user had to pass `--resample 0.001`).
#[test]
fn emps_recorded_times_read_as_a_uniform_clock() {
    let Some(folder) = folder(Benchmark::Emps) else {
        return;
    };
    for (file, rows) in [("estimation.csv", 24_841), ("validation.csv", 24_841)] {
        let table = mmenn::data_file::read_table(&folder.join(file)).unwrap();
        let t = &table.columns[table.column_index("t").unwrap()];
        assert!(
            t.windows(2).any(|w| (w[1] - w[0] - 1e-3).abs() > 1e-8),
            "{file}: the record's steps are expected to jitter"
        );
        let e = mmenn::data_file::table_to_experiment(&table, &["u".into()], &["y".into()])
            .unwrap_or_else(|err| panic!("{file}: {err}"));
        assert_eq!(e.len(), rows, "{file}");
        assert!((e.dt() - 1e-3).abs() < 1e-9, "{file}: dt = {}", e.dt());
    }
}

/// Physics-structured linear model of the two tanks in deviations from the estimation
/// record's means: `h1' = a1 h1 + b u`, `h2' = 0.02 h1 + a2 h2 + d`, `y = h2` (upper level
/// unmeasured, the correction on the measured lower tank). Coefficients: the linear
/// output-error fit of this structure on the estimation record (`cargo xtask reproduce`,
/// table `real_cascaded_tanks`), rounded.
const TANKS_MODEL: &str = r#"
states = ["h1", "h2"]
inputs = ["u"]
A = [[-0.02044, 0.0], [0.02, -0.005863]]
B = [[0.027596], [0.0]]
measured = ["h2"]
corrected = ["h2"]
noise_variance = [NOISE]
units = { h1 = "V", h2 = "V", u = "V" }
"#;

/// A benchmark record as deviations `(u − u0, y − y0)` with the output named `h2`.
fn shifted(d: &Dataset, u0: f64, y0: f64) -> Dataset {
    let e = &d.experiments()[0];
    let exp = Experiment::new(
        e.t0(),
        e.dt(),
        e.inputs().map(|v| v - u0),
        e.outputs().map(|v| v - y0),
    )
    .unwrap();
    Dataset::new(
        d.input_channels().to_vec(),
        vec![mmenn::sysid_core::Channel::new("h2")],
        vec![exp],
    )
    .unwrap()
}

fn column(path: &Path, name: &str) -> Vec<f64> {
    let t = read_table(path).unwrap();
    t.columns[t.column_index(name).unwrap()].clone()
}

#[test]
fn cascaded_tanks_fit_then_predict_beats_the_physics_model() {
    // `mmenn fit` on the official estimation record, then `mmenn predict` on the official
    // test record (never seen by the fit: no validation data are given), with the state
    // initialised on the first 50 test outputs and the RMSE scored after them (the official
    // loader's protocol).
    let Some(folder) = tanks_folder() else {
        return;
    };
    let data = load(Benchmark::CascadedTanks, &folder).unwrap();
    let e = &data.estimation.experiments()[0];
    let (u0, y0) = (e.inputs().mean(), e.outputs().mean());
    let est = shifted(&data.estimation, u0, y0);
    let test = shifted(&data.tests[0].data, u0, y0);
    let dir = std::env::temp_dir().join(format!("mmenn-real-fit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (est_csv, test_csv) = (dir.join("estimation.csv"), dir.join("test.csv"));
    write_experiment(&est_csv, &est, 0).unwrap();
    write_experiment(&test_csv, &test, 0).unwrap();
    // The benchmark states an output SNR close to 40 dB: noise variance = var(y)/10⁴.
    let y = est.experiments()[0].outputs();
    let noise = y.iter().map(|v| v * v).sum::<f64>() / (y.len() as f64 - 1.0) / 1e4;
    let model = dir.join("model.toml");
    std::fs::write(&model, TANKS_MODEL.replace("NOISE", &format!("{noise:e}"))).unwrap();

    // The assumed model alone, judged with the same protocol.
    let spec = mmenn::read_model(&model).unwrap();
    let lin = &spec.linear;
    let texp = &test.experiments()[0];
    let window = Benchmark::CascadedTanks.init_window();
    let fit = InitialStateFit {
        window,
        ..InitialStateFit::default()
    };
    let x0 = fit_initial_state(lin, lin.c(), texp, &[0.0; 2], &fit).unwrap();
    let xs = mmenn::sysid_core::simulate(
        lin,
        &x0,
        texp.t0(),
        texp.dt(),
        texp.inputs(),
        &fit.integrator,
        1e12,
    )
    .unwrap();
    let measured: Vec<f64> = texp.outputs().row(0).iter().copied().collect();
    let linear: Vec<f64> = xs.row(1).iter().copied().collect();
    let rmse_linear = test_rmse(Benchmark::CascadedTanks, &measured, &linear).unwrap();

    // A reduced sweep (1–6 units × 3 initialisations; the full 1–10 × 10 sweep picks the same
    // network here) keeps the test near a second.
    let opts = FitOptions {
        max_hidden: 6,
        inits: 3,
        seed: 1,
        ..FitOptions::default()
    };
    let summary = run_fit(
        std::slice::from_ref(&est_csv),
        &model,
        &[],
        &opts,
        &dir.join("fit"),
    )
    .unwrap();
    // Trajectory refinement (the default) is a descent method on the training windows.
    let refine = summary.refinement.as_ref().unwrap();
    assert!(refine.report.final_train_objective() <= refine.report.initial_train_objective());
    let p = run_predict(
        &dir.join("fit/model.json"),
        &test_csv,
        &InitialChoice::Fit,
        window,
        &dir.join("pred"),
    )
    .unwrap();
    assert_eq!(p.free_run.x0.len(), 2);
    let hybrid = column(&dir.join("pred/prediction.csv"), "h2");
    let rmse = test_rmse(Benchmark::CascadedTanks, &measured, &hybrid).unwrap();
    // Published free-run test RMSEs (../shared/data/README.md): linear state-space 0.588 V,
    // BLA 0.75 V, best 0.18–0.19 V (grey-box with a physical overflow term). The assumed
    // linear model alone lands between the linear anchors (measured 0.603 V). The hybrid
    // model (measured 0.476 V; 0.48–0.51 V over seeds 1, 2, 7) must remove at least 10 % of
    // the assumed model's error, beat the published linear state-space model, and stay
    // within 3× the best published result (it has no overflow physics).
    assert!(
        (0.5..0.75).contains(&rmse_linear),
        "assumed model alone: RMSE {rmse_linear} V"
    );
    assert!(
        rmse < 0.9 * rmse_linear,
        "MME/NN RMSE {rmse} V vs assumed model {rmse_linear} V"
    );
    assert!(
        rmse < 0.588,
        "MME/NN RMSE {rmse} V vs linear state-space 0.588 V"
    );
    assert!(rmse < 3.0 * 0.19, "MME/NN RMSE {rmse} V");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A fresh user's Cascaded Tanks model: Torricelli outflows `sqrt(h1)` with the upper
/// level unmeasured. The level's start comes out at ~1e-15, where `sqrt` has no slope and
/// the data determine fewer quantities than are estimated; the solve stops on its first
/// iteration with the cost unchanged. `greyest` must not call that converged (it did,
/// with exit status 0 and every coefficient "not identifiable").
#[test]
fn greyest_does_not_call_a_stuck_start_converged() {
    let Some(folder) = tanks_folder() else {
        return;
    };
    let model = r#"
states = ["h1", "h2"]
inputs = ["u"]
C = [[0.0, 1.0]]
outputs = ["y"]
corrected = ["h1", "h2"]
noise_variance = "auto"

[parameters]
k1 = { value = 0.05, bounds = [0.001, 1.0] }
k2 = { value = 0.05, bounds = [0.001, 1.0] }
k3 = { value = 0.05, bounds = [0.001, 1.0] }
k4 = { value = 0.03, bounds = [0.001, 1.0] }

[[terms]]
state = "h1"
effect = "orifice_outflow"
term = "-k1*sqrt(h1) + k4*u"

[[terms]]
state = "h2"
effect = "orifice_outflow"
term = "k2*sqrt(h1) - k3*sqrt(h2)"
"#;
    let dir = std::env::temp_dir().join(format!("mmenn-real-greyest-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("model.toml"), model).unwrap();
    let outcome = mmenn::greyest::run_greyest(
        &dir.join("model.toml"),
        &[folder.join("estimation.csv")],
        &mmenn::greyest::GreyestOptions::default(),
        &dir.join("out"),
        &mmenn::progress::NoProgress,
    )
    .unwrap();
    let s = &outcome.summary;
    let last = s.stages.last().unwrap();
    // The situation the check is for: rank-deficient, cost unchanged.
    assert!(s.rank.0 < s.rank.1, "rank {:?}", s.rank);
    assert!(
        (last.initial_cost - last.final_cost).abs() <= 1e-9 * last.initial_cost,
        "{last:?}"
    );
    assert!(!last.converged, "{last:?}");
    assert!(
        last.termination.contains("stopped where it started"),
        "{last:?}"
    );
    assert!(last.termination.contains("--x0"), "{last:?}");
    // Started where sqrt has a slope (`--x0 h1=5`), the same model calibrates: the cost
    // falls by more than an order of magnitude (8.0e3 -> 3.7e2 when this was written).
    #[allow(clippy::result_large_err)] // mmenn's errors carry paths and context
    let from = |state: &str, value: f64, out: &str| {
        mmenn::greyest::run_greyest(
            &dir.join("model.toml"),
            &[folder.join("estimation.csv")],
            &mmenn::greyest::GreyestOptions {
                x0_start: vec![(state.into(), value)],
                ..mmenn::greyest::GreyestOptions::default()
            },
            &dir.join(out),
            &mmenn::progress::NoProgress,
        )
    };
    let moved = from("h1", 5.0, "out-x0").unwrap();
    let last = moved.summary.stages.last().unwrap();
    assert!(last.converged, "{last:?}");
    assert!(last.final_cost < 0.1 * last.initial_cost, "{last:?}");
    assert!(
        (moved.summary.records[0].x0["h1"] - 5.0).abs() > 1e-6,
        "the start is calibrated"
    );
    // A state the model does not have is refused, naming the option and the states.
    let err = from("h9", 5.0, "out-bad").unwrap_err();
    assert!(
        matches!(&err, mmenn::MmennError::UnknownState { option: "--x0", name, states }
            if name == "h9" && states == "h1, h2"),
        "{err:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Janot et al.'s EMPS model as a user writes it (`[mechanics]`, the published IDIM-LS
/// values as starts, the mass held): `M q'' = gτ·u − Fv·q' − Fc·tanh(q'/ε) − off`.
const EMPS_MODEL: &str = r#"
inputs = ["u"]
measured = ["q"]
corrected = ["v"]
noise_variance = [1e-10]
units = { q = "m", v = "m/s", u = "V" }

[parameters]
M = { value = 95.1089, unit = "kg", fixed = true }
gtau = { value = 35.15, unit = "N/V", bounds = [0.0, 100.0] }
Fv = { value = 203.5, unit = "N*s/m", bounds = [0.0, 1000.0] }
Fc = { value = 20.39, unit = "N", bounds = [0.0, 100.0] }
off = { value = -3.16, unit = "N" }

[mechanics]
q = ["q"]
qdot = ["v"]
mass = [["M"]]
forces = ["gtau*u - Fv*v - Fc*tanh(v/0.0003) - off"]
"#;

/// On the EMPS estimation record greyest's calibrated start state carries the fit: the
/// position integrates a velocity set by the small difference of drive force and
/// friction, and the start velocity calibrated with the parameters absorbs a drift
/// (−26 mm/s where the record starts near +7 mm/s; the reproduce's grey box shows the
/// same, docs/decisions/emps-window-state-calibration.md). greyest must say so, with the
/// number `mmenn predict` will give (when written: RMSE 2.36 mm calibrated, 7.09 mm from
/// the first 200 samples, 3.0×).
#[test]
fn greyest_says_when_the_fit_leans_on_its_calibrated_start() {
    let Some(folder) = folder(Benchmark::Emps) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("mmenn-real-emps-start-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("model.toml"), EMPS_MODEL).unwrap();
    let text = std::fs::read_to_string(folder.join("estimation.csv")).unwrap();
    let (header, rows) = text.split_once('\n').unwrap();
    assert_eq!(header.trim(), "k,t,u,y,q_ref", "the shared file's header");
    std::fs::write(dir.join("est.csv"), format!("k,t,u,q,q_ref\n{rows}")).unwrap();
    let outcome = mmenn::greyest::run_greyest(
        &dir.join("model.toml"),
        &[dir.join("est.csv")],
        &mmenn::greyest::GreyestOptions::default(),
        &dir.join("out"),
        &mmenn::progress::NoProgress,
    )
    .unwrap();
    let s = &outcome.summary;
    assert!(s.stages.last().unwrap().converged, "{:?}", s.stages);
    let record = &s.records[0];
    let judged = record.as_predict.as_ref().unwrap();
    let leans = record.leans_on_start();
    assert_eq!(leans.len(), 1, "{record:?}");
    assert_eq!(leans[0].0, "q");
    assert!(
        judged.rmse["q"] > mmenn::greyest::START_RELIANCE * record.rmse["q"],
        "{record:?}"
    );
    let report = std::fs::read_to_string(dir.join("out/report.md")).unwrap();
    assert!(
        report.contains("leans on its calibrated start state"),
        "{report}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Force-space discovery on measured Silverbox data with the textbook Duffing model
/// (`m·y'' = g·(u − u0) − d·y' − k·y − k3·y³`, coefficients as `mmenn greyest` calibrated
/// them on these 8192 samples: free-run RMSE 13.2 mV, fit 76 %). What it misses is the
/// input path (the published grey boxes need an input stage), which no catalogue force of
/// the joint's own rate is. Rule fixed before the run: with the noise given at σ = 1 mV
/// (an upper bound: published models simulate these records to 0.26–0.30 mV), no force is
/// kept and the verdict is `unexplained`, not `none`, because the assumed model's free-run
/// cost is above the noise-level bound; before this rule it read `none`.
#[test]
fn silverbox_duffing_with_nothing_kept_is_unexplained_not_none() {
    let Some(folder) = folder(Benchmark::Silverbox) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("mmenn-real-sb-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    silverbox_halves(&folder, &dir);
    std::fs::write(
        dir.join("duffing.toml"),
        r#"
states = ["y", "v"]
inputs = ["u"]
measured = ["y"]
corrected = ["v"]
noise_variance = [1e-6]
units = { y = "V", v = "V/s", u = "V" }

[parameters]
m = { value = 1.0, fixed = true }
d = { value = 43.54454317156031 }
g = { value = 191479.2 }
k = { value = 190764.5 }
k3 = { value = 811854.2 }
u0 = { value = 5.341836e-3 }

[mechanics]
q = ["y"]
qdot = ["v"]
mass = [["m"]]
forces = ["g*(u - u0) - d*v - k*y - k3*y^3"]
"#,
    )
    .unwrap();
    let s = mmenn::discover::run_discover(
        &[dir.join("est.csv")],
        &dir.join("duffing.toml"),
        &[dir.join("val.csv")],
        &mmenn::discover::DiscoverOptions::default(),
        &dir.join("out"),
    )
    .unwrap();
    assert_eq!(s.verdict, mmenn::discovery::Verdict::Unexplained, "{s:#?}");
    assert!(s.effects.is_empty(), "{:?}", s.effects);
    assert!(
        s.warnings
            .iter()
            .any(|w| w.contains("above the noise-level bound")),
        "{:?}",
        s.warnings
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The first 8192 samples of Silverbox's official training record and the next 8192,
/// written into `dir` as `est.csv` and `val.csv`.
fn silverbox_halves(folder: &Path, dir: &Path) {
    let text = std::fs::read_to_string(folder.join("train_val_multisine.csv")).unwrap();
    let head: Vec<&str> = text.lines().take(8193).collect();
    std::fs::write(dir.join("est.csv"), head.join("\n") + "\n").unwrap();
    let val: Vec<&str> = text
        .lines()
        .take(1)
        .chain(text.lines().skip(8193).take(8192))
        .collect();
    std::fs::write(dir.join("val.csv"), val.join("\n") + "\n").unwrap();
}

/// The greyest-calibrated Duffing model of the Silverbox (linear part and cubic term as
/// `A`, `B` and `[[terms]]`), with the noise variance left to MME.
const SILVERBOX_DUFFING_AUTO: &str = r#"
states = ["y", "v"]
inputs = ["u"]
A = [[0.0, 1.0], [-190764.5, -43.54454]]
B = [[0.0], [191479.2]]
measured = ["y"]
corrected = ["v"]
noise_variance = "auto"
units = { y = "V", v = "V/s", u = "V" }

[[terms]]
state = "v"
effect = "cubic_stiffness"
term = "y^3"
coefficient = -811854.2

[[terms]]
state = "v"
effect = "offset"
term = "1"
coefficient = -1022.9
"#;

/// The noise variance MME estimates on a record oscillating near its Nyquist frequency
/// (Silverbox: 610 Hz, content to 200 Hz, resonance near 70 Hz). Independent bound: the
/// best published models simulate these records to 0.26–0.30 mV RMS, so the white
/// measurement noise is below (0.30 mV)² = 9e-8 V² (a model's free-run error includes the
/// noise). Rule fixed before the run: the estimate is positive and below that bound.
/// Before the degeneracy rule took the spectral floor into account, the likelihood's
/// estimate was rejected and the second differences, 1.28e-4 V² (11 mV RMS, the
/// signal's curvature), were reported; measured after: 3.63e-12 V² (1.9 µV).
#[test]
fn silverbox_noise_variance_is_below_the_published_simulation_floor() {
    let Some(folder) = folder(Benchmark::Silverbox) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("mmenn-real-sbn-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    silverbox_halves(&folder, &dir);
    std::fs::write(dir.join("duffing.toml"), SILVERBOX_DUFFING_AUTO).unwrap();
    let s = run_estimate(
        &[dir.join("est.csv")],
        &dir.join("duffing.toml"),
        &EstimateOptions::default(),
        &dir.join("est"),
    )
    .unwrap();
    let nv = s.noise_variance["y"];
    assert!(nv > 0.0 && nv < 9e-8, "noise variance {nv}");
    // The references it was judged against are in the summary and the report: second
    // differences far above it, a spectral floor (upper bound of white noise) above it.
    let (diff, floor) = s.noise_references["y"];
    assert!(
        diff > 1e-5 && floor.is_some_and(|f| f > nv && f < diff),
        "{diff} {floor:?}"
    );
    let report = std::fs::read_to_string(dir.join("est").join("report.md")).unwrap();
    assert!(report.contains("spectral floor"), "{report}");
    // With σ at the µV level the neighbour screen, in units of σ alone, flagged 1 453 of
    // the 8 192 samples (the oscillation's own curvature); measured against the record's
    // robust spread it must flag under 1 % of them.
    assert!(s.outliers.len() < 82, "{} outliers", s.outliers.len());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `compare --poly-monomials frols-kfold` on Silverbox: the sparse polynomial NARX (FROLS
/// ranking, count by 5-fold free run on the estimation record) runs free over both
/// records, where the model with every monomial of the same dictionary diverges within
/// the first 130 samples (measured on this record: estimation sample 124, validation
/// 127). Rule (set after one CLI run gave 98.9 % on both records, linear SS 85.8 %): the
/// row has numbers in both tables, and its validation fit is at least 95 % and above the
/// linear state-space row's.
#[test]
fn silverbox_sparse_polynomial_narx_runs_free() {
    use mmenn::compare::{CompareOptions, PolyNarxChoice, PolyNarxMonomials, run_compare};
    let Some(folder) = folder(Benchmark::Silverbox) else {
        return;
    };
    let dir = std::env::temp_dir().join(format!("mmenn-real-sbp-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    silverbox_halves(&folder, &dir);
    std::fs::write(
        dir.join("duffing.toml"),
        SILVERBOX_DUFFING_AUTO.replace("\"auto\"", "[1e-8]"),
    )
    .unwrap();
    let opts = CompareOptions {
        poly_narx: Some(PolyNarxChoice {
            monomials: PolyNarxMonomials::FrolsKfold,
            ..PolyNarxChoice::default()
        }),
        fit: FitOptions {
            max_hidden: 2,
            inits: 1,
            ..FitOptions::default()
        },
        ..CompareOptions::default()
    };
    let s = run_compare(
        &[dir.join("est.csv")],
        &dir.join("duffing.toml"),
        &[dir.join("val.csv")],
        &opts,
        &dir.join("cmp"),
    )
    .unwrap();
    let fit = |t: &mmenn::sysid_baselines::EvaluationTable, label: &str| -> Option<f64> {
        t.rows()
            .iter()
            .find(|r| r.label.starts_with(label))
            .map(|r| r.evaluation.channel("y").unwrap().fit_percent)
    };
    let val = s.validation.as_ref().unwrap();
    assert!(
        fit(&s.estimation, "polynomial NARX").is_some(),
        "{:?}",
        s.failures
    );
    let poly = fit(val, "polynomial NARX").unwrap_or_else(|| panic!("{:?}", s.failures));
    let ss = fit(val, "linear SS").unwrap();
    assert!(
        poly >= 95.0 && poly > ss,
        "polynomial NARX {poly} %, linear SS {ss} %"
    );
    let p = s.poly_narx.as_ref().unwrap();
    assert!(
        p.selection.as_deref().unwrap_or("").contains("5-fold"),
        "{p:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
