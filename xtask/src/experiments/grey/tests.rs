use super::*;
use mmenn::sysid_core::Term;

/// A model with the given coefficients (in term order).
fn with_coefficients(model: &TermModel, c: &[f64]) -> TermModel {
    let (linear, terms) = model.clone().into_parts();
    let terms: Vec<Term> = terms
        .into_iter()
        .zip(c)
        .map(|(t, &c)| Term {
            coefficient: c,
            ..t
        })
        .collect();
    TermModel::new(linear, terms).unwrap()
}

fn run(spec: &GreySpec, model: &TermModel, x0: &[f64], u: &[f64], dt: f64) -> DMatrix<f64> {
    let n = model.linear().n_states();
    let e = Experiment::new(
        0.0,
        dt,
        DMatrix::from_row_slice(1, u.len(), u),
        DMatrix::zeros(1, u.len()),
    )
    .unwrap()
    .with_intersample(spec.intersample);
    simulate_outputs(model, &DMatrix::identity(n, n), x0, &e, &spec.integrator).unwrap()
}

/// The outflows act on the positive part of each level: started below empty with the
/// pump off, no term drains further (the pump offset refills the upper tank, the
/// inflow is ≥ 0), so the levels never fall below their start and stay bounded. With
/// `√|h|` and the calibrated `+k5·h2` the lower level ran away below zero (the MME/NN
/// blow-up on b801ccd, h2 = −1e12 at t = 2044 s).
#[test]
fn tanks_levels_below_empty_do_not_run_away() {
    let spec = tanks_model(&TanksOptions::default()).unwrap();
    // outflow, pump, overflow, inflow, outflow, overflow_inflow, overflow,
    // linear_outflow, pump_offset: the calibrated values of the full run.
    let c = [
        -0.033, 0.027, -1.0, 0.084, -0.147, 1.38, -1.0, 0.0196, 0.0172,
    ];
    let model = with_coefficients(&spec.model, &c);
    let u = vec![0.0; 1024];
    let x = run(&spec, &model, &[-1.0, -1.0], &u, 4.0);
    for k in 0..u.len() {
        for i in 0..2 {
            let h = x[(i, k)];
            assert!(
                h.is_finite() && (-1.0 - 1e-9..=10.0).contains(&h),
                "h{} = {h} at {k}",
                i + 1
            );
        }
    }
    // The upper tank settles where its outflow balances the pump offset:
    // k1·√h1 = k0, h1 = (0.0172/0.033)² = 0.2717 (analytic).
    let h1 = x[(0, u.len() - 1)];
    assert!((h1 - (0.0172f64 / 0.033).powi(2)).abs() < 1e-3, "h1 = {h1}");
}

/// The upper level is unmeasured: scaling it by `s` maps `(k1, k4, k0, k2, c2, H1)` to
/// `(k1·√s, k4·s, k0·s, k2/√s, c2/s, s·H1)` with the same lower level, so calibrating
/// `k2` with `H1` held fits the overflow level in effect (analytic identity, checked
/// on a run whose upper tank overflows).
#[test]
fn tanks_overflow_level_is_absorbed_by_the_upper_level_scale() {
    let s = 1.7_f64;
    let base = TanksOptions::default();
    let a = tanks_model(&base).unwrap();
    let b = tanks_model(&TanksOptions {
        h1_top: base.h1_top * s,
        ..base
    })
    .unwrap();
    // outflow, pump, overflow, inflow, outflow, overflow_inflow, overflow,
    // linear_outflow, pump_offset
    let c = [
        -0.033, 0.027, -1.0, 0.084, -0.147, 1.38, -1.0, 0.0196, 0.0172,
    ];
    let r = s.sqrt();
    let cs = [
        c[0] * r,
        c[1] * s,
        c[2],
        c[3] / r,
        c[4],
        c[5] / s,
        c[6],
        c[7],
        c[8] * s,
    ];
    let (ma, mb) = (
        with_coefficients(&a.model, &c),
        with_coefficients(&b.model, &cs),
    );
    let u: Vec<f64> = (0..400)
        .map(|k| 2.8 + 3.0 * (k as f64 * 4.0 * std::f64::consts::TAU / 800.0).sin())
        .collect();
    let ya = run(&a, &ma, &[7.6, 5.2], &u, 4.0);
    let yb = run(&b, &mb, &[7.6 * s, 5.2], &u, 4.0);
    let top = ya.row(0).max();
    assert!(
        top > base.h1_top,
        "the upper tank never overflowed (max {top})"
    );
    for k in 0..u.len() {
        assert!((ya[(1, k)] - yb[(1, k)]).abs() < 1e-9, "lower level at {k}");
        assert!(
            (ya[(0, k)] * s - yb[(0, k)]).abs() < 1e-8,
            "upper level at {k}"
        );
    }
}

/// The asymmetric EMPS model started from a symmetric one is that model
/// (`(v + |v|)/2 + (v − |v|)/2 = v`, no Coulomb asymmetry yet).
#[test]
fn emps_asymmetric_start_equals_the_symmetric_model() {
    let sym = emps_spec(3e-4).unwrap();
    let asym = emps_asymmetric_from(&sym.model, 3e-4).unwrap();
    let u: Vec<f64> = (0..3000)
        .map(|k| 2.0 * (k as f64 * 1e-3 * 3.0).sin() - 0.3)
        .collect();
    let ys = run(&sym, &sym.model, &[0.1, 0.0], &u, 1e-3);
    let ya = run(&asym, &asym.model, &[0.1, 0.0], &u, 1e-3);
    let moving = ys.row(1).amax();
    assert!(moving > 1e-3, "the carriage hardly moved ({moving} m/s)");
    for k in 0..u.len() {
        assert!((ys[(0, k)] - ya[(0, k)]).abs() < 1e-12, "position at {k}");
    }
}

/// With its calibrated paths at zero (the start), the Silverbox input stage leaves the
/// oscillator as it is; the input stage itself tracks the input (first-order lag).
#[test]
fn silverbox_input_stage_at_zero_is_the_plain_oscillator() {
    let (k, c, b) = (1.9e5, 40.0, 1.9e5);
    let plain = silverbox_model(k, c, b, &[SilverboxExtra::QuadraticSpring]).unwrap();
    let staged = silverbox_model(
        k,
        c,
        b,
        &[
            SilverboxExtra::QuadraticSpring,
            SilverboxExtra::Feedthrough(2e-4),
        ],
    )
    .unwrap();
    let dt = 16_384.0 / 1e7;
    let u: Vec<f64> = (0..2000)
        .map(|k| 0.1 * (k as f64 * dt * 400.0).sin())
        .collect();
    // Both on the staged model's integrator (4 RK4 sub-steps).
    let yp = run(&staged, &plain.model, &[0.0, 0.0], &u, dt);
    let ys = run(&staged, &staged.model, &[0.0, 0.0, 0.0], &u, dt);
    let amp = yp.row(0).amax();
    assert!(amp > 1e-3, "the oscillator hardly moved ({amp})");
    for j in 0..u.len() {
        assert!((yp[(0, j)] - ys[(0, j)]).abs() < 1e-12, "output at {j}");
    }
    // w lags u by about τ: |w − u| ≤ τ·max|u'| + transient.
    let slope = 0.1 * 400.0;
    for j in 100..u.len() {
        assert!(
            (ys[(2, j)] - u[j]).abs() < 2.0 * 2e-4 * slope,
            "stage at {j}"
        );
    }
}

/// The measurement filter (Rule 3's output filter) does not act on the oscillator: with the
/// input gain's terms at zero (their start), the oscillator and the input stage run as
/// without either, the filter state follows the displacement within its lag, and the
/// measured output is the filter state. With the input gain's coefficients set, the
/// acceleration gains exactly `u·(b1·y + b2·y²)` (checked on the model's right-hand side
/// against that sum).
#[test]
fn silverbox_output_filter_and_input_gain() {
    use SilverboxExtra::*;
    let (k, c, b) = (1.9e5, 40.0, 1.9e5);
    let base = silverbox_model(k, c, b, &[QuadraticSpring, Feedthrough(1e-4)]).unwrap();
    let full = silverbox_model(
        k,
        c,
        b,
        &[
            QuadraticSpring,
            InputGainVariation,
            Feedthrough(1e-4),
            OutputFilter(2e-4),
        ],
    )
    .unwrap();
    let lin = full.model.linear();
    assert_eq!(lin.state_names(), ["y", "v", "w", "z"]);
    assert_eq!(
        lin.c().row(0).iter().copied().collect::<Vec<_>>(),
        [0.0, 0.0, 0.0, 1.0]
    );
    let dt = 16_384.0 / 1e7;
    let u: Vec<f64> = (0..2000)
        .map(|k| 0.1 * (k as f64 * dt * 400.0).sin())
        .collect();
    // Both on the filtered model's integrator (its sub-steps follow the smaller constant).
    let xb = run(&full, &base.model, &[0.0, 0.0, 0.0], &u, dt);
    let xf = run(&full, &full.model, &[0.0, 0.0, 0.0, 0.0], &u, dt);
    let amp = xb.row(0).amax();
    assert!(amp > 1e-4, "the oscillator hardly moved ({amp})");
    let vmax = xb.row(1).amax();
    for j in 0..u.len() {
        for s in 0..3 {
            assert!((xb[(s, j)] - xf[(s, j)]).abs() < 1e-12, "state {s} at {j}");
        }
        if j > 100 {
            // z lags y by about τo: |z − y| ≤ τo·max|y'| (twice, for the transient's tail).
            assert!(
                (xf[(3, j)] - xf[(0, j)]).abs() < 2.0 * 2e-4 * vmax,
                "filter at {j}"
            );
        }
    }
    // The two terms enter the acceleration as u·y and u·y².
    let names: Vec<&str> = full
        .model
        .terms()
        .iter()
        .map(|t| t.effect.as_str())
        .collect();
    let i1 = names
        .iter()
        .position(|n| *n == "input_gain_linear_in_y")
        .unwrap();
    let i2 = names
        .iter()
        .position(|n| *n == "input_gain_quadratic_in_y")
        .unwrap();
    let (lin, mut terms) = full.model.clone().into_parts();
    terms[i1].coefficient = 3.0e3;
    terms[i2].coefficient = 2.5e4;
    let set = TermModel::new(lin, terms).unwrap();
    let (x, uu) = ([0.12, -0.4, 0.05, 0.11], [0.07]);
    let mut f0 = vec![0.0; 4];
    let mut f1 = vec![0.0; 4];
    mmenn::sysid_core::Dynamics::rhs(&full.model, 0.0, &x, &uu, &mut f0);
    mmenn::sysid_core::Dynamics::rhs(&set, 0.0, &x, &uu, &mut f1);
    let expect = 0.07 * (3.0e3 * 0.12 + 2.5e4 * 0.12 * 0.12);
    assert!(
        (f1[1] - f0[1] - expect).abs() < 1e-9 * expect.abs(),
        "{} vs {expect}",
        f1[1] - f0[1]
    );
    for s in [0, 2, 3] {
        assert!((f1[s] - f0[s]).abs() < 1e-12, "state {s}'s equation");
    }
}

/// The nested calibration recovers known coefficients and state: noise-free data from the
/// EMPS grey box at chosen coefficients and a state the record's first difference does not
/// give, started 5–10 % off every coefficient.
#[test]
fn window_state_calibration_recovers_a_known_model() {
    let spec = emps_spec(3e-4).unwrap();
    let truth = [0.39, -2.0, -0.25, 0.04];
    let true_model = with_coefficients(&spec.model, &truth);
    let n = 3000;
    let u: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * 1e-3;
            0.8 * (t * 5.0).sin() + 0.4 * (t * 17.0).cos() - 0.1
        })
        .collect();
    let x0 = [0.01, 0.05];
    let states = run(&spec, &true_model, &x0, &u, 1e-3);
    let est = Experiment::new(
        0.0,
        1e-3,
        DMatrix::from_row_slice(1, n, &u),
        states.rows(0, 1).into_owned(),
    )
    .unwrap();
    let start = with_coefficients(&spec.model, &[0.42, -1.8, -0.27, 0.036]);
    let (model, x) = calibrate_window_state(&spec, &start, &est, 20).unwrap();
    for (t, want) in model.terms().iter().zip(truth) {
        assert!(
            (t.coefficient - want).abs() < 1e-5 * want.abs(),
            "{}: {} against {want}",
            t.effect,
            t.coefficient
        );
    }
    assert!(
        (x[0] - x0[0]).abs() < 1e-9 && (x[1] - x0[1]).abs() < 1e-7,
        "{x:?}"
    );
}

/// Each state starts where its [`Start`] says, in state order: position, first-difference
/// velocity, the input stage at the first input, the measurement filter at the first
/// reading (Silverbox); both levels, the sensor and the pump lag (Cascaded Tanks).
#[test]
fn starting_states_follow_the_state_layout() {
    let e = Experiment::new(
        0.0,
        0.5,
        DMatrix::from_row_slice(1, 3, &[7.0, 8.0, 9.0]),
        DMatrix::from_row_slice(1, 3, &[2.0, 3.0, 5.0]),
    )
    .unwrap();
    let sb = silverbox_model(
        1.0,
        0.1,
        1.0,
        &[
            SilverboxExtra::Feedthrough(1e-4),
            SilverboxExtra::OutputFilter(1e-4),
        ],
    )
    .unwrap();
    assert_eq!(sb.x0_guess(&e), vec![2.0, 2.0, 7.0, 2.0]);
    let plain = silverbox_model(1.0, 0.1, 1.0, &[]).unwrap();
    assert_eq!(plain.x0_guess(&e), vec![2.0, 2.0]);
    let tanks = tanks_model(&TanksOptions {
        sensor: Some(10.0),
        pump_lag: Some(4.0),
        ..TanksOptions::default()
    })
    .unwrap();
    assert_eq!(tanks.x0_guess(&e), vec![2.0, 2.0, 2.0, 7.0]);
}

/// Rule 7's recalibration on a record whose two channels were recorded through a known
/// filter with a 34° lag above the input's band (where only the cubic spring's distortion
/// lives): recalibrated on the records deconvolved by that filter, the grey box recovers the
/// coefficients the record was simulated with (cubic to 5e-5), from a start 20 % off in the
/// cubic term;
/// calibrated on the record as recorded, the same start lands further from the cubic truth.
#[test]
fn recalibration_through_the_acquisition_filter_recovers_the_system() {
    use nalgebra::Complex;
    let spec = silverbox_model(1.9e5, 40.0, 2.0e5, &[]).unwrap();
    // input_gain, input_offset, linear_spring, damping, cubic_spring.
    let truth = [2.0e5, 0.0, -1.9e5, -40.0, -2.5e6];
    let true_model = with_coefficients(&spec.model, &truth);
    let dt = 1.0 / 610.35;
    let n = 12_000;
    // A multisine below 150 Hz (odd harmonics of 0.5 Hz, Schroeder phases).
    let lines: Vec<f64> = (0..150).map(|j| (2 * j + 1) as f64 * 0.5).collect();
    let u_sys: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * dt;
            let m = lines.len() as f64;
            lines
                .iter()
                .enumerate()
                .map(|(j, f)| {
                    let phase = -std::f64::consts::PI * (j * (j + 1)) as f64 / m;
                    (std::f64::consts::TAU * f * t + phase).cos()
                })
                .sum::<f64>()
                * 0.03
                * (2.0 / m).sqrt()
        })
        .collect();
    let x = run(&spec, &true_model, &[0.0, 0.0], &u_sys, dt);
    let y_sys: Vec<f64> = x.row(0).iter().copied().collect();
    let amp = y_sys.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
    assert!(amp > 0.05, "the oscillator hardly moved ({amp})");
    let lag = Complex::from_polar(0.85, -0.6);
    let bands: Vec<(f64, Complex<f64>)> = (0..14).map(|j| (165.0 + 10.0 * j as f64, lag)).collect();
    let filter = AcquisitionFilter::from_bands(160.0, bands).unwrap();
    let u_rec = filter.apply(&u_sys, dt).unwrap();
    let y_rec = filter.apply(&y_sys, dt).unwrap();
    let est = Experiment::new(
        0.0,
        dt,
        DMatrix::from_row_slice(1, n, &u_rec),
        DMatrix::from_row_slice(1, n, &y_rec),
    )
    .unwrap();
    let start = with_coefficients(&spec.model, &[2.0e5, 0.0, -1.9e5, -40.0, -3.0e6]);
    let fit = GreyFit {
        model: start.clone(),
        x0: vec![0.0, 0.0],
        train_rmse: f64::NAN,
        train_rmse_all: f64::NAN,
        tests: Vec::new(),
    };
    let (model, _) = recalibrated_through(&spec, &fit, &filter, &est).unwrap();
    let cubic = |m: &TermModel| m.terms()[4].coefficient;
    let through = (cubic(&model) / truth[4] - 1.0).abs();
    assert!(
        through < 5e-5,
        "cubic {} against {} ({through:.3e})",
        cubic(&model),
        truth[4]
    );
    for (i, want) in [(0, truth[0]), (2, truth[2]), (3, truth[3])] {
        let got = model.terms()[i].coefficient;
        assert!(
            (got / want - 1.0).abs() < 1e-4,
            "term {i}: {got} against {want}"
        );
    }
    // The same start calibrated on the record as recorded.
    let plain = calibrate(
        &start,
        &record(&est, n, spec.intersample).unwrap(),
        &[vec![0.0, 0.0]],
        &CalibrationConfig {
            horizons: vec![1.0],
            ..calibration(&spec)
        },
    )
    .unwrap();
    let recorded = (cubic(&plain.model) / truth[4] - 1.0).abs();
    assert!(
        recorded > 3.0 * through,
        "as recorded the cubic is off by {recorded:.2e}, through the filter by {through:.2e}"
    );
}

/// `model` written as a model file (its linear part, its terms as they are, the spec's
/// intersample rule) and run by `mmenn::predict` — the one judge every command uses — from
/// the state it fits to the record's first `window` outputs: the scored output and the RK4
/// steps taken (`substeps`: `None`, the predict command's automatic rule).
pub(super) fn predicted(
    spec: &GreySpec,
    model: &TermModel,
    record: &Experiment,
    window: usize,
    substeps: Option<mmenn::sysid_core::Substeps>,
) -> Result<(Vec<f64>, Option<usize>)> {
    predicted_through(spec, model, None, record, window, substeps)
}

/// [`predicted`] with the model file's `[acquisition]` filter set to `filter`.
pub(super) fn predicted_through(
    spec: &GreySpec,
    model: &TermModel,
    filter: Option<&AcquisitionFilter>,
    record: &Experiment,
    window: usize,
    substeps: Option<mmenn::sysid_core::Substeps>,
) -> Result<(Vec<f64>, Option<usize>)> {
    use mmenn::predict::{InitialChoice, PredictOptions, compute_predict_record_with};
    let mut file = model_file(spec, model, 1.0, str::to_string);
    file.acquisition = filter.cloned();
    let loaded = mmenn::model::LoadedModel::from_spec(std::path::Path::new("grey.toml"), file)?;
    let opts = PredictOptions {
        x0: InitialChoice::Fit,
        x0_window: Some(window),
        horizon: None,
        score_from: None,
    };
    let steps = substeps.unwrap_or_else(|| mmenn::predict::default_substeps(&loaded));
    let out = compute_predict_record_with(&loaded, record, loaded.outputs(), &opts, steps)?;
    let column = format!("{}_predicted", out.observation.names[0]);
    let y = out
        .column(&column)
        .with_context(|| format!("no column {column}"))?
        .to_vec();
    Ok((y, out.summary.substeps))
}

/// The one-judge cases' record and model: the EMPS structure run from rest on a sum of
/// sines (amplitude, Hz) for 3 s at 1 kHz, and the same structure with every coefficient
/// 5 % off (a model other than the one that made the record, so the error is not zero).
fn one_judge_case(sines: &[(f64, f64)]) -> (GreySpec, TermModel, Experiment, DMatrix<f64>) {
    let spec = emps_spec(3e-4).unwrap();
    let n = 3000;
    let dt = 1e-3;
    let u: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * dt;
            sines
                .iter()
                .map(|(a, f)| a * (2.0 * std::f64::consts::PI * f * t).sin())
                .sum()
        })
        .collect();
    let q = run(&spec, &spec.model, &[0.0, 0.0], &u, dt);
    let exp = Experiment::new(
        0.0,
        dt,
        DMatrix::from_row_slice(1, n, &u),
        q.rows(0, 1).into_owned(),
    )
    .unwrap()
    .with_intersample(spec.intersample);
    let c: Vec<f64> = spec
        .model
        .terms()
        .iter()
        .map(|t| 1.05 * t.coefficient)
        .collect();
    let other = with_coefficients(&spec.model, &c);
    (spec, other, exp, q)
}

/// The one-judge assertions: the table's run misses the record (the comparison is not of
/// two exact runs) and equals predict's to 1e-9 of the record's range.
fn assert_one_judge(table: &[f64], judged: &[f64], q: &DMatrix<f64>, window: usize) {
    let range = q.row(0).max() - q.row(0).min();
    let worst = table
        .iter()
        .zip(judged)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let y: Vec<f64> = q.row(0).iter().copied().collect();
    let err = rmse_after(&y, table, window);
    assert!(
        err > 1e-3 * range,
        "the scored model should miss the record: {err:e}"
    );
    assert!(
        worst <= 1e-9 * range,
        "table and predict differ by {worst:e} (range {range:e})"
    );
}

/// One judge (SPEC §6): the tables score a grey box by `window_state` + `free_run` with the
/// calibration's integrator; `mmenn predict` on the same model written as a model file must
/// give the same run. Checked on the EMPS structure ([`one_judge_case`]) with the
/// calibration's 1 RK4 step: the two runs agree to 1e-9 of the output's range (a predict
/// state fitted to 30 samples instead of 20 differs by 1.8e-8 of it and fails). On the real
/// test records the same comparison (`explore_one_judge`) gave 5.965584 mm both ways.
#[test]
fn the_tables_grey_box_score_is_the_predict_commands() {
    let (spec, other, exp, q) = one_judge_case(&[(2.0, 0.7), (0.8, 3.1)]);
    let window = 20;
    let table = window_state(&spec, &other, &exp, window)
        .map_err(|e| format!("{e:#}"))
        .and_then(|x0| free_run(&spec, &other, &exp, &x0))
        .unwrap();
    let (judged, steps) = predicted(
        &spec,
        &other,
        &exp,
        window,
        Some(mmenn::sysid_core::Substeps::Fixed(1)),
    )
    .unwrap();
    assert_eq!(steps, Some(1));
    assert_one_judge(&table, &judged, &q, window);
}

/// One judge through an acquisition filter: the tables' rows read through Ã
/// ([`filtered_run`]) must be what `mmenn predict` gives for the same model written as a
/// model file with that `[acquisition]` table. The case of [`one_judge_case`] with a
/// 23-Hz sine added, read through a first-order low-pass (200 Hz corner, given in 5-Hz
/// bands from 1 Hz) that acts where the position has its content; the calibration's 1 RK4
/// step. The two runs agree to 1e-9 of the output's range. Before the tables' state fit
/// read the deconvolved outputs, as predict's does, they differed by 4.9e-5 of it (the
/// state was fitted to the recorded outputs). On the real Silverbox records the grey box
/// read through Ã now scores what the hybrid that keeps the physics alone scores (judged
/// by predict's path) to 2e-10 relative.
#[test]
fn the_tables_filtered_grey_box_score_is_the_predict_commands() {
    use nalgebra::Complex;
    let (spec, other, exp, q) = one_judge_case(&[(2.0, 0.7), (0.8, 3.1), (0.5, 23.0)]);
    let bands: Vec<(f64, Complex<f64>)> = (0..100)
        .map(|i| {
            let f = 1.0 + 5.0 * i as f64;
            (f, Complex::new(1.0, f / 200.0).inv())
        })
        .collect();
    let filter = AcquisitionFilter::from_bands(0.0, bands).unwrap();
    let window = 20;
    let table = filtered_run(&spec, &other, &filter, &exp, window).unwrap();
    let (judged, steps) = predicted_through(
        &spec,
        &other,
        Some(&filter),
        &exp,
        window,
        Some(mmenn::sysid_core::Substeps::Fixed(1)),
    )
    .unwrap();
    assert_eq!(steps, Some(1));
    assert_one_judge(&table, &judged, &q, window);
}

/// `one_flow` (docs/decisions/tanks-one-flow-rule.md): the upper outflow and the lower
/// inflow become one transfer term out of h1 into h2 — one coefficient fewer, the same
/// free coefficients otherwise — and the water it moves leaves one tank and enters the
/// other: started with only the upper tank holding water, pump off and no outflow from
/// the lower tank, the total h1 + h2 stays constant.
#[test]
fn tanks_one_flow_is_one_transfer_that_conserves_water() {
    let two = tanks_model(&TanksOptions::default()).unwrap();
    let one = tanks_model(&TanksOptions {
        one_flow: true,
        ..TanksOptions::default()
    })
    .unwrap();
    assert_eq!(one.model.terms().len() + 1, two.model.terms().len());
    assert_eq!(one.free.len() + 1, two.free.len());
    assert_eq!(one.model.terms()[0].into, Some(1));
    assert!(two.model.terms().iter().all(|t| t.into.is_none()));
    // Only the flow acts (every other coefficient zero).
    let c: Vec<f64> = (0..one.model.terms().len())
        .map(|i| if i == 0 { -0.05 } else { 0.0 })
        .collect();
    let flow_only = with_coefficients(&one.model, &c);
    let x = run(&one, &flow_only, &[6.0, 1.0], &[0.0; 200], 4.0);
    for k in 0..200 {
        assert!((x[(0, k)] + x[(1, k)] - 7.0).abs() < 1e-9, "sample {k}");
    }
    assert!(
        x[(0, 199)] < 1.0 && x[(1, 199)] > 6.0,
        "the water moved down"
    );
}
