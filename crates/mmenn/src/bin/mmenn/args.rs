//! The command line of `mmenn`: global flags, subcommands and their arguments (clap).

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use mmenn::plants::Recipe;

/// Hybrid nonlinear system identification: Minimum Model Error estimation + neural networks.
///
/// Every command writes its --out folder all-or-nothing: into a fresh folder beside it,
/// put in place at the end. An existing --out folder is replaced only when it holds the
/// results of the same command (or with --force). Errors are printed without a backtrace
/// unless --debug is given or MMENN_BACKTRACE is set. Exit status: 0 success, 1 error,
/// 2 bad arguments, 3 results written but the estimator did not converge, 4 the
/// --budget of estimate, fit, greyest or discover ran out (nothing written).
#[derive(Debug, Parser)]
#[command(name = "mmenn", version, about)]
pub(crate) struct Cli {
    /// Print errors with their full detail (and a backtrace when RUST_BACKTRACE=1).
    #[arg(long, global = true)]
    pub(crate) debug: bool,
    /// Replace an existing --out folder even when it holds another command's results or
    /// files mmenn did not write (never one holding an input file). `show` and `monitor
    /// classify` write no folder and refuse it.
    #[arg(long, global = true)]
    pub(crate) force: bool,
    /// Print no progress (bars on a terminal, periodic lines otherwise) on stderr.
    #[arg(long, short, global = true)]
    pub(crate) quiet: bool,
    #[command(subcommand)]
    pub(crate) command: Command,
}

/// A count that must be at least 1.
fn at_least_one(text: &str) -> std::result::Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(v) if v >= 1 => Ok(v),
        Ok(_) => Err("must be at least 1".into()),
        Err(e) => Err(format!("'{text}' is not a whole number ({e})")),
    }
}

/// Reference draws: 0 (off) or at least 4, at most 1000.
fn draws(text: &str) -> std::result::Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(v) if v == 0 || (4..=1000).contains(&v) => Ok(v),
        Ok(v) => Err(format!("{v} draws: 0 (off) or 4 to 1000")),
        Err(e) => Err(format!("'{text}' is not a whole number ({e})")),
    }
}

/// A count that must be at least 2.
fn at_least_two(text: &str) -> std::result::Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(v) if v >= 2 => Ok(v),
        Ok(_) => Err("must be at least 2".into()),
        Err(e) => Err(format!("'{text}' is not a whole number ({e})")),
    }
}

/// Sub-steps per sample interval: 1 to `MAX_SUBSTEPS`.
fn substeps(text: &str) -> std::result::Result<usize, String> {
    let max = mmenn::mme_core::discretize::MAX_SUBSTEPS;
    match text.trim().parse::<u64>() {
        Ok(v) if (1..=max as u64).contains(&v) => Ok(v as usize),
        Ok(v) => Err(format!("{v} is outside 1..={max}")),
        Err(e) => Err(format!("'{text}' is not a whole number ({e})")),
    }
}

/// Free-run RK4 sub-steps: `auto` (at least `AUTO_MIN`, more where the model is stiff)
/// or a fixed number, 1 to `MAX_SUBSTEPS`.
fn free_run_substeps_from(
    text: &str,
    auto_min: usize,
) -> std::result::Result<mmenn::sysid_core::Substeps, String> {
    if text.trim().eq_ignore_ascii_case("auto") {
        Ok(mmenn::sysid_core::Substeps::Auto { min: auto_min })
    } else {
        substeps(text)
            .map(mmenn::sysid_core::Substeps::Fixed)
            .map_err(|e| format!("{e} (or auto)"))
    }
}

/// `greyest --substeps`: `auto` means at least 2.
fn free_run_substeps(text: &str) -> std::result::Result<mmenn::sysid_core::Substeps, String> {
    free_run_substeps_from(text, 2)
}

/// `predict --substeps`: `auto` means at least 4 (a model file's free-run default).
fn predict_substeps(text: &str) -> std::result::Result<mmenn::sysid_core::Substeps, String> {
    free_run_substeps_from(text, 4)
}

/// `NAME=VALUE` with a finite number.
fn name_value(text: &str) -> std::result::Result<(String, f64), String> {
    let Some((name, value)) = text.split_once('=') else {
        return Err(format!("'{text}': expected NAME=VALUE"));
    };
    match value.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok((name.trim().to_string(), v)),
        Ok(v) => Err(format!("'{text}': {v} is not a finite number")),
        Err(e) => Err(format!("'{text}': '{value}' is not a number ({e})")),
    }
}

/// `compare --poly-degree`: 0 (no polynomial NARX row) or a degree, 1 to 5.
fn poly_degree(text: &str) -> std::result::Result<usize, String> {
    match text.trim().parse::<usize>() {
        Ok(v) if v <= 5 => Ok(v),
        Ok(v) => Err(format!("degree {v}: 0 (no polynomial NARX row) or 1 to 5")),
        Err(e) => Err(format!(
            "'{text}' is not a whole number ({e}): 0 (no polynomial NARX row) or 1 to 5"
        )),
    }
}

/// `compare --narx-focus` and `--poly-focus`: `prediction` or `simulation` (at most 30
/// Levenberg–Marquardt iterations).
fn focus(text: &str) -> std::result::Result<mmenn::compare::Focus, String> {
    match text.trim() {
        "prediction" => Ok(mmenn::compare::Focus::Prediction),
        "simulation" => Ok(mmenn::compare::Focus::Simulation { max_iterations: 30 }),
        other => Err(format!("'{other}': prediction or simulation")),
    }
}

/// `compare --poly-monomials`: `all` or `frols-kfold`.
fn poly_monomials(text: &str) -> std::result::Result<mmenn::compare::PolyNarxMonomials, String> {
    match text.trim() {
        "all" => Ok(mmenn::compare::PolyNarxMonomials::All),
        "frols-kfold" => Ok(mmenn::compare::PolyNarxMonomials::FrolsKfold),
        other => Err(format!("'{other}': all or frols-kfold")),
    }
}

/// A fraction in [0, 1).
fn fraction(text: &str) -> std::result::Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..1.0).contains(&v) => Ok(v),
        Ok(v) => Err(format!("{v} is not a fraction in [0, 1)")),
        Err(e) => Err(format!("'{text}' is not a number ({e})")),
    }
}

#[derive(Debug, Subcommand)]
pub(crate) enum Command {
    /// Simulate a built-in system: writes data.csv, truth.csv and model.toml.
    Simulate(SimulateArgs),
    /// Minimum Model Error estimate: smooth states and the model correction d(t).
    Estimate(EstimateArgs),
    /// Fit the MME/NN hybrid model: MME, network sizing sweep, free-run validation.
    Fit(FitArgs),
    /// Free-run (and k-step) prediction of any model mmenn writes on new data.
    Predict(PredictArgs),
    /// Print any model mmenn writes as equations (names, units, ±σ where known).
    Show(ShowArgs),
    /// Grey-box estimation: the free [parameters] of a physical model file and each
    /// record's start state by free-run output error, with ±σ and correlations.
    Greyest(GreyestArgs),
    /// Compare the assumed model, linear OE, linear SS (subspace + OE), NARX, polynomial
    /// NARX and MME/NN on the same data (free-run).
    Compare(CompareArgs),
    /// Find where model and data disagree, name the missing effect, add it, show the gap shrink.
    Discover(DiscoverArgs),
    /// Condition monitoring from identified models.
    #[command(subcommand)]
    Monitor(MonitorCommand),
}

#[derive(Debug, Args)]
pub(crate) struct CompareArgs {
    /// Estimation data file(s) (CSV).
    #[arg(long, required = true, num_args = 1..)]
    pub(crate) data: Vec<PathBuf>,
    /// Model file (TOML).
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Validation data file(s): every row is judged on them, and by default no row is
    /// chosen on them (see --val-use).
    #[arg(long, num_args = 1..)]
    pub(crate) val: Vec<PathBuf>,
    /// What --val is for (as `fit --val-use`): score (the default: every model is chosen
    /// on the estimation data, the validation fit is independent) or select (the MME/NN
    /// also makes its choices on them, as the thesis did; the baselines do not, so its row
    /// there is favoured).
    #[arg(long, value_name = "USE", default_value = "score")]
    pub(crate) val_use: mmenn::fit::ValidationUse,
    /// NARX delays (default: suggested from PACF/XCF).
    #[arg(long)]
    pub(crate) narx_lags: Option<usize>,
    /// How the NARX network's weights are estimated: `prediction` (one-step
    /// Levenberg–Marquardt) or `simulation` (then refined by free-run error over the
    /// estimation data, at most 30 Levenberg–Marquardt iterations).
    #[arg(long, value_name = "FOCUS", default_value = "prediction", value_parser = focus)]
    pub(crate) narx_focus: mmenn::compare::Focus,
    /// Polynomial NARX row (the NARX delays; monomials of the newest output lags and
    /// input taps, see --poly-nonlinear-lags; see --poly-focus): highest total degree,
    /// 1 to 5 (1: linear ARX), or 0 for no polynomial NARX row.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 3,
        value_parser = poly_degree,
        allow_negative_numbers = true
    )]
    pub(crate) poly_degree: usize,
    /// How many of the newest output lags and input taps (each channel) enter the
    /// polynomial NARX's monomials of degree 2 and more: at least 1 (a value above the
    /// NARX delays uses all of them).
    #[arg(long, value_name = "N", default_value_t = 2, value_parser = at_least_one)]
    pub(crate) poly_nonlinear_lags: usize,
    /// How the polynomial NARX coefficients are estimated: `prediction` (one-step least
    /// squares) or `simulation` (then refined by free-run error over the estimation data,
    /// at most 30 Levenberg–Marquardt iterations).
    #[arg(long, value_name = "FOCUS", default_value = "prediction", value_parser = focus)]
    pub(crate) poly_focus: mmenn::compare::Focus,
    /// Which monomials the polynomial NARX keeps: `all` (every monomial, one least-squares
    /// fit) or `frols-kfold` (sparse: FROLS ranks at most 40 on the first estimation
    /// record and the count is the smallest within 2 % of the best 5-fold free-run error,
    /// so the kept model runs free on every fold; --poly-focus must then be `prediction`).
    #[arg(long, value_name = "WHICH", default_value = "all", value_parser = poly_monomials)]
    pub(crate) poly_monomials: mmenn::compare::PolyNarxMonomials,
    /// Largest order of the linear state-space row (subspace, then free-run output error;
    /// the smallest order within 2 % of the best held-out free-run error is kept).
    #[arg(long, value_name = "N", default_value_t = 6, value_parser = at_least_one)]
    pub(crate) ss_max_order: usize,
    /// Largest network of the MME/NN sizing sweep.
    #[arg(long, default_value_t = 10, value_parser = at_least_one)]
    pub(crate) max_hidden: usize,
    /// Initialisations per network size (MME/NN).
    #[arg(long, default_value_t = 10, value_parser = at_least_one)]
    pub(crate) inits: usize,
    /// How the MME/NN networks are trained: trainlm or accelerated (as `fit --training`).
    #[arg(long, default_value = "trainlm")]
    pub(crate) training: mmenn::fit::Training,
    /// Where MME/NN's guard judges its candidates unless --val-use select: last-fifth or K-fold
    /// (as `fit --guard`).
    #[arg(long, default_value = "last-fifth")]
    pub(crate) guard: mmenn::fit::GuardHeldOut,
    /// What MME/NN's network does outside its training box: checked, extrapolate or hold
    /// (as `fit --network-domain`).
    #[arg(long, value_name = "POLICY", default_value = "checked")]
    pub(crate) network_domain: mmenn::fit::DomainPolicy,
    /// The same as `--network-domain hold` (as `fit --hold-network-domain`).
    #[arg(long, conflicts_with = "network_domain")]
    pub(crate) hold_network_domain: bool,
    /// What MME/NN's network reads: states-and-inputs or states (as `fit
    /// --network-inputs`).
    #[arg(long, default_value = "states-and-inputs")]
    pub(crate) network_inputs: mmenn::fit::NetworkInputs,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Output directory.
    #[arg(long)]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) prep: PrepArgs,
}

#[derive(Debug, Args)]
pub(crate) struct DiscoverArgs {
    /// List the catalogue of named effects (term, where it may enter) and exit.
    #[arg(long)]
    pub(crate) list_effects: bool,
    /// Estimation data file(s) (CSV).
    #[arg(long, required_unless_present = "list_effects", num_args = 1..)]
    pub(crate) data: Vec<PathBuf>,
    /// Model file (TOML).
    #[arg(long, required_unless_present = "list_effects")]
    pub(crate) model: Option<PathBuf>,
    /// Validation data file(s): they judge the free-run search's candidate sets and get
    /// their own before/after gap.
    #[arg(long, num_args = 1..)]
    pub(crate) val: Vec<PathBuf>,
    /// Without --val: fraction at the end of every estimation record held out to judge
    /// the free-run search (0: judge on the estimation records).
    #[arg(long, default_value_t = 0.5, value_parser = fraction)]
    pub(crate) holdout_fraction: f64,
    /// Most discover–augment rounds.
    #[arg(long, default_value_t = 3)]
    pub(crate) max_rounds: usize,
    /// Seed of the noise-floor simulation, the bootstrap judge and the stand-in's draws.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Reference draws of the flexible stand-in on d̂ (MME reruns on simulated copies of
    /// the data); 0 skips it, and then a `found`/`none` verdict rests on the bootstrap
    /// judge alone.
    #[arg(long, default_value_t = 12, value_parser = draws)]
    pub(crate) stand_in_draws: usize,
    /// Output directory.
    #[arg(long, required_unless_present = "list_effects")]
    pub(crate) out: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) prep: PrepArgs,
    #[command(flatten)]
    pub(crate) budget: BudgetArgs,
}

#[derive(Debug, Subcommand)]
pub(crate) enum MonitorCommand {
    /// Identify every labelled record and train the classifiers.
    Train(MonitorTrainArgs),
    /// Identify one record and classify its condition.
    Classify(MonitorClassifyArgs),
}

#[derive(Debug, Args)]
pub(crate) struct MonitorTrainArgs {
    /// A condition and its records: NAME=FILE[,FILE…] (repeat per condition).
    #[arg(long = "class", required = true)]
    pub(crate) classes: Vec<String>,
    /// Model file (TOML).
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Features: raw, canonical, physical or canonical+physical.
    #[arg(long, default_value = "canonical+physical")]
    pub(crate) features: mmenn::monitor::FeatureKind,
    /// Hidden units of each record's network.
    #[arg(long, default_value_t = 3, value_parser = at_least_one)]
    pub(crate) hidden: usize,
    /// Seed of the networks.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Output directory.
    #[arg(long)]
    pub(crate) out: PathBuf,
}

#[derive(Debug, Args)]
pub(crate) struct MonitorClassifyArgs {
    /// Directory written by `monitor train`.
    #[arg(long)]
    pub(crate) monitor: PathBuf,
    /// Data file to classify.
    #[arg(long)]
    pub(crate) data: PathBuf,
}

#[derive(Debug, Args)]
pub(crate) struct FitArgs {
    /// Training data file(s) (CSV).
    #[arg(long, required = true, num_args = 1..)]
    pub(crate) data: Vec<PathBuf>,
    /// Model file (TOML).
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Validation data file(s): the hybrid is judged free-run on them (see --val-use).
    #[arg(long, num_args = 1..)]
    pub(crate) val: Vec<PathBuf>,
    /// What --val is for: score (the default: every choice — the network sweep's test
    /// set, trajectory training's early stopping, the guard that keeps physics alone, the
    /// network or the refined network — is made on the training data as without --val, so
    /// the validation fit is independent) or select (those choices are made on the
    /// validation data, as the thesis did; their fit is then optimistic).
    #[arg(long, value_name = "USE", default_value = "score")]
    pub(crate) val_use: mmenn::fit::ValidationUse,
    /// Hidden units: "auto" (sizing sweep 1–10 × inits) or a number.
    #[arg(long, default_value = "auto")]
    pub(crate) hidden: mmenn::fit::HiddenChoice,
    /// Initialisations per network size.
    #[arg(long, default_value_t = 10, value_parser = at_least_one)]
    pub(crate) inits: usize,
    /// Largest network of the automatic sizing sweep.
    #[arg(long, default_value_t = 10, value_parser = at_least_one)]
    pub(crate) max_hidden: usize,
    /// How networks are trained: trainlm (MATLAB's schedule, the thesis) or accelerated
    /// (trainlm for 10 steps, then gain ratio with geodesic acceleration).
    #[arg(long, default_value = "trainlm")]
    pub(crate) training: mmenn::fit::Training,
    /// Update the assumed model by regression on d̂ first: none or regression (thesis §4.3.3).
    #[arg(long, default_value = "none")]
    pub(crate) update_model: mmenn::fit::ModelUpdateChoice,
    /// How the network is picked from the sweep: d-mse (thesis rule on the test MSE of d)
    /// or free-run (smallest free-run output error of the hybrid model on the training data).
    #[arg(long, default_value = "d-mse")]
    pub(crate) select: mmenn::fit::NetworkSelection,
    /// Keep one network (single) or average every sweep network within the sizing rule's
    /// band of the best test MSE into one wider network (band).
    #[arg(long, default_value = "single")]
    pub(crate) ensemble: mmenn::fit::NetworkEnsemble,
    /// Train the network on trajectories after training on d̂: yes or no
    /// (multiple-shooting LM on the free-run output error; thesis §7.1). The old spelling
    /// `--refine trajectory|none` still works.
    #[arg(long, alias = "refine", default_value = "yes")]
    pub(crate) train_on_trajectories: mmenn::fit::TrajectoryChoice,
    /// Samples per shooting window of the trajectory training (old spelling:
    /// `--refine-window`).
    #[arg(long, alias = "refine-window", default_value_t = 100, value_parser = at_least_one)]
    pub(crate) trajectory_window: usize,
    /// Where physics alone, the network and the refined network are judged unless the
    /// validation data choose (--val-use select): last-fifth (the last fifth of the first record) or
    /// K-fold, e.g. 5-fold (K stretches, the networks retrained without each; K more
    /// trainings).
    #[arg(long, default_value = "last-fifth")]
    pub(crate) guard: mmenn::fit::GuardHeldOut,
    /// What the network does outside the box its training pairs spanned (saved in
    /// model.json; `predict` and `simulate` use it). checked: the guard runs each network
    /// candidate and the physics alone free on the held-out input scaled by 1.5 about its
    /// mean; a candidate whose run fails, or which changes the physics' response by more
    /// than the response's own RMS size on any output, holds, the others extrapolate (the
    /// summary says which, with the numbers). extrapolate: the network is evaluated
    /// wherever it is asked (the thesis), unchecked. hold: each network input (states,
    /// inputs) is clamped to its training range, so beyond the data the correction keeps
    /// its edge value and only the physics extrapolates.
    #[arg(long, value_name = "POLICY", default_value = "checked")]
    pub(crate) network_domain: mmenn::fit::DomainPolicy,
    /// The same as `--network-domain hold`.
    #[arg(long, conflicts_with = "network_domain")]
    pub(crate) hold_network_domain: bool,
    /// What the network reads: states-and-inputs (x̂, u; the thesis) or states (x̂ alone,
    /// for a model that already carries the input's path: a wider input than the training
    /// one cannot push the network outside its training box). model.json records it
    /// through the network's input count.
    #[arg(long, default_value = "states-and-inputs")]
    pub(crate) network_inputs: mmenn::fit::NetworkInputs,
    /// Correction weight W for MME: "auto" or a positive number.
    #[arg(long, default_value = "auto")]
    pub(crate) w: mmenn::estimate::WeightChoice,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Output directory.
    #[arg(long)]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) prep: PrepArgs,
    #[command(flatten)]
    pub(crate) budget: BudgetArgs,
}

#[derive(Debug, Args)]
pub(crate) struct ShowArgs {
    /// Model: a model file (TOML, with or without [[terms]]), model.discovered.toml, or
    /// fit's model.json.
    pub(crate) model: PathBuf,
}

#[derive(Debug, Args)]
pub(crate) struct PredictArgs {
    /// Model: a model file (TOML, with or without [[terms]]), model.discovered.toml, or
    /// fit's model.json (told apart by content).
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Data file with the inputs (and, optionally, state or output columns to compare with).
    #[arg(long)]
    pub(crate) data: PathBuf,
    /// Initial state, comma-separated (default: fitted to the first samples of this record).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    pub(crate) x0: Option<Vec<f64>>,
    /// Samples used to fit the initial state (from the start of the record).
    #[arg(long, default_value_t = 200, value_parser = at_least_one)]
    pub(crate) x0_window: usize,
    /// Also predict k steps ahead (beside the free run, labelled).
    #[arg(long, value_parser = at_least_one)]
    pub(crate) horizon: Option<usize>,
    /// First sample (0-based) the metrics score (default: every sample). The benchmark
    /// protocols score after their initialisation window: `--x0-window 50 --score-from 50`
    /// (Cascaded Tanks, Silverbox) or 20 and 20 (EMPS).
    #[arg(long, value_name = "N")]
    pub(crate) score_from: Option<usize>,
    /// RK4 steps per sample interval of a model file's free run: `auto` (the default:
    /// four, or as many as a stiff model needs for stability along the record) or a
    /// number, 1 to 1000. A hybrid model (model.json) keeps the steps it was trained with.
    #[arg(long, value_parser = predict_substeps)]
    pub(crate) substeps: Option<mmenn::sysid_core::Substeps>,
    /// Output directory.
    #[arg(long)]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) prep: PrepArgs,
}

/// Data preparation shared by the commands that read data files.
#[derive(Debug, Args)]
pub(crate) struct PrepArgs {
    /// Resample every data file onto a uniform grid with this step, s (linear
    /// interpolation; the prepared files and a report go to OUT/prepared/). Without it a
    /// non-uniform time column is an error naming the row.
    #[arg(long, value_name = "DT")]
    pub(crate) resample: Option<f64>,
    /// Use file columns under the model's names, e.g. `--map t=time,theta1=pos_meas1`.
    #[arg(long, value_name = "NAME=COLUMN,...")]
    pub(crate) map: Vec<String>,
}

#[derive(Debug, Args)]
pub(crate) struct GreyestArgs {
    /// Data file(s) (CSV); several files are several records, each with its own start
    /// state.
    #[arg(long, required = true, num_args = 1..)]
    pub(crate) data: Vec<PathBuf>,
    /// Model file (TOML) with a [parameters] table: its free parameters are estimated
    /// within their bounds, the fixed ones are kept.
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Multiple shooting before the free run: segments of this many samples, each from
    /// its own start state (for long or lightly damped records). Default: free run only.
    #[arg(long, value_name = "SAMPLES", value_parser = at_least_two)]
    pub(crate) shooting: Option<usize>,
    /// RK4 steps per sample interval: `auto` (two, or as many as a stiff model needs
    /// for stability along each record, e.g. a steep friction law near rest) or a number,
    /// 1 to 1000, taken as given.
    #[arg(long, default_value = "auto", value_parser = free_run_substeps)]
    pub(crate) substeps: mmenn::sysid_core::Substeps,
    /// Start of named states of every record's initial state, NAME=VALUE (repeatable or
    /// comma-separated); the others start from the measured outputs' minimum-norm state.
    /// For an unmeasured state whose default start (0) sits where a term has no slope,
    /// e.g. a tank level under sqrt: `--x0 h1=5`.
    #[arg(long, value_name = "NAME=VALUE", value_delimiter = ',', value_parser = name_value)]
    pub(crate) x0: Vec<(String, f64)>,
    /// Most Levenberg–Marquardt iterations per solve.
    #[arg(long, default_value_t = 100, value_parser = at_least_one)]
    pub(crate) max_iterations: usize,
    /// Seeded starts besides the model file's own, run in parallel; the lowest final cost
    /// is kept, and report.md lists every start, the distinct minima, and warns when
    /// another minimum is nearly as good (within 1 %, or the likelihood-ratio bound when
    /// wider) with a parameter more than 10 % different (the data do not pin it). Start k multiplies each non-zero free start
    /// value by exp(0.7 z), z ~ N(0, 1) (sign kept), and draws a zero one uniformly within
    /// its bounds, or, with an infinite bound, as s·z with s the size of the model file's
    /// own start's estimate of it. Default 0: the model file's start only.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub(crate) starts: usize,
    /// Seed of --starts: start k draws from a ChaCha8 generator seeded with SEED + k.
    #[arg(long, value_name = "SEED", default_value_t = 1)]
    pub(crate) seed: u64,
    /// Output directory: model.toml (estimates with sigma), greyest.json, report.md.
    #[arg(long)]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) prep: PrepArgs,
    #[command(flatten)]
    pub(crate) budget: BudgetArgs,
}

#[derive(Debug, Args)]
pub(crate) struct EstimateArgs {
    /// Data file(s) (CSV); several files are several experiments.
    #[arg(long, required = true, num_args = 1..)]
    pub(crate) data: Vec<PathBuf>,
    /// Model file (TOML). An optional [x0_prior] table (state = { mean, std }) puts a
    /// Gaussian prior on each record's initial state; states left out start free.
    #[arg(long)]
    pub(crate) model: PathBuf,
    /// Correction weight W: "auto" (covariance constraint) or a positive number (W = value·I).
    #[arg(long, default_value = "auto")]
    pub(crate) w: mmenn::estimate::WeightChoice,
    /// Robust estimate: Huber weights (c = 2σ) by iterating the exact sweep on
    /// pseudo-observations, so a few wild samples cannot move W; outliers are reported.
    #[arg(long)]
    pub(crate) robust: bool,
    /// Sub-steps per sample interval, 1 to 1000 (default: chosen from the model).
    #[arg(long, value_parser = substeps)]
    pub(crate) substeps: Option<usize>,
    /// Output directory.
    #[arg(long)]
    pub(crate) out: PathBuf,
    #[command(flatten)]
    pub(crate) prep: PrepArgs,
    #[command(flatten)]
    pub(crate) budget: BudgetArgs,
}

#[derive(Debug, Args)]
pub(crate) struct SimulateArgs {
    /// List the systems, their parameters and recipes, and exit.
    #[arg(long)]
    pub(crate) list: bool,
    /// System name (see --list).
    #[arg(long, required_unless_present = "list")]
    pub(crate) system: Option<String>,
    /// Recipe: train or test (a different input signal).
    #[arg(long, default_value = "train")]
    pub(crate) recipe: Recipe,
    /// Measurement noise variance per measured channel (overrides the system's default).
    #[arg(long)]
    pub(crate) noise_variance: Option<f64>,
    /// Sample rate, Hz (overrides the system's default).
    #[arg(long)]
    pub(crate) fs: Option<f64>,
    /// Seed of every random choice (noise, random inputs).
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Duration, s (overrides the recipe's default).
    #[arg(long)]
    pub(crate) duration: Option<f64>,
    /// Parameter override NAME=VALUE (repeatable; see --list).
    #[arg(long = "param", value_name = "NAME=VALUE")]
    pub(crate) params: Vec<String>,
    /// Output directory.
    #[arg(long, required_unless_present = "list")]
    pub(crate) out: Option<PathBuf>,
}

/// Default of `--budget`, s.
pub(crate) const DEFAULT_BUDGET_SECONDS: f64 = 600.0;

/// The job's time budget (`--budget`).
#[derive(Debug, Args)]
pub(crate) struct BudgetArgs {
    /// Stop with an error naming the stage that ran out and how far it got (exit status 4)
    /// once the estimation (MME's iterations; greyest's and discover's free-run
    /// calibrations) has run this many seconds; `inf` for no limit.
    #[arg(long, value_name = "SECONDS", default_value_t = DEFAULT_BUDGET_SECONDS, value_parser = budget_seconds)]
    pub(crate) budget: f64,
}

impl BudgetArgs {
    /// The budget, starting now (`inf` = unlimited).
    pub(crate) fn start(&self) -> mmenn::sysid_core::Budget {
        mmenn::sysid_core::Budget::seconds(self.budget).unwrap_or_default()
    }
}

fn budget_seconds(text: &str) -> std::result::Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v >= 0.0 => Ok(v),
        _ => Err(format!(
            "'{text}' is not a number of seconds >= 0 (or inf for no limit)"
        )),
    }
}
