//! Exploration harness (ignored; reads /work/shared/data; prints training and test
//! RMSE — choose by the training numbers). Semicolon-separated variants of `key=value`:
//! `GREY_TANKS` keys rate k2 smooth sensor lin lin1 pump0 bias c h1 h2 area1 area2 trainx0
//! pumpq lag res ontest (calibrate on the test record: a diagnosis, never a choice) win
//! (calibrate with the training state fitted to the window, `TrainState::Window`) selfwin
//! (print only the training record's free run from the window-fitted state)
//! holdout (calibrate on the first 80 %, score the last 20 %) halves (calibrate on each half,
//! score the other; no test record) one (`TanksOptions::one_flow`) starts (seeded multi-start,
//! training only) seed (one seeded start) sub hz;
//! `explore_emps_window_rule` applies docs/decisions/emps-window-state-calibration.md
//! (bare options unless given: no pump offset, no linear outflow, calibrated overflow
//! rates); `GREY_EMPS` keys eps asym g fv fc off sub full pos load lim (drive clamped at
//! ±lim V) holdout halves ontest ref (the reference IDIM-LS coefficients uncalibrated)
//! starts (seeded multi-start, training only; docs/decisions/tanks-multistart-rule.md);
//! `GREY_SB` keys q dd vv
//! (quadratic drag) q5 ft sub and the monomials v3 yv v2 yv2 ya yav vay.
//! `explore_silverbox_bandlimited` takes `GREY_SB` with `up=L` (records resampled `L`× by
//! windowed sinc, scored at the recorded samples) and the input monomials u2 u3 u2y uv uyv
//! u2v uv2. `GREY_DUMP=/tmp/prefix` writes the training and first test run as CSV. E.g.
//! `GREY_TANKS="pump0=1 lin=1 c=1" cargo test --release -p xtask explore_tanks --
//! --ignored --nocapture`.
use super::*;
use mmenn::benchmarks::{Benchmark, load};

fn data(b: Benchmark) -> mmenn::benchmarks::BenchmarkData {
    // `GREY_DATA_DIR` points at a copy with transformed inputs (diagnoses only).
    let root = std::env::var("GREY_DATA_DIR").unwrap_or_else(|_| "/work/shared/data".into());
    load(b, &std::path::Path::new(&root).join(b.folder())).unwrap()
}

fn report(b: Benchmark, label: &str, spec: &GreySpec) {
    let d = data(b);
    let (scale, unit) = b.reporting_unit();
    let w = b.init_window();
    let tests: Vec<(String, Experiment)> = d
        .tests
        .iter()
        .map(|t| (t.name.clone(), t.data.experiments()[0].clone()))
        .collect();
    let clock = std::time::Instant::now();
    let fit = match fit_grey(spec, &d.estimation.experiments()[0], &tests, w) {
        Ok(f) => f,
        Err(e) => {
            println!("{label}: failed {e:#}");
            return;
        }
    };
    let secs = clock.elapsed().as_secs_f64();
    let est = &d.estimation.experiments()[0];
    let yest: Vec<f64> = est.outputs().row(0).iter().copied().collect();
    let proto = window_state(spec, &fit.model, est, w)
        .ok()
        .and_then(|x| free_run(spec, &fit.model, est, &x).ok())
        .map(|s| scale * rmse_after(&yest, &s, w))
        .unwrap_or(f64::NAN);
    let mut line = format!(
        "{label}: train {:.4} {unit} (train window-x0 {proto:.4}) ({secs:.1} s)",
        scale * fit.train_rmse
    );
    for (t, (_, e)) in fit.tests.iter().zip(&tests) {
        let y: Vec<f64> = e.outputs().row(0).iter().copied().collect();
        match &t.sim {
            Ok(s) => line += &format!(" | {} {:.4}", t.name, scale * rmse_after(&y, s, w)),
            Err(m) => line += &format!(" | {} diverged {m}", t.name),
        }
    }
    println!("{line}");
    if let Ok(path) = std::env::var("GREY_DUMP") {
        let est = &d.estimation.experiments()[0];
        let tr = free_run(spec, &fit.model, est, &fit.x0).unwrap_or_default();
        let mut text = String::from("u,y,sim,tu,ty,tsim\n");
        let te = &tests[0].1;
        let ts = fit.tests[0].sim.clone().unwrap_or_default();
        for k in 0..est.len().max(te.len()) {
            let g = |m: &nalgebra::DMatrix<f64>, k: usize| {
                if k < m.ncols() { m[(0, k)] } else { f64::NAN }
            };
            text += &format!(
                "{},{},{},{},{},{}\n",
                g(est.inputs(), k),
                g(est.outputs(), k),
                tr.get(k).copied().unwrap_or(f64::NAN),
                g(te.inputs(), k),
                g(te.outputs(), k),
                ts.get(k).copied().unwrap_or(f64::NAN)
            );
        }
        std::fs::write(format!("{path}-{}.csv", label.replace(' ', "_")), text).unwrap();
        // Every test record (input, measured, simulated), one file each.
        for (t, (name, e)) in fit.tests.iter().zip(&tests) {
            let sim = t.sim.clone().unwrap_or_default();
            let file = format!("{path}-{}-{name}.csv", label.replace(' ', "_"));
            dump(&file, e, &sim);
        }
    }
    println!("    {} x0 {:?}", terms(&fit), fit.x0);
}

/// A record's input, measured output and simulated output as CSV (NaN past the run's end).
fn dump(file: &str, e: &Experiment, sim: &[f64]) {
    let mut text = String::from("u,y,sim\n");
    for k in 0..e.len() {
        text += &format!(
            "{},{},{}\n",
            e.inputs()[(0, k)],
            e.outputs()[(0, k)],
            sim.get(k).copied().unwrap_or(f64::NAN)
        );
    }
    std::fs::write(file, text).unwrap();
}

/// The calibrated coefficients, one `effect ±c` per term.
fn terms(fit: &GreyFit) -> String {
    let terms: Vec<String> = fit
        .model
        .terms()
        .iter()
        .map(|t| format!("{} {:+.4e}", t.effect, t.coefficient))
        .collect();
    terms.join(", ")
}

fn kv(item: &str) -> Vec<(String, f64)> {
    item.split_whitespace()
        .filter_map(|p| p.split_once('='))
        .map(|(k, v)| (k.to_string(), v.parse().unwrap()))
        .collect()
}

#[test]
#[ignore]
fn explore_emps() {
    let all = std::env::var("GREY_EMPS").unwrap_or_default();
    for item in all.split(';').filter(|s| !s.trim().is_empty()) {
        let mut o = EmpsOptions {
            eps: 3e-4,
            asymmetric: false,
            start: None,
            position_force: false,
            load_friction: false,
            drive_limit: None,
        };
        let mut substeps = 1;
        let mut full = false;
        let mut holdout = false;
        let mut ontest = false;
        let mut halves_only = false;
        let mut reference = false;
        let mut starts = 0;
        for (k, v) in kv(item) {
            match k.as_str() {
                "ref" => reference = v != 0.0,
                "eps" => o.eps = v,
                "asym" => o.asymmetric = v != 0.0,
                "g" => o.start.get_or_insert([0.0; 4])[0] = v,
                "fv" => o.start.get_or_insert([0.0; 4])[1] = v,
                "fc" => o.start.get_or_insert([0.0; 4])[2] = v,
                "off" => o.start.get_or_insert([0.0; 4])[3] = v,
                "sub" => substeps = v as usize,
                "full" => full = v != 0.0,
                "pos" => o.position_force = v != 0.0,
                "load" => o.load_friction = v != 0.0,
                "lim" => o.drive_limit = Some(v),
                "holdout" => holdout = v != 0.0,
                "ontest" => ontest = v != 0.0,
                "halves" => halves_only = v != 0.0,
                "starts" => starts = v as usize,
                _ => panic!("unknown key {k}"),
            }
        }
        let mut spec = emps_model(&o).unwrap();
        spec.integrator = Integrator::Rk4 { substeps };
        if full {
            spec.horizons = vec![1.0];
        }
        if reference {
            // The published IDIM-LS coefficients as they are: only the state is fitted.
            spec.free.clear();
        }
        if ontest {
            on_test(Benchmark::Emps, item.trim(), &spec);
        } else if starts > 0 {
            multistart(Benchmark::Emps, item.trim(), &spec, starts);
        } else if halves_only {
            halves(Benchmark::Emps, item.trim(), &spec);
        } else if holdout {
            held_out(Benchmark::Emps, item.trim(), &spec);
        } else {
            report(Benchmark::Emps, item.trim(), &spec);
        }
    }
}

/// One `GREY_SB` item: the extra terms, the RK4 sub-steps if given (`sub`), the
/// resampling factor (`up`, 1 unless given; [`explore_silverbox_bandlimited`] only).
/// The reproduce run's start for Silverbox: the ARX(2, 2) oscillator of the training record.
fn silverbox_guess() -> (f64, f64, f64) {
    crate::experiments::real::setups::oscillator_guess(
        &data(Benchmark::Silverbox).estimation.experiments()[0],
    )
    .unwrap()
}

fn silverbox_item(item: &str) -> (Vec<SilverboxExtra>, Option<usize>, usize) {
    use SilverboxExtra::*;
    let mut extra = Vec::new();
    let mut substeps = None;
    let mut l = 1usize;
    for (key, v) in kv(item) {
        extra.push(match key.as_str() {
            "sub" => {
                substeps = Some(v as usize);
                continue;
            }
            "up" => {
                l = v as usize;
                continue;
            }
            "q" => QuadraticSpring,
            "ig" => InputGainVariation,
            "dd" => DisplacementDamping,
            "q5" => QuinticSpring,
            "ft" => Feedthrough(v),
            "vv" => QuadraticDrag,
            "v3" => Monomial("v^3"),
            "yv" => Monomial("y*v"),
            "v2" => Monomial("v^2"),
            "yv2" => Monomial("y*v^2"),
            "ya" => Monomial("y*abs(y)"),
            "yav" => Monomial("abs(y)*v"),
            "vay" => Monomial("abs(v)*y"),
            "u2" => Monomial("u^2"),
            "u3" => Monomial("u^3"),
            "u2y" => Monomial("u^2*y"),
            "uv" => Monomial("u*v"),
            "uyv" => Monomial("u*y*v"),
            "u2v" => Monomial("u^2*v"),
            "uv2" => Monomial("u*v^2"),
            _ => panic!("unknown key {key}"),
        });
    }
    (extra, substeps, l)
}

#[test]
#[ignore]
fn explore_silverbox() {
    let all = std::env::var("GREY_SB").unwrap_or_default();
    let (k, c, b) = silverbox_guess();
    for item in all.split(';').filter(|s| !s.trim().is_empty()) {
        let (extra, substeps, _) = silverbox_item(item);
        let mut spec = silverbox_model(k, c, b, &extra).unwrap();
        if let Some(substeps) = substeps {
            spec.integrator = Integrator::Rk4 { substeps };
        }
        report(Benchmark::Silverbox, item.trim(), &spec);
    }
}

#[test]
#[ignore]
fn explore_tanks() {
    let all = std::env::var("GREY_TANKS").unwrap_or_default();
    for item in all.split(';').filter(|s| !s.trim().is_empty()) {
        let mut o = TanksOptions {
            linear_outflow: false,
            pump_offset: false,
            overflow_rate: None,
            ..TanksOptions::default()
        };
        let mut trainx0 = false;
        let mut holdout = false;
        let mut ontest = false;
        let mut selfwin = false;
        let mut win = false;
        let mut halves_only = false;
        let mut starts = 0;
        let mut seed = 0;
        let mut substeps = 8;
        let mut hz = 2;
        for (k, v) in kv(item) {
            match k.as_str() {
                "rate" => o.rate = v,
                "k2" => o.free_k2 = v != 0.0,
                "smooth" => o.smooth = Some(v),
                "sensor" => o.sensor = Some(v),
                "lin" => o.linear_outflow = v != 0.0,
                "h1" => o.h1_top = v,
                "h2" => o.h2_top = v,
                "pump0" => o.pump_offset = v != 0.0,
                "bias" => o.sensor_offset = v,
                "c" => o.overflow_rate = Some(v),
                "lin1" => o.linear_outflow1 = v != 0.0,
                "area2" => o.area2 = v != 0.0,
                "area1" => o.area1 = v != 0.0,
                "holdout" => holdout = v != 0.0,
                "sub" => substeps = v as usize,
                "hz" => hz = v as usize,
                "trainx0" => trainx0 = v != 0.0,
                "pumpq" => o.pump_quadratic = v != 0.0,
                "lag" => o.pump_lag = Some(v),
                "res" => o.reservoir_head = v != 0.0,
                "ontest" => ontest = v != 0.0,
                "win" => win = v != 0.0,
                "selfwin" => selfwin = v != 0.0,
                "halves" => halves_only = v != 0.0,
                "one" => o.one_flow = v != 0.0,
                "starts" => starts = v as usize,
                "seed" => seed = v as u64,
                _ => panic!("unknown key {k}"),
            }
        }
        let mut spec = tanks_model(&o).unwrap();
        if win {
            spec.train_state = TrainState::Window;
        }
        spec.test_from_training_x0 = trainx0;
        spec.integrator = Integrator::Rk4 { substeps };
        if hz == 4 {
            spec.horizons = vec![0.1, 0.25, 0.5, 1.0];
        } else if hz == 1 {
            spec.horizons = vec![1.0];
        }
        if seed > 0 {
            spec = perturbed(&spec, seed).unwrap();
        }
        if ontest {
            on_test(Benchmark::CascadedTanks, item.trim(), &spec);
        } else if starts > 0 {
            multistart(Benchmark::CascadedTanks, item.trim(), &spec, starts);
        } else if halves_only {
            halves(Benchmark::CascadedTanks, item.trim(), &spec);
        } else if selfwin {
            training_from_window(Benchmark::CascadedTanks, item.trim(), &spec);
        } else if holdout {
            held_out(Benchmark::CascadedTanks, item.trim(), &spec);
        } else {
            report(Benchmark::CascadedTanks, item.trim(), &spec);
        }
    }
}

/// Diagnosis only, never a model choice: the structure calibrated on the official *test*
/// record itself and scored there (state fitted to its first window samples, RMSE after
/// them) — how far the structure can follow that record with coefficients of its own,
/// against what the training record's coefficients give.
fn on_test(bench: Benchmark, label: &str, spec: &GreySpec) {
    let d = data(bench);
    let w = bench.init_window();
    let (scale, unit) = bench.reporting_unit();
    let test = d.tests[0].data.experiments()[0].clone();
    // Started from the coefficients the training record calibrates (its basin), not from
    // the structure's generic start.
    let mut spec = spec.clone();
    if let Ok(t) = fit_grey(&spec, &d.estimation.experiments()[0], &[], w) {
        spec.model = t.model;
    }
    match fit_and_score(&spec, &test, &test, w) {
        Ok((f, r)) => println!(
            "{label}: calibrated on the test record: {:.4} {unit} from its calibrated state, {:.4} {unit} from the state fitted to its first {w} samples; {}",
            scale * f.train_rmse,
            scale * r,
            terms(&f)
        ),
        Err(e) => println!("{label}: failed {e:#}"),
    }
}

/// `spec` calibrated on `fit_on` and run free over `score_on` from the state fitted to its
/// first `w` samples: the fit and that run's RMSE after the window (recorded units; NaN
/// when the run failed).
fn fit_and_score(
    spec: &GreySpec,
    fit_on: &Experiment,
    score_on: &Experiment,
    w: usize,
) -> Result<(GreyFit, f64)> {
    let f = fit_grey(spec, fit_on, &[("scored".into(), score_on.clone())], w)?;
    let y: Vec<f64> = score_on.outputs().row(0).iter().copied().collect();
    let r = f.tests[0]
        .sim
        .as_ref()
        .map_or(f64::NAN, |s| rmse_after(&y, s, w));
    Ok((f, r))
}

/// The training record's free run from the state fitted to its first window samples (the
/// test protocol's start), the coefficients calibrated on the whole record; no test record
/// is run.
fn training_from_window(bench: Benchmark, label: &str, spec: &GreySpec) {
    let d = data(bench);
    let w = bench.init_window();
    let (scale, unit) = bench.reporting_unit();
    let est = &d.estimation.experiments()[0];
    match fit_and_score(spec, est, est, w) {
        Ok((f, r)) => println!(
            "{label}: training {:.6} {unit} from the calibration's own state, {:.6} {unit} from the state fitted to the first {w} samples; {}",
            scale * f.train_rmse,
            scale * r,
            terms(&f)
        ),
        Err(e) => println!("{label}: failed {e:#}"),
    }
}

/// Calibrate on the first 80 % of a benchmark's training record and score the free run on
/// the last 20 % (state fitted to its first window samples, as the test protocol does).
fn held_out(bench: Benchmark, label: &str, spec: &GreySpec) {
    let d = data(bench);
    let w = bench.init_window();
    let (scale, unit) = bench.reporting_unit();
    let est = &d.estimation.experiments()[0];
    let n = est.len();
    let cut = n * 4 / 5;
    let part = |a: usize, b: usize| est.window(a, b).unwrap();
    let (fit_part, held) = (part(0, cut), part(cut, n));
    match fit_and_score(spec, &fit_part, &held, w) {
        Ok((f, r)) => println!(
            "{label}: first 80 % {:.6} {unit} | held-out last 20 % {:.6} {unit}",
            scale * f.train_rmse,
            scale * r
        ),
        Err(e) => println!("{label}: failed {e:#}"),
    }
}

/// Diagnosis: the structure calibrated on each half of the training record alone, each half's
/// coefficients printed and run free over the other half (state fitted to its first window
/// samples). How far the coefficients move between two disjoint stretches of one record, to
/// set against how far the test record moves them (test-record-floors.md). No test record.
fn halves(bench: Benchmark, label: &str, spec: &GreySpec) {
    let d = data(bench);
    let w = bench.init_window();
    let (scale, unit) = bench.reporting_unit();
    let est = &d.estimation.experiments()[0];
    let n = est.len();
    let part = |a: usize, b: usize| est.window(a, b).unwrap();
    let (first, second) = (part(0, n / 2), part(n / 2, n));
    for (name, fit_on, other) in [
        ("first half", &first, &second),
        ("second half", &second, &first),
    ] {
        match fit_and_score(spec, fit_on, other, w) {
            Ok((f, r)) => println!(
                "{label}: {name}: own {:.4} {unit}, other half {:.4} {unit}; {}",
                scale * f.train_rmse,
                scale * r,
                terms(&f)
            ),
            Err(e) => println!("{label}: {name}: failed {e:#}"),
        }
    }
}

/// Training record only: the generic start and `n` seeded starts ([`super::multistart`]),
/// each calibrated as the table calibrates; prints each one's training free-run RMSE (from its
/// calibrated state) and coefficients, sorted by that RMSE. No test record is run.
fn multistart(bench: Benchmark, label: &str, spec: &GreySpec, n: usize) {
    let d = data(bench);
    let w = bench.init_window();
    let (scale, unit) = bench.reporting_unit();
    let est = &d.estimation.experiments()[0];
    // The generic start, then the seeded ones as the full run draws them.
    let generic = fit_grey(spec, est, &[], w).map_err(|e| format!("{e:#}"));
    let runs: Vec<(String, std::result::Result<GreyFit, String>)> =
        std::iter::once(("generic".to_string(), generic))
            .chain(
                super::multistart(spec, est, w, n as u64)
                    .into_iter()
                    .map(|(seed, fit)| (format!("seed {seed}"), fit)),
            )
            .collect();
    let mut rows: Vec<(f64, String)> = runs
        .iter()
        .map(|(name, r)| match r {
            Ok(f) => (
                f.train_rmse,
                format!(
                    "{name}: train {:.6} {unit}; {} x0 {:?}",
                    scale * f.train_rmse,
                    terms(f),
                    f.x0
                ),
            ),
            Err(e) => (f64::INFINITY, format!("{name}: failed {e}")),
        })
        .collect();
    rows.sort_by(|a, b| a.0.total_cmp(&b.0));
    println!("{label}: {} starts, training only", n + 1);
    for (_, line) in rows {
        println!("    {line}");
    }
}

/// The Schroeder multisine record of the Silverbox distribution (outside the loader's
/// split; docs/decisions/silverbox-schroeder-rule.md).
fn schroeder() -> Experiment {
    let dir = std::path::Path::new("/work/shared/data/silverbox");
    let extra = mmenn::benchmarks::load_extra(Benchmark::Silverbox, dir).unwrap();
    extra[0].data.experiments()[0].clone()
}

/// The candidates of docs/decisions/silverbox-schroeder-rule.md, calibrated on the
/// training record and scored on the Schroeder record only (no test record is run).
#[test]
#[ignore]
fn explore_silverbox_schroeder() {
    use SilverboxExtra::*;
    let d = data(Benchmark::Silverbox);
    let est = &d.estimation.experiments()[0];
    let sch = schroeder();
    let (k, c, b) = silverbox_guess();
    let stage = Feedthrough(SILVERBOX_STAGE_TAU);
    let all: Vec<(&str, Vec<SilverboxExtra>)> = vec![
        (
            "C0",
            vec![QuadraticSpring, DisplacementDamping, QuadraticDrag, stage],
        ),
        ("C1", vec![QuadraticSpring, DisplacementDamping, stage]),
        ("C2", vec![QuadraticSpring, QuadraticDrag, stage]),
        ("C3", vec![DisplacementDamping, QuadraticDrag, stage]),
        (
            "C4",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                QuinticSpring,
                stage,
            ],
        ),
        // Rule 2's proposals (from the first half's residuals: at |y| > 0.15 V the error is
        // mostly along the simulated velocity, a phase error growing with the amplitude).
        (
            "P1",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                Monomial("v^3"),
                stage,
            ],
        ),
        (
            "P2",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                Monomial("abs(y)*v"),
                stage,
            ],
        ),
        (
            "P3",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                Monomial("u^3"),
                stage,
            ],
        ),
        // Rule 3 (docs/decisions/silverbox-schroeder-rule.md): a measurement filter on the
        // output at three held time constants, PNLSS's state polynomial, input coupling.
        (
            "O0.1",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                stage,
                OutputFilter(1e-4),
            ],
        ),
        (
            "O0.2",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                stage,
                OutputFilter(2e-4),
            ],
        ),
        (
            "O0.4",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                stage,
                OutputFilter(4e-4),
            ],
        ),
        (
            "R1",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                Monomial("y*v"),
                Monomial("v^2"),
                Monomial("y*v^2"),
                Monomial("v^3"),
                stage,
            ],
        ),
        (
            "R2",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                InputGainVariation,
                stage,
            ],
        ),
        // Rule 4: amplitude-dependent damping beyond y²·y' (inverse dynamics of the first
        // half), on R2.
        (
            "P4",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                InputGainVariation,
                Monomial("y^4*v"),
                stage,
            ],
        ),
        (
            "P5",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                InputGainVariation,
                Monomial("y^4*v"),
                QuinticSpring,
                stage,
            ],
        ),
        // Rule 5: the measurement chain's polynomial (O2) on R2; R2 itself again for the
        // band-limited reading (B: run with SB_UP=8).
        (
            "O2",
            vec![
                QuadraticSpring,
                DisplacementDamping,
                QuadraticDrag,
                InputGainVariation,
                OutputPolynomial,
                stage,
            ],
        ),
    ];
    // Rule 2 judges on the second half: samples 65 486.. (the first 50 fit the state).
    let sch = if std::env::var("SB_HALF").is_ok() {
        let a = 65_536 - 50;
        Experiment::new(
            0.0,
            SILVERBOX_DT,
            sch.inputs().columns(a, sch.len() - a).into_owned(),
            sch.outputs().columns(a, sch.len() - a).into_owned(),
        )
        .unwrap()
    } else {
        sch
    };
    let ysch: Vec<f64> = sch.outputs().row(0).iter().copied().collect();
    // `SB_UP=L`: both records read band-limited (resampled `L`×), scored at the recorded
    // samples (Rule 5's B).
    let up: usize = std::env::var("SB_UP").map_or(1, |v| v.parse().unwrap());
    let (est_up, sch_up) = if up > 1 {
        (upsample(est, up), upsample(&sch, up))
    } else {
        (est.clone(), sch.clone())
    };
    let y_est: Vec<f64> = est.outputs().row(0).iter().copied().collect();
    let at = |s: &[f64]| s.iter().step_by(up).copied().collect::<Vec<f64>>();
    let only = std::env::var("SB_ONLY").unwrap_or_default();
    for (label, extra) in all {
        if !only.is_empty() && !only.split(',').any(|o| o == label) {
            continue;
        }
        let mut spec = silverbox_model(k, c, b, &extra).unwrap();
        if up > 1 {
            // The input stage's sub-step bound (2.1 τ) at the finer step.
            if let Integrator::Rk4 { substeps } = spec.integrator {
                spec.integrator = Integrator::Rk4 {
                    substeps: substeps.div_ceil(up),
                };
            }
        }
        let clock = std::time::Instant::now();
        let fit = fit_grey(
            &spec,
            &est_up,
            &[("schroeder".into(), sch_up.clone())],
            50 * up,
        )
        .unwrap();
        let s = match &fit.tests[0].sim {
            Ok(sim) => format!("{:.4} mV", 1e3 * rmse_after(&ysch, &at(sim), 50)),
            Err(m) => format!("diverged {m}"),
        };
        let train = free_run(&spec, &fit.model, &est_up, &fit.x0)
            .map(|s| 1e3 * rmse_after(&y_est, &at(&s), 50))
            .unwrap_or(f64::NAN);
        println!(
            "{label}: train {train:.4} mV | schroeder {s} ({:.0} s)",
            clock.elapsed().as_secs_f64()
        );
        println!("    {}", terms(&fit));
        if let (Ok(path), Ok(sim)) = (std::env::var("SB_DUMP"), &fit.tests[0].sim) {
            dump(&format!("{path}-{label}.csv"), &sch, &at(sim));
        }
    }
}

/// Diagnosis of the arrow's gap (not a model choice; the reported rows never see the
/// Schroeder record's samples): the reported structure calibrated on the training record
/// alone and on the training record plus `schroeder80mV.csv` (outputs to 0.265 V, against
/// 0.216 V), both scored on test_arrow_full before and after sample 29 049 (where the
/// arrow first leaves the training amplitude). If the second extrapolates much better,
/// the gap is the training record's amplitude range, not the structure.
#[test]
#[ignore]
fn explore_silverbox_amplitude_coverage() {
    let d = data(Benchmark::Silverbox);
    let est = d.estimation.experiments()[0].clone();
    let sch = schroeder();
    let arrow = d
        .tests
        .iter()
        .find(|t| t.name == "test_arrow_full")
        .unwrap()
        .data
        .experiments()[0]
        .clone();
    let y: Vec<f64> = arrow.outputs().row(0).iter().copied().collect();
    let (k, c, b) = silverbox_guess();
    let spec = silverbox_model(k, c, b, &SILVERBOX_REPORTED).unwrap();
    let with_sch = std::env::var("SB_COVER").is_ok_and(|v| v == "1");
    let exps = if with_sch {
        vec![est.clone(), sch.clone()]
    } else {
        vec![est.clone()]
    };
    let x0: Vec<Vec<f64>> = exps.iter().map(|e| spec.x0_guess(e)).collect();
    let data = Dataset::new(vec![Channel::new("u")], vec![Channel::new("y")], exps)
        .unwrap()
        .with_intersample(spec.intersample);
    // Exactly the reported grey box's calibration, on one or two records.
    let cfg = calibration(&spec);
    let clock = std::time::Instant::now();
    let cal = calibrate(&spec.model, &data, &x0, &cfg).unwrap();
    let xs = window_state(&spec, &cal.model, &arrow, 50).unwrap();
    let sim = free_run(&spec, &cal.model, &arrow, &xs).unwrap();
    let cut = 29_049;
    let part = |a: usize, b: usize| {
        ((a..b).map(|i| (y[i] - sim[i]).powi(2)).sum::<f64>() / (b - a) as f64).sqrt()
    };
    println!(
        "calibrated on {}: arrow full {:.4} mV | samples 50..{cut} {:.4} mV | {cut}.. {:.4} mV ({:.0} s)",
        if with_sch {
            "training + Schroeder"
        } else {
            "training"
        },
        1e3 * rmse_after(&y, &sim, 50),
        1e3 * part(50, cut),
        1e3 * part(cut, y.len()),
        clock.elapsed().as_secs_f64()
    );
    println!(
        "    {}",
        terms(&GreyFit {
            model: cal.model.clone(),
            x0: xs,
            train_rmse: f64::NAN,
            train_rmse_all: f64::NAN,
            tests: Vec::new(),
        })
    );
}

/// The rule of docs/decisions/emps-window-state-calibration.md on the training record only
/// (no test record is run): (a) each procedure's training free run from the state fitted to
/// the first 20 samples, (b) calibrated on the first 80 %, the last 20 % from its own
/// 20-sample state.
#[test]
#[ignore]
fn explore_emps_window_rule() {
    let d = data(Benchmark::Emps);
    let est = &d.estimation.experiments()[0];
    let w = Benchmark::Emps.init_window();
    let (scale, unit) = Benchmark::Emps.reporting_unit();
    let y: Vec<f64> = est.outputs().row(0).iter().copied().collect();
    for (label, state) in [
        ("current (state calibrated)", TrainState::Calibrated),
        ("W (state fitted to the window)", TrainState::Window),
    ] {
        let mut spec = emps_spec(3e-4).unwrap();
        spec.train_state = state;
        let clock = std::time::Instant::now();
        let fit = fit_grey(&spec, est, &[], w).unwrap();
        let secs = clock.elapsed().as_secs_f64();
        let proto = window_state(&spec, &fit.model, est, w)
            .ok()
            .and_then(|x| free_run(&spec, &fit.model, est, &x).ok())
            .map(|s| scale * rmse_after(&y, &s, w))
            .unwrap_or(f64::NAN);
        println!(
            "{label}: (a) train from the 20-sample state {proto:.4} {unit} (from its own \
             state {:.4}; {secs:.1} s)\n    {} x0 {:?}",
            scale * fit.train_rmse,
            terms(&fit),
            fit.x0
        );
        held_out(Benchmark::Emps, &format!("{label} (b)"), &spec);
    }
}

/// `e` resampled `l`× (`l` divides `BL_FACTOR`) by the library's band-limited reading
/// (`sysid_core::bandlimited`: windowed sinc, ends held). Every `l`-th sample is the
/// original one.
fn upsample(e: &Experiment, l: usize) -> Experiment {
    use mmenn::sysid_core::bandlimited::{BL_FACTOR, band_limited_grid};
    assert!(
        BL_FACTOR.is_multiple_of(l),
        "up={l} must divide {BL_FACTOR}"
    );
    let pick = |m: &nalgebra::DMatrix<f64>| -> Vec<f64> {
        let grid = band_limited_grid(m);
        let step = BL_FACTOR / l;
        let mut v: Vec<f64> = grid.iter().step_by(step).copied().collect();
        // The grid ends at the last sample; the fine record holds it over its last interval.
        let last = *v.last().unwrap_or(&0.0);
        v.resize(e.len() * l, last);
        v
    };
    let (u, y) = (pick(e.inputs()), pick(e.outputs()));
    Experiment::new(
        e.t0(),
        e.dt() / l as f64,
        nalgebra::DMatrix::from_row_slice(1, e.len() * l, &u),
        nalgebra::DMatrix::from_row_slice(1, e.len() * l, &y),
    )
    .unwrap()
}

/// `GREY_SB` as in [`explore_silverbox`] plus `up=L`: every record resampled `L`× by
/// band-limited interpolation, the model calibrated and run at the fine rate, scored at
/// the original samples (state from the first 50 original samples' span).
#[test]
#[ignore]
fn explore_silverbox_bandlimited() {
    let all = std::env::var("GREY_SB").unwrap_or_default();
    let (k, c, b) = silverbox_guess();
    for item in all.split(';').filter(|s| !s.trim().is_empty()) {
        let (extra, substeps, l) = silverbox_item(item);
        let mut spec = silverbox_model(k, c, b, &extra).unwrap();
        if let Some(substeps) = substeps {
            spec.integrator = Integrator::Rk4 { substeps };
        }
        let d = data(Benchmark::Silverbox);
        let w = Benchmark::Silverbox.init_window();
        let est0 = d.estimation.experiments()[0].clone();
        let est = upsample(&est0, l);
        let mut records = d.tests.clone();
        records.extend(mmenn::benchmarks::load_extra(Benchmark::Silverbox, &d.dir).unwrap());
        let tests: Vec<(String, Experiment)> = records
            .iter()
            .map(|t| (t.name.clone(), upsample(&t.data.experiments()[0], l)))
            .collect();
        let clock = std::time::Instant::now();
        let fit = match fit_grey(&spec, &est, &tests, w * l) {
            Ok(f) => f,
            Err(e) => {
                println!("{item}: failed {e:#}");
                continue;
            }
        };
        let secs = clock.elapsed().as_secs_f64();
        let at = |s: &[f64]| s.iter().step_by(l).copied().collect::<Vec<f64>>();
        let y0: Vec<f64> = est0.outputs().row(0).iter().copied().collect();
        let train = free_run(&spec, &fit.model, &est, &fit.x0)
            .map(|s| 1e3 * rmse_after(&y0, &at(&s), w))
            .unwrap_or(f64::NAN);
        let mut line = format!("{item}: train {train:.4} mV ({secs:.1} s)");
        for (t, rec) in fit.tests.iter().zip(&records) {
            let y: Vec<f64> = rec.data.experiments()[0]
                .outputs()
                .row(0)
                .iter()
                .copied()
                .collect();
            match &t.sim {
                Ok(s) => line += &format!(" | {} {:.4}", t.name, 1e3 * rmse_after(&y, &at(s), w)),
                Err(m) => line += &format!(" | {} diverged {m}", t.name),
            }
        }
        println!("{line}");
        println!("    {}", terms(&fit));
    }
}

/// One judge (SPEC §6): the reported Cascaded Tanks and EMPS grey boxes scored on their
/// test record by the table's path (`fit_grey`: the calibration's integrator, the state fitted
/// by `window_state`) and by `mmenn::predict` on the same model as a model file (automatic
/// and the calibration's fixed RK4 steps). Diagnosis only; prints the RMSEs. Measured on
/// 25731f1: Cascaded Tanks 0.211009 V all three ways (the automatic rule takes 1000 steps);
/// EMPS 5.965584 mm by the table and with 1 fixed step, 5.966247 mm with the automatic 4.
#[test]
#[ignore]
fn explore_one_judge() {
    use mmenn::sysid_core::Substeps;
    let tanks = tanks_model(&TanksOptions {
        pump_lag: Some(4.0),
        area2: true,
        ..TanksOptions::default()
    })
    .unwrap();
    for (b, spec, k) in [
        (Benchmark::CascadedTanks, tanks, 8usize),
        (Benchmark::Emps, emps_spec(3e-4).unwrap(), 1),
    ] {
        let d = data(b);
        let w = b.init_window();
        let (scale, unit) = b.reporting_unit();
        let test = d.tests[0].data.experiments()[0].clone();
        let tests = vec![("test".to_string(), test.clone())];
        let fit = fit_grey(&spec, &d.estimation.experiments()[0], &tests, w).unwrap();
        let y: Vec<f64> = test.outputs().row(0).iter().copied().collect();
        let table = fit.tests[0]
            .sim
            .as_ref()
            .map_or(f64::NAN, |s| rmse_after(&y, s, w));
        let mut line = format!("{b}: table path {:.6} {unit}", scale * table);
        for (label, sub) in [
            ("automatic steps", None),
            ("fixed steps", Some(Substeps::Fixed(k))),
        ] {
            match super::tests::predicted(&spec, &fit.model, &test, w, sub) {
                Ok((p, steps)) => {
                    line += &format!(
                        " | predict, {label} ({steps:?}) {:.6} {unit}",
                        scale * rmse_after(&y, &p, w)
                    )
                }
                Err(e) => line += &format!(" | predict, {label}: failed {e:#}"),
            }
        }
        println!("{line}");
    }
}

/// `mmenn greyest --starts` on the real Cascaded Tanks training record: the reported
/// structure written as a physical model file (one parameter per term, the held terms
/// fixed), estimated from the file's start and 24 seeded starts, the upper level and the
/// pump lag started at 5 V and the first input (`--x0`). Prints greyest's report (its
/// multi-start table and identifiability warning). Training record only.
#[test]
#[ignore]
fn explore_tanks_greyest_starts() {
    use mmenn::greyest::{GreyestOptions, compute_greyest_quietly, report};
    use mmenn::model_file::ParameterEntry;
    use mmenn::sysid_core::Estimation;
    let spec = tanks_model(&TanksOptions {
        pump_lag: Some(4.0),
        area2: true,
        ..TanksOptions::default()
    })
    .unwrap();
    let mut file = model_file(&spec, &spec.model, 4.692e-4, str::to_string);
    file.parameters = file
        .terms
        .iter()
        .enumerate()
        .map(|(i, t)| ParameterEntry {
            name: format!("c{i}_{}_{}", t.state, t.effect),
            value: t.coefficient,
            unit: None,
            bounds: None,
            estimation: if spec.free.contains(&i) {
                Estimation::Free
            } else {
                Estimation::Fixed
            },
            sigma: None,
        })
        .collect();
    for (i, t) in file.terms.iter_mut().enumerate() {
        t.term = format!("c{i}_{}_{}*({})", t.state, t.effect, t.term);
        t.coefficient = 1.0;
    }
    let loaded =
        mmenn::model::LoadedModel::from_spec(std::path::Path::new("tanks.toml"), file).unwrap();
    let d = data(Benchmark::CascadedTanks);
    let est = d.estimation.experiments()[0].clone();
    let u0 = est.inputs()[(0, 0)];
    let starts: usize = std::env::var("GREY_STARTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(24);
    let opts = GreyestOptions {
        starts,
        seed: 1,
        substeps: mmenn::sysid_core::Substeps::Fixed(8),
        x0_start: vec![("h1".into(), 5.0), ("w".into(), u0)],
        ..GreyestOptions::default()
    };
    match compute_greyest_quietly(&loaded, &[est], &["estimation.csv".into()], &opts) {
        Ok(outcome) => println!("{}", report(&outcome)),
        Err(e) => println!("failed: {e}"),
    }
}
