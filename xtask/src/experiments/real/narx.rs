//! NARX networks on the official records, their orders chosen by the data: every
//! `(na, nb)` of a small grid (delay window no longer than the official initialisation
//! window, so the test run uses only the samples the protocol grants) is trained on the
//! first 80 % of the training record and run free over the last 20 %; the order with the
//! lowest held-out free-run RMSE is trained on the whole record and scored on the tests.

use std::time::Instant;

use anyhow::Result;
use mmenn::benchmarks::{Benchmark, BenchmarkData};
use mmenn::fit::{STRESS_FACTOR, stress_input};
use mmenn::sysid_baselines::{
    BaselineError, FrolsConfig, KFOLD_FOLDS, NarxConfig, NarxOrders, NetworkChoice, PolyNarxConfig,
    TermCount, count_by_free_run, fit_frols, fit_narx, fit_poly_narx, poly_narx::Focus,
    refine_narx,
};
use mmenn::sysid_core::{Channel, Dataset, Experiment, InterSample, Model, Prediction};

use super::{OFFICIAL, rmse_after};
use crate::experiments::{FIT_SEED, Mode, row};
use crate::table::Table;

/// Fraction of the training record the order selection trains on.
const SELECT_FRACTION: f64 = 0.8;

/// The grid of `(na, nb)`, the network of the selection runs and of the final fit, and
/// how many training samples the selection uses (`None`: all).
struct Plan {
    grid: Vec<(usize, usize)>,
    select: NetworkChoice,
    last: NetworkChoice,
    select_samples: Option<usize>,
}

fn plan(b: Benchmark, mode: Mode) -> Plan {
    let hidden = |units, restarts| NetworkChoice::Hidden { units, restarts };
    match mode {
        Mode::Quick => Plan {
            grid: vec![(4, 4), (8, 8)],
            select: hidden(3, 1),
            last: hidden(3, 1),
            select_samples: Some(8192),
        },
        Mode::Full => Plan {
            // Delay windows up to the official initialisation window (50 samples; 20 on
            // EMPS), with input windows longer than the output's as well.
            grid: match b {
                Benchmark::Emps => vec![(4, 4), (8, 8), (8, 19), (16, 16), (19, 19)],
                _ => vec![(4, 4), (8, 8), (8, 24), (16, 16), (24, 24)],
            },
            select: hidden(3, 2),
            // 4 restarts: with 2 on Silverbox the final fit took 9.8 s instead of 195 s
            // but test_multisine went from 0.694 to 1.31 mV (full run on cd26143).
            last: hidden(5, 4),
            // The selection on the first 16 384 of the 65 062 Silverbox samples and the
            // first 12 288 of the 24 841 EMPS samples (all of them took 178 s on b801ccd);
            // the final fit uses all of them.
            select_samples: match b {
                Benchmark::Silverbox => Some(16_384),
                Benchmark::Emps => Some(12_288),
                Benchmark::CascadedTanks => None,
            },
        },
    }
}

fn dataset(e: &Experiment, start: usize, len: usize, hold: InterSample) -> Result<Dataset> {
    let x = Experiment::new(
        e.t0() + start as f64 * e.dt(),
        e.dt(),
        e.inputs().columns(start, len).into_owned(),
        e.outputs().columns(start, len).into_owned(),
    )?
    .with_intersample(hold);
    Ok(Dataset::new(
        vec![Channel::new("u")],
        vec![Channel::new("y")],
        vec![x],
    )?)
}

/// One-step training (the simulation focus refines its result with [`refine_narx`]).
fn config(orders: NarxOrders, network: NetworkChoice) -> NarxConfig {
    NarxConfig {
        orders,
        network,
        seed: FIT_SEED,
        ..NarxConfig::default()
    }
}

/// "diverged at …" or the error text, for a failed free run.
fn failure(e: &dyn std::fmt::Display) -> String {
    let text = e.to_string();
    if text.contains("diverg") || text.contains("limits") {
        format!("diverged ({text})")
    } else {
        format!("failed ({text})")
    }
}

/// The order selection's records: how many training samples it uses (`select_samples`,
/// else all), the first 80 % of them to fit, the rest to run free over, and that rest's
/// measured output.
fn selection_split(
    est: &Experiment,
    select_samples: Option<usize>,
) -> Result<(usize, Dataset, Experiment, Vec<f64>)> {
    let hold = est.intersample();
    let used = select_samples.map_or(est.len(), |n| n.min(est.len()));
    let cut = (used as f64 * SELECT_FRACTION) as usize;
    let head = dataset(est, 0, cut, hold)?;
    let tail = dataset(est, cut, used - cut, hold)?.experiments()[0].clone();
    let y_tail = row(tail.outputs(), 0);
    Ok((used, head, tail, y_tail))
}

/// A candidate's held-out free-run RMSE after the window, or why it has none.
fn held_out(
    run: Result<Prediction, BaselineError>,
    y: &[f64],
    window: usize,
    scale: f64,
) -> Result<f64, String> {
    let p = run.map_err(|e| failure(&e))?;
    rmse_after(y, &row(&p.outputs, 0), window, scale)
        .ok_or_else(|| "diverged (non-finite output)".to_string())
}

/// NARX rows (network, then polynomial) under the official protocol; the first test
/// record's free run of each joins the figure when it has the figure's grid (`offset`: what the figure adds back).
pub fn narx_rows(
    data: &BenchmarkData,
    mode: Mode,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
) {
    if let Err(e) = narx_inner(data, mode, table, sims, offset) {
        table.note(format!("NARX: not built: {e:#}"));
    }
    match poly_narx_inner(data, mode, table, sims, offset, None) {
        Ok(chosen) => {
            // docs/decisions/poly-narx-stress-selection.md: a second row whose selection
            // refuses candidates that diverge on the held-out input scaled by 1.5.
            if let Err(e) = poly_narx_inner(data, mode, table, sims, offset, Some(chosen)) {
                table.note(format!(
                    "Polynomial NARX, stress-checked selection: not built: {e:#}"
                ));
            }
        }
        Err(e) => table.note(format!("Polynomial NARX: not built: {e:#}")),
    }
    // docs/decisions/frols-polynomial-narx.md and, beside it,
    // docs/decisions/frols-term-count-by-free-run.md (the number of terms by held-out free
    // run instead of AIC/BIC), from the same FROLS runs, and
    // docs/decisions/frols-count-kfold.md (the number of terms by free run pooled over
    // K folds of the whole selection record).
    frols_rows(data, mode, table, sims, offset);
}

/// A network NARX selected and fitted under one focus, before its rows are written.
struct NarxOutcome {
    focus: Focus,
    orders: NarxOrders,
    /// The networks of the selection runs and of the final fit.
    select_net: NetworkChoice,
    final_net: NetworkChoice,
    fit: mmenn::sysid_baselines::NarxFit,
    /// The chosen order's held-out free-run RMSE in the selection (reporting unit).
    held_out: f64,
    tried: Vec<String>,
    used: usize,
    select_seconds: f64,
    fit_seconds: f64,
}

/// Jacobians at most of the simulation-focus refinement
/// (docs/decisions/narx-simulation-focus.md); the quick run (a regression guard, whose
/// critical path is the Silverbox experiment) keeps 5.
fn simulation_iterations(mode: Mode) -> usize {
    match mode {
        Mode::Quick => 5,
        Mode::Full => 30,
    }
}

/// Marks the network NARX row whose selection scored lower on held-out training data
/// (docs/decisions/narx-simulation-focus.md; the glance table reads it).
pub const NARX_CHOSEN: &str = "the NARX chosen on held-out training data";

/// Both network NARX rows: one-step training, then simulation focus; the one whose chosen
/// order ran free lower on the held-out part of the training record is marked.
fn narx_inner(
    data: &BenchmarkData,
    mode: Mode,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
) -> Result<()> {
    let mut outcomes = Vec::new();
    for (focus, outcome) in narx_select(data, mode)? {
        match outcome {
            Ok(o) => outcomes.push(o),
            Err(e) => table.note(format!("NARX ({}): not built: {e:#}", focus_name(&focus))),
        }
    }
    let chosen = outcomes
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.held_out.total_cmp(&b.1.held_out).then(a.0.cmp(&b.0)))
        .map(|(i, _)| i);
    let seeds = spread_seeds(data.benchmark, mode);
    for (i, o) in outcomes.iter().enumerate() {
        let median_row = o.focus != Focus::Prediction && !seeds.is_empty();
        let reported = narx_emit(
            data,
            o,
            chosen == Some(i) && !median_row,
            table,
            sims,
            offset,
        );
        if median_row {
            let spread = seed_spread(data, o, reported, seeds, simulation_iterations(mode));
            spread_emit(data, o, &spread, chosen == Some(i), table);
        }
    }
    Ok(())
}

/// Marks the row whose number is the median over network seeds
/// (docs/decisions/narx-seed-spread.md); target 4's best black box counts it instead of
/// the single-seed row of the same focus.
pub const SEED_MEDIAN: &str = "median over network seeds";

/// The network seeds the simulation-focus final fit is repeated with, besides
/// [`FIT_SEED`] (docs/decisions/narx-seed-spread.md; EMPS three, its cost amendment).
fn spread_seeds(b: Benchmark, mode: Mode) -> &'static [u64] {
    match (b, mode) {
        (Benchmark::Silverbox, _) | (Benchmark::Emps, Mode::Quick) => &[],
        (Benchmark::CascadedTanks, Mode::Quick) => &[1, 2],
        (Benchmark::CascadedTanks, Mode::Full) => &[1, 2, 3, 4, 5],
        (Benchmark::Emps, Mode::Full) => &[1, 2, 3],
    }
}

/// One seed's final fit: its training free-run RMSE (the refinement's, reporting unit) and
/// each test record's RMSE or why it has none.
struct SeedFit {
    seed: u64,
    train: Result<f64, String>,
    tests: Vec<Result<f64, String>>,
}

/// The final fits over the seeds (the reported one, [`FIT_SEED`], first) and their wall time.
struct Spread {
    fits: Vec<SeedFit>,
    seconds: f64,
}

/// The simulation-focus final fit of `o` repeated with each of `seeds` (same orders,
/// network, data and refinement), scored on the test records; a seed whose fit fails is
/// listed as failed. `reported` holds the test scores of `o`'s own fit (its rows').
fn seed_spread(
    data: &BenchmarkData,
    o: &NarxOutcome,
    reported: Vec<Result<f64, String>>,
    seeds: &[u64],
    iterations: usize,
) -> Spread {
    let (window, (scale, _)) = (
        data.benchmark.init_window(),
        data.benchmark.reporting_unit(),
    );
    let refined_rmse = |fit: &mmenn::sysid_baselines::NarxFit| {
        fit.refinement
            .as_ref()
            .map(|r| scale * r.final_rmse[0])
            .ok_or_else(|| "not refined".to_string())
    };
    let mut fits = vec![SeedFit {
        seed: FIT_SEED,
        train: refined_rmse(&o.fit),
        tests: reported,
    }];
    let clock = Instant::now();
    for &seed in seeds {
        let config = NarxConfig {
            seed,
            ..config(o.orders, o.final_net.clone())
        };
        let fit = fit_narx(&data.estimation, &config).and_then(|mut fit| {
            let r = refine_narx(&mut fit.model, &data.estimation, iterations)?;
            fit.refinement = Some(r);
            Ok(fit)
        });
        fits.push(match fit {
            Ok(fit) => SeedFit {
                seed,
                train: refined_rmse(&fit),
                tests: data
                    .tests
                    .iter()
                    .map(|test| {
                        let e = &test.data.experiments()[0];
                        held_out(fit.model.simulate(e), &row(e.outputs(), 0), window, scale)
                    })
                    .collect(),
            },
            Err(e) => SeedFit {
                seed,
                train: Err(failure(&e)),
                tests: vec![Err(failure(&e)); data.tests.len()],
            },
        });
    }
    Spread {
        fits,
        seconds: clock.elapsed().as_secs_f64(),
    }
}

/// The median of `scores` (a failed or diverged one counts as larger than any number; an
/// even count's median is the mean of the middle two): `None` when the median is a failure.
fn median_score(scores: &[&Result<f64, String>]) -> Option<f64> {
    let mut v: Vec<f64> = scores
        .iter()
        .map(|s| s.as_ref().map_or(f64::INFINITY, |&r| r))
        .collect();
    let m = crate::experiments::median(&mut v);
    m.is_finite().then_some(m)
}

/// The median row over the seeds and its note.
fn spread_emit(
    data: &BenchmarkData,
    o: &NarxOutcome,
    spread: &Spread,
    chosen: bool,
    table: &mut Table,
) {
    let b = data.benchmark;
    let (window, (_, unit)) = (b.init_window(), b.reporting_unit());
    let n = spread.fits.len();
    let mut label = format!(
        "NARX, simulation focus (na = {}, nb = {}, order chosen on held-out data), {SEED_MEDIAN} ({n} fits)",
        o.orders.na, o.orders.nb
    );
    if chosen {
        label = format!("{label}; {NARX_CHOSEN}");
    }
    let protocol = format!(
        "{OFFICIAL}: all training samples at full rate; delay window = the first {} of the {window} initialisation samples, RMSE after them; median of the fits' RMSEs",
        o.orders.max_lag()
    );
    for (t, test) in data.tests.iter().enumerate() {
        let scores: Vec<&Result<f64, String>> = spread.fits.iter().map(|f| &f.tests[t]).collect();
        let failed = scores.iter().filter(|s| s.is_err()).count();
        match median_score(&scores) {
            Some(m) => table.push(&[&label, &test.name, &protocol], &[Some(m)]),
            None => table.push_remark(
                &[&label, &test.name, &protocol],
                &[None],
                &format!("diverged (the median fit: {failed} of {n} runs diverged or failed)"),
            ),
        }
    }
    let show = |r: &Result<f64, String>| match r {
        Ok(v) => format!("{v:.4}"),
        Err(why) => why.split(" (").next().unwrap_or("failed").to_string(),
    };
    let per_seed: Vec<String> = spread
        .fits
        .iter()
        .map(|f| {
            let tests: Vec<String> = f.tests.iter().map(show).collect();
            format!(
                "seed {}: training {} → test {}",
                f.seed,
                show(&f.train),
                tests.join(" / ")
            )
        })
        .collect();
    table.note(format!(
        "NARX, simulation focus, {SEED_MEDIAN} (docs/decisions/narx-seed-spread.md): the \
         final fit above (orders ({}, {}), its network, refined as above) repeated with \
         every network seed listed, the reported seed {FIT_SEED} first; training free-run \
         RMSE (the refinement's) and test RMSE in {unit}: {}. The row gives the median of \
         the test RMSEs (a diverged run counts as larger than any number); it, not the \
         single-seed row, is the NARX target 4's best black box counts{}. Time to \
         accuracy: the repeated fits took {:.1} s wall besides the reported one's.",
        o.orders.na,
        o.orders.nb,
        per_seed.join("; "),
        if chosen {
            " and the glance table shows"
        } else {
            ""
        },
        spread.seconds,
    ));
    table.set_for_model(
        &label,
        "train_s",
        o.select_seconds + o.fit_seconds + spread.seconds,
    );
    table.set_for_model(&label, "threads", rayon::current_num_threads() as f64);
}

fn focus_name(focus: &Focus) -> String {
    match focus {
        Focus::Prediction => "one-step training".into(),
        Focus::Simulation { max_iterations } => format!(
            "simulation focus: the chosen restart refined by free-run error, at most \
             {max_iterations} Jacobians"
        ),
    }
}

/// One focus's order selection as it goes.
#[derive(Default)]
struct Track {
    tried: Vec<String>,
    best: Option<(NarxOrders, f64)>,
    seconds: f64,
}

impl Track {
    fn record(&mut self, orders: NarxOrders, scored: Result<f64, String>, unit: &str) {
        let (na, nb) = (orders.na, orders.nb);
        match scored {
            Ok(r) => {
                self.tried.push(format!("({na}, {nb}): {r:.4} {unit}"));
                if self.best.is_none_or(|(_, b)| r < b) {
                    self.best = Some((orders, r));
                }
            }
            Err(why) => self.tried.push(format!("({na}, {nb}): {why}")),
        }
    }
}

/// The order selection and final fit of both rows. The simulation focus trains the same
/// networks (same data, orders, restarts and seeds) and refines the chosen one, so each
/// one-step network is trained once and refined on a copy: `fit_narx` with
/// [`Focus::Simulation`] is `fit_narx` with [`Focus::Prediction`] then
/// [`refine_narx`]. Each row's time counts the one-step training it rests on.
fn narx_select(data: &BenchmarkData, mode: Mode) -> Result<Vec<(Focus, Result<NarxOutcome>)>> {
    let b = data.benchmark;
    let window = b.init_window();
    let (scale, unit) = b.reporting_unit();
    let est = &data.estimation.experiments()[0];
    let Plan {
        grid,
        select: small,
        last,
        select_samples,
    } = plan(b, mode);
    let iterations = simulation_iterations(mode);
    let simulation = Focus::Simulation {
        max_iterations: iterations,
    };
    let clock = Instant::now();
    let (used, head, tail, y_tail) = selection_split(est, select_samples)?;
    let split_seconds = clock.elapsed().as_secs_f64();
    let (mut pred, mut sim) = (Track::default(), Track::default());
    pred.seconds = split_seconds;
    sim.seconds = split_seconds;
    for &(na, nb) in &grid {
        let orders = NarxOrders { na, nb, nk: 1 };
        if orders.max_lag() > window {
            continue;
        }
        let clock = Instant::now();
        let fit = fit_narx(&head, &config(orders, small.clone()));
        let one_step = clock.elapsed().as_secs_f64();
        pred.seconds += one_step;
        sim.seconds += one_step;
        match fit {
            Ok(f) => {
                let clock = Instant::now();
                pred.record(
                    orders,
                    held_out(f.model.simulate(&tail), &y_tail, window, scale),
                    unit,
                );
                pred.seconds += clock.elapsed().as_secs_f64();
                let clock = Instant::now();
                let mut m = f.model;
                let refined =
                    refine_narx(&mut m, &head, iterations).and_then(|_| m.simulate(&tail));
                sim.record(orders, held_out(refined, &y_tail, window, scale), unit);
                sim.seconds += clock.elapsed().as_secs_f64();
            }
            Err(e) => {
                pred.record(orders, Err(failure(&e)), unit);
                sim.record(orders, Err(failure(&e)), unit);
            }
        }
    }
    let mut out = Vec::new();
    let mut one_step_final: Option<(
        NarxOrders,
        NetworkChoice,
        mmenn::sysid_baselines::NarxFit,
        f64,
    )> = None;
    for (focus, track) in [(Focus::Prediction, pred), (simulation, sim)] {
        let outcome = (|| -> Result<NarxOutcome> {
            let Some((orders, held_out)) = track.best else {
                anyhow::bail!("every order of the grid failed: {}", track.tried.join("; "));
            };
            // The simulation focus's final fit trains the network its selection scored
            // (docs/decisions/narx-simulation-focus.md, cost amendment).
            let network = final_network(&focus, &small, &last);
            let (mut fit, mut fit_seconds) = match &one_step_final {
                Some((o, n, f, secs)) if *o == orders && *n == network => (f.clone(), *secs),
                _ => {
                    let clock = Instant::now();
                    let f = fit_narx(&data.estimation, &config(orders, network.clone()))?;
                    (f, clock.elapsed().as_secs_f64())
                }
            };
            if focus == Focus::Prediction {
                one_step_final = Some((orders, network.clone(), fit.clone(), fit_seconds));
            } else {
                let clock = Instant::now();
                let r = refine_narx(&mut fit.model, &data.estimation, iterations)?;
                fit.refinement = Some(r);
                fit_seconds += clock.elapsed().as_secs_f64();
            }
            Ok(NarxOutcome {
                focus,
                orders,
                select_net: small.clone(),
                final_net: network,
                fit,
                held_out,
                tried: track.tried,
                used,
                select_seconds: track.seconds,
                fit_seconds,
            })
        })();
        out.push((focus, outcome));
    }
    Ok(out)
}

/// The network of a row's final fit: the one-step row trains the plan's larger final
/// network; the simulation focus trains the network its selection scored (refined), so
/// the model it reports is of the kind the held-out run validated.
fn final_network(focus: &Focus, select: &NetworkChoice, last: &NetworkChoice) -> NetworkChoice {
    match focus {
        Focus::Prediction => last.clone(),
        Focus::Simulation { .. } => select.clone(),
    }
}

/// The row of `o`'s fit on each test record, its note and its time; returns each test
/// record's score (RMSE, or why it has none).
fn narx_emit(
    data: &BenchmarkData,
    o: &NarxOutcome,
    chosen: bool,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
) -> Vec<Result<f64, String>> {
    let b = data.benchmark;
    let window = b.init_window();
    let est = &data.estimation.experiments()[0];
    let orders = o.orders;
    let name = match o.focus {
        Focus::Prediction => "NARX",
        Focus::Simulation { .. } => "NARX, simulation focus",
    };
    let mut label = format!(
        "{name} (na = {}, nb = {}, order chosen on held-out data)",
        orders.na, orders.nb
    );
    if chosen {
        label = format!("{label}; {NARX_CHOSEN}");
    }
    let protocol = format!(
        "{OFFICIAL}: all training samples at full rate; delay window = the first {} of the {window} initialisation samples, RMSE after them",
        orders.max_lag()
    );
    let scores = test_rows(
        &o.fit.model,
        data,
        &label,
        &protocol,
        name,
        table,
        sims,
        offset,
    );
    let net = |c: &NetworkChoice| match c {
        NetworkChoice::Hidden { units, restarts } => {
            format!("{units} hidden × {restarts} restarts")
        }
        NetworkChoice::Sweep { .. } => "a sizing sweep".into(),
    };
    let refined = o.fit.refinement.as_ref().map_or(String::new(), |r| {
        format!(
            "; the final fit's refinement: {} Jacobians, training free-run RMSE {:.4e} → \
             {:.4e} (recorded units)",
            r.iterations, r.start_rmse[0], r.final_rmse[0]
        )
    });
    table.note(format!(
        "{name} ({OFFICIAL}; {}): orders chosen by the data — each (na, nb) of the grid with a delay \
         window no longer than the {window}-sample initialisation window, nk = 1, trained \
         ({}) on the first {:.0} % of the first {} of the {} training samples and run free over the rest of them \
         (held-out free-run RMSE after {window} samples: {}); chosen (na, nb) = ({}, {}), \
         trained on all training samples ({}){refined}.{} Time to accuracy: order selection \
         {:.1} s, final fit {:.1} s wall, rayon pool of {} threads \
         on 2 shared cores.",
        focus_name(&o.focus),
        net(&o.select_net),
        100.0 * SELECT_FRACTION,
        o.used,
        est.len(),
        o.tried.join(", "),
        orders.na,
        orders.nb,
        net(&o.final_net),
        if chosen {
            " Of the two network NARX rows, this one's chosen order ran free lower on the \
             held-out part of the training record, so the glance table shows it \
             (docs/decisions/narx-simulation-focus.md)."
        } else {
            ""
        },
        o.select_seconds,
        o.fit_seconds,
        rayon::current_num_threads(),
    ));
    table.set_for_model(&label, "train_s", o.select_seconds + o.fit_seconds);
    table.set_for_model(&label, "threads", rayon::current_num_threads() as f64);
    scores
}

/// Each test record's free run of `model` as a row (or its divergence as a remark); the
/// first test record's run joins the figure when it has the figure's grid. Returns each
/// record's score as [`held_out`] gives it.
#[allow(clippy::too_many_arguments)]
fn test_rows<M: Model<Error = BaselineError>>(
    model: &M,
    data: &BenchmarkData,
    label: &str,
    protocol: &str,
    figure_name: &str,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
) -> Vec<Result<f64, String>> {
    let b = data.benchmark;
    let (window, (scale, _)) = (b.init_window(), b.reporting_unit());
    let mut scores = Vec::with_capacity(data.tests.len());
    for (i, test) in data.tests.iter().enumerate() {
        let e = &test.data.experiments()[0];
        let y = row(e.outputs(), 0);
        let run = model.simulate(e);
        match &run {
            Ok(p) => {
                let v = row(&p.outputs, 0);
                match rmse_after(&y, &v, window, scale) {
                    Some(r) => table.push(&[label, &test.name, protocol], &[Some(r)]),
                    None => table.push_remark(
                        &[label, &test.name, protocol],
                        &[None],
                        "diverged (non-finite output)",
                    ),
                }
                if i == 0 && sims.first().is_some_and(|(_, f)| f.len() == v.len()) {
                    sims.push((figure_name.into(), v.iter().map(|x| x - offset).collect()));
                }
            }
            Err(BaselineError::Diverged {
                sample,
                channel,
                value,
            }) => table.push_remark(
                &[label, &test.name, protocol],
                &[None],
                &format!(
                    "diverged at t = {:.3} s (sample {sample}; {channel} = {value:.3e})",
                    e.time(*sample) - e.t0()
                ),
            ),
            Err(err) => table.push_remark(&[label, &test.name, protocol], &[None], &failure(err)),
        }
        scores.push(held_out(run, &y, window, scale));
    }
    scores
}

/// The polynomial NARX candidates (docs/decisions/polynomial-narx-baseline.md):
/// `(na = nb, degree, nonlinear lags)`.
fn poly_grid(mode: Mode) -> Vec<(usize, usize, usize)> {
    let (delays, degrees, nls): (&[usize], &[usize], &[usize]) = match mode {
        Mode::Quick => (&[2, 4], &[3], &[1, 2]),
        Mode::Full => (&[2, 3, 4, 6, 8], &[2, 3], &[1, 2, 3]),
    };
    let mut grid = Vec::new();
    for &d in delays {
        for &deg in degrees {
            for &nl in nls {
                if nl <= d {
                    grid.push((d, deg, nl));
                }
            }
        }
    }
    grid
}

/// Polynomial NARX rows under the official protocol: every candidate of [`poly_grid`]
/// fitted on the first 80 % of the samples the network NARX's order selection uses and run
/// free over the rest; the best is refitted on the whole training record. With
/// `stress_after` (the unconstrained selection's choice), the stress-checked selection of
/// docs/decisions/poly-narx-stress-selection.md: a candidate whose held-out free run
/// diverges with the input scaled by [`STRESS_FACTOR`] is not chosen, and no row is added
/// when it chooses what the unconstrained selection chose. Returns the choice.
fn poly_narx_inner(
    data: &BenchmarkData,
    mode: Mode,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
    stress_after: Option<(usize, usize, usize)>,
) -> Result<(usize, usize, usize)> {
    let b = data.benchmark;
    let window = b.init_window();
    let (scale, unit) = b.reporting_unit();
    let est = &data.estimation.experiments()[0];
    let clock = Instant::now();
    let (used, head, tail, y_tail) = selection_split(est, plan(b, mode).select_samples)?;
    let tail = &tail;
    let tail_stressed = match stress_after {
        Some(_) => Some(stress_input(tail)?),
        None => None,
    };
    // A candidate's held-out score; under the stress check, an error when its free run on
    // the stressed held-out input fails.
    let score = |c: &PolyNarxConfig| -> Result<f64, String> {
        let fit = fit_poly_narx(&head, c).map_err(|e| failure(&e))?;
        let r = held_out(fit.model.simulate(tail), &y_tail, window, scale)?;
        if let Some(st) = &tail_stressed {
            fit.model.simulate(st).map_err(|e| {
                format!("refused: its free run with the input scaled by {STRESS_FACTOR} fails ({}; {r:.4} unscaled)", failure(&e))
            })?;
        }
        Ok(r)
    };
    let max_iterations = match mode {
        Mode::Quick => 10,
        Mode::Full => 30,
    };
    let config = |d: usize, degree, nl| PolyNarxConfig {
        orders: NarxOrders::symmetric(d),
        degree,
        nonlinear_lags: nl,
        focus: Focus::Simulation { max_iterations },
        // docs/decisions/poly-narx-hold.md: holding the monomials at the training box made
        // every record worse (the cubic is what bounds the response); not adopted.
        hold: false,
        ..PolyNarxConfig::default()
    };
    let mut tried = Vec::new();
    let mut best: Option<((usize, usize, usize), f64)> = None;
    for (d, degree, nl) in poly_grid(mode) {
        if d > window {
            continue;
        }
        match score(&config(d, degree, nl)) {
            Ok(r) => {
                tried.push(format!("({d}, {degree}, {nl}): {r:.4}"));
                if best.is_none_or(|(_, b)| r < b) {
                    best = Some(((d, degree, nl), r));
                }
            }
            Err(why) => tried.push(format!("({d}, {degree}, {nl}): {why}")),
        }
    }
    // The grid's edge (docs/decisions/polynomial-narx-baseline.md, addendum): a choice at
    // the largest delay is tried at 1.5× the delay while the held-out error falls.
    let largest = poly_grid(mode)
        .iter()
        .map(|c| c.0)
        .filter(|&d| d <= window)
        .max()
        .unwrap_or(0);
    while let Some(((d0, degree, nl), r0)) = best {
        if d0 < largest {
            break;
        }
        let d = (d0 * 3).div_ceil(2);
        if d > window {
            break;
        }
        match score(&config(d, degree, nl)) {
            Ok(r) => {
                tried.push(format!("({d}, {degree}, {nl}): {r:.4}"));
                if r >= r0 {
                    break;
                }
                best = Some(((d, degree, nl), r));
            }
            Err(why) => {
                tried.push(format!("({d}, {degree}, {nl}): {why}"));
                break;
            }
        }
    }
    let select_seconds = clock.elapsed().as_secs_f64();
    let Some(((d, degree, nl), _)) = best else {
        anyhow::bail!("every candidate failed: {}", tried.join("; "));
    };
    if stress_after == Some((d, degree, nl)) {
        table.note(format!(
            "Polynomial NARX, stress-checked selection (docs/decisions/\
             poly-narx-stress-selection.md: a candidate whose held-out free run fails with the \
             input scaled by {STRESS_FACTOR} about its mean is not chosen): it chooses ({d}, \
             {degree}, {nl}) as the row above does, so no second row (held-out, {unit}: {}).",
            tried.join(", ")
        ));
        return Ok((d, degree, nl));
    }
    let clock = Instant::now();
    let fit = fit_poly_narx(&data.estimation, &config(d, degree, nl))?;
    let fit_seconds = clock.elapsed().as_secs_f64();
    let label = match stress_after {
        None => {
            format!("polynomial NARX (na = nb = {d}, degree {degree}, chosen on held-out data)")
        }
        Some(_) => format!(
            "polynomial NARX, stress-checked selection (na = nb = {d}, degree {degree}, chosen \
             on held-out data)"
        ),
    };
    let protocol = format!(
        "{OFFICIAL}: all training samples at full rate; delay window = the first {d} of the {window} initialisation samples, RMSE after them"
    );
    test_rows(
        &fit.model,
        data,
        &label,
        &protocol,
        match stress_after {
            None => "polynomial NARX",
            Some(_) => "polynomial NARX (stress-checked)",
        },
        table,
        sims,
        offset,
    );
    let intro = match stress_after {
        None => format!("Polynomial NARX ({OFFICIAL}; docs/decisions/polynomial-narx-baseline.md)"),
        Some(_) => format!(
            "Polynomial NARX, stress-checked selection ({OFFICIAL}; docs/decisions/\
             poly-narx-stress-selection.md: as the row above, but a candidate whose held-out \
             free run fails with the input scaled by {STRESS_FACTOR} about its mean is not chosen)"
        ),
    };
    table.note(format!(
        "{intro}: \
         y(k) = a constant + every output lag and input tap (na = nb, nk = 1) + every monomial \
         of degree 2..=degree in the newest `nl` output lags and input taps, variables \
         centred and scaled by the training record (not held at their training range: \
         docs/decisions/poly-narx-hold.md), coefficients by one-step least squares \
         (QR), then by free-run error over the same samples (Levenberg–Marquardt, exact \
         sensitivities, at most {max_iterations} Jacobians); candidates (na = nb, degree, nl) fitted on the first {:.0} % of the first \
         {used} of the {} training samples and run free over the rest (held-out free-run \
         RMSE after {window} samples, {unit}: {}; a choice at the grid's largest delay is \
         tried again at 1.5× the delay while its held-out error falls); chosen ({d}, {degree}, {nl}): {} terms, \
         rank {}, refitted on all training samples (training free-run RMSE {}). Time to accuracy: selection \
         {select_seconds:.1} s, final fit {fit_seconds:.1} s wall, 1 thread.",
        100.0 * SELECT_FRACTION,
        est.len(),
        tried.join(", "),
        fit.model.n_terms(),
        fit.rank,
        fit.refinement.as_ref().map_or("not refined".into(), |r| format!(
            "{:.4} → {:.4} {unit}",
            r.start_rmse[0] * scale,
            r.final_rmse[0] * scale
        )),
    ));
    table.set_for_model(&label, "train_s", select_seconds + fit_seconds);
    table.set_for_model(&label, "threads", 1.0);
    Ok((d, degree, nl))
}

/// How close (relative) to a FROLS run's best held-out free run its chosen term count
/// must come (docs/decisions/frols-term-count-by-free-run.md).
const FREE_RUN_COUNT_TOLERANCE: f64 = 0.02;

/// The sparse polynomial NARX candidates (docs/decisions/frols-polynomial-narx.md):
/// `(na = nb, degree, nonlinear lags)` and the cap on the number of terms.
fn frols_grid(mode: Mode) -> (Vec<(usize, usize, usize)>, usize) {
    let (delays, degrees, nls, cap): (&[usize], &[usize], &[usize], usize) = match mode {
        Mode::Quick => (&[2, 4], &[3], &[1, 2], 20),
        Mode::Full => (&[2, 4, 8, 16, 32], &[2, 3], &[1, 2, 4], 40),
    };
    let mut grid = Vec::new();
    for &d in delays {
        for &deg in degrees {
            for &nl in nls {
                if nl <= d {
                    grid.push((d, deg, nl));
                }
            }
        }
    }
    (grid, cap)
}

/// The three FROLS rows: the number of terms by AIC or BIC (docs/decisions/
/// frols-polynomial-narx.md), by held-out free run (docs/decisions/
/// frols-term-count-by-free-run.md), or by free run pooled over K folds (docs/decisions/
/// frols-count-kfold.md).
#[derive(Debug, Clone, Copy, PartialEq)]
enum FrolsRow {
    Criterion,
    FreeRun,
    KFold,
}

/// One FROLS row's selection: every candidate's held-out score (or why it has none), the
/// best candidate `(d, degree, nl, count)` with its score, and the wall time the row's
/// selection takes alone (the FROLS runs both rows share plus its own free runs).
#[derive(Default)]
struct FrolsChoice {
    tried: Vec<String>,
    best: Option<((usize, usize, usize, TermCount), f64)>,
    seconds: f64,
}

impl FrolsChoice {
    /// Keep `candidate` if it beats the best so far (ties: the first in grid order).
    fn consider(&mut self, candidate: (usize, usize, usize, TermCount), r: f64) {
        if self.best.is_none_or(|(_, b)| r < b) {
            self.best = Some((candidate, r));
        }
    }

    /// One FROLS run's prefix scores (held-out or pooled K-fold; recorded units times
    /// `scale`): its count by [`count_by_free_run`] considered, every count's score listed in
    /// `tried`; `where_failed` ends the line when no count is eligible.
    #[allow(clippy::too_many_arguments)]
    fn consider_scores(
        &mut self,
        (d, degree, nl): (usize, usize, usize),
        fit: &mmenn::sysid_baselines::frols::FrolsFit,
        scores: mmenn::sysid_baselines::Result<Vec<mmenn::sysid_baselines::PrefixScore>>,
        scale: f64,
        where_failed: &str,
    ) {
        let selected = fit.ranking.len();
        let scores = match scores {
            Ok(s) => s,
            Err(e) => {
                self.tried
                    .push(format!("({d}, {degree}, {nl}): {}", failure(&e)));
                return;
            }
        };
        let pairs: Vec<(usize, Option<f64>)> = scores
            .iter()
            .map(|s| (s.n, s.value().map(|v| scale * v)))
            .collect();
        let by_count: Vec<String> = pairs
            .iter()
            .map(|(_, r)| r.map_or("×".into(), |v| format!("{v:.3}")))
            .collect();
        match count_by_free_run(&pairs, FREE_RUN_COUNT_TOLERANCE) {
            Some((n, r)) => {
                self.tried.push(format!(
                    "({d}, {degree}, {nl}) {n} of {selected} selected of {}: {r:.4} \
                     [counts 1–{selected}: {}]",
                    fit.candidates,
                    by_count.join(" ")
                ));
                self.consider((d, degree, nl, TermCount::Fixed(n)), r);
            }
            None => self.tried.push(format!(
                "({d}, {degree}, {nl}): every prefix of its {selected} terms failed in free \
                 run{where_failed}"
            )),
        }
    }
}

/// The FROLS rows' selections. The first two come from one FROLS run per candidate of
/// [`frols_grid`] on the first 80 % of the samples the other NARX selections use: the AIC
/// and the BIC count of each run (docs/decisions/frols-polynomial-narx.md) and the smallest
/// prefix count within 2 % of the run's best (docs/decisions/
/// frols-term-count-by-free-run.md), each run free over the rest. The K-fold row's
/// FROLS runs rank on all the samples the selections use (docs/decisions/
/// frols-count-kfold.md, rule 1), so it has runs of its own: each run's smallest prefix
/// count within 2 % of its best pooled K-fold free-run score.
struct FrolsSelection {
    used: usize,
    cap: usize,
    /// Wall time of the FROLS runs the first two rows share.
    shared_seconds: f64,
    criterion: FrolsChoice,
    free_run: FrolsChoice,
    /// Wall time of the K-fold row's own FROLS runs (of its selection time).
    kfold_runs_seconds: f64,
    kfold: FrolsChoice,
}

fn frols_config(d: usize, degree: usize, nl: usize, cap: usize, count: TermCount) -> FrolsConfig {
    FrolsConfig {
        orders: NarxOrders::symmetric(d),
        degree,
        nonlinear_lags: nl,
        max_terms: cap,
        count,
        ..FrolsConfig::default()
    }
}

fn frols_selection(data: &BenchmarkData, mode: Mode) -> Result<FrolsSelection> {
    let b = data.benchmark;
    let window = b.init_window();
    let (scale, _) = b.reporting_unit();
    let est = &data.estimation.experiments()[0];
    let (used, head, tail, y_tail) = selection_split(est, plan(b, mode).select_samples)?;
    let whole = dataset(est, 0, used, est.intersample())?;
    let (grid, cap) = frols_grid(mode);
    let (mut criterion, mut free_run) = (FrolsChoice::default(), FrolsChoice::default());
    let mut kfold = FrolsChoice::default();
    let (mut shared_seconds, mut kfold_runs_seconds) = (0.0, 0.0);
    for (d, degree, nl) in grid {
        if d > window {
            continue;
        }
        kfold_candidate(
            &whole,
            (d, degree, nl, cap),
            window,
            scale,
            &mut kfold,
            &mut kfold_runs_seconds,
        );
        let clock = Instant::now();
        let fit = fit_frols(&head, &frols_config(d, degree, nl, cap, TermCount::Aic));
        shared_seconds += clock.elapsed().as_secs_f64();
        let fit = match fit {
            Ok(f) => f,
            Err(e) => {
                let why = format!("({d}, {degree}, {nl}): {}", failure(&e));
                criterion.tried.push(why.clone());
                free_run.tried.push(why);
                continue;
            }
        };
        let clock = Instant::now();
        for count in [TermCount::Aic, TermCount::Bic] {
            let n = fit.count(count);
            let what = format!(
                "({d}, {degree}, {nl}) {}, {n} of {}",
                count.label(),
                fit.candidates
            );
            match held_out(
                fit.model_with(n).and_then(|m| m.simulate(&tail)),
                &y_tail,
                window,
                scale,
            ) {
                Ok(r) => {
                    criterion.tried.push(format!("{what}: {r:.4}"));
                    criterion.consider((d, degree, nl, count), r);
                }
                Err(why) => criterion.tried.push(format!("{what}: {why}")),
            }
        }
        criterion.seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        free_run.consider_scores(
            (d, degree, nl),
            &fit,
            fit.free_run_scores(std::slice::from_ref(&tail), window),
            scale,
            "",
        );
        free_run.seconds += clock.elapsed().as_secs_f64();
    }
    criterion.seconds += shared_seconds;
    free_run.seconds += shared_seconds;
    Ok(FrolsSelection {
        used,
        cap,
        shared_seconds,
        criterion,
        free_run,
        kfold_runs_seconds,
        kfold,
    })
}

/// One candidate `(d, degree, nl, cap)` of the K-fold row (docs/decisions/
/// frols-count-kfold.md): FROLS ranks on the whole selection record `whole`, every prefix
/// count is scored by [`FrolsFit::kfold_scores`](mmenn::sysid_baselines::FrolsFit::kfold_scores)
/// over [`KFOLD_FOLDS`] folds (each fold's first `window` samples its delay window), and
/// the run's count is the smallest within the 2 % tolerance of its best pooled score. Adds
/// the candidate's line (every count's pooled score, × where it has none) to `choice`, and
/// the wall time to `choice.seconds` (of it the FROLS run to `runs_seconds`).
fn kfold_candidate(
    whole: &Dataset,
    (d, degree, nl, cap): (usize, usize, usize, usize),
    window: usize,
    scale: f64,
    choice: &mut FrolsChoice,
    runs_seconds: &mut f64,
) {
    let clock = Instant::now();
    let fit = fit_frols(whole, &frols_config(d, degree, nl, cap, TermCount::Aic));
    let run = clock.elapsed().as_secs_f64();
    *runs_seconds += run;
    choice.seconds += run;
    let fit = match fit {
        Ok(f) => f,
        Err(e) => {
            choice
                .tried
                .push(format!("({d}, {degree}, {nl}): {}", failure(&e)));
            return;
        }
    };
    let clock = Instant::now();
    choice.consider_scores(
        (d, degree, nl),
        &fit,
        fit.kfold_scores(whole, KFOLD_FOLDS, window),
        scale,
        " on some fold",
    );
    choice.seconds += clock.elapsed().as_secs_f64();
}

/// Both FROLS rows; a failure of either is a note.
fn frols_rows(
    data: &BenchmarkData,
    mode: Mode,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
) {
    let selection = match frols_selection(data, mode) {
        Ok(s) => s,
        Err(e) => {
            table.note(format!("Polynomial NARX, FROLS (sparse): not built: {e:#}"));
            table.note(format!(
                "Polynomial NARX, FROLS, terms by free run: not built: {e:#}"
            ));
            table.note(format!(
                "Polynomial NARX, FROLS, terms by K-fold free run: not built: {e:#}"
            ));
            return;
        }
    };
    for (row, what) in [
        (FrolsRow::Criterion, "Polynomial NARX, FROLS (sparse)"),
        (
            FrolsRow::FreeRun,
            "Polynomial NARX, FROLS, terms by free run",
        ),
        (
            FrolsRow::KFold,
            "Polynomial NARX, FROLS, terms by K-fold free run",
        ),
    ] {
        if let Err(e) = frols_row(data, &selection, row, table, sims, offset) {
            table.note(format!("{what}: not built: {e:#}"));
        }
    }
}

/// One FROLS row from its selection: the winner's FROLS run again on the whole training
/// record (its count by the same criterion, or its first `n` terms), scored on the tests
/// as the dense row is.
fn frols_row(
    data: &BenchmarkData,
    selection: &FrolsSelection,
    row: FrolsRow,
    table: &mut Table,
    sims: &mut Vec<(String, Vec<f64>)>,
    offset: f64,
) -> Result<()> {
    let b = data.benchmark;
    let window = b.init_window();
    let (scale, unit) = b.reporting_unit();
    let est = &data.estimation.experiments()[0];
    let (used, cap) = (selection.used, selection.cap);
    let by_free_run = row == FrolsRow::FreeRun;
    let choice = match row {
        FrolsRow::Criterion => &selection.criterion,
        FrolsRow::FreeRun => &selection.free_run,
        FrolsRow::KFold => &selection.kfold,
    };
    let select_seconds = choice.seconds;
    let Some(((d, degree, nl, count), _)) = choice.best else {
        anyhow::bail!("every candidate failed: {}", choice.tried.join("; "));
    };
    let clock = Instant::now();
    let fit = fit_frols(&data.estimation, &frols_config(d, degree, nl, cap, count))?;
    let fit_seconds = clock.elapsed().as_secs_f64();
    let label = match row {
        FrolsRow::FreeRun => format!(
            "polynomial NARX, FROLS (sparse) (na = nb = {d}, degree {degree}, {} terms by held-out free run)",
            fit.n_terms
        ),
        FrolsRow::KFold => format!(
            "polynomial NARX, FROLS (sparse) (na = nb = {d}, degree {degree}, {} terms by K-fold free run)",
            fit.n_terms
        ),
        FrolsRow::Criterion => format!(
            "polynomial NARX, FROLS (sparse) (na = nb = {d}, degree {degree}, {} terms by {}, chosen on held-out data)",
            fit.n_terms,
            count.label()
        ),
    };
    let protocol = format!(
        "{OFFICIAL}: all training samples at full rate; delay window = the first {d} of the {window} initialisation samples, RMSE after them"
    );
    test_rows(
        &fit.model,
        data,
        &label,
        &protocol,
        match row {
            FrolsRow::FreeRun => "polynomial NARX, FROLS, terms by free run",
            FrolsRow::KFold => "polynomial NARX, FROLS, terms by K-fold free run",
            FrolsRow::Criterion => "polynomial NARX, FROLS",
        },
        table,
        sims,
        offset,
    );
    let terms: Vec<String> = fit.ranking[..fit.n_terms]
        .iter()
        .zip(&fit.coefficients)
        .map(|(r, c)| format!("{c:+.5e}·{} ({:.2e})", r.name, r.err))
        .collect();
    let timing = match row {
        FrolsRow::KFold => format!(
            "Time to accuracy: selection {select_seconds:.1} s (of it {:.1} s its own FROLS runs \
             on the whole selection record, the rest the per-fold refits and free runs), final \
             fit {fit_seconds:.1} s wall, 1 thread.",
            selection.kfold_runs_seconds
        ),
        _ => format!(
            "Time to accuracy: selection {select_seconds:.1} s (of it {:.1} s the FROLS runs both \
             FROLS rows share, run once), final fit {fit_seconds:.1} s wall, 1 thread.",
            selection.shared_seconds
        ),
    };
    if row == FrolsRow::KFold {
        table.note(format!(
            "Polynomial NARX, FROLS, terms by K-fold free run ({OFFICIAL}; \
             docs/decisions/frols-count-kfold.md): the FROLS row's candidates (at most {cap} \
             terms), but each FROLS run ranks its terms on all the first {used} of the {} \
             training samples, which are cut into {KFOLD_FOLDS} contiguous folds; for each fold \
             and each count n, the first n terms are refitted by least squares on the rows of \
             the other folds (rows with a sample in the fold dropped) and run free \
             over the fold from its measured start, and the squared errors after each fold's \
             first {window} samples are pooled; each run keeps the smallest count whose pooled \
             free-run RMSE is within {:.0} % of its best (a count whose free run fails on any \
             fold is not eligible), instead of AIC or BIC (pooled K-fold free-run RMSE of each \
             run's count, {unit}, then in brackets every count's, × where it has none: {}); \
             chosen ({d}, {degree}, {nl}) with {} terms, FROLS run again on all training \
             samples ({} rows, {} candidates) keeping its first {} terms: {}; one-step RMSE \
             {:.3e} {unit}. {timing}",
            est.len(),
            100.0 * FREE_RUN_COUNT_TOLERANCE,
            choice.tried.join(", "),
            fit.n_terms,
            fit.rows,
            fit.candidates,
            fit.n_terms,
            terms.join(" "),
            fit.one_step_rmse * scale,
        ));
    } else if by_free_run {
        table.note(format!(
            "Polynomial NARX, FROLS, terms by held-out free run ({OFFICIAL}; \
             docs/decisions/frols-term-count-by-free-run.md): the FROLS row's candidates and \
             term ranking (at most {cap} terms), but each FROLS run keeps the smallest number \
             of its first terms whose free run over the held-out rest is within {:.0} % of its \
             best (a count whose free run fails is not eligible), instead of AIC or BIC; \
             selected on the first {:.0} % of the first {used} of the {} training samples \
             (held-out free-run RMSE after {window} samples of each run's count, {unit}, then \
             in brackets every count's, × where its free run failed: {}); chosen ({d}, \
             {degree}, {nl}) with {} terms, FROLS run again on all training samples ({} rows, \
             {} candidates) keeping its first {} terms: {}; one-step RMSE {:.3e} {unit}. \
             {timing}",
            100.0 * FREE_RUN_COUNT_TOLERANCE,
            100.0 * SELECT_FRACTION,
            est.len(),
            choice.tried.join(", "),
            fit.n_terms,
            fit.rows,
            fit.candidates,
            fit.n_terms,
            terms.join(" "),
            fit.one_step_rmse * scale,
        ));
    } else {
        table.note(format!(
            "Polynomial NARX, FROLS (sparse) ({OFFICIAL}; docs/decisions/frols-polynomial-narx.md): \
             the dense polynomial NARX's terms for (na = nb, nk = 1, degree, nl) as candidates, \
             variables divided by their RMS (not centred), terms chosen one at a time by Forward \
             Regression Orthogonal Least Squares with the Error Reduction Ratio (Billings 2013, \
             ch. 3; modified Gram–Schmidt), their number by AIC or BIC on the one-step residual \
             (at most {cap}), coefficients by least squares on the chosen terms (not refined by \
             free-run error); candidates (na = nb, degree, nl, criterion: terms kept of the \
             candidates) selected on the first {:.0} % of the first {used} of the {} training \
             samples and run free over the rest (held-out free-run RMSE after {window} samples, \
             {unit}: {}); chosen ({d}, {degree}, {nl}) with {}, FROLS run again on all training \
             samples ({} rows, {} candidates): {} terms, in the order chosen, in recorded units, \
             each with its ERR (share of the uncentred yᵀy): {}; one-step RMSE {:.3e} {unit}. \
             {timing}",
            100.0 * SELECT_FRACTION,
            est.len(),
            choice.tried.join(", "),
            count.label(),
            fit.rows,
            fit.candidates,
            fit.n_terms,
            terms.join(" "),
            fit.one_step_rmse * scale,
        ));
    }
    table.set_for_model(&label, "train_s", select_seconds + fit_seconds);
    table.set_for_model(&label, "threads", 1.0);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::median_score;

    /// The median counts a failed run as larger than any number: odd and even counts, a
    /// failure in the upper half, and a median that is itself a failure.
    #[test]
    fn median_counts_failures_as_largest() {
        let r = |v: &[Result<f64, String>]| median_score(&v.iter().collect::<Vec<_>>());
        let bad = || Err("diverged".to_string());
        assert_eq!(r(&[Ok(3.0), Ok(1.0), Ok(2.0)]), Some(2.0));
        assert_eq!(r(&[Ok(4.0), Ok(1.0), Ok(2.0), Ok(3.0)]), Some(2.5));
        assert_eq!(r(&[Ok(1.0), bad(), Ok(2.0)]), Some(2.0));
        assert_eq!(r(&[Ok(1.0), bad(), Ok(2.0), bad()]), None);
        assert_eq!(
            r(&[Ok(1.0), bad(), Ok(2.0), Ok(5.0), bad(), Ok(0.5)]),
            Some(3.5)
        );
        assert_eq!(r(&[]), None);
    }
}
