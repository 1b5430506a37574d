//! The physics-first grey-box rows: candidates, calibration by free-run output error,
//! the choice by training error, and the rows under the official and dynoNet's protocols.

use super::*;

/// Candidate grey boxes of a benchmark (several structures or starting points; the one
/// with the lowest training free-run RMSE is reported) and a label.
pub(super) fn grey_candidates(
    data: &mmenn::benchmarks::BenchmarkData,
    mode: Mode,
) -> Result<(String, Vec<(String, grey::GreySpec)>)> {
    Ok(match data.benchmark {
        Benchmark::Emps => {
            // docs/decisions/emps-full-horizon-minimum.md: the same start descended over the
            // whole record at once reaches a lower training cost than over growing horizons.
            let mut whole = grey::emps_spec(3e-4)?;
            whole.horizons = vec![1.0];
            (
                "physics-first grey box (M q'' = gτ u − Fv q' − Fc tanh(q'/ε) − offset)".into(),
                vec![
                    (
                        "ε = 0.3 mm/s, growing horizons".into(),
                        grey::emps_spec(3e-4)?,
                    ),
                    ("ε = 0.3 mm/s, one horizon".into(), whole),
                ],
            )
        }
        Benchmark::CascadedTanks => {
            let base = grey::TanksOptions::default();
            let mut v = vec![(
                "Torricelli outflows, overflows, pump offset".to_string(),
                grey::tanks_model(&grey::TanksOptions {
                    linear_outflow: false,
                    ..base
                })?,
            )];
            v.push((
                "+ linear term in the lower outflow".into(),
                grey::tanks_spec(base.h1_top, base.h2_top, base.rate)?,
            ));
            // docs/decisions/tanks-pump-rule.md: chosen before the test record was run,
            // by training error and the held-out last fifth of the training record.
            v.push((
                "+ linear term in the lower outflow, pump lag 4 s".into(),
                grey::tanks_model(&grey::TanksOptions {
                    pump_lag: Some(4.0),
                    ..base
                })?,
            ));
            // docs/decisions/tanks-area2-lag-rule.md: chosen before the test record was run,
            // by training error and the held-out last fifth (not blind: disclosed there).
            v.push((
                "+ linear term in the lower outflow, pump lag 4 s, lower section varying \
                 with the level"
                    .into(),
                grey::tanks_model(&grey::TanksOptions {
                    pump_lag: Some(4.0),
                    area2: true,
                    ..base
                })?,
            ));
            if mode == Mode::Full {
                v.push((
                    "+ lower sensor offset 1 V".into(),
                    grey::tanks_model(&grey::TanksOptions {
                        sensor_offset: 1.0,
                        ..base
                    })?,
                ));
            }
            (
                "physics-first grey box (√h outflows, both overflows, pump offset)".into(),
                v,
            )
        }
        Benchmark::Silverbox => {
            let (k, c, b) = oscillator_guess(&data.estimation.experiments()[0])?;
            use grey::SILVERBOX_STAGE_TAU;
            use grey::SilverboxExtra::{DisplacementDamping, Feedthrough, QuadraticSpring};
            let mut v = vec![(
                "cubic + quadratic spring, y²·y' damping, quadratic drag, input gain varying \
                 with y, input stage τ = 0.1 ms"
                    .to_string(),
                grey::silverbox_model(k, c, b, &grey::SILVERBOX_REPORTED)?,
            )];
            if mode == Mode::Full {
                v.push((
                    "cubic + quadratic spring, y²·y' damping, input stage τ = 0.1 ms".into(),
                    grey::silverbox_model(
                        k,
                        c,
                        b,
                        &[
                            QuadraticSpring,
                            DisplacementDamping,
                            Feedthrough(SILVERBOX_STAGE_TAU),
                        ],
                    )?,
                ));
            }
            // Two horizon stages (0.02 and 0.3 dropped), in both runs since the full run hit
            // the 10-minute bound (616 s on 67dec87): about 40 % less calibration (34 s
            // instead of about 55 s on 6d677f6), and the same calibration to 2e-6 of its test
            // RMSE (quick fixtures of 8a5e8a1 against the full ones of b8739a8).
            for (_, spec) in &mut v {
                spec.horizons = vec![0.1, 1.0];
            }
            (
                "physics-first grey box (polynomial spring and damping, input stage, input offset)"
                    .into(),
                v,
            )
        }
    })
}

/// The grey box the table reports (lowest training free-run RMSE among the candidates):
/// its structure, calibration, candidate name and the wall time of all candidates' calibration.
/// MME/NN on the grey box starts from it (no second calibration).
pub struct ChosenGrey {
    pub spec: grey::GreySpec,
    pub fit: grey::GreyFit,
    pub name: String,
    pub seconds: f64,
    /// The acquisition filter the records share, where the benchmark's grey box is read
    /// through one (Silverbox, Rule 6 of docs/decisions/silverbox-schroeder-rule.md).
    pub acquisition: Option<AcquisitionFilter>,
}

/// Rows of the physics-first grey box (see [`grey`]): calibrated by free-run output error
/// on the whole training record at full rate, scored under the official protocol. Returns
/// the chosen grey box (`None` when every calibration failed).
pub(super) fn grey_rows(
    data: &mmenn::benchmarks::BenchmarkData,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    mode: Mode,
    offset: f64,
) -> Option<ChosenGrey> {
    let window = data.benchmark.init_window();
    let (scale, unit) = data.benchmark.reporting_unit();
    let (label, candidates) = match grey_candidates(data, mode) {
        Ok(c) => c,
        Err(e) => {
            table.note(format!("grey box: not built: {e:#}"));
            return None;
        }
    };
    let tests: Vec<(String, Experiment)> = data
        .tests
        .iter()
        .map(|t| (t.name.clone(), t.data.experiments()[0].clone()))
        .collect();
    let est = &data.estimation.experiments()[0];
    // Records outside the split (Silverbox's Schroeder record) are run free beside the test
    // records; their scores are reported, no official number uses them.
    let extra = match mmenn::benchmarks::load_extra(data.benchmark, &data.dir) {
        Ok(x) => x,
        Err(e) => {
            table.note(format!("Records outside the split: not read: {e:#}"));
            Vec::new()
        }
    };
    let with_extra: Vec<(String, Experiment)> = tests
        .iter()
        .cloned()
        .chain(
            extra
                .iter()
                .map(|t| (t.name.clone(), t.data.experiments()[0].clone())),
        )
        .collect();
    let clock = std::time::Instant::now();
    let mut best: Option<(String, grey::GreySpec, grey::GreyFit)> = None;
    let mut tried = Vec::new();
    let mut beyond = Vec::new();
    // The candidates are independent: each is calibrated on its own thread (not rayon's
    // pool, whose threads the NARX rows beside this need), then chosen in order as before.
    let threads = candidates.len().max(1);
    let fits: Vec<(String, grey::GreySpec, Result<grey::GreyFit>)> = std::thread::scope(|s| {
        let handles: Vec<_> = candidates
            .into_iter()
            .map(|(name, spec)| {
                let with_extra = &with_extra;
                s.spawn(move || {
                    let fit = grey::fit_grey(&spec, est, with_extra, window);
                    (name, spec, fit)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
            })
            .collect()
    });
    for (name, spec, fit) in fits {
        match fit {
            Ok(mut fit) => {
                tried.push(format!("{name}: {:.4} {unit}", scale * fit.train_rmse));
                for (t, (_, e)) in fit.tests[tests.len()..]
                    .iter()
                    .zip(&with_extra[tests.len()..])
                {
                    let y = row(e.outputs(), 0);
                    beyond.push(match &t.sim {
                        Ok(v) => format!(
                            "{name}: {:.4} {unit}",
                            rmse_after(&y, v, window, scale).unwrap_or(f64::NAN)
                        ),
                        Err(m) => format!("{name}: diverged ({m})"),
                    });
                }
                fit.tests.truncate(tests.len());
                if fit.train_rmse.is_finite()
                    && best
                        .as_ref()
                        .is_none_or(|(_, _, b)| fit.train_rmse < b.train_rmse)
                {
                    best = Some((name, spec, fit));
                }
            }
            Err(e) => tried.push(format!("{name}: failed ({e:#})")),
        }
    }
    let seconds = clock.elapsed().as_secs_f64();
    let Some((chosen, chosen_spec, fit)) = best else {
        table.note(format!(
            "grey box: every calibration failed: {}",
            tried.join("; ")
        ));
        return None;
    };
    push_grey(
        table,
        sims,
        &label,
        &fit.tests,
        &tests,
        window,
        scale,
        Some(offset),
    );
    if data.benchmark == Benchmark::Emps {
        push_dynonet(table, &label, &fit, scale);
    }
    if data.benchmark == Benchmark::CascadedTanks
        && let Some((name, e)) = tests.first()
    {
        push_same_x0(table, &label, name, &chosen_spec, &fit, e, scale);
    }
    table.set_for_model(&label, "train_s", seconds);
    table.set_for_model(&label, "threads", threads as f64);
    table.note(format!(
        "Grey box ({OFFICIAL}): the published physics as named terms, coefficients and the \
         training initial state calibrated by free-run output error (mmenn::discovery::calibrate: \
         Levenberg–Marquardt with exact RK4 sensitivities, growing horizons) on all {} \
         training samples at full rate; test state fitted to the first {window} test \
         outputs with the coefficients held. Candidates (training free-run RMSE; the lowest \
         is reported, chosen without the test records): {}. Chosen: {chosen}. Calibrated \
         terms: {}. Training initial state {:?} (recorded units); training free-run RMSE {:.4} {unit}; training wall time {seconds:.1} s \
         for all candidates (calibrated in parallel, one thread each, on 2 shared cores).",
        est.len(),
        tried.join("; "),
        grey_terms(&fit),
        fit.x0.iter().map(|v| format!("{v:.5e}")).collect::<Vec<_>>(),
        scale * fit.train_rmse,
    ));
    if !beyond.is_empty() {
        let names: Vec<&str> = extra.iter().map(|t| t.name.as_str()).collect();
        table.note(format!(
            "Beyond the training amplitude: free-run RMSE of every grey-box candidate on {} \
             (a record of the benchmark's distribution outside the loader's split: a \
             Schroeder multisine whose output reaches 0.265 V, against 0.216 V in the training \
             record and 0.300 V in test_arrow_full; state from its first {window} samples, \
             RMSE after them): {}. The structure is chosen by training error; a rule fixed \
             before this record was first run (docs/decisions/silverbox-schroeder-rule.md) \
             would replace it only if another candidate scored at least 2 % lower here.",
            names.join(", "),
            beyond.join("; ")
        ));
    }
    if data.benchmark == Benchmark::CascadedTanks
        && let Some((_, e)) = tests.first()
    {
        table.note(shared_state_note(
            &chosen_spec,
            &fit,
            e,
            window,
            scale,
            unit,
        ));
    }
    if data.benchmark == Benchmark::CascadedTanks && mode == Mode::Full {
        table.note(multistart_note(
            &chosen_spec,
            &fit,
            est,
            tests.first().map(|(_, e)| e),
            window,
            scale,
            unit,
        ));
    }
    if data.benchmark == Benchmark::Emps {
        reference_rows(table, est, &tests, window, scale, unit, &fit);
    }
    if data.benchmark == Benchmark::Emps {
        // Janot et al. 2019 (§3) report direction-dependent friction; started from the
        // symmetric fit, reported beside it as its own structure.
        let grey_seconds = seconds;
        let clock = std::time::Instant::now();
        let asym = grey::emps_asymmetric_from(&fit.model, 3e-4)
            .and_then(|spec| grey::fit_grey(&spec, est, &tests, window));
        let seconds = clock.elapsed().as_secs_f64();
        let label = "physics-first grey box, asymmetric friction (Fv±, Fc±)";
        match asym {
            Ok(a) => {
                push_grey(table, sims, label, &a.tests, &tests, window, scale, None);
                push_dynonet(table, label, &a, scale);
                // Started from the symmetric grey box: its calibration time counts too.
                table.set_for_model(label, "train_s", grey_seconds + seconds);
                table.set_for_model(label, "threads", 1.0);
                table.note(format!(
                    "{label} ({OFFICIAL}): `M q'' = gτ·u − Fv+·max(q', 0) − Fv−·min(q', 0) − \
                     Fc·tanh(q'/ε) − ΔFc·|tanh(q'/ε)| − offset` (Janot et al. 2019, §3), \
                     calibrated as above from the symmetric grey box's coefficients; \
                     calibrated terms: {}; training free-run RMSE {:.4} {unit} (symmetric: \
                     {:.4}); training wall time {seconds:.1} s. It fits the training record \
                     better and the test record worse: the test experiment adds 5-V force \
                     pulses to the drive command vir (a wider input than the training \
                     record's, with steps it never has) and excites a flexibility the \
                     training record does not (data README), so training error does not \
                     rank these structures on the test record.",
                    grey_terms(&a),
                    scale * a.train_rmse,
                    scale * fit.train_rmse,
                ));
            }
            Err(e) => table.note(format!("{label}: failed: {e:#}")),
        }
    }
    let acquisition = match (data.benchmark, extra.first()) {
        (Benchmark::Silverbox, schroeder) => acquisition_rows(
            table,
            sims,
            offset,
            &label,
            &chosen_spec,
            &fit,
            est,
            &tests,
            schroeder.map(|t| &t.data.experiments()[0]),
            seconds,
            mode == Mode::Full,
        ),
        _ => None,
    };
    let (acquisition, recalibrated) = match acquisition {
        Some((filter, r)) => (Some(filter), r),
        None => (None, None),
    };
    // Where Rule 7 adopts the recalibrated coefficients, the hybrid is built on them.
    let (fit, chosen, seconds) = match recalibrated {
        Some(r) => (
            grey::GreyFit {
                model: r.model,
                x0: r.x0,
                train_rmse: r.train_rmse,
                ..fit
            },
            format!("{chosen}, recalibrated through the acquisition filter by Rule 7"),
            seconds + r.seconds,
        ),
        None => (fit, chosen, seconds),
    };
    Some(ChosenGrey {
        spec: chosen_spec,
        fit,
        name: chosen,
        seconds,
        acquisition,
    })
}

/// Marks the grey-box row read through the acquisition filter its records share (the glance
/// table reads it).
pub const ACQUISITION: &str = "read through the acquisition filter both channels share (Rule 6 of \
     docs/decisions/silverbox-schroeder-rule.md)";

/// Silverbox's grey box read through the acquisition filter (Rule 6): rows on the test
/// records, the filter and the rule's judgement on the Schroeder record's second half in a
/// note. Returns the filter (`None` when it could not be estimated). Rule 7's
/// recalibration runs only when `rule7` is set (the full run; it is the quick run's largest
/// single step after the calibration and has never passed, so the quick run says so and keeps
/// the calibrated coefficients, as the full run has so far).
#[allow(clippy::too_many_arguments)]
fn acquisition_rows(
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
    label: &str,
    spec: &grey::GreySpec,
    fit: &grey::GreyFit,
    est: &Experiment,
    tests: &[(String, Experiment)],
    schroeder: Option<&Experiment>,
    grey_seconds: f64,
    rule7: bool,
) -> Option<(AcquisitionFilter, Option<Recalibrated>)> {
    let window = Benchmark::Silverbox.init_window();
    let (scale, unit) = Benchmark::Silverbox.reporting_unit();
    let clock = std::time::Instant::now();
    let filtered = match grey::acquisition_filtered(
        spec,
        fit,
        est,
        tests,
        window,
        &grey::SILVERBOX_ACQUISITION,
    ) {
        Ok(f) => f,
        Err(e) => {
            table.note(format!("{label}, {ACQUISITION}: not built: {e:#}"));
            return None;
        }
    };
    let seconds = clock.elapsed().as_secs_f64();
    // Rule 7: the grey box recalibrated on the training record deconvolved by Ã (G), judged
    // against F (the calibrated coefficients read through Ã) on the Schroeder record's second
    // half and in training, both through Ã; no test record enters the choice.
    let clock = std::time::Instant::now();
    let half_start = SCHROEDER_HALF - window;
    let f_half = schroeder.and_then(|e| {
        grey::rmse_through_from(spec, &fit.model, &filtered.filter, e, half_start, window)
    });
    let g = if rule7 {
        grey::recalibrated_through(spec, fit, &filtered.filter, est)
    } else {
        Err(anyhow::anyhow!(
            "run in the full mode only (the quick run keeps the calibrated coefficients)"
        ))
    };
    let g = g.map(|(model, x0)| {
        let train = grey::rmse_through_from(spec, &model, &filtered.filter, est, 0, window);
        let half = schroeder.and_then(|e| {
            grey::rmse_through_from(spec, &model, &filtered.filter, e, half_start, window)
        });
        (model, x0, train, half)
    });
    let g_seconds = clock.elapsed().as_secs_f64();
    let f_train = filtered.train_rmse;
    let (recalibrated, rule7) = match g {
        Ok((model, x0, Some(train), Some(half))) => {
            let f_half_v = f_half.unwrap_or(f64::NAN);
            let passes = half <= 0.98 * f_half_v && train <= 1.01 * f_train;
            let text = format!(
                "Rule 7 (the grey box recalibrated on the training record deconvolved by Ã in both channels, one stage warm-started at its calibrated coefficients and state, Ã held; judged through Ã against the calibrated coefficients on the Schroeder record's second half and in training, no test record): Schroeder second half {:.4} {unit} recalibrated against {:.4} {unit} ({:+.1} %; the rule asks at least −2 %), training {:.4} against {:.4} {unit} ({:+.1} %; at most +1 %): {}; recalibrated terms: {}; recalibration and its judgement {g_seconds:.1} s.",
                scale * half,
                scale * f_half_v,
                100.0 * (half / f_half_v - 1.0),
                scale * train,
                scale * f_train,
                100.0 * (train / f_train - 1.0),
                if passes {
                    "it passes, so the rows read through Ã and the hybrid use the recalibrated coefficients"
                } else {
                    "it does not pass, so the rows read through Ã and the hybrid keep the calibrated coefficients"
                },
                model_terms(&model),
            );
            (
                passes.then_some(Recalibrated {
                    model,
                    x0,
                    train_rmse: train,
                    seconds: g_seconds,
                }),
                text,
            )
        }
        Ok(_) => (
            None,
            "Rule 7 (the grey box recalibrated through Ã): a free run of the recalibrated model failed, so it is not used.".to_string(),
        ),
        Err(e) => (
            None,
            format!("Rule 7 (the grey box recalibrated through Ã): not built: {e:#}."),
        ),
    };
    let scored_tests: Vec<grey::GreyTest> = match &recalibrated {
        Some(r) => tests
            .iter()
            .map(|(name, exp)| grey::GreyTest {
                name: name.clone(),
                sim: grey::filtered_run(spec, &r.model, &filtered.filter, exp, window),
            })
            .collect(),
        None => filtered.tests.clone(),
    };
    let row_label = format!("{label}, {ACQUISITION}");
    // The figure draws the grey box the target note reports: the one read through Ã.
    let mut figure = sims.clone();
    figure.retain(|(l, _)| l != "grey box");
    let before = figure.len();
    push_grey(
        table,
        &mut figure,
        &row_label,
        &scored_tests,
        tests,
        window,
        scale,
        Some(offset),
    );
    if figure.len() > before
        && let Some(last) = figure.last_mut()
    {
        last.0 = "grey box, read through Ã".into();
        *sims = figure;
    }
    let seconds = seconds
        + if recalibrated.is_some() {
            g_seconds
        } else {
            0.0
        };
    table.set_for_model(&row_label, "train_s", grey_seconds + seconds);
    table.set_for_model(&row_label, "threads", 1.0);
    let y_est = row(est.outputs(), 0);
    let plain_train = grey::window_state(spec, &fit.model, est, window)
        .ok()
        .and_then(|x0| grey::free_run(spec, &fit.model, est, &x0).ok())
        .and_then(|s| rmse_after(&y_est, &s, window, scale));
    // Rule 6's judgement, run again here: the Schroeder record's second half, its state
    // fitted to the 50 samples before it.
    let judged = schroeder.map(|e| -> Result<(Option<f64>, Option<f64>)> {
        let start = SCHROEDER_HALF - window;
        let half = e.window(start, e.len())?;
        let y = row(half.outputs(), 0);
        let plain = grey::window_state(spec, &fit.model, &half, window)
            .ok()
            .and_then(|x0| grey::free_run(spec, &fit.model, &half, &x0).ok())
            .and_then(|s| rmse_after(&y, &s, window, scale));
        // Through the filter: Rule 7's judgement of F above, the same run.
        Ok((plain, f_half.map(|v| scale * v)))
    });
    let judged = match judged {
        Some(Ok((Some(a), Some(b)))) => format!(
            "on the Schroeder record's second half (samples {SCHROEDER_HALF}–, state from the {window} before; outside the loader's split) {a:.4} {unit} without the filter and {b:.4} {unit} through it ({:+.1} %)",
            100.0 * (b / a - 1.0)
        ),
        Some(Ok(_)) => "on the Schroeder record's second half: a run failed".into(),
        Some(Err(e)) => format!("on the Schroeder record's second half: not run ({e:#})"),
        None => "the Schroeder record was not read".into(),
    };
    let coefficients = if recalibrated.is_some() {
        "its coefficients recalibrated through Ã (Rule 7, below)"
    } else {
        "its coefficients as calibrated"
    };
    let bands: Vec<String> = filtered
        .filter
        .bands()
        .iter()
        .zip(filtered.filter.standard_errors())
        .map(|((f, g), se)| {
            let se = se.map_or(String::new(), |v| format!(" (±{v:.3})"));
            format!(
                "{f:.1} Hz {:.3}∠{:+.1}°{se}",
                g.norm(),
                g.arg().to_degrees()
            )
        })
        .collect();
    table.note(format!(
        "{row_label} ({OFFICIAL}): the grey box above with {coefficients}, its input deconvolved by the acquisition filter Ã and its simulated output filtered by it (`y = Ã·N(Ã⁻¹·u)`; sysid_core::acquisition). Both channels are recorded by identical HP1430A cards; a filter they share cancels from the linear relation between them but not from the distortion the cubic spring generates above the input's band, which is recorded through it. Ã is one below 190 Hz and, above, the least-squares gain of the measured on the simulated training output per 5-Hz band (training record only, from the coefficients as calibrated; in parentheses each band's standard error of its complex gain, sysid_core::acquisition): {}. Test state fitted to the first {window} recorded outputs, as for the grey box. Training free-run RMSE of the coefficients as calibrated, with the state fitted to the window: {} {unit} without the filter, {:.4} {unit} through it; {judged}. Chosen by Rule 6, written before that second-half run; not blind: the test records' band phases had been looked at. Training wall time: the grey box's calibration plus {seconds:.1} s.",
        bands.join(", "),
        plain_train.map_or("n/a".into(), |v| format!("{v:.4}")),
        scale * filtered.train_rmse,
    ));
    table.note(rule7);
    Some((filtered.filter, recalibrated))
}

/// The grey box recalibrated through the acquisition filter, where Rule 7 adopts it.
pub struct Recalibrated {
    pub model: mmenn::sysid_core::TermModel,
    /// Its training state (on the deconvolved record).
    pub x0: Vec<f64>,
    /// Its training free-run RMSE through the filter (state fitted to the window).
    pub train_rmse: f64,
    /// Wall time of the recalibration and its judgement.
    pub seconds: f64,
}

/// First sample of the Schroeder record's second half (Rules 2–6).
const SCHROEDER_HALF: usize = 65_536;

/// Row label of the published physics with its published coefficients.
pub(super) const REFERENCE_LABEL: &str = "published physics: Janot et al. 2019 reference model, IDIM-LS coefficients (not calibrated here)";

/// EMPS: the symmetric reference model with the published IDIM-LS coefficients as they are
/// (only the state is fitted, as the protocol fits every model's), scored like the grey box:
/// what the physics a user starts from gives before any calibration.
fn reference_rows(
    table: &mut Table,
    est: &Experiment,
    tests: &[(String, Experiment)],
    window: usize,
    scale: f64,
    unit: &str,
    calibrated: &grey::GreyFit,
) {
    let label = REFERENCE_LABEL;
    let fit = grey::emps_spec(3e-4).and_then(|mut spec| {
        spec.free.clear();
        grey::fit_grey(&spec, est, tests, window)
    });
    match fit {
        Ok(f) => {
            push_grey(
                table,
                &mut Vec::new(),
                label,
                &f.tests,
                tests,
                window,
                scale,
                None,
            );
            push_dynonet(table, label, &f, scale);
            table.note(format!(
                "{label} ({OFFICIAL}): `M q'' = gτ·u − Fv·q' − Fc·tanh(q'/ε) − offset` with \
                 M = 95.1089 kg, Fv = 203.5034 N·s/m, Fc = 20.3935 N, offset = −3.1648 N, \
                 gτ = 35.15 N/V (data README), ε = 0.3 mm/s; no coefficient is fitted here, \
                 only each record's state as the protocol says. Training free-run RMSE \
                 {:.4} {unit} from its fitted training state (the calibrated grey box: \
                 {:.4} {unit}): the calibration changes the coefficients by {}.",
                scale * f.train_rmse,
                scale * calibrated.train_rmse,
                relative_changes(&f, calibrated),
            ));
        }
        Err(e) => table.note(format!("{label}: failed: {e:#}")),
    }
}

/// Each calibrated coefficient's change relative to the reference's, `effect +x.x %`.
fn relative_changes(reference: &grey::GreyFit, calibrated: &grey::GreyFit) -> String {
    reference
        .model
        .terms()
        .iter()
        .zip(calibrated.model.terms())
        .map(|(r, c)| {
            format!(
                "{} {:+.1} %",
                r.effect,
                100.0 * (c.coefficient - r.coefficient) / r.coefficient
            )
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// Cascaded Tanks: the test record run from the calibrated training initial state, which
/// the benchmark description says both records share (docs/decisions/
/// tanks-shared-initial-state.md): a reported number beside the official one, never a
/// choice.
fn shared_state_note(
    spec: &grey::GreySpec,
    fit: &grey::GreyFit,
    test: &Experiment,
    window: usize,
    scale: f64,
    unit: &str,
) -> String {
    let y = row(test.outputs(), 0);
    let score = |sim: std::result::Result<Vec<f64>, String>| match sim {
        Ok(v) => match rmse_after(&y, &v, window, scale) {
            Some(r) => format!("{r:.4} {unit}"),
            None => "non-finite".into(),
        },
        Err(m) => format!("failed ({m})"),
    };
    let given = score(grey::free_run(spec, &fit.model, test, &fit.x0));
    let fitted = score(
        grey::window_state_from(spec, &fit.model, test, window, fit.x0.clone())
            .map_err(|e| format!("{e:#}"))
            .and_then(|x0| grey::free_run(spec, &fit.model, test, &x0)),
    );
    format!(
        "Shared initial state (benchmark description, not the loader's protocol; \
         docs/decisions/tanks-shared-initial-state.md): the description says the estimation \
         and test records start from the same unknown state. Run from the grey box's \
         calibrated training initial state with no fit, its test RMSE after {window} samples \
         is {given}; with the state fitted to the first {window} test outputs starting there \
         (instead of from a state guessed from those outputs), {fitted}. The official row \
         and every target comparison use the loader's protocol."
    )
}

/// Seeded starts of the multi-start check (docs/decisions/tanks-multistart-rule.md).
const MULTISTART_SEEDS: u64 = 24;

/// Cascaded Tanks, full run: the reported grey box's calibration against
/// [`MULTISTART_SEEDS`] seeded starts of the same structure on the training record
/// (docs/decisions/tanks-multistart-rule.md): how many reach the reported minimum, whether
/// any is at least 1 % lower (the rule's condition for a multi-start calibration), and the
/// other minima within 1 % of its training cost with their test RMSE — a diagnosis of how
/// far the training record pins the coefficients, run after the choice and never a choice.
fn multistart_note(
    spec: &grey::GreySpec,
    fit: &grey::GreyFit,
    est: &Experiment,
    test: Option<&Experiment>,
    window: usize,
    scale: f64,
    unit: &str,
) -> String {
    let clock = std::time::Instant::now();
    let runs = grey::multistart(spec, est, window, MULTISTART_SEEDS);
    let seconds = clock.elapsed().as_secs_f64();
    let reference = fit.train_rmse;
    let coefficients = |m: &mmenn::sysid_core::TermModel| -> Vec<f64> {
        m.terms().iter().map(|t| t.coefficient).collect()
    };
    let same_as = |a: &grey::GreyFit, b_rmse: f64, b: &[f64]| {
        (a.train_rmse / b_rmse - 1.0).abs() <= 1e-5
            && coefficients(&a.model)
                .iter()
                .zip(b)
                .all(|(x, y)| (x - y).abs() <= 1e-3 * y.abs().max(1e-6))
    };
    let own = coefficients(&fit.model);
    let (mut same, mut lower, mut above, mut failed) = (0, Vec::new(), 0, 0);
    // Other starts within 1 % of the reported cost, grouped into valleys: training RMSE
    // within 0.1 % and every coefficient within 10 % of the valley's first member (a flat
    // valley ends its descents at slightly different points).
    let mut near: Vec<Vec<grey::GreyFit>> = Vec::new();
    let same_valley = |a: &grey::GreyFit, b: &grey::GreyFit| {
        (a.train_rmse / b.train_rmse - 1.0).abs() <= 1e-3
            && coefficients(&a.model)
                .iter()
                .zip(coefficients(&b.model))
                .all(|(x, y)| (x - y).abs() <= 0.1 * y.abs().max(1e-6))
    };
    for (seed, run) in runs {
        let Ok(f) = run else {
            failed += 1;
            continue;
        };
        if !f.train_rmse.is_finite() {
            failed += 1;
        } else if same_as(&f, reference, &own) {
            same += 1;
        } else if f.train_rmse < 0.99 * reference {
            lower.push(format!("seed {seed}: {:.4} {unit}", scale * f.train_rmse));
        } else if f.train_rmse <= 1.01 * reference {
            match near.iter_mut().find(|v| same_valley(&f, &v[0])) {
                Some(v) => v.push(f),
                None => near.push(vec![f]),
            }
        } else {
            above += 1;
        }
    }
    for v in &mut near {
        v.sort_by(|a, b| a.train_rmse.total_cmp(&b.train_rmse));
    }
    near.sort_by(|a, b| a[0].train_rmse.total_cmp(&b[0].train_rmse));
    let y = test.map(|e| row(e.outputs(), 0));
    let on_test = |f: &grey::GreyFit| -> Option<f64> {
        let (e, y) = (test?, y.as_ref()?);
        let x0 = grey::window_state(spec, &f.model, e, window).ok()?;
        let v = grey::free_run(spec, &f.model, e, &x0).ok()?;
        rmse_after(y, &v, window, scale)
    };
    let described: Vec<String> = near
        .iter()
        .map(|v| {
            let scores: Vec<Option<f64>> = v.iter().map(on_test).collect();
            let ok: Vec<f64> = scores.iter().flatten().copied().collect();
            let test_text = if ok.is_empty() {
                "no test run".to_string()
            } else {
                let lo = ok.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = ok.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let failed = scores.len() - ok.len();
                format!(
                    "test {lo:.4}–{hi:.4} {unit}{}",
                    if failed > 0 {
                        format!(" ({failed} run(s) failed)")
                    } else {
                        String::new()
                    }
                )
            };
            format!(
                "a valley reached by {} start(s) at {:.4}–{:.4} {unit} (+{:.2} % or more), \
                 {test_text}; its lowest point's terms: {}",
                v.len(),
                scale * v[0].train_rmse,
                scale * v[v.len() - 1].train_rmse,
                100.0 * (v[0].train_rmse / reference - 1.0),
                grey_terms(&v[0])
            )
        })
        .collect();
    let verdict = if lower.is_empty() {
        "none is 1 % lower, so by the rule the single calibration stands".to_string()
    } else {
        format!(
            "{} at least 1 % lower ({}): the rule's condition for a multi-start calibration \
             holds and the reported grey box is not the lowest training cost",
            lower.len(),
            lower.join(", ")
        )
    };
    format!(
        "Multi-start (docs/decisions/tanks-multistart-rule.md; training record only, the \
         test runs below are a diagnosis after the choice): {MULTISTART_SEEDS} seeded starts \
         of the chosen structure, each coefficient drawn around its start (×exp(z), z ~ \
         N(0, 0.7²); N(0, 0.05²) where it starts at 0), calibrated as the reported one: \
         {same} reach its minimum ({:.4} {unit}); {verdict}; other minima within 1 % of its \
         training cost: {}; {above} end more than 1 % above it and {failed} fail. Minima the \
         training record scores alike can differ on the test record by more than the gap \
         to the published 0.18 V. Wall time {seconds:.1} s.",
        scale * reference,
        if described.is_empty() {
            "none".to_string()
        } else {
            described.join("; ")
        },
    )
}

/// Cascaded Tanks: the grey box's row under the older protocol
/// ([`same_x0_protocol`]): the test record run from the calibrated training initial state,
/// RMSE over all samples (docs/decisions/tanks-older-protocol-rows.md).
fn push_same_x0(
    table: &mut Table,
    label: &str,
    record: &str,
    spec: &grey::GreySpec,
    fit: &grey::GreyFit,
    test: &Experiment,
    scale: f64,
) {
    let protocol = same_x0_protocol();
    let key = [label, record, protocol.as_str()];
    let y = row(test.outputs(), 0);
    match grey::free_run(spec, &fit.model, test, &fit.x0) {
        Ok(v) => match rmse_after(&y, &v, 0, scale) {
            Some(r) => table.push(&key, &[Some(r)]),
            None => table.push_remark(&key, &[None], "diverged (non-finite output)"),
        },
        Err(m) => table.push_remark(&key, &[None], &format!("diverged ({m})")),
    }
}

/// The row of a grey box scored under dynoNet's published EMPS protocol
/// ([`DYNONET_RECORD`]).
pub(super) fn push_dynonet(table: &mut Table, label: &str, fit: &grey::GreyFit, scale: f64) {
    let value = fit
        .train_rmse_all
        .is_finite()
        .then_some(scale * fit.train_rmse_all);
    table.push(
        &[
            label,
            DYNONET_RECORD,
            "dynoNet's published EMPS script: estimation record (DATA_EMPS), free run over \
             every sample from the record's measured start (position y[0], first-difference velocity)",
        ],
        &[value],
    );
}

/// A grey box's calibrated terms for a note.
pub(super) fn grey_terms(fit: &grey::GreyFit) -> String {
    model_terms(&fit.model)
}

/// A term model's terms and coefficients for a note.
fn model_terms(model: &mmenn::sysid_core::TermModel) -> String {
    model
        .terms()
        .iter()
        .map(|t| {
            format!(
                "{} {}: {:+.5e}·{}",
                model.linear().state_names()[t.state],
                t.effect,
                t.coefficient,
                t.expr
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The rows of one grey box's test runs (and, with `figure_offset`, its first test run in
/// the figure, shifted by that offset).
#[allow(clippy::too_many_arguments)]
pub(super) fn push_grey(
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    label: &str,
    runs: &[grey::GreyTest],
    tests: &[(String, Experiment)],
    window: usize,
    scale: f64,
    figure_offset: Option<f64>,
) {
    let protocol = format!(
        "{OFFICIAL}: all training samples at full rate; x0 from the first {window} test samples, RMSE after them"
    );
    for (i, (t, (_, e))) in runs.iter().zip(tests).enumerate() {
        let y = row(e.outputs(), 0);
        let rmse = match &t.sim {
            Ok(v) => rmse_after(&y, v, window, scale),
            Err(m) => {
                table.note(format!("{label} on {}: diverged: {m}", t.name));
                None
            }
        };
        table.push(&[label, &t.name, &protocol], &[rmse]);
        if let (0, Ok(v), Some(offset)) = (i, &t.sim, figure_offset)
            && sims.first().is_some_and(|(_, f)| f.len() == v.len())
        {
            sims.push(("grey box".into(), v.iter().map(|x| x - offset).collect()));
        }
    }
}
