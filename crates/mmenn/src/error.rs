//! The facade's error type: file problems carry the path and, where it applies, the line,
//! column or matrix; errors of the numerical crates are wrapped with what was being done.

use std::path::PathBuf;

use thiserror::Error;

/// What is wrong in a CSV data file.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum CsvProblem {
    /// The file has no header row.
    #[error("the file is empty (no header row)")]
    Empty,
    /// There is no `t` column.
    #[error("there is no 't' column in the header")]
    NoTimeColumn,
    /// A header name appears twice.
    #[error("column name '{0}' appears twice in the header")]
    DuplicateColumn(String),
    /// A header name is empty.
    #[error("a column name in the header is empty")]
    EmptyColumnName,
    /// A row has a different number of fields than the header.
    #[error("row has {found} fields, the header has {expected}")]
    Ragged {
        /// Fields in the header.
        expected: usize,
        /// Fields in this row.
        found: usize,
    },
    /// A cell is not a number.
    #[error("'{text}' is not a number")]
    NotANumber {
        /// The cell text.
        text: String,
    },
    /// A cell that must be present (time or an input) is empty or NaN.
    #[error("the value is missing or NaN, but {kind} must be complete")]
    Missing {
        /// `time` or `input`.
        kind: &'static str,
    },
    /// A cell is infinite.
    #[error("the value is infinite")]
    Infinite,
    /// Time does not increase.
    #[error("time {t} does not increase after {t_prev}")]
    NonIncreasingTime {
        /// Previous time, s.
        t_prev: f64,
        /// This time, s.
        t: f64,
    },
    /// Time is not uniformly sampled.
    #[error(
        "time step {step} s differs from the file's typical (median) step {dt} s: data must \
         be uniformly sampled (resample it explicitly with --resample DT)"
    )]
    NonUniformTime {
        /// Step found, s.
        step: f64,
        /// The file's median step, s.
        dt: f64,
    },
    /// Time values so large that `f64` cannot resolve the sample step.
    #[error(
        "time values up to {t} s are too large for double precision to resolve the step \
         {dt} s: subtract a time offset (e.g. start at 0)"
    )]
    TimeResolution {
        /// Largest |t|, s.
        t: f64,
        /// Mean step, s.
        dt: f64,
    },
    /// Fewer than two data rows.
    #[error("the file has {0} data rows; at least 2 are needed")]
    TooFewRows(usize),
    /// A channel the model needs is not in the file.
    #[error(
        "the model needs a column '{name}', which is not in the header (its columns: \
         {header}); a column of another name can stand in for it with --map {name}=COLUMN"
    )]
    MissingChannel {
        /// The name looked for.
        name: String,
        /// The file's header, comma-separated.
        header: String,
    },
    /// The CSV parser itself failed (bad quoting, invalid UTF-8).
    #[error("unreadable CSV: {0}")]
    Syntax(String),
}

/// What is wrong in a TOML model file.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum ModelProblem {
    /// TOML syntax or a key of the wrong type / unknown key.
    #[error("{message}")]
    Syntax {
        /// Parser message.
        message: String,
    },
    /// A matrix row has the wrong length.
    #[error("matrix {matrix}: row {row} has {found} entries, expected {expected}")]
    RaggedRow {
        /// Matrix key.
        matrix: &'static str,
        /// Row index (0-based).
        row: usize,
        /// Entries found.
        found: usize,
        /// Entries expected.
        expected: usize,
    },
    /// A matrix has the wrong number of rows.
    #[error("matrix {matrix} has {found} rows, expected {expected}")]
    Rows {
        /// Matrix key.
        matrix: &'static str,
        /// Rows found.
        found: usize,
        /// Rows expected.
        expected: usize,
    },
    /// A key that is required in this combination is missing.
    #[error("key '{key}' is required: {why}")]
    MissingKey {
        /// The key.
        key: &'static str,
        /// Why it is needed.
        why: &'static str,
    },
    /// Keys that exclude each other are both present.
    #[error("keys '{a}' and '{b}' cannot both be given")]
    Conflict {
        /// First key.
        a: &'static str,
        /// Second key.
        b: &'static str,
    },
    /// A name in `measured`, `corrected`, `units` or a term is not a state/input.
    #[error("'{name}' in '{key}' is not a known {kind}")]
    UnknownName {
        /// The key where it appears.
        key: &'static str,
        /// The name.
        name: String,
        /// What it should be.
        kind: &'static str,
    },
    /// A state, input or output name that cannot be a CSV column or a file name part.
    #[error("'{name}' in '{key}' is not a usable name: {reason}")]
    BadName {
        /// The key where it appears.
        key: &'static str,
        /// The name.
        name: String,
        /// What is wrong.
        reason: &'static str,
    },
    /// The model has no states.
    #[error("'states' is empty: the model needs at least one state")]
    NoStates,
    /// `noise_variance` is neither a list nor "auto".
    #[error("noise_variance must be a list of positive numbers or \"auto\", got \"{0}\"")]
    NoiseWord(String),
    /// `noise_variance` has the wrong length.
    #[error("noise_variance has {found} entries, but there are {expected} measured channels")]
    NoiseLength {
        /// Entries found.
        found: usize,
        /// Measured channels.
        expected: usize,
    },
    /// A noise variance is not positive.
    #[error("noise_variance[{index}] = {value} must be positive and finite")]
    NonPositiveVariance {
        /// Index.
        index: usize,
        /// Value.
        value: f64,
    },
    /// A named term does not parse or names an unknown state or input.
    #[error(transparent)]
    Term(Box<sysid_core::TermError>),
    /// The model is inconsistent (shape, non-finite entry, duplicate name).
    #[error(transparent)]
    Model(#[from] sysid_core::CoreError),
    /// A parameter, the mechanics part or an expression in it is invalid.
    #[error(transparent)]
    Physical(Box<sysid_core::PhysicalError>),
    /// A mass-matrix model was given to a step that needs the state-space form with
    /// named terms (`M⁻¹` is not a sum of terms).
    #[error(
        "{what} needs a state-space model with named terms; this model has a [mechanics] \
         part (mass-matrix form), whose dynamics are not A and B"
    )]
    Mechanical {
        /// The step that needs the state-space form.
        what: &'static str,
    },
    /// A step built on MME's correction was given a model that corrects no equation:
    /// MME would only smooth, its `d̂` is zero by construction, and the step's answer
    /// (nothing missing) would be an artefact of the file.
    #[error(
        "{what} estimates the correction d̂ of the equations the model file names in \
         `corrected`, and this model file corrects none (`corrected` is missing or empty), so \
         d̂ would be zero whatever the data: add `corrected = [{suggestion}]` (the equations \
         that may be wrong{why})"
    )]
    Uncorrected {
        /// The step that needs a correction.
        what: &'static str,
        /// The states to suggest, quoted and comma-separated.
        suggestion: String,
        /// Why those states, when the model says (e.g. the rates of `[mechanics]`).
        why: &'static str,
    },
    /// The `[acquisition]` table is malformed.
    #[error("{key}{}: {reason}", row.map(|r| format!(", row {r}")).unwrap_or_default())]
    Acquisition {
        /// The key (`acquisition.pass_below_hz`, `acquisition.bands`).
        key: &'static str,
        /// The band row (0-based), for `bands`.
        row: Option<usize>,
        /// What is wrong.
        reason: String,
    },
    /// A step that does not read the `[acquisition]` table was given a model with one.
    #[error(
        "{what} does not read the [acquisition] table yet (fit, predict, compare and show \
         do): its numbers would ignore the filter, so take the table out for this step"
    )]
    AcquisitionUnread {
        /// The step.
        what: &'static str,
    },
    /// An entry of `[x0_prior]` is invalid: a `mean` that is not finite or a `std` that
    /// is not positive and finite.
    #[error(
        "x0_prior.{state}.{field} = {value} must be {}",
        if *field == "mean" { "finite" } else { "positive and finite" }
    )]
    Prior {
        /// The state.
        state: String,
        /// `mean` or `std`.
        field: &'static str,
        /// The value given.
        value: f64,
    },
    /// A step that does not apply the initial-state prior was given a model with one.
    #[error(
        "{what} does not apply the [x0_prior] table (only estimate does: {}), so take the \
         table out for this step",
        if *what == "greyest" {
            "greyest calibrates each record's start state by free-run error without a prior, \
             and the model.toml it writes would not carry the table"
        } else {
            "the MME runs of this step start at other states, on validation records and folds"
        }
    )]
    PriorUnread {
        /// The step.
        what: &'static str,
    },
    /// The file is none of the models mmenn writes (a model-file TOML, with or without
    /// `[[terms]]`, or `fit`'s `model.json`).
    #[error("not a model mmenn reads: {why}")]
    NotAModel {
        /// What was found instead.
        why: String,
    },
}

impl From<sysid_core::PhysicalError> for ModelProblem {
    fn from(e: sysid_core::PhysicalError) -> Self {
        ModelProblem::Physical(Box::new(e))
    }
}

impl From<sysid_core::TermError> for ModelProblem {
    fn from(e: sysid_core::TermError) -> Self {
        ModelProblem::Term(Box::new(e))
    }
}

/// Errors of the facade.
#[derive(Debug, Error)]
#[non_exhaustive]
pub enum MmennError {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A CSV data file is malformed.
    #[error("{path}:{line}{}: {problem}", column.as_ref().map(|c| format!(", column '{c}'")).unwrap_or_default())]
    Csv {
        /// The file.
        path: PathBuf,
        /// 1-based line number (1 = header).
        line: usize,
        /// Column name, when one is involved.
        column: Option<String>,
        /// What is wrong.
        problem: CsvProblem,
    },
    /// A TOML model file is malformed.
    #[error("{path}{}: {problem}", line.map(|l| format!(":{l}:{}", column.unwrap_or(0))).unwrap_or_default())]
    Model {
        /// The file.
        path: PathBuf,
        /// 1-based line, when known.
        line: Option<usize>,
        /// 1-based column, when known.
        column: Option<usize>,
        /// What is wrong.
        problem: ModelProblem,
    },
    /// An output folder cannot be used (it holds another run's or the user's files, or an
    /// input file).
    #[error("output folder {path}: {reason}")]
    OutputDir {
        /// The folder.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A simulated system could not be generated.
    #[error("simulation: {0}")]
    Plant(#[from] plants::PlantError),
    /// A core-vocabulary error while doing something named.
    #[error("{context}: {source}")]
    Core {
        /// What was being done.
        context: &'static str,
        /// The error.
        #[source]
        source: sysid_core::CoreError,
    },
    /// Drawing a figure failed.
    #[error("drawing a figure: {0}")]
    Plot(String),
    /// The MME estimator failed.
    #[error("MME: {0}")]
    Mme(#[from] mme_core::MmeError),
    /// The MME estimator found the model non-finite in an equation with named terms.
    #[error("MME: {source}; named terms in that equation: {terms}")]
    MmeTerms {
        /// The estimator's error.
        source: mme_core::MmeError,
        /// The terms, as `effect = coefficient·(term)`.
        terms: String,
    },
    /// MME could not determine a record's initial state: names the state where the
    /// factorisation failed and what usually helps.
    #[error(
        "MME: {source}; the first state not determined by the measurements given the ones \
         before it is '{state}'. A state the outputs see only briefly from the record's first \
         sample (a fast lag, a state the first samples do not excite) does this: starting the \
         record a few samples later, or a model without that state, usually helps"
    )]
    MmeUnobservable {
        /// The estimator's error.
        source: mme_core::MmeError,
        /// The state's name.
        state: String,
    },
    /// An MME estimate `fit` builds on did not converge, and the fit's policy refuses to
    /// train a network on its `d̂` ([`crate::fit::UnconvergedMme::Refuse`], the library's
    /// default): returned as soon as that estimate ends, before any network is trained.
    #[error(
        "MME's {report}. No network was trained on its d̂, which is not MME's estimate: {}; \
         FitOptions::on_unconverged_mme = Warn builds the hybrid anyway, for inspection",
        report.remedy()
    )]
    MmeNotConverged {
        /// Which estimate, how it ended and its residual/noise variance ratios.
        report: crate::fit::MmeConvergence,
    },
    /// A network could not be built or trained.
    #[error("network: {0}")]
    Nn(#[from] nn::NnError),
    /// Condition monitoring failed.
    #[error("condition monitoring: {0}")]
    Condmon(#[from] condmon::CondmonError),
    /// A baseline model failed.
    #[error("baseline model: {0}")]
    Baseline(#[from] sysid_baselines::BaselineError),
    /// Discovery failed.
    #[error("discovery: {0}")]
    Discovery(#[from] discovery::DiscoveryError),
    /// JSON serialisation failed.
    #[error("writing JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// An option names a state the model does not have.
    #[error("{option}: the model has no state '{name}' (its states: {states})")]
    UnknownState {
        /// The option, e.g. `--x0`.
        option: &'static str,
        /// The name given.
        name: String,
        /// The model's states, comma-separated.
        states: String,
    },
    /// `predict`'s first scored sample is not in the record.
    #[error(
        "--score-from {first}: the record has {len} samples (the first scored sample is \
         0-based, so it must be below {len})"
    )]
    ScoreFromBeyondRecord {
        /// The first sample asked to be scored.
        first: usize,
        /// Samples in the record.
        len: usize,
    },
    /// A record judged or fitted through a model's acquisition filter misses a sample.
    #[error(
        "the model's [acquisition] filter needs every sample of channel '{channel}', but \
         sample {sample} (0-based) is missing: the filter's inverse would spread it over the \
         filter's length"
    )]
    AcquisitionMissing {
        /// The channel.
        channel: String,
        /// The first missing sample.
        sample: usize,
    },
    /// k-step prediction was asked of a model with an acquisition filter.
    #[error(
        "k-step prediction (--horizon) is not defined through the model's [acquisition] \
         filter, which acts on whole records (non-causal): predict it free-run"
    )]
    AcquisitionKStep,
    /// A real benchmark's data folder is in none of the places searched.
    #[error(
        "benchmark data '{benchmark}' not found (looked in: {searched:?}); pass --data-dir or set MMENN_DATA_DIR"
    )]
    BenchmarkMissing {
        /// The benchmark's folder name.
        benchmark: &'static str,
        /// The data folders searched, in order.
        searched: Vec<PathBuf>,
    },
}

/// Result alias of the facade.
pub type Result<T, E = MmennError> = std::result::Result<T, E>;
