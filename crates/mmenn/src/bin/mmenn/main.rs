//! The `mmenn` command-line tool: thin argument parsing over the facade's workflows.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use clap::Parser;
use mmenn::atomic::{StageOptions, StagedDir};
use mmenn::plants::{self, SimulationRequest};

use args::{
    Cli, Command, CompareArgs, DiscoverArgs, EstimateArgs, FitArgs, GreyestArgs, MonitorCommand,
    PredictArgs, PrepArgs, ShowArgs, SimulateArgs,
};
use reporter::Reporter;

/// `println!` that ends the program quietly when standard output has been closed (piped
/// into `head`, say), as Unix tools do, where `println!` would panic.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout().lock(), $($arg)*) {
            crate::stdout_failed(e);
        }
    }};
}

/// `print!` with [`outln!`]'s handling of a closed standard output.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = write!(std::io::stdout().lock(), $($arg)*) {
            crate::stdout_failed(e);
        }
    }};
}

/// Standard output failed: a closed pipe ends the program with success (the reader has
/// what it wanted, and every file was written before anything was printed); any other
/// error is reported.
#[allow(clippy::print_stderr)]
fn stdout_failed(e: std::io::Error) -> ! {
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(0)
    }
    eprintln!("error: writing to standard output: {e}");
    std::process::exit(1)
}

mod args;
mod reporter;

/// The results were written, but an iterative search did not converge (exit status 3).
#[derive(Debug)]
struct NotConverged(String);

impl std::fmt::Display for NotConverged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NotConverged {}

/// Exit status 3 ([`NotConverged`]) when an MME solve did not converge
/// (`MmeConvergence::converged`; without its record, when its ending is not `exact` or
/// `converged`): the results are written, but not to be trusted. The message names which
/// part failed — the `W` search, or the Gauss–Newton iteration at a `W` — in
/// `MmeConvergence`'s words.
fn check_mme_converged(
    command: &str,
    estimate: Option<&mmenn::fit::MmeConvergence>,
    termination: Option<mmenn::sysid_core::Termination>,
    out: &Path,
) -> Result<()> {
    let written = || {
        format!(
            "the results in {} are written for inspection only (see report.md)",
            out.display()
        )
    };
    match (estimate, termination) {
        (Some(m), _) if m.converged() => Ok(()),
        (Some(m), _) => Err(NotConverged(format!("{command}: MME's {m}; {}", written())).into()),
        (
            None,
            Some(mmenn::sysid_core::Termination::Exact | mmenn::sysid_core::Termination::Converged)
            | None,
        ) => Ok(()),
        (None, Some(ended)) => Err(NotConverged(format!(
            "{command}: MME did not converge ({}); {}",
            mmenn::words::termination(Some(ended)),
            written()
        ))
        .into()),
    }
}

/// Exit status 3 ([`NotConverged`]) when an MME estimate `fit` ran did not end `exact` or
/// `converged` (`FitSummary::mme_estimates`, under `UnconvergedMme::Warn`): the results
/// are written, but not to be trusted.
fn check_fit_mme_converged(s: &mmenn::fit::FitSummary, out: &Path) -> Result<()> {
    match s.unconverged_mme().first() {
        None => Ok(()),
        Some(m) => Err(NotConverged(format!(
            "fit: MME's {m}; the results in {} are written for inspection only (see \
             report.md)",
            out.display()
        ))
        .into()),
    }
}

/// Stage `out` for `command` (see [`StagedDir`]).
fn stage(out: &Path, command: &str, force: bool, inputs: &[&PathBuf]) -> Result<StagedDir> {
    Ok(StagedDir::begin(
        out,
        StageOptions {
            command: command.into(),
            force,
            inputs: inputs.iter().map(|p| p.to_path_buf()).collect(),
            protect: Vec::new(),
        },
    )?)
}

/// Print the catalogue of named effects: name, label, term over placeholder variables,
/// and the equations it may enter.
#[allow(clippy::print_stdout)]
fn list_effects() {
    use mmenn::discovery::{Effect, EquationKind, Role, Slot};
    outln!(
        "Named effects discover tries (term written over placeholders: x position, theta \
         angle, v velocity, h level, x_j any state, u input):"
    );
    for e in Effect::ALL.into_iter().filter(|e| e.is_candidate()) {
        let vars: Vec<&str> = e
            .slots()
            .iter()
            .map(|s| match s {
                Slot::Input => "u",
                Slot::AnyState => "x_j",
                Slot::State(roles) => match roles.first() {
                    Some(Role::Velocity) => "v",
                    Some(Role::Angle) => "theta",
                    Some(Role::Level) => "h",
                    _ => "x",
                },
            })
            .collect();
        // Sentinel values mark where each named parameter goes.
        let sentinels = [0.111, 0.222];
        let mut term = e.template(&vars, &sentinels[..e.parameters().len()]);
        for (p, v) in e.parameters().iter().zip(["0.111", "0.222"]) {
            term = term.replace(v, p);
        }
        let enters: Vec<&str> = e
            .enters()
            .iter()
            .map(|k| match k {
                EquationKind::Acceleration => "a velocity's equation (acceleration)",
                EquationKind::Flow => "a level's equation (flow)",
                _ => "any other equation",
            })
            .collect();
        outln!("  {:<28} {:<30} {term}", e.name(), e.label());
        outln!("  {:<28} enters {}", "", enters.join(", "));
    }
}

/// `paths` prepared as `prep` says (unchanged without `--map`/`--resample`), written
/// under `out`; what was done is printed.
#[allow(clippy::print_stderr)]
fn prepared(paths: &[PathBuf], prep: &PrepArgs, out: &Path) -> Result<Vec<PathBuf>> {
    let opts = mmenn::data_file::PrepareOptions {
        map: mmenn::data_file::PrepareOptions::parse_map(&prep.map).map_err(anyhow::Error::msg)?,
        resample: prep.resample,
    };
    let (paths, reports) = mmenn::data_file::prepare_files(paths, &opts, out)?;
    for r in &reports {
        eprintln!("prepared {}", r.describe());
    }
    Ok(paths)
}

fn parse_param(text: &str) -> Result<(String, f64)> {
    let Some((name, value)) = text.split_once('=') else {
        bail!("--param '{text}': expected NAME=VALUE");
    };
    let v: f64 = value
        .trim()
        .parse()
        .with_context(|| format!("--param '{text}': '{value}' is not a number"))?;
    Ok((name.trim().to_string(), v))
}

#[allow(clippy::print_stdout)]
fn simulate(args: SimulateArgs, force: bool, progress: &Reporter) -> Result<()> {
    if args.list {
        for s in plants::systems() {
            outln!(
                "{}  (default fs {} Hz; recipes: train, test)",
                s.name,
                s.default_fs
            );
            outln!("    {}", s.description);
            let params: Vec<String> = s
                .parameters
                .iter()
                .map(|(n, v, u)| format!("{n}={v} {u}"))
                .collect();
            outln!("    parameters: {}", params.join(", "));
            outln!("    default noise variance: {:?}", s.default_noise_variance);
        }
        return Ok(());
    }
    let (Some(system), Some(out)) = (args.system, args.out) else {
        bail!("--system and --out are required");
    };
    let params = args
        .params
        .iter()
        .map(|p| parse_param(p))
        .collect::<Result<Vec<_>>>()?;
    let request = SimulationRequest {
        system,
        recipe: args.recipe,
        noise_variance: args.noise_variance,
        fs: args.fs,
        seed: args.seed,
        params,
        duration: args.duration,
    };
    // Never silently replace a data, truth or model file with different contents.
    let staged = StagedDir::begin(
        &out,
        StageOptions {
            command: "simulate".into(),
            force,
            inputs: Vec::new(),
            protect: vec!["data.csv".into(), "truth.csv".into(), "model.toml".into()],
        },
    )?;
    mmenn::progress::stage(progress, "simulation", || {
        mmenn::simulate::run_simulate(&request, staged.path()).map_err(anyhow::Error::from)
    })?;
    staged.commit()?;
    outln!(
        "wrote {}, {}, {}",
        out.join("data.csv").display(),
        out.join("truth.csv").display(),
        out.join("model.toml").display()
    );
    Ok(())
}

#[allow(clippy::print_stdout)]
fn estimate(args: EstimateArgs, force: bool, progress: &Reporter) -> Result<()> {
    let opts = mmenn::estimate::EstimateOptions {
        w: args.w,
        substeps: args.substeps,
        budget: args.budget.start(),
        ..Default::default()
    };
    let inputs: Vec<&PathBuf> = args.data.iter().chain([&args.model]).collect();
    let staged = stage(&args.out, "estimate", force, &inputs)?;
    let data = prepared(&args.data, &args.prep, staged.path())?;
    let robust = args.robust.then(mmenn::mme_core::RobustConfig::default);
    // One task for the whole job; MME's phases and steps show as its stage and note.
    let s = mmenn::progress::stage(progress, mmenn::progress::MME_TASK, || {
        mmenn::estimate::run_estimate_with_progress(
            &data,
            &args.model,
            &opts,
            robust.as_ref(),
            staged.path(),
            progress,
        )
        .map_err(anyhow::Error::from)
    })?;
    staged.commit()?;
    outln!(
        "MME estimate (smoother over the whole record; not a prediction) of {} samples:",
        s.samples
    );
    for (name, n) in s.missing.iter().filter(|(_, n)| **n > 0) {
        outln!(
            "  {name}: {n} of {} samples missing (empty or NaN cells; MME skips them)",
            s.samples
        );
    }
    for (name, nv) in &s.noise_variance {
        outln!(
            "  {name}: noise variance {nv:.4e} ({}), residual variance {:.4e} (ratio {:.3})",
            mmenn::words::noise_method(s.noise_method),
            s.residual_variance[name],
            s.residual_to_noise[name]
        );
    }
    outln!(
        "  W diagonal: {}",
        mmenn::words::named_values(&s.w_by_correction)
    );
    if let Some(c) = s.convergence.as_ref().filter(|c| c.within_sampling_band()) {
        outln!("  {}", c.ending());
    }
    for w in &s.warnings {
        outln!("  warning: {w}");
    }
    for o in s.outliers.iter().take(10) {
        outln!(
            "  outlier: experiment {}, {} at sample {} (t = {} s): {} is {:.1} σ out",
            o.experiment,
            o.channel,
            o.sample,
            o.time,
            o.value,
            o.sigmas
        );
    }
    if s.outliers.len() > 10 {
        outln!("  … {} outliers in all (report.md)", s.outliers.len());
    }
    if !s.outliers.is_empty() && !args.robust {
        outln!("  (outliers pull a plain estimate: consider --robust)");
    }
    if let Some(r) = s.sweep_samples_per_second {
        outln!("  final sweep: {:.3e} samples/s", r);
    }
    outln!("wrote {} files into {}", s.files.len(), args.out.display());
    // As `fit` judges its training estimate: a W search not bracketed below 1 within the
    // sampling band is converged (docs/decisions/mme-ratio-tolerance.md).
    let converged = s.convergence.as_ref().map(|c| c.converged());
    if let Some(ended) = s.report.termination
        && converged != Some(true)
        && !matches!(
            ended,
            mmenn::sysid_core::Termination::Exact | mmenn::sysid_core::Termination::Converged
        )
    {
        let detail = s
            .w_search
            .as_ref()
            .map(|w| {
                format!(
                    "; W search: α = {:.4e}, ratio {:.4}, {} after {} sweeps",
                    w.alpha,
                    w.ratio,
                    mmenn::words::termination(Some(w.termination)),
                    w.evaluations
                )
            })
            .unwrap_or_default();
        return Err(NotConverged(format!(
            "the estimate did not converge ({}{detail}); the results in {} are \
             written for inspection only (see report.md)",
            mmenn::words::termination(Some(ended)),
            args.out.display()
        ))
        .into());
    }
    Ok(())
}

#[allow(clippy::print_stdout)]
fn greyest(args: GreyestArgs, force: bool, progress: &Reporter) -> Result<()> {
    let opts = mmenn::greyest::GreyestOptions {
        segment: args.shooting,
        substeps: args.substeps,
        max_iterations: args.max_iterations,
        budget: args.budget.start(),
        x0_start: args.x0,
        starts: args.starts,
        seed: args.seed,
    };
    let inputs: Vec<&PathBuf> = args.data.iter().chain([&args.model]).collect();
    let staged = stage(&args.out, "greyest", force, &inputs)?;
    let data = prepared(&args.data, &args.prep, staged.path())?;
    // Records are named by the files given; a copy prepared by --map/--resample lives in
    // the staging folder, which becomes --out.
    let names: Vec<String> = args
        .data
        .iter()
        .zip(&data)
        .map(|(given, used)| {
            if given == used {
                given.display().to_string()
            } else {
                let copy = used.strip_prefix(staged.path()).unwrap_or(used);
                format!("{} (as {})", given.display(), args.out.join(copy).display())
            }
        })
        .collect();
    let outcome = mmenn::greyest::run_greyest_named(
        &args.model,
        &data,
        &names,
        &opts,
        staged.path(),
        progress,
    )?;
    staged.commit()?;
    let s = &outcome.summary;
    outln!("grey-box estimate ({}):", s.weighting);
    for p in &s.parameters {
        let sigma = match (p.sigma, p.held()) {
            (Some(v), _) => format!("± {v:.3e}"),
            (None, Some(held)) => format!("({held})"),
            (None, None) => "(not identifiable)".into(),
        };
        outln!(
            "  {} = {:.6e} {sigma} {}  (start {:.4e})",
            p.name,
            p.value,
            p.unit.as_deref().unwrap_or(""),
            p.start
        );
    }
    for r in &s.records {
        outln!(
            "  free-run fit on {} from its calibrated start ({} RK4 steps per sample): {}",
            r.file,
            r.substeps,
            mmenn::greyest::fit_words(&r.fit_percent, &r.rmse, &outcome.spec)
        );
        for line in mmenn::greyest::predict_lines(r, &outcome.spec) {
            outln!("    {line}");
        }
    }
    for st in &s.stages {
        outln!(
            "  {}: {} after {} iterations, cost {:.4e} -> {:.4e}",
            st.shooting,
            st.termination,
            st.iterations,
            st.initial_cost,
            st.final_cost
        );
    }
    outln!(
        "  residual variance ratio s² = {:.4}, rank {} of {}",
        s.residual_variance_ratio,
        s.rank.0,
        s.rank.1
    );
    if let Some(ms) = &s.multi_start {
        for line in ms.terminal_lines() {
            outln!("{line}");
        }
    }
    outln!("wrote {} into {}", s.files.join(", "), args.out.display());
    let last = &s.stages[s.stages.len() - 1];
    if !last.converged {
        return Err(NotConverged(format!(
            "the free-run solve did not converge ({}); the results in {} are written for \
             inspection only",
            last.termination,
            args.out.display()
        ))
        .into());
    }
    Ok(())
}

#[allow(clippy::print_stdout)]
fn print_free_run(label: &str, r: &mmenn::fit::FreeRunReport) {
    outln!(
        "{label} — {}, {} scored, from x0 = {} ({}):",
        r.horizon,
        r.scored,
        mmenn::words::numbers(&r.x0),
        r.x0_source
    );
    for (name, m) in &r.channels {
        outln!(
            "  {name}: fit {:.2} %, R² {:.5}, RMSE {:.4e}, error variance {:.4e}",
            m.fit_percent,
            m.r2,
            m.rmse,
            m.error_variance
        );
    }
}

/// The network's behaviour outside its training box from `--network-domain` and its
/// shorthand `--hold-network-domain`.
fn domain(policy: mmenn::fit::DomainPolicy, hold: bool) -> mmenn::fit::DomainPolicy {
    if hold {
        mmenn::fit::DomainPolicy::Hold
    } else {
        policy
    }
}

#[allow(clippy::print_stdout)]
fn fit(args: FitArgs, force: bool, progress: &Reporter) -> Result<()> {
    let opts = mmenn::fit::FitOptions {
        estimate: mmenn::estimate::EstimateOptions {
            w: args.w,
            substeps: None,
            budget: args.budget.start(),
            ..Default::default()
        },
        hidden: args.hidden,
        inits: args.inits,
        max_hidden: args.max_hidden,
        update: args.update_model,
        selection: args.select,
        ensemble: args.ensemble,
        seed: args.seed,
        train_on_trajectories: args.train_on_trajectories,
        training: args.training,
        guard: args.guard,
        validation_use: args.val_use,
        network_domain: domain(args.network_domain, args.hold_network_domain),
        network_inputs: args.network_inputs,
        trajectory: mmenn::nn::TrajectoryConfig {
            window: args.trajectory_window,
            ..Default::default()
        },
        // The results are written for inspection, and the exit status says they are not to
        // be trusted (`check_fit_mme_converged`).
        on_unconverged_mme: mmenn::fit::UnconvergedMme::Warn,
        ..Default::default()
    };
    let inputs: Vec<&PathBuf> = args
        .data
        .iter()
        .chain(&args.val)
        .chain([&args.model])
        .collect();
    let staged = stage(&args.out, "fit", force, &inputs)?;
    let data = prepared(&args.data, &args.prep, staged.path())?;
    let val = prepared(&args.val, &args.prep, &staged.path().join("val"))?;
    let s = mmenn::fit::run_fit_with_progress(
        &data,
        &args.model,
        &val,
        &opts,
        staged.path(),
        progress,
    )?;
    staged.commit()?;
    outln!(
        "network: {} hidden unit{} (train MSE {:.3e}, test MSE {:.3e} of d)",
        s.hidden,
        if s.hidden == 1 { "" } else { "s" },
        s.chosen.train_mse,
        s.chosen.test_mse
    );
    print_free_run("training data", &s.train);
    if let Some(v) = &s.validation {
        print_free_run("validation data", v);
    }
    if let Some(line) = s.validation_use_line() {
        outln!("{line}");
    }
    for line in s.decision_lines() {
        outln!("{line}");
    }
    outln!("wrote {} files into {}", s.files.len(), args.out.display());
    check_fit_mme_converged(&s, &args.out)
}

#[allow(clippy::print_stdout)]
fn predict(args: PredictArgs, force: bool, progress: &Reporter) -> Result<()> {
    let x0 = match args.x0 {
        Some(v) => mmenn::fit::InitialChoice::Given(v),
        None => mmenn::fit::InitialChoice::Fit,
    };
    let staged = stage(&args.out, "predict", force, &[&args.model, &args.data])?;
    let opts = mmenn::predict::PredictOptions {
        x0,
        x0_window: Some(args.x0_window),
        horizon: args.horizon,
        score_from: args.score_from,
    };
    let data = prepared(std::slice::from_ref(&args.data), &args.prep, staged.path())?;
    let s = mmenn::progress::stage(progress, "prediction", || {
        mmenn::predict::run_predict_substeps(
            &args.model,
            &data[0],
            &opts,
            args.substeps,
            staged.path(),
        )
        .map_err(anyhow::Error::from)
    })?;
    staged.commit()?;
    print_free_run(&format!("prediction ({})", s.model_kind), &s.free_run);
    if let Some(steps) = s.substeps {
        outln!("  free run: classical RK4, {steps} steps per sample interval");
    }
    if let Some(d) = s.network_domain.as_ref().filter(|d| d.outside > 0) {
        outln!("  network: {}", d.sentence());
    }
    if let Some(k) = &s.k_step {
        print_free_run(
            &format!("prediction ({})", s.model_kind),
            &mmenn::fit::FreeRunReport {
                horizon: k.horizon,
                x0: k.x0.clone(),
                x0_source: k.k_step_rule.clone().unwrap_or_default(),
                scored: k.scored,
                channels: k.channels.clone(),
            },
        );
    }
    Ok(())
}

#[allow(clippy::print_stdout)]
fn show(args: ShowArgs) -> Result<()> {
    out!("{}", mmenn::show::show_model(&args.model)?);
    Ok(())
}

#[allow(clippy::print_stdout)]
fn compare(a: CompareArgs, force: bool, progress: &Reporter) -> Result<()> {
    let opts = mmenn::compare::CompareOptions {
        fit: mmenn::fit::FitOptions {
            max_hidden: a.max_hidden,
            inits: a.inits,
            seed: a.seed,
            training: a.training,
            guard: a.guard,
            validation_use: a.val_use,
            network_domain: domain(a.network_domain, a.hold_network_domain),
            network_inputs: a.network_inputs,
            // As before the policy existed: the table is computed whatever MME's ending.
            on_unconverged_mme: mmenn::fit::UnconvergedMme::Warn,
            ..Default::default()
        },
        narx_lags: a.narx_lags,
        narx_focus: a.narx_focus,
        poly_narx: (a.poly_degree > 0).then_some(mmenn::compare::PolyNarxChoice {
            degree: a.poly_degree,
            nonlinear_lags: a.poly_nonlinear_lags,
            focus: a.poly_focus,
            monomials: a.poly_monomials,
        }),
        ss_max_order: a.ss_max_order,
        ..Default::default()
    };
    let inputs: Vec<&PathBuf> = a.data.iter().chain(&a.val).chain([&a.model]).collect();
    let staged = stage(&a.out, "compare", force, &inputs)?;
    let data = prepared(&a.data, &a.prep, staged.path())?;
    let val = prepared(&a.val, &a.prep, &staged.path().join("val"))?;
    let outcome =
        mmenn::compare::run_compare_outcome(&data, &a.model, &val, &opts, staged.path(), progress)?;
    staged.commit()?;
    let s = &outcome.summary;
    for (dataset, t) in std::iter::once(("estimation", &s.estimation))
        .chain(s.validation.as_ref().map(|v| ("validation", v)))
    {
        outln!("{} — {}:", t.title(), t.horizon());
        for row in t.rows() {
            let cells: Vec<String> = row
                .evaluation
                .channels
                .iter()
                .map(|c| {
                    format!(
                        "{} fit {:.1} % R² {:.4}",
                        c.name, c.metrics.fit_percent, c.metrics.r2
                    )
                })
                .collect();
            outln!("  {:<16} {}", row.label, cells.join("; "));
        }
        // A free-run failure on the other dataset leaves this table's row in place.
        for f in s
            .failures
            .iter()
            .filter(|f| t.rows().iter().all(|r| r.label != f.model) && f.concerns(dataset))
        {
            outln!(
                "  {:<16} {}: {}",
                f.model,
                f.at.to_string().to_uppercase(),
                f.reason
            );
            let dense = s
                .poly_narx
                .as_ref()
                .is_some_and(|p| p.choice.monomials == mmenn::compare::PolyNarxMonomials::All);
            if f.model == mmenn::compare::POLY_NARX_ROW
                && f.at == mmenn::compare::FailedAt::FreeRun
                && dense
            {
                outln!(
                    "  {:<16} (--poly-monomials frols-kfold keeps a sparse model whose term \
                     count is chosen by free run)",
                    ""
                );
            }
        }
    }
    for f in &s.residual_failures {
        outln!("residual analysis of {} failed {}", f.model, f.reason);
    }
    if s.linear_ss.order.is_some() {
        outln!("linear SS order {}", s.linear_ss.choice);
    }
    if s.narx_refinement.is_some() {
        outln!("NARX network: {}", s.narx_training);
    }
    if let Some(line) = s.poly_narx.as_ref().and_then(|p| p.selection.as_ref()) {
        outln!("polynomial NARX terms: {line}");
    }
    // The MME/NN's choices, in `fit`'s words; its rows above are the kept model's.
    let f = &outcome.fit.summary;
    outln!(
        "MME/NN ({}; its rows above are the kept model, {}):",
        a.out.join("mme_nn").display(),
        match f.guard.chosen {
            mmenn::fit::GuardCandidate::PhysicsAlone => "physics alone",
            _ => mmenn::words::network_domain(f.network_domain),
        }
    );
    for line in f.decision_lines() {
        outln!("  {line}");
    }
    outln!("wrote {} files into {}", s.files.len(), a.out.display());
    Ok(())
}

#[allow(clippy::print_stdout)]
fn discover(a: DiscoverArgs, force: bool, progress: &Reporter) -> Result<()> {
    if a.list_effects {
        list_effects();
        return Ok(());
    }
    let (Some(model), Some(out)) = (&a.model, &a.out) else {
        bail!("--data, --model and --out are required");
    };
    let opts = mmenn::discover::DiscoverOptions {
        workflow: mmenn::discover::WorkflowConfig {
            max_rounds: a.max_rounds,
            seed: a.seed,
            holdout_fraction: a.holdout_fraction,
            stand_in_draws: a.stand_in_draws,
            ..Default::default()
        },
        estimate: mmenn::estimate::EstimateOptions {
            budget: a.budget.start(),
            ..Default::default()
        },
        ..Default::default()
    };
    let inputs: Vec<&PathBuf> = a.data.iter().chain(&a.val).chain([model]).collect();
    let staged = stage(out, "discover", force, &inputs)?;
    let data = prepared(&a.data, &a.prep, staged.path())?;
    let val = prepared(&a.val, &a.prep, &staged.path().join("val"))?;
    let s = mmenn::discover::run_discover_with_progress(
        &data,
        model,
        &val,
        &opts,
        staged.path(),
        progress,
    )?;
    staged.commit()?;
    outln!("verdict: {}", mmenn::words::discover_verdict(&s));
    for w in &s.warnings {
        outln!("  warning: {w}");
    }
    for e in &s.effects {
        outln!(
            "  {} in {}: {} × {:.6} (free-run calibrated; {})",
            e.name,
            e.equations(),
            e.term,
            e.coefficient,
            e.named_by
        );
    }
    for e in &s.unconfirmed {
        let support = match e.interval_excludes_zero() {
            Some(true) => " (95 % interval excludes 0)",
            Some(false) => " (95 % interval includes 0: not supported by the data)",
            None => "",
        };
        let why = if s.stand_in.as_ref().is_some_and(|st| !st.accepts())
            && s.judgement.as_ref().is_some_and(|j| j.accepts())
        {
            "d̂ still predictable"
        } else {
            "cost stays above the noise level"
        };
        outln!(
            "  not claimed ({why}): {} in {}: {} × {:.6}{support}",
            e.name,
            e.equations(),
            e.term,
            e.coefficient
        );
    }
    if let Some(st) = &s.stand_in {
        outln!(
            "  flexible stand-in on d̂: held-out gain {:.4} against threshold {:.4} ({})",
            st.statistic,
            st.threshold,
            if st.accepts() {
                "nothing predictable left"
            } else {
                "structure remains"
            }
        );
    }
    let show = |label: &str, g: &mmenn::discover::GapPair| {
        for (k, b) in &g.before.fit_percent {
            outln!(
                "  {label} free-run fit of {k}: {b:.2} % → {:.2} %",
                g.after.fit_percent[k]
            );
        }
        for (k, b) in &g.before.d_rms {
            match g.after.d_rms.get(k) {
                Some(a) => outln!("  {label} d̂ RMS of {k}: {b:.4e} → {a:.4e}"),
                None => outln!("  {label} d̂ RMS of {k}: {b:.4e} (MME not rerun)"),
            }
        }
    };
    show("estimation", &s.gap);
    if let Some(v) = &s.validation_gap {
        show("validation", v);
    }
    outln!("wrote {}", out.join(&s.model).display());
    check_mme_converged("discover", s.mme_estimate.as_ref(), s.mme_termination, out)
}

#[allow(clippy::print_stdout)]
fn monitor(cmd: MonitorCommand, force: bool, progress: &Reporter) -> Result<()> {
    match cmd {
        MonitorCommand::Train(a) => {
            let mut classes = Vec::new();
            for c in &a.classes {
                let Some((name, files)) = c.split_once('=') else {
                    bail!("--class '{c}': expected NAME=FILE[,FILE…]");
                };
                classes.push((
                    name.to_string(),
                    files.split(',').map(PathBuf::from).collect::<Vec<_>>(),
                ));
            }
            let opts = mmenn::monitor::MonitorOptions {
                features: a.features,
                hidden: a.hidden,
                seed: a.seed,
                ..Default::default()
            };
            let mut inputs: Vec<&PathBuf> = classes.iter().flat_map(|(_, f)| f).collect();
            inputs.push(&a.model);
            let staged = stage(&a.out, "monitor train", force, &inputs)?;
            let m = mmenn::progress::stage(progress, "monitor training", || {
                mmenn::monitor::train_monitor(&classes, &a.model, &opts, staged.path())
                    .map_err(anyhow::Error::from)
            })?;
            staged.commit()?;
            outln!(
                "trained on {} records; classify will use {} with {}",
                m.rows.len(),
                m.classifier.label(),
                m.preprocessing.label()
            );
            outln!("cross-validated error % ({}):", m.table.columns.join(" | "));
            for (i, row) in m.table.rows.iter().enumerate() {
                let cells: Vec<String> = (0..m.table.columns.len())
                    .filter_map(|j| m.table.cell(i, j))
                    .map(|c| format!("{:.1}", c.error_percent()))
                    .collect();
                outln!("  {row}: {}", cells.join(" | "));
            }
        }
        MonitorCommand::Classify(a) => {
            let c = mmenn::progress::stage(progress, "classification", || {
                mmenn::monitor::classify(&a.monitor, &a.data).map_err(anyhow::Error::from)
            })?;
            outln!(
                "condition: {} ({}; {})",
                c.condition,
                c.classifier,
                c.score_kind
            );
            for (name, s) in &c.scores {
                outln!("  {name}: {s:.3}");
            }
        }
    }
    Ok(())
}

/// Whether errors are printed in full detail: `--debug`, or `MMENN_BACKTRACE` set to
/// anything but empty or `0`. `RUST_BACKTRACE` alone does not: a user error is not a bug.
fn debug_requested(flag: bool) -> bool {
    flag || std::env::var_os("MMENN_BACKTRACE").is_some_and(|v| !v.is_empty() && v != "0")
}

/// The error and its causes on one line, skipping a cause whose text the message already
/// holds (several errors print their source themselves).
fn error_chain(e: &anyhow::Error) -> String {
    let mut msg = e.to_string();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !msg.contains(&c) {
            msg.push_str(": ");
            msg.push_str(&c);
        }
    }
    msg
}

/// Whether `e` is a spent `--budget` (exit status 4), wherever it sits in the chain.
fn budget_ran_out(e: &anyhow::Error) -> bool {
    use mmenn::mme_core::MmeError;
    use mmenn::sysid_core::{BudgetExhausted, CoreError};
    e.chain().any(|c| {
        c.is::<BudgetExhausted>()
            || matches!(c.downcast_ref(), Some(CoreError::BudgetExhausted(_)))
            || matches!(
                c.downcast_ref(),
                Some(MmeError::Core(CoreError::BudgetExhausted(_)))
            )
            || matches!(
                c.downcast_ref(),
                Some(mmenn::discovery::DiscoveryError::Core(
                    CoreError::BudgetExhausted(_)
                ))
            )
    })
}

/// `--force` replaces an existing `--out` folder: a command that writes none (`show`,
/// `monitor classify`, and `simulate --list` / `discover --list-effects`, which only
/// print) refuses it as a bad argument (exit status 2, clap's error) rather than
/// ignoring it.
fn refuse_force(cli: &Cli) -> std::result::Result<(), clap::Error> {
    // The subcommand path (for clap's usage line) and the flag that makes it write nothing.
    let (path, flag): (&[&str], Option<&str>) = match &cli.command {
        Command::Show(_) => (&["show"], None),
        Command::Monitor(MonitorCommand::Classify(_)) => (&["monitor", "classify"], None),
        Command::Simulate(a) if a.list => (&["simulate"], Some("--list")),
        Command::Discover(a) if a.list_effects => (&["discover"], Some("--list-effects")),
        _ => return Ok(()),
    };
    if !cli.force {
        return Ok(());
    }
    use clap::CommandFactory as _;
    let message = format!(
        "--force has no effect with `{}`: it writes nothing",
        path.iter()
            .copied()
            .chain(flag)
            .collect::<Vec<_>>()
            .join(" ")
    );
    // The error carries the subcommand's usage line.
    let kind = clap::error::ErrorKind::ArgumentConflict;
    let mut root = Cli::command();
    root.build();
    Err(
        match path
            .iter()
            .try_fold(&mut root, |c, name| c.find_subcommand_mut(name))
        {
            Some(sub) => sub.error(kind, message),
            None => Cli::command().error(kind, message),
        },
    )
}

#[allow(clippy::print_stderr)]
fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Err(e) = refuse_force(&cli) {
        e.exit()
    }
    let force = cli.force;
    let progress = Reporter::new(cli.quiet);
    let result = match cli.command {
        Command::Simulate(a) => simulate(a, force, &progress),
        Command::Estimate(a) => estimate(a, force, &progress),
        Command::Fit(a) => fit(a, force, &progress),
        Command::Predict(a) => predict(a, force, &progress),
        Command::Show(a) => show(a),
        Command::Greyest(a) => greyest(a, force, &progress),
        Command::Compare(a) => compare(a, force, &progress),
        Command::Discover(a) => discover(a, force, &progress),
        Command::Monitor(c) => monitor(c, force, &progress),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            if debug_requested(cli.debug) {
                // The chain, one cause per line, and anyhow's backtrace when one was
                // captured (RUST_BACKTRACE / RUST_LIB_BACKTRACE).
                eprintln!("error: {e:?}");
            } else {
                eprintln!("error: {}", error_chain(&e));
            }
            if e.downcast_ref::<NotConverged>().is_some() {
                ExitCode::from(3)
            } else if budget_ran_out(&e) {
                ExitCode::from(4)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::check_mme_converged;
    use mmenn::fit::{MmeConvergence, MmeStage};
    use mmenn::sysid_core::Termination;
    use std::path::Path;

    /// A first estimate that ended `termination`, its `W` search `w_search` at `ratio`.
    fn ended(
        termination: Termination,
        w_search: Option<(Termination, f64)>,
    ) -> (MmeConvergence, String) {
        let m = MmeConvergence {
            stage: MmeStage::Training,
            termination: Some(termination),
            w_search: w_search.map(|w| w.0),
            variance_ratio: [("theta".to_string(), w_search.map_or(0.3, |w| w.1))].into(),
            w_search_ratio: w_search.map(|w| w.1),
            sampling_band: w_search.map(|_| mmenn::fit::sampling_band(400, 2)),
            fold: None,
        };
        let message = check_mme_converged("discover", Some(&m), Some(termination), Path::new("o"))
            .err()
            .map_or(String::new(), |e| e.to_string());
        (m, message)
    }

    /// `discover`'s exit-3 message names the part of MME that failed: the Gauss–Newton
    /// iteration (at a given `W`, or at the `W` the search found) or the `W` search.
    #[test]
    fn the_message_names_the_gauss_newton_iteration_or_the_w_search() {
        let (_, given) = ended(Termination::MaxIterations, None);
        assert!(
            given.contains("Gauss–Newton iteration at the given W: stopped at the iteration limit"),
            "{given}"
        );
        assert!(!given.contains("W search"), "{given}");

        let (_, at_final) = ended(
            Termination::LineSearchFailed,
            Some((Termination::Converged, 1.0)),
        );
        assert!(
            at_final.contains("Gauss–Newton iteration at the final W: stopped: the line search"),
            "{at_final}"
        );
        assert!(
            at_final.contains("W search (covariance constraint): converged"),
            "{at_final}"
        );

        let (_, search) = ended(
            Termination::NotBracketed,
            Some((Termination::NotBracketed, 1.7)),
        );
        assert!(
            search.contains("W search (covariance constraint): the target was never bracketed"),
            "{search}"
        );
        assert!(!search.contains("Gauss–Newton"), "{search}");
        for m in [&given, &at_final, &search] {
            assert!(
                m.starts_with("discover: MME's training estimate did not converge"),
                "{m}"
            );
        }

        // Not bracketed below 1 within the sampling band: converged, exit 0.
        let (m, within) = ended(
            Termination::NotBracketed,
            Some((Termination::NotBracketed, 0.96)),
        );
        assert!(m.converged() && within.is_empty(), "{within}");
        assert!(
            m.to_string()
                .contains("within the sampling band (ratio 0.960 ≥ 0.712)"),
            "{m}"
        );
    }
}
