//! `mmenn discover`: find where the assumed model and the data disagree, name the missing
//! physical effect, add it to the model, calibrate it by free-run error, rerun MME, and
//! show the gap before and after on estimation and validation data.
//!
//! Rounds: MME → noise floor of `d̂` (MME on data simulated from the assumed model itself
//! with the same noise, `W` and `R`) → selection over the catalogue → augment and
//! calibrate → repeat while a significant effect is found (at most `max_rounds`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use discovery::{
    Discovery, DiscoveryConfig, Localisation, LocaliseConfig, NoiseFloor, RefineCandidate,
    RefineConfig, Verdict,
};
use nalgebra::DMatrix;
use serde::Serialize;
use sysid_core::{
    Channel, Dataset, Experiment, InitialStateFit, TermModel, channel_metrics, fit_initial_state,
};

use crate::atomic::{ensure_dir, write_atomic};
use crate::error::{MmennError, Result};
use crate::estimate::{EstimateOptions, estimate_spec, mme_config};
use crate::model_file::{ModelSpec, NoiseVariance, TermEntry, read_model, write_model};
use discovery::measured_values;
use holdout::{holdout_initial_states, recalibrate_on, split_records};
use report::{figures, report};

mod holdout;
mod report;

/// Largest free-run cost `J = (1/M) Σ r²/R` (1 for a right model and right noise
/// variance) at which named effects are claimed when `R` is estimated (`noise_variance =
/// "auto"`): twice the noise power leaves room for an estimated `R` and a coloured
/// residual, but not for a missing effect. It also ends the rounds: a round that leaves
/// the cost above it is not proven by MME.
pub const CONFIRM_COST: f64 = 2.0;

/// The free-run cost on `measured` judged values below which named effects are claimed.
/// With `R` given, a right model must reach the noise level itself: `J ≤ 1 + 3√(2/M)`
/// (`M·J` is χ²_M, standard deviation `√(2M)`), the bound that also separates `none` from
/// `unexplained`. A set of terms that fits "nearly" — a local optimum that names effects
/// in the wrong equations, as on a partially observed cascade — stays unclaimed. With
/// `R` estimated, [`CONFIRM_COST`].
pub fn claim_bound(noise: &NoiseVariance, measured: usize) -> f64 {
    match noise {
        NoiseVariance::Given(_) => noise_level_bound(measured),
        NoiseVariance::Auto => CONFIRM_COST,
    }
}

/// `1 + 3√(2/M)`: the largest free-run cost of a right model on `M` values (3σ).
fn noise_level_bound(measured: usize) -> f64 {
    1.0 + 3.0 * (2.0 / measured.max(1) as f64).sqrt()
}

/// Options of [`run_discover`].
#[derive(Debug, Clone, PartialEq)]
pub struct DiscoverOptions {
    /// MME settings.
    pub estimate: EstimateOptions,
    /// Most discover–augment rounds.
    pub max_rounds: usize,
    /// Seed of the noise-floor simulation.
    pub seed: u64,
    /// Samples used to fit free-run initial states.
    pub x0_window: usize,
    /// Fraction of samples dropped at each end of every record before selection: a
    /// smoother's `d̂` is least reliable at the ends (end effects), and on a decaying
    /// response the ends carry the largest states, hence the most leverage. Default 0.05.
    pub trim_fraction: f64,
    /// Smallest relative drop of `d̂`'s mean square (over its floor) that accepts a
    /// round's terms. Default 0.1.
    pub min_d_drop: f64,
    /// Without validation records, the fraction at the end of every estimation record
    /// held out to judge the free-run search's candidate sets (coefficients are calibrated
    /// on the rest). 0 judges on the estimation records themselves. Default 0.5 (0.3
    /// named quadratic drag for viscous damping on the decaying MSD record, whose last
    /// 30 % holds only small velocities; 0.2 and 0.5 named it right).
    pub holdout_fraction: f64,
}

/// Drop `fraction` of the samples at each end of every record.
fn trim_ends(samples: &[discovery::Samples], fraction: f64) -> Result<Vec<discovery::Samples>> {
    samples
        .iter()
        .map(|s| {
            let n = s.len();
            let cut = ((n as f64) * fraction).floor() as usize;
            let keep = n.saturating_sub(2 * cut).max(1);
            let start = cut.min(n - keep);
            Ok(discovery::Samples::new(
                s.states().columns(start, keep).into_owned(),
                s.inputs().columns(start, keep).into_owned(),
                s.corrections().columns(start, keep).into_owned(),
            )?)
        })
        .collect()
}

impl Default for DiscoverOptions {
    fn default() -> Self {
        Self {
            estimate: EstimateOptions::default(),
            max_rounds: 3,
            seed: 1,
            x0_window: 200,
            trim_fraction: 0.05,
            min_d_drop: 0.1,
            holdout_fraction: 0.5,
        }
    }
}

/// Fit %, RMSE (free-run, per measured channel) and `d̂` RMS (per corrected equation).
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct Gap {
    /// Free-run fit % per channel.
    pub fit_percent: BTreeMap<String, f64>,
    /// Free-run RMSE per channel.
    pub rmse: BTreeMap<String, f64>,
    /// RMS of MME's `d̂` per corrected equation.
    pub d_rms: BTreeMap<String, f64>,
}

/// Before and after on one data set.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GapPair {
    /// With the assumed model.
    pub before: Gap,
    /// With the discovered model.
    pub after: Gap,
}

/// A named effect as `discovery.json` reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NamedEffect {
    /// Catalogue name.
    pub name: String,
    /// Equation (state) it enters.
    pub state: String,
    /// For a transfer: the equation (state) that receives the negated term — the flow
    /// leaves `state` and enters `into` (absent for an ordinary term).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub into: Option<String>,
    /// Expression, as written into the model.
    pub term: String,
    /// Coefficient calibrated by free-run simulation error.
    pub coefficient: f64,
    /// 95 % interval of `coefficient` (the free-run fit's Gauss–Newton standard error,
    /// inflated for residual colour; ±1.96 σ).
    pub ci95: Option<[f64; 2]>,
    /// 95 % interval of the regression on `d̂` (when the regression named it): of the
    /// regression's own, shrunk coefficient, not of `coefficient`.
    pub ci95_regression: Option<[f64; 2]>,
    /// Share of `d̂` it explains in the regression (when the regression named it).
    pub share_of_d: Option<f64>,
    /// Which stage named it.
    pub named_by: String,
    /// The term's shaping parameters by name (a saturation's `limit`, a dead zone's
    /// `width`, a smoothed Coulomb law's `eps`, a Stribeck `v_s`), as calibrated.
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub parameters: BTreeMap<String, f64>,
    /// For a linear term (a bare state or input): the assumed model's entry it adds to.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub adjusts: Option<AssumedEntry>,
}

/// The entry of the assumed `A` or `B` that a linear named term adds to: a linear term
/// is a recalibration of the assumed model, and when it cancels the entry
/// (`effective ≈ 0`) the named effect beside it *replaces* the assumed law (an orifice
/// outflow replacing a linear one).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AssumedEntry {
    /// `A` or `B`.
    pub matrix: &'static str,
    /// Row (state) name.
    pub row: String,
    /// Column (state or input) name.
    pub column: String,
    /// The assumed value.
    pub assumed: f64,
    /// Assumed value plus the term's coefficient.
    pub effective: f64,
    /// Whether the 95 % interval of `effective` (the coefficient's calibrated interval,
    /// shifted) contains 0: the assumed term is cancelled.
    pub cancelled: bool,
}

/// The assumed entry a bare-variable term `term` in equation `state` adds to.
fn assumed_entry(
    spec: &ModelSpec,
    state: &str,
    term: &str,
    coefficient: f64,
    ci: Option<[f64; 2]>,
) -> Option<AssumedEntry> {
    let lin = &spec.linear;
    let row = lin.state_names().iter().position(|s| s == state)?;
    let (matrix, value) = match lin.state_names().iter().position(|s| s == term) {
        Some(j) => ("A", lin.a()[(row, j)]),
        None => {
            let j = lin.input_names().iter().position(|s| s == term)?;
            ("B", lin.b()[(row, j)])
        }
    };
    let effective = value + coefficient;
    Some(AssumedEntry {
        matrix,
        row: state.to_string(),
        column: term.to_string(),
        assumed: value,
        effective,
        cancelled: value != 0.0
            && ci.is_some_and(|[lo, hi]| lo + value <= 0.0 && 0.0 <= hi + value),
    })
}

impl NamedEffect {
    /// Where it enters, for reports: `d(h1)`, or `d(h1) and −d(h2) (transfer h1 → h2)`.
    pub fn equations(&self) -> String {
        match &self.into {
            None => format!("d({})", self.state),
            Some(r) => format!(
                "d({}) and −d({r}) (transfer {} → {r})",
                self.state, self.state
            ),
        }
    }
}

/// One round of discovery.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Round {
    /// The selection's full report (verdict, effects, per-equation steps, roles).
    pub discovery: Discovery,
    /// Where `d̂` and the free-run error exceed their floors.
    pub localisation: Localisation,
    /// `d̂` RMS floor per corrected equation.
    pub floor_rms: Vec<f64>,
    /// Coefficients after free-run calibration (in the order of `discovery.effects`).
    pub calibrated: Vec<f64>,
    /// Free-run cost (`Σ r²/R`) of the model before the round and after it.
    pub calibration_cost: [f64; 2],
    /// The free-run search's add/remove decisions.
    pub refinement: Vec<discovery::RefineStep>,
    /// Why the round's terms were not accepted, when they were not.
    pub rejected: Option<String>,
}

/// `discovery.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DiscoverSummary {
    /// `found` if a round was accepted; `unexplained` if a round was rejected or the
    /// free-run search left a cost above the noise level; else `none`.
    pub verdict: Verdict,
    /// Every named effect, with its calibrated coefficient and the regression's interval.
    pub effects: Vec<NamedEffect>,
    /// Terms that improved the model (and are in `model.discovered.toml`) but did not
    /// bring its free-run cost down to the noise level, so they are not claimed as the
    /// missing physics (verdict `unexplained`).
    pub unconfirmed: Vec<NamedEffect>,
    /// The free-run cost (on the judging records, 1 = the noise level) below which named
    /// effects are claimed, or the model is judged to need none: the reference quantile
    /// of `judgement` when the bootstrap ran, else [`claim_bound`].
    pub claim_bound: f64,
    /// The judged statistic and its reference distribution under the pipeline that
    /// produced it (parametric bootstrap, see `discovery::judge`); `None` when no free-run
    /// search ran or the bootstrap could not complete (`judge_note` says why).
    pub judgement: Option<discovery::Judgement>,
    /// Terms the free-run search kept that the judge's test showed unneeded (dropped
    /// from the model before the claim).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub passengers: Vec<String>,
    /// Why the bootstrap judge did not decide, when it did not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub judge_note: Option<String>,
    /// Gap on the estimation data (`before`, `after`), and on validation data when given.
    pub gap: GapPair,
    /// Gap on the validation data.
    pub validation_gap: Option<GapPair>,
    /// When named effects were not claimed because the data cannot tell them from
    /// another set of terms (partial observation), the two explanations.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ambiguity: Option<Ambiguity>,
    /// The augmented model file.
    pub model: String,
    /// Every round.
    pub rounds: Vec<Round>,
}

/// Two sets of terms that both bring the free-run cost to the noise level, found when
/// the first touches an unmeasured state whose scale the measurements leave free (see
/// `discovery::gauge`): the search run again without the terms touching such states
/// found the second. Neither is claimed (verdict `unexplained`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ambiguity {
    /// The states whose scale no measurement or known equation fixes.
    pub free_states: Vec<String>,
    /// The search's set (`equation: term`) and its judged free-run cost.
    pub named: Vec<String>,
    /// Its judged free-run cost.
    pub named_cost: f64,
    /// The set found without the named terms that touch `free_states`.
    pub alternative: Vec<String>,
    /// Its judged free-run cost.
    pub alternative_cost: f64,
}

/// What judges a round's model: the records and initial-state guesses of its free-run
/// search, the model as calibrated on the calibration records only (before any
/// recalibration on the whole records), the indices of the terms the round calibrated,
/// and the noise variance of the judged cost.
#[derive(Debug, Clone)]
struct JudgeContext {
    model: TermModel,
    new_terms: Vec<usize>,
    cal: Dataset,
    cal_x0: Vec<Vec<f64>>,
    hold: Option<(Dataset, Vec<Vec<f64>>)>,
    noise_variance: Vec<f64>,
}

impl JudgeContext {
    /// Its judging protocol, with the free-run search's calibration settings.
    fn protocol<'a>(
        &'a self,
        calibration: &'a discovery::CalibrationConfig,
    ) -> discovery::Protocol<'a> {
        discovery::Protocol {
            cal: &self.cal,
            cal_x0: &self.cal_x0,
            hold: self.hold.as_ref().map(|(d, x)| (d, x.as_slice())),
            noise_variance: &self.noise_variance,
            calibration,
        }
    }

    /// Judge its model by the protocol against the protocol's bootstrap reference.
    fn judge(&self, seed: u64) -> discovery::Result<discovery::Judgement> {
        let calibration = RefineConfig::default().calibration;
        let protocol = self.protocol(&calibration);
        let config = discovery::JudgeConfig {
            seed,
            ..discovery::JudgeConfig::default()
        };
        discovery::judge(&self.model, &self.new_terms, &protocol, &config)
    }
}

/// Free-run states of `model` over one record from `x0` (default integrator, inputs
/// between samples as the record says).
fn free_run_states(
    model: &TermModel,
    x0: &[f64],
    exp: &Experiment,
) -> sysid_core::Result<DMatrix<f64>> {
    sysid_core::simulate_with(
        model,
        x0,
        exp.t0(),
        exp.dt(),
        exp.inputs(),
        exp.intersample(),
        &sysid_core::Integrator::default(),
        sysid_core::integrate::DEFAULT_BLOW_UP,
    )
}

/// The spec's term model; a spec built in memory that does not form one is a model error.
fn term_model_of(spec: &ModelSpec) -> Result<TermModel> {
    spec.term_model().map_err(|problem| MmennError::Model {
        path: "<model>".into(),
        line: None,
        column: None,
        problem,
    })
}

fn core(context: &'static str) -> impl FnOnce(sysid_core::CoreError) -> MmennError {
    move |source| MmennError::Core { context, source }
}

/// Free-run of a model over the first experiment, from an initial state fitted to its first
/// samples (starting from `guess`); fit % and RMSE per output.
fn free_run_gap(
    model: &TermModel,
    spec: &ModelSpec,
    data: &Dataset,
    guess: &[f64],
    window: usize,
) -> Result<(Gap, DMatrix<f64>)> {
    let exp = &data.experiments()[0];
    let c = spec.linear.c();
    let fit = InitialStateFit {
        window,
        ..InitialStateFit::default()
    };
    let x0 = fit_initial_state(model, c, exp, guess, &fit)
        .map_err(core("fitting the free-run initial state"))?;
    let xs = sysid_core::simulate_with(
        model,
        &x0,
        exp.t0(),
        exp.dt(),
        exp.inputs(),
        exp.intersample(),
        &fit.integrator,
        fit.blow_up,
    )
    .map_err(core("free-run simulation"))?;
    let y = c * xs;
    let mut gap = Gap::default();
    for (i, name) in spec.linear.output_names().iter().enumerate() {
        let meas: Vec<f64> = exp.outputs().row(i).iter().copied().collect();
        let sim: Vec<f64> = y.row(i).iter().copied().collect();
        let m = channel_metrics(&meas, &sim).map_err(core("free-run metrics"))?;
        gap.fit_percent.insert(name.clone(), m.fit_percent);
        gap.rmse.insert(name.clone(), m.rmse);
    }
    Ok((gap, y))
}

fn d_rms(est: &sysid_core::MmeEstimate) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    for (i, name) in est.correction_names.iter().enumerate() {
        let (mut s, mut n) = (0.0, 0usize);
        for e in &est.experiments {
            for v in e.corrections.row(i).iter() {
                s += v * v;
                n += 1;
            }
        }
        out.insert(name.clone(), (s / n.max(1) as f64).sqrt());
    }
    out
}

/// Noise floor of `d̂`: simulate the assumed model itself (free-run from MME's `x̂(t0)`),
/// add measurement noise of the estimated variance, and run MME at the same `W` and `R`
/// (inputs between samples as the record says, for the simulation and for MME).
fn noise_floor(
    spec: &ModelSpec,
    data: &Dataset,
    est: &sysid_core::MmeEstimate,
    opts: &DiscoverOptions,
) -> Result<NoiseFloor> {
    let model = term_model_of(spec)?;
    let c = spec.linear.c();
    let mut experiments = Vec::new();
    for (i, (exp, e)) in data.experiments().iter().zip(&est.experiments).enumerate() {
        let x0: Vec<f64> = e.states.column(0).iter().copied().collect();
        let xs = free_run_states(&model, &x0, exp)
            .map_err(core("simulating the assumed model for the noise floor"))?;
        let noise =
            plants::noise::gaussian_noise(&est.noise_variance, exp.len(), opts.seed, i as u64)?;
        let y = c * xs + noise;
        experiments.push(
            Experiment::new(exp.t0(), exp.dt(), exp.inputs().clone(), y)
                .map_err(core("noise-floor data"))?
                .with_intersample(exp.intersample()),
        );
    }
    let names = |v: Vec<String>| v.into_iter().map(Channel::new).collect::<Vec<_>>();
    let sim = Dataset::new(
        names(data.input_names()),
        names(data.output_names()),
        experiments,
    )
    .map_err(core("noise-floor data"))?;
    let mut config = mme_config(spec, &opts.estimate);
    config.w = mme_core::WeightSpec::Matrix(est.w.clone());
    config.noise_variance = mme_core::NoiseSpec::Given(est.noise_variance.clone());
    let out = estimate_spec(spec, &sim, &config)?;
    Ok(NoiseFloor::from_estimate(&out.estimate)?)
}

/// The search's set as `equation: term` lines (`a→b: term` for a transfer).
fn term_labels(list: &[RefineCandidate], selected: &[usize]) -> Vec<String> {
    selected
        .iter()
        .map(|&i| {
            let c = &list[i];
            match &c.into {
                Some(r) => format!("{}→{r}: {}", c.state, c.term),
                None => format!("{}: {}", c.state, c.term),
            }
        })
        .collect()
}

/// When `refined` (indexing `chosen_from`) touches a state of free scale, the best set
/// `search` finds over `candidates` without those terms (starting from the others), with
/// both sets' judged costs; `None` when it touches none or the model has no such state.
fn alternative_explanation(
    spec: &ModelSpec,
    search: &discovery::Search<'_>,
    candidates: &[RefineCandidate],
    refined: &discovery::Refinement,
    chosen_from: &[RefineCandidate],
) -> Result<Option<Ambiguity>> {
    let free = discovery::scale_free_states(&spec.linear);
    if free.is_empty() {
        return Ok(None);
    }
    let (touching, keep): (Vec<RefineCandidate>, Vec<RefineCandidate>) = refined
        .selected
        .iter()
        .map(|&i| chosen_from[i].clone())
        .partition(|c| discovery::touches(c, &spec.linear, &free));
    if touching.is_empty() {
        return Ok(None);
    }
    let (list, start) = discovery::ban_touching(candidates, &touching, &keep);
    let (alt, alt_list) = discovery::refine_with_transfers(search, &list, &start)?;
    let names = spec.linear.state_names();
    Ok(Some(Ambiguity {
        free_states: free.iter().map(|&j| names[j].clone()).collect(),
        named: term_labels(chosen_from, &refined.selected),
        named_cost: refined.cost[1],
        alternative: term_labels(&alt_list, &alt.selected),
        alternative_cost: alt.cost[1],
    }))
}

/// Run the discovery workflow and write `discovery.json`, `model.discovered.toml`,
/// `report.md` and figures into `out`.
pub fn run_discover(
    data_paths: &[PathBuf],
    model_path: &Path,
    val_paths: &[PathBuf],
    opts: &DiscoverOptions,
    out: &Path,
) -> Result<DiscoverSummary> {
    let original = read_model(model_path)?;
    // Free-run simulations treat the inputs between samples as the model file says (the
    // records come back tagged with its `intersample`).
    let (data, val) = crate::data_file::read_with_validation(data_paths, val_paths, &original)?;
    ensure_dir(out)?;

    let first = estimate_spec(&original, &data, &mme_config(&original, &opts.estimate))?;
    let x0_guess: Vec<f64> = first.estimate.experiments[0]
        .states
        .column(0)
        .iter()
        .copied()
        .collect();
    let base_model = original.term_model().map_err(|problem| MmennError::Model {
        path: model_path.to_path_buf(),
        line: None,
        column: None,
        problem,
    })?;
    let (mut before, y_before) =
        free_run_gap(&base_model, &original, &data, &x0_guess, opts.x0_window)?;
    before.d_rms = d_rms(&first.estimate);
    let val_before = match &val {
        Some(v) => Some(free_run_gap(&base_model, &original, v, &x0_guess, opts.x0_window)?.0),
        None => None,
    };

    let mut spec = original.clone();
    let mut result = first;
    let mut rounds = Vec::new();
    let mut effects: Vec<NamedEffect> = Vec::new();
    let mut first_verdict = None;
    let mut any_rejected = false;
    let mut ambiguity = None;
    // Free-run cost (held-out when given) of the last accepted model.
    let mut accepted_cost = f64::NAN;
    // Whether `result` is MME's estimate with the final model.
    let mut d_after_known = true;
    // Measured values of the records that judged the last free-run search.
    let mut judged_measured = measured_values(&data);
    // The protocol of the last free-run search, and of the last round whose terms were
    // kept (what judges the verdict).
    let mut last_ctx: Option<JudgeContext> = None;
    let mut claim_ctx: Option<JudgeContext> = None;
    let mut confirm_cost_stop = false;
    // The bound against which an ambiguity was declared.
    let mut ambiguity_bound: Option<f64> = None;
    for _ in 0..opts.max_rounds.max(1) {
        let est = &result.estimate;
        // After an accepted round, a model MME cannot handle ends the search (the first
        // round's failure is the user's problem and is reported as an error).
        let floor = match noise_floor(&spec, &data, est, opts) {
            Ok(f) => f,
            Err(_) if !rounds.is_empty() => break,
            Err(e) => return Err(e),
        };
        let all_samples = discovery::samples_from_estimate(est, &data)?;
        let samples = trim_ends(&all_samples, opts.trim_fraction)?;
        let found = discovery::discover(
            &spec.linear,
            &spec.units,
            &samples,
            &floor,
            &DiscoveryConfig::default(),
        )?;
        first_verdict.get_or_insert(found.verdict);
        let current = term_model_of(&spec)?;
        let exp = &data.experiments()[0];
        let x0: Vec<f64> = est.experiments[0]
            .states
            .column(0)
            .iter()
            .copied()
            .collect();
        let xs = free_run_states(&current, &x0, exp).map_err(core("free-run simulation"))?;
        let simulated = spec.linear.c() * xs;
        let fr = discovery::FreeRun {
            measured: exp.outputs(),
            simulated: &simulated,
            noise_variance: &est.noise_variance,
        };
        let localisation = discovery::localise(
            &spec.linear,
            &all_samples[0],
            exp.t0(),
            exp.dt(),
            &floor,
            Some(&fr),
            &LocaliseConfig::default(),
        )?;
        // The regression's terms: those of `found` equations, and also those of
        // `unexplained` ones (MME's shrinkage can leave a right term explaining too little
        // of d̂; the free-run search and the proof below decide).
        let proposed: Vec<discovery::FoundEffect> = found
            .equations
            .iter()
            .flat_map(|e| e.terms.iter().cloned())
            .collect();
        // With nothing proposed in the first round while `d̂` is above its floor (the
        // regression saw a disagreement it could not name — or `d̂` is so shrunk that it
        // cannot), the free-run search still runs, from the empty set: it adds what
        // lowers the free-run cost significantly, and otherwise measures the assumed
        // model's cost on the judging records, which decides `none` against
        // `unexplained` below. In later rounds the previous search already screened
        // every candidate.
        let stop_now =
            found.verdict == Verdict::None || (proposed.is_empty() && !rounds.is_empty());
        // This round's record, once its outcome is known (each path below builds it once).
        let floor_rms = floor.rms.clone();
        let round = move |refinement: Vec<discovery::RefineStep>,
                          calibrated: Vec<f64>,
                          calibration_cost: [f64; 2],
                          rejected: Option<String>| Round {
            discovery: found,
            localisation,
            floor_rms,
            refinement,
            calibrated,
            calibration_cost,
            rejected,
        };
        if stop_now {
            rounds.push(round(vec![], vec![], [f64::NAN; 2], None));
            break;
        }
        // The regression names candidates; the free-run search decides (see
        // `discovery::refine`): every library term of the corrected equations is a
        // candidate, the regression's choice the starting set, coefficients calibrated by
        // free-run simulation error for every set tried.
        let roles = discovery::StateRoles::infer(&spec.linear, &spec.units, &[])?;
        let libraries = discovery::build_library(
            &spec.linear,
            &roles,
            &spec.units,
            &samples,
            &discovery::LibraryConfig::default(),
        )?;
        let mut candidates: Vec<RefineCandidate> = Vec::new();
        for lib in &libraries {
            for c in &lib.candidates {
                candidates.push(RefineCandidate {
                    effect: c.model_effect.name().to_string(),
                    state: c.state.clone(),
                    into: None,
                    term: c.model_term.clone(),
                    coefficient: 0.0,
                    variables: c.variables.clone(),
                    parameters: c.model_parameters.clone(),
                });
            }
        }
        let mut initial = Vec::new();
        for e in &proposed {
            match candidates
                .iter()
                .position(|c| c.into.is_none() && c.state == e.state && c.term == e.model_term)
            {
                Some(i) => {
                    candidates[i].coefficient = e.coefficient;
                    initial.push(i);
                }
                None => {
                    candidates.push(RefineCandidate {
                        effect: e.model_effect.clone(),
                        state: e.state.clone(),
                        into: None,
                        term: e.model_term.clone(),
                        coefficient: e.coefficient,
                        variables: vec![],
                        parameters: vec![],
                    });
                    initial.push(candidates.len() - 1);
                }
            }
        }
        let current = term_model_of(&spec)?;
        let x0s: Vec<Vec<f64>> = est
            .experiments
            .iter()
            .map(|e| e.states.column(0).iter().copied().collect())
            .collect();
        // Validation records, when given, judge every candidate set (coefficients are
        // calibrated on the estimation data only).
        let val_x0: Option<Vec<Vec<f64>>> = match &val {
            Some(v) => Some(holdout_initial_states(
                &current,
                &spec,
                v,
                &x0_guess,
                opts.x0_window,
            )?),
            None => None,
        };
        // Without them, the end of every estimation record is held out (initial states
        // from MME's x̂ at the split).
        let split = match &val {
            None => split_records(&data, est, opts.holdout_fraction)?,
            Some(_) => None,
        };
        let holdout = match (&val, &val_x0, &split) {
            (Some(v), Some(x), _) => Some(discovery::Holdout { data: v, x0: x }),
            (None, _, Some(sp)) => Some(discovery::Holdout {
                data: &sp.hold,
                x0: &sp.hold_x0,
            }),
            _ => None,
        };
        judged_measured = measured_values(holdout.map_or(&data, |h| h.data));
        let (cal_data, cal_x0) = match &split {
            Some(sp) => (&sp.cal, &sp.cal_x0),
            None => (&data, &x0s),
        };
        // Flows the assumed model already routes between two equations are also tried as
        // transfers (one coefficient, both equations; see `discovery::transfer`), and the
        // better search is kept with the candidate list it indexes.
        let refine_config = RefineConfig::default();
        let search = discovery::Search {
            base: &current,
            data: cal_data,
            x0: cal_x0,
            noise_variance: &est.noise_variance,
            holdout,
            config: &refine_config,
        };
        let (refined, chosen_from) =
            discovery::refine_with_transfers(&search, &candidates, &initial)?;
        let first_new_term = current.terms().len();
        let ctx = JudgeContext {
            model: if refined.selected.is_empty() {
                current.clone()
            } else {
                refined.model.clone()
            },
            new_terms: (first_new_term..first_new_term + refined.selected.len()).collect(),
            cal: cal_data.clone(),
            cal_x0: cal_x0.clone(),
            hold: holdout.map(|h| (h.data.clone(), h.x0.to_vec())),
            noise_variance: est.noise_variance.clone(),
        };
        last_ctx = Some(ctx.clone());
        // The held-out half chose the terms; their coefficients (and intervals) come
        // from the whole estimation records.
        let refined = match &split {
            Some(_) if !refined.selected.is_empty() => {
                recalibrate_on(refined, &current, &data, &x0s, &est.noise_variance)
            }
            _ => refined,
        };
        if refined.selected.is_empty() {
            rounds.push(round(refined.steps, vec![], refined.cost, None));
            break;
        }
        // A set that reaches the noise level but touches a state of free scale is
        // claimed only when the search, run again without its terms touching such states,
        // cannot reach the noise level too.
        // "Reaching the noise level" is judged as the verdict is: against the bootstrap
        // reference of the set's own protocol (only computed when the model has states
        // of free scale, the only case in which an alternative is sought).
        let mut claim_now = claim_bound(&original.noise_variance, judged_measured);
        if !discovery::scale_free_states(&spec.linear).is_empty()
            && let Ok(j) = ctx.judge(opts.seed)
        {
            claim_now = j.threshold;
        }
        if refined.cost[1] <= claim_now
            && let Some(found_too) =
                alternative_explanation(&spec, &search, &candidates, &refined, &chosen_from)?
            && found_too.alternative_cost <= claim_now
        {
            let why = format!(
                "ambiguous: {{{}}} and, without its terms touching {}, {{{}}} both reach \
                 the noise level (judged cost {:.4} and {:.4} ≤ {claim_now:.4}); the \
                 scale of an unmeasured state is free, so neither is claimed",
                found_too.named.join(", "),
                found_too.free_states.join(", "),
                found_too.alternative.join(", "),
                found_too.named_cost,
                found_too.alternative_cost,
            );
            rounds.push(round(refined.steps, vec![], refined.cost, Some(why)));
            ambiguity = Some(found_too);
            ambiguity_bound = Some(claim_now);
            any_rejected = true;
            break;
        }
        let candidates = chosen_from;
        let first_new = spec.terms.len();
        let effects_before_round = effects.len();
        let calibrated: Vec<f64> = refined.model.terms()[first_new..]
            .iter()
            .map(|t| t.coefficient)
            .collect();
        let mut augmented = spec.clone();
        for (pos, (&i, c)) in refined.selected.iter().zip(&calibrated).enumerate() {
            let ci95_calibrated = refined
                .coefficient_std
                .get(pos)
                .filter(|sd| sd.is_finite())
                .map(|sd| [c - 1.96 * sd, c + 1.96 * sd]);
            let cand = &candidates[i];
            augmented.terms.push(TermEntry {
                state: cand.state.clone(),
                into: cand.into.clone(),
                effect: cand.effect.clone(),
                term: cand.term.clone(),
                coefficient: *c,
            });
            // Report the regression's evidence for it when the regression named it.
            // (A transfer's regression evidence covers only its own equation: not reported.)
            let regression = proposed.iter().find(|e| {
                cand.into.is_none() && e.state == cand.state && e.model_term == cand.term
            });
            effects.push(NamedEffect {
                name: cand.effect.clone(),
                state: cand.state.clone(),
                into: cand.into.clone(),
                term: cand.term.clone(),
                coefficient: *c,
                ci95_regression: regression.map(|e| e.ci95),
                share_of_d: regression.map(|e| e.share_of_d),
                parameters: discovery::Effect::from_name(&cand.effect)
                    .map(|e| {
                        e.parameters()
                            .iter()
                            .zip(&cand.parameters)
                            .map(|(n, v)| (n.to_string(), *v))
                            .collect()
                    })
                    .unwrap_or_default(),
                adjusts: assumed_entry(&spec, &cand.state, &cand.term, *c, ci95_calibrated),
                ci95: ci95_calibrated,
                named_by: if regression.is_some() {
                    "regression on d̂, kept by free-run search".into()
                } else {
                    "free-run search".into()
                },
            });
        }
        // Terms that leave the free-run cost far above the noise level will not be claimed:
        // keep the better model (its free-run error fell on the judged records) but skip
        // MME's proof and stop — more rounds would only pile up stand-ins.
        // With `R` estimated the cost is relative to MME's R̂ with the model *before* the
        // round, which a wrong model biases (its correction absorbs part of the noise:
        // on a pendulum missing sin θ, R̂ of ω was a third of the truth); the MME proof
        // below re-estimates R with the augmented model, and the claim is judged against
        // that. So this shortcut applies to a given `R` only.
        let r_given = matches!(original.noise_variance, NoiseVariance::Given(_));
        if r_given && refined.cost[1] > CONFIRM_COST && refined.cost[1] < refined.cost[0] {
            rounds.push(round(
                refined.steps,
                calibrated,
                refined.cost,
                Some(format!(
                    "free-run cost {:.4e} stays above {CONFIRM_COST} × the noise level: the \
                     terms improve the model but are not claimed (MME not rerun)",
                    refined.cost[1]
                )),
            ));
            accepted_cost = refined.cost[1];
            spec = augmented;
            d_after_known = false;
            confirm_cost_stop = true;
            claim_ctx = Some(ctx);
            break;
        }
        // Proof before acceptance: the augmented model must leave MME less to correct
        // (total d̂ mean square, relative to the floor, down by at least `min_d_drop`), and,
        // when validation data are given, simulate them free-run no worse than before.
        let new_result =
            match estimate_spec(&augmented, &data, &mme_config(&augmented, &opts.estimate)) {
                Ok(r) => r,
                Err(e) => {
                    rounds.push(round(
                        refined.steps,
                        calibrated,
                        refined.cost,
                        Some(format!("MME failed on the augmented model: {e}")),
                    ));
                    effects.truncate(effects_before_round);
                    any_rejected = true;
                    break;
                }
            };
        let ms = |e: &sysid_core::MmeEstimate| {
            d_rms(e)
                .values()
                .zip(&floor.rms)
                .map(|(d, f)| (d / f.max(f64::MIN_POSITIVE)).powi(2))
                .sum::<f64>()
        };
        let (ms_before, ms_after) = (ms(&result.estimate), ms(&new_result.estimate));
        let mut rejection = None;
        let shrank = ms_after <= (1.0 - opts.min_d_drop) * ms_before;
        if !shrank {
            rejection = Some(format!(
                "d̂ did not shrink: mean square / floor² {ms_before:.4e} → {ms_after:.4e}"
            ));
        } else if let Some(v) = &val {
            let prev = term_model_of(&spec)?;
            let next = term_model_of(&augmented)?;
            let cost = |m: &TermModel| -> Result<f64> {
                match free_run_gap(m, &spec, v, &x0_guess, opts.x0_window) {
                    Ok((g, _)) => Ok(g
                        .rmse
                        .values()
                        .zip(&result.estimate.noise_variance)
                        .map(|(r, n)| r * r / n)
                        .sum()),
                    Err(MmennError::Core { .. }) => Ok(f64::INFINITY),
                    Err(e) => Err(e),
                }
            };
            let (vb, va) = (cost(&prev)?, cost(&next)?);
            let improved = va < vb;
            if !improved {
                rejection = Some(format!(
                    "validation free-run error did not fall: Σ RMSE²/R {vb:.4e} → {va:.4e}"
                ));
            }
        }
        let accepted = rejection.is_none();
        rounds.push(round(refined.steps, calibrated, refined.cost, rejection));
        if !accepted {
            effects.truncate(effects_before_round);
            any_rejected = true;
            break;
        }
        // With R estimated, the round's cost is relative to MME's R with the model before
        // the round, which a far-off model inflates (MME puts unexplained dynamics into
        // the residual); MME with the augmented model estimates R again, and the claim
        // is judged against the smaller estimate, channel by channel (never the larger).
        let inflation = match original.noise_variance {
            NoiseVariance::Auto => est
                .noise_variance
                .iter()
                .zip(&new_result.estimate.noise_variance)
                .map(|(before, after)| before / after)
                .filter(|r| r.is_finite())
                .fold(1.0, f64::max),
            NoiseVariance::Given(_) => 1.0,
        };
        accepted_cost = refined.cost[1] * inflation;
        // With `R` estimated, the claim is judged against MME's R̂ with the model under
        // judgement (the augmented one), channel by channel.
        let mut claim = ctx;
        if let NoiseVariance::Auto = original.noise_variance {
            for (r, after) in claim
                .noise_variance
                .iter_mut()
                .zip(&new_result.estimate.noise_variance)
            {
                if after.is_finite() && *after > 0.0 {
                    *r = *after;
                }
            }
        }
        claim_ctx = Some(claim);
        spec = augmented;
        result = new_result;
    }

    // Found: a round was accepted. Unexplained: the library fitted something but the proof
    // failed (never name an effect that does not make the model better).
    // With nothing named, the free-run search's last cost decides between `none` (the
    // model already simulates the (held-out) data to the noise level: J within 3σ of 1,
    // σ = √(2/M) for M measured values) and `unexplained`.
    let measured = judged_measured;
    let last_cost = rounds
        .last()
        .map(|r| r.calibration_cost[1])
        .filter(|c| c.is_finite());
    let at_noise_level = |j: f64| j <= noise_level_bound(measured);
    // Named effects are claimed only when they bring the free-run cost down to the noise
    // level (`claim_bound`); otherwise a combination of catalogue terms may be standing
    // in for something outside the catalogue, or for the right effect in the wrong place.
    //
    // The judged cost is compared with its reference distribution under the pipeline
    // that produced it (`discovery::judge`: the model simulated with noise, initial states
    // re-estimated, coefficients recalibrated, the same records judging), so that what
    // the pipeline estimates does not deny a right answer. When that bootstrap cannot
    // run, the fixed bounds decide.
    let mut claim = claim_bound(&original.noise_variance, measured);
    let mut judgement = None;
    let mut judge_note = None;
    let judged_ctx = if !effects.is_empty() && !confirm_cost_stop {
        claim_ctx.as_ref()
    } else if effects.is_empty() && !any_rejected {
        last_ctx.as_ref().filter(|c| c.new_terms.is_empty())
    } else {
        None
    };
    if let Some(ctx) = judged_ctx {
        match ctx.judge(opts.seed) {
            Ok(j) => {
                claim = j.threshold;
                judgement = Some(j);
            }
            Err(e) => judge_note = Some(format!("the bootstrap judge could not run: {e}")),
        }
    }
    // Parsimony: of a claimed set, every term must be needed by the same test — a term
    // whose removal (the others recalibrated by the protocol) still leaves the statistic
    // within the reference is dropped (a passenger), and the rest are recalibrated on
    // the whole estimation records.
    let mut passengers: Vec<String> = Vec::new();
    if let (Some(j), Some(ctx)) = (&judgement, judged_ctx)
        && j.accepts()
        && !effects.is_empty()
        && ctx.new_terms.len() > 1
    {
        let calibration = RefineConfig::default().calibration;
        let protocol = ctx.protocol(&calibration);
        let dropped =
            discovery::judge::prune(&ctx.model, &ctx.new_terms, &protocol, j.threshold)?.dropped;
        if !dropped.is_empty() && spec.terms.len() == ctx.model.terms().len() {
            let first_new = ctx.new_terms[0];
            let n_new = ctx.new_terms.len();
            let effects_first = effects.len().saturating_sub(n_new);
            let mut drop_spec: Vec<usize> = dropped.iter().map(|(k, _)| *k).collect();
            drop_spec.sort_unstable();
            for &k in drop_spec.iter().rev() {
                let entry = spec.terms.remove(k);
                let e = effects_first + (k - first_new);
                if e < effects.len() {
                    effects.remove(e);
                }
                let stat = dropped
                    .iter()
                    .find(|(d, _)| *d == k)
                    .map_or(f64::NAN, |d| d.1);
                passengers.push(format!(
                    "{} in d({}): {} (without it the judged cost is {stat:.4}, within the \
                     reference quantile {:.4})",
                    entry.effect, entry.state, entry.term, j.threshold
                ));
            }
            let kept_new: Vec<usize> = (first_new..spec.terms.len()).collect();
            let model = term_model_of(&spec)?;
            let x0s: Vec<Vec<f64>> = result
                .estimate
                .experiments
                .iter()
                .map(|e| e.states.column(0).iter().copied().collect())
                .collect();
            let config = discovery::CalibrationConfig {
                terms: Some(kept_new.clone()),
                initial_state: discovery::InitialState::Estimate,
                weights: discovery::OutputWeights::NoiseVariance(ctx.noise_variance.clone()),
                ..calibration
            };
            if let Ok(fit) = discovery::calibrate(&model, &data, &x0s, &config)
                && fit.cost_after.is_finite()
            {
                for &k in &kept_new {
                    let c = fit.coefficients_after[k];
                    spec.terms[k].coefficient = c;
                    let e = effects_first + (k - first_new);
                    if let Some(effect) = effects.get_mut(e) {
                        effect.coefficient = c;
                    }
                }
            }
            d_after_known = false;
        }
    }
    if judgement.is_none()
        && let Some(b) = ambiguity_bound
    {
        claim = b;
    }
    let mut unconfirmed = Vec::new();
    let claimed = match &judgement {
        Some(j) => j.accepts(),
        None => !(accepted_cost.is_nan() || accepted_cost > claim),
    };
    if !effects.is_empty() && (confirm_cost_stop || !claimed) {
        unconfirmed = std::mem::take(&mut effects);
    }
    let verdict = if !effects.is_empty() {
        Verdict::Found
    } else if any_rejected || !unconfirmed.is_empty() {
        Verdict::Unexplained
    } else {
        match (&judgement, last_cost) {
            (Some(j), _) if j.accepts() => Verdict::None,
            (Some(_), _) => Verdict::Unexplained,
            (None, Some(j)) if at_noise_level(j) => Verdict::None,
            (None, Some(_)) => Verdict::Unexplained,
            (None, None) => first_verdict.unwrap_or(Verdict::None),
        }
    };
    let final_model = term_model_of(&spec)?;
    let (mut after, y_after) = free_run_gap(&final_model, &spec, &data, &x0_guess, opts.x0_window)?;
    if d_after_known {
        after.d_rms = d_rms(&result.estimate);
    }
    let validation_gap = match (&val, val_before) {
        (Some(v), Some(b)) => Some(GapPair {
            before: b,
            after: free_run_gap(&final_model, &spec, v, &x0_guess, opts.x0_window)?.0,
        }),
        _ => None,
    };
    let mut written = spec.clone();
    if let NoiseVariance::Auto = original.noise_variance {
        written.noise_variance = NoiseVariance::Auto;
    }
    write_model(&out.join("model.discovered.toml"), &written)?;
    let summary = DiscoverSummary {
        verdict,
        effects,
        unconfirmed,
        claim_bound: claim,
        judgement,
        judge_note,
        passengers,
        ambiguity,
        gap: GapPair { before, after },
        validation_gap,
        model: "model.discovered.toml".into(),
        rounds,
    };
    figures(&summary, &data, &spec, &y_before, &y_after, out)?;
    write_atomic(
        &out.join("discovery.json"),
        serde_json::to_string_pretty(&summary)?.as_bytes(),
    )?;
    write_atomic(&out.join("report.md"), report(&summary).as_bytes())?;
    Ok(summary)
}
