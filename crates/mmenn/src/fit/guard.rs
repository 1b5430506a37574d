//! The guard of `mmenn fit`: the hybrid is never kept when it is worse than the physics
//! it starts from. Three candidates — the assumed model alone (a network whose output is
//! zero), the network as trained on `d̂`, and the network after trajectory training —
//! are run free on held-out data (the validation record when given, else the last fifth
//! of the first training record, or K contiguous stretches of it with the networks
//! retrained per stretch: [`GuardHeldOut`]; never a test record) and the one with the
//! smallest normalised free-run error is kept, ties going to the simpler candidate.
//!
//! Under [`DomainPolicy::Checked`] each network candidate first meets an amplitude stress
//! check ([`check_domains`]): the held-out data rarely leave the box of the network's
//! training pairs, so they cannot show a network that explodes beyond it. The candidate
//! and the physics alone are run free on the held-out input scaled by [`STRESS_FACTOR`]
//! about its mean; a candidate whose run fails, or which changes the physics' response by
//! more than that response's own size on any output, is judged and kept with
//! [`nn::Domain::Hold`].

use std::collections::BTreeMap;

use nalgebra::DMatrix;
use nn::{Mlp, Scaler};
use serde::Serialize;
use sysid_core::{Dataset, Experiment, InitialRule, Judgement, MmeEstimate};

use crate::error::{MmennError, Result};
use crate::fit::{DomainPolicy, FitOptions, hybrid_loaded, judge_outputs};
use crate::model_file::ModelSpec;

/// Factor by which the stress check scales the held-out input about its mean.
pub const STRESS_FACTOR: f64 = 1.5;

/// Where the guard judges its candidates unless validation data choose ([`crate::fit::ValidationUse::Select`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GuardHeldOut {
    /// The last fifth of the first training record (the network sweep holds its `d̂`
    /// pairs out; trajectory training does not).
    #[default]
    LastFifth,
    /// K contiguous stretches of the first training record (`--guard 5-fold`): for each,
    /// the sweep, selection and trajectory training run again with the stretch left out
    /// of the `d̂` pairs and of the shooting windows, and every candidate is run free over
    /// it from a state fitted to its first samples. A candidate's score pools its K
    /// squared errors; the kept kind is then trained on the whole record, as with
    /// [`GuardHeldOut::LastFifth`]. Costs K more network trainings.
    Folds(usize),
    /// The last fifth of the first training record, with the networks trained once more
    /// without it, as one stretch of [`GuardHeldOut::Folds`] (`--guard
    /// last-fifth-retrained`): nothing judged there was trained or chosen on it. Costs one
    /// more network training.
    LastFifthRetrained,
}

impl std::str::FromStr for GuardHeldOut {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        let bad = || {
            format!(
                "'{s}': expected last-fifth, last-fifth-retrained or K-fold with K ≥ 2 \
                 (e.g. 5-fold)"
            )
        };
        match s {
            "last-fifth" => return Ok(Self::LastFifth),
            "last-fifth-retrained" => return Ok(Self::LastFifthRetrained),
            _ => {}
        }
        let k: usize = s
            .strip_suffix("-fold")
            .and_then(|k| k.parse().ok())
            .ok_or_else(bad)?;
        if k < 2 {
            return Err(bad());
        }
        Ok(Self::Folds(k))
    }
}

impl std::fmt::Display for GuardHeldOut {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::LastFifth => f.write_str("last-fifth"),
            Self::Folds(k) => write!(f, "{k}-fold"),
            Self::LastFifthRetrained => f.write_str("last-fifth-retrained"),
        }
    }
}

/// A model `fit` may keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum GuardCandidate {
    /// The assumed model alone: the network's output is held at zero.
    PhysicsAlone,
    /// The network as trained on MME's `d̂`, before trajectory training.
    Network,
    /// The network after trajectory training.
    Refined,
}

impl GuardCandidate {
    /// The candidate in words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::PhysicsAlone => "physics alone (no network)",
            Self::Network => "network before trajectory training",
            Self::Refined => "network after trajectory training",
        }
    }
}

/// One candidate's free run on the held-out data.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CandidateScore {
    /// Which model.
    pub candidate: GuardCandidate,
    /// What its network did outside its training box in this run (`None` for the physics
    /// alone).
    pub domain: Option<nn::Domain>,
    /// Mean over the judged channels of `‖y − ŷ‖ / ‖y − mean y‖` (`1 − fit % / 100`),
    /// or `None` when the free run failed.
    pub held_out_error: Option<f64>,
    /// Free-run RMSE per channel on the held-out data (empty when it failed).
    pub rmse: std::collections::BTreeMap<String, f64>,
    /// Free-run fit % per channel on the held-out data (empty when it failed).
    pub fit_percent: std::collections::BTreeMap<String, f64>,
    /// Why the free run failed (e.g. "… diverged at t = 2044 s …"), when it did.
    pub failure: Option<String>,
}

/// Which candidate `fit` kept, on what evidence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GuardReport {
    /// The held-out data the candidates were judged on, in words.
    pub held_out: String,
    /// Every candidate's score, in the order physics alone, network, network trained on
    /// trajectories.
    pub candidates: Vec<CandidateScore>,
    /// The candidate kept.
    pub chosen: GuardCandidate,
    /// Why, in words.
    pub reason: String,
    /// Whether trajectory training made the held-out free run worse than the network
    /// before it (`None` when there was no trajectory training or either run failed).
    pub refinement_hurt: Option<bool>,
    /// Each stretch's scores, when the guard judged K stretches
    /// ([`GuardHeldOut::Folds`]; empty otherwise).
    pub folds: Vec<FoldScores>,
    /// How the networks' domain was decided, with the stress checks when they ran.
    pub domain: DomainCheck,
}

/// The outcome of one candidate's stress check.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StressVerdict {
    /// The network changed the physics' stress response by at most its own size on every
    /// output: it extrapolates.
    Passed,
    /// Its stress run failed (diverged, errored, non-finite), or it changed the physics'
    /// response by more than the response's own size on some output: it holds.
    Failed,
    /// The physics alone failed on the stress input, so there was nothing to compare with:
    /// it extrapolates, unchecked.
    Inconclusive,
}

/// One output's numbers in a stress check.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StressChannel {
    /// RMS of (hybrid output − physics-alone output) on the stress run.
    pub change_rms: f64,
    /// RMS of the physics-alone output's deviation from its own mean on the stress run.
    pub response_rms: f64,
}

/// One network candidate's amplitude stress check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StressCheck {
    /// Which candidate.
    pub candidate: GuardCandidate,
    /// The outcome.
    pub verdict: StressVerdict,
    /// Per output (empty when a stress run failed).
    pub channels: BTreeMap<String, StressChannel>,
    /// Why a stress run failed (the candidate's, or the physics alone's), when one did.
    pub failure: Option<String>,
    /// The domain the candidate was then judged, and would be kept, with.
    pub domain: nn::Domain,
}

/// How the networks' domain outside their training box was decided.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DomainCheck {
    /// What `fit` was asked for.
    pub policy: DomainPolicy,
    /// The stress input in words (`None` when no check ran).
    pub stress_input: Option<String>,
    /// Each network candidate's check, in the guard's order (empty unless
    /// [`DomainPolicy::Checked`]).
    pub checks: Vec<StressCheck>,
}

impl DomainCheck {
    /// The decision without a check (a policy that fixes the domain).
    pub(crate) fn unchecked(policy: DomainPolicy) -> Self {
        Self {
            policy,
            stress_input: None,
            checks: Vec::new(),
        }
    }

    /// The decision in one line per network candidate (one line when no check ran).
    pub fn lines(&self) -> Vec<String> {
        match self.policy {
            DomainPolicy::Extrapolate => vec![
                "network domain: extrapolate, as asked (no stress check; `--network-domain \
                 checked` runs it)"
                    .into(),
            ],
            DomainPolicy::Hold => vec![
                "network domain: hold, as asked (the network keeps its edge value outside its \
                 training box; the stress check is not needed)"
                    .into(),
            ],
            DomainPolicy::Checked => self
                .checks
                .iter()
                .map(|c| {
                    let numbers = if c.channels.is_empty() {
                        c.failure.clone().unwrap_or_default()
                    } else {
                        c.channels
                            .iter()
                            .map(|(n, v)| {
                                format!(
                                    "{n} changed by RMS {:.4e} against the response's {:.4e}",
                                    v.change_rms, v.response_rms
                                )
                            })
                            .collect::<Vec<_>>()
                            .join(", ")
                    };
                    let outcome = match c.verdict {
                        StressVerdict::Passed => "passed; it extrapolates",
                        StressVerdict::Failed => {
                            "failed; its domain became hold (it keeps its edge value outside its \
                             training box)"
                        }
                        StressVerdict::Inconclusive => {
                            "inconclusive (the physics alone failed on the stress input); it \
                             extrapolates"
                        }
                    };
                    format!(
                        "stress check, {}: {} — {numbers}: {outcome}",
                        c.candidate.describe(),
                        self.stress_input.as_deref().unwrap_or("")
                    )
                })
                .collect(),
        }
    }
}

/// The candidates' free runs over one held-out stretch of the K-fold guard, with networks
/// trained without it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FoldScores {
    /// First and one-past-last sample of the stretch in the first training record.
    pub samples: (usize, usize),
    /// Each candidate's score on the stretch, in the order of
    /// [`GuardReport::candidates`].
    pub candidates: Vec<CandidateScore>,
    /// Training samples left out of this stretch's networks because MME could not
    /// estimate them on their own (a piece, or its first samples; with why); empty when
    /// none were.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub left_out: Vec<String>,
    /// When MME could not estimate the state on the stretch's first window alone: why,
    /// and what the free run started from instead; `None` when it could.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub start_guess: Option<String>,
    /// The stretch's MME estimates (the records without it) that did not converge
    /// ([`super::MmeConvergence::converged`]; kept only under
    /// [`super::UnconvergedMme::Warn`], `fit` refuses otherwise); empty when all did.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unconverged_mme: Vec<super::MmeConvergence>,
}

impl GuardReport {
    /// The score of `candidate`, when it was judged.
    pub fn score(&self, candidate: GuardCandidate) -> Option<&CandidateScore> {
        self.candidates.iter().find(|s| s.candidate == candidate)
    }

    /// Markdown section for `report.md`.
    pub fn markdown(&self) -> String {
        let mut s = format!(
            "\n## Which model was kept\n\nEach candidate was run free on {}; the smallest \
             normalised error ‖y − ŷ‖ / ‖y − mean y‖ (mean over channels) is kept, ties going \
             to the simpler model.\n\n| candidate | held-out error | RMSE per channel |\n\
             |---|---|---|\n",
            self.held_out
        );
        for c in &self.candidates {
            let err = match (&c.held_out_error, &c.failure) {
                (Some(e), _) => format!("{e:.4}"),
                (None, Some(f)) => format!("failed: {f}"),
                (None, None) => "—".into(),
            };
            s.push_str(&format!(
                "| {}{} | {err} | {} |\n",
                c.candidate.describe(),
                if c.domain == Some(nn::Domain::Hold) {
                    " (held)"
                } else {
                    ""
                },
                crate::words::named_values(&c.rmse)
            ));
        }
        s.push_str(&format!(
            "\nKept: **{}** — {}.\n",
            self.chosen.describe(),
            self.reason
        ));
        s.push_str("\nWhat the network does outside its training box:\n\n");
        for line in self.domain.lines() {
            s.push_str(&format!("- {line}\n"));
        }
        if self.refinement_hurt == Some(true) {
            s.push_str(
                "\n**Trajectory training made the held-out free run worse**; the network \
                 before it (or the physics alone) was kept instead.\n",
            );
        }
        if !self.folds.is_empty() {
            s.push_str("\nPer held-out stretch (networks trained without it):\n\n| samples |");
            for c in &self.candidates {
                s.push_str(&format!(" {} |", c.candidate.describe()));
            }
            s.push_str(&format!(
                "\n|---|{}\n",
                "---|".repeat(self.candidates.len())
            ));
            for f in &self.folds {
                s.push_str(&format!("| {}..{} |", f.samples.0, f.samples.1));
                for c in &f.candidates {
                    let cell = match (&c.held_out_error, &c.failure) {
                        (Some(_), _) => crate::words::named_values(&c.rmse),
                        (None, Some(why)) => format!("failed: {why}"),
                        (None, None) => "—".into(),
                    };
                    s.push_str(&format!(" {cell} |"));
                }
                s.push('\n');
            }
            for f in self.folds.iter().filter(|f| !f.left_out.is_empty()) {
                s.push_str(&format!(
                    "\nStretch {}..{}: left out of its networks' training because MME could \
                     not estimate it on its own: {}.\n",
                    f.samples.0,
                    f.samples.1,
                    f.left_out.join("; ")
                ));
            }
            for f in &self.folds {
                if let Some(g) = &f.start_guess {
                    s.push_str(&format!(
                        "\nStretch {}..{}: {g}.\n",
                        f.samples.0, f.samples.1
                    ));
                }
            }
        }
        s
    }
}

/// Held-out data for the guard: the record, the state its fit starts from, the samples
/// fitted for the initial state, and a description.
pub(crate) struct HeldOut {
    data: Dataset,
    x0: Vec<f64>,
    window: usize,
    description: String,
    /// Which data, in a few words (for the stress check's line).
    subject: String,
}

/// The validation data when given (judged as `fit` judges it, from the training `x0`),
/// else the last fifth of the first training record, started from MME's `x̂` at its
/// first sample; records too short to cut fall back to the whole training record.
pub(crate) fn held_out(
    data: &Dataset,
    val: Option<&Dataset>,
    est: &MmeEstimate,
    x0: &[f64],
    opts: &FitOptions,
) -> Result<HeldOut> {
    if let Some(v) = val {
        return Ok(HeldOut {
            data: v.clone(),
            x0: x0.to_vec(),
            window: opts.x0_window,
            description: format!(
                "the first validation record (initial state fitted to its first {} samples)",
                opts.x0_window
            ),
            subject: "the first validation record".into(),
        });
    }
    let len = data.experiments()[0].len();
    let start = len - len / 5;
    if len - start < 4 {
        return Ok(HeldOut {
            data: data.clone(),
            x0: x0.to_vec(),
            window: opts.x0_window,
            description: "the whole training record (too short to hold a segment out)".into(),
            subject: "the first training record".into(),
        });
    }
    let segment = data
        .window(0, start, len)
        .map_err(|source| MmennError::Core {
            context: "cutting the held-out segment of the training record",
            source,
        })?;
    let window = opts.x0_window.min((len - start) / 2).max(1);
    Ok(HeldOut {
        data: segment,
        x0: est.experiments[0]
            .states
            .column(start)
            .iter()
            .copied()
            .collect(),
        window,
        description: format!(
            "the last fifth of the first training record (samples {start}..{len}; the \
             network sweep held these pairs out, trajectory training did not), initial \
             state fitted to its first {window} samples from MME's x̂ there"
        ),
        subject: format!("the held-out last fifth (samples {start}..{len})"),
    })
}

/// A network of `like`'s shape whose output is exactly zero: every weight zero and the
/// output scaler centred at zero, so the hybrid is the assumed model alone.
pub(crate) fn zero_network(like: &Mlp) -> Result<Mlp> {
    let q = like.n_outputs();
    let out = Scaler::new(vec![0.0; q], vec![1.0; q])?;
    Ok(Mlp::from_parts(
        like.architecture().clone(),
        vec![0.0; like.n_weights()],
        like.input_scaler().clone(),
        out,
    )?)
}

/// Whether `net` is [`zero_network`]'s kind: the correction is zero everywhere (a hybrid
/// whose guard kept physics alone).
pub(crate) fn is_zero_network(net: &Mlp) -> bool {
    #[allow(clippy::float_cmp, reason = "zero_network writes exact zeros")]
    let zero = net.weights().iter().all(|w| *w == 0.0)
        && net.output_scaler().centre().iter().all(|c| *c == 0.0);
    zero
}

/// A candidate's score from its held-out free run (`domain`: its network's domain in that
/// run, `None` for the physics alone).
pub(super) fn score(
    candidate: GuardCandidate,
    domain: Option<nn::Domain>,
    judged: Result<Judgement>,
) -> CandidateScore {
    match judged {
        Ok(j) => {
            let fits: Vec<f64> = j.channels.values().map(|m| m.fit_percent).collect();
            let error = if !fits.is_empty() && fits.iter().all(|f| f.is_finite()) {
                fits.iter().map(|f| 1.0 - f / 100.0).sum::<f64>() / fits.len() as f64
            } else {
                let r: Vec<f64> = j.channels.values().map(|m| m.rmse).collect();
                r.iter().sum::<f64>() / r.len().max(1) as f64
            };
            CandidateScore {
                candidate,
                domain,
                held_out_error: error.is_finite().then_some(error),
                rmse: j
                    .channels
                    .iter()
                    .map(|(k, m)| (k.clone(), m.rmse))
                    .collect(),
                fit_percent: j
                    .channels
                    .iter()
                    .map(|(k, m)| (k.clone(), m.fit_percent))
                    .collect(),
                failure: (!error.is_finite()).then(|| "non-finite free-run error".to_string()),
            }
        }
        Err(e) => CandidateScore {
            candidate,
            domain,
            held_out_error: None,
            rmse: Default::default(),
            fit_percent: Default::default(),
            failure: Some(e.to_string()),
        },
    }
}

/// A candidate the guard judges: which model, its network, and the network's domain
/// outside its training box.
pub(crate) type Candidate = (GuardCandidate, Mlp, nn::Domain);

/// The domain of a candidate's network in its score (`None` for the physics alone).
pub(super) fn scored_domain(kind: GuardCandidate, domain: nn::Domain) -> Option<nn::Domain> {
    (kind != GuardCandidate::PhysicsAlone).then_some(domain)
}

/// Judge every candidate on the held-out data and keep the best; returns the report, the
/// kept network and its domain. `candidates` are in the order physics alone, network,
/// refined; a later one is kept only when strictly better.
pub(crate) fn choose(
    spec: &ModelSpec,
    candidates: Vec<Candidate>,
    held: &HeldOut,
    dt: f64,
    substeps: usize,
    domain: DomainCheck,
) -> Result<(GuardReport, Mlp, nn::Domain)> {
    let mut scores = Vec::with_capacity(candidates.len());
    for (c, net, d) in &candidates {
        let judged = hybrid_loaded(spec, net, &held.x0, dt, substeps, *d)
            .and_then(|(_, loaded)| judge_outputs(&loaded, &held.data, held.window));
        scores.push(score(*c, scored_domain(*c, *d), judged));
    }
    Ok(decide(
        scores,
        candidates,
        held.description.clone(),
        Vec::new(),
        domain,
    ))
}

/// Keep the candidate with the smallest held-out error (a later one only when strictly
/// better; the physics alone when every one failed).
pub(super) fn decide(
    scores: Vec<CandidateScore>,
    candidates: Vec<Candidate>,
    held_out: String,
    folds: Vec<FoldScores>,
    domain: DomainCheck,
) -> (GuardReport, Mlp, nn::Domain) {
    let mut best: Option<usize> = None;
    for (i, s) in scores.iter().enumerate() {
        if let Some(e) = s.held_out_error
            && best.is_none_or(|b| scores[b].held_out_error.is_some_and(|be| e < be))
        {
            best = Some(i);
        }
    }
    let error_of = |c: GuardCandidate| {
        scores
            .iter()
            .find(|s| s.candidate == c)
            .and_then(|s| s.held_out_error)
    };
    let refinement_hurt = match (
        error_of(GuardCandidate::Network),
        error_of(GuardCandidate::Refined),
    ) {
        (Some(before), Some(after)) => Some(after > before),
        _ => None,
    };
    let (index, reason) = match best {
        Some(i) => {
            let others: Vec<String> = scores
                .iter()
                .filter(|s| s.candidate != scores[i].candidate)
                .map(|s| match s.held_out_error {
                    Some(e) => format!("{} {e:.4}", s.candidate.describe()),
                    None => format!("{} failed", s.candidate.describe()),
                })
                .collect();
            (
                i,
                format!(
                    "smallest held-out free-run error ({:.4}; {})",
                    scores[i].held_out_error.unwrap_or(f64::NAN),
                    others.join(", ")
                ),
            )
        }
        None => (
            0,
            "every candidate failed on the held-out data; the physics alone is kept".into(),
        ),
    };
    let chosen = scores[index].candidate;
    let (_, network, kept_domain) = candidates[index].clone();
    (
        GuardReport {
            held_out,
            candidates: scores,
            chosen,
            reason,
            refinement_hurt,
            folds,
            domain,
        },
        network,
        kept_domain,
    )
}

/// Give every candidate its domain as `policy` says: [`DomainPolicy::Extrapolate`] and
/// [`DomainPolicy::Hold`] fix it; under [`DomainPolicy::Checked`] each network candidate
/// meets the amplitude stress check on `held`'s first record and holds when it fails
/// ([`stress_check`]). `candidates` start with the physics alone, which needs no check.
pub(crate) fn check_domains(
    spec: &ModelSpec,
    candidates: Vec<(GuardCandidate, Mlp)>,
    held: &HeldOut,
    dt: f64,
    substeps: usize,
    policy: DomainPolicy,
) -> Result<(Vec<Candidate>, DomainCheck)> {
    let fixed = policy.initial();
    if policy != DomainPolicy::Checked {
        let all = candidates.into_iter().map(|(c, n)| (c, n, fixed)).collect();
        return Ok((all, DomainCheck::unchecked(policy)));
    }
    let exp = &held.data.experiments()[0];
    let stressed = stress_input(exp)?;
    let names = spec.linear.output_names();
    // The physics alone on the stress input: every network's reference.
    let physics = match candidates.first() {
        Some((_, net)) => stress_run(
            spec,
            &zero_network(net)?,
            &held.x0,
            &stressed,
            dt,
            substeps,
            nn::Domain::Extrapolate,
        ),
        None => return Ok((Vec::new(), DomainCheck::unchecked(policy))),
    };
    let mut out = Vec::with_capacity(candidates.len());
    let mut checks = Vec::new();
    for (c, net) in candidates {
        if c == GuardCandidate::PhysicsAlone {
            out.push((c, net, fixed));
            continue;
        }
        let check = match &physics {
            Err(e) => StressCheck {
                candidate: c,
                verdict: StressVerdict::Inconclusive,
                channels: BTreeMap::new(),
                failure: Some(format!("the physics alone failed: {e}")),
                domain: nn::Domain::Extrapolate,
            },
            Ok(y_physics) => {
                let run = stress_run(
                    spec,
                    &net,
                    &held.x0,
                    &stressed,
                    dt,
                    substeps,
                    nn::Domain::Extrapolate,
                );
                stress_check(c, names, y_physics, run)
            }
        };
        out.push((c, net, check.domain));
        checks.push(check);
    }
    Ok((
        out,
        DomainCheck {
            policy,
            stress_input: Some(format!(
                "the input of {} scaled by {STRESS_FACTOR} about its mean, run free from \
                 the state the held-out run starts from",
                held.subject
            )),
            checks,
        },
    ))
}

/// The record with each input scaled by [`STRESS_FACTOR`] about its mean (its measured
/// outputs unchanged: the stress runs score nothing). The guard's stress input, and the
/// reproduce's stress-checked polynomial NARX selection's.
pub fn stress_input(exp: &Experiment) -> Result<Experiment> {
    let mut u = exp.inputs().clone();
    for mut row in u.row_iter_mut() {
        let mean = row.mean();
        for v in row.iter_mut() {
            *v = mean + STRESS_FACTOR * (*v - mean);
        }
    }
    Experiment::new(exp.t0(), exp.dt(), u, exp.outputs().clone())
        .map(|e| e.with_intersample(exp.intersample()))
        .map_err(|source| MmennError::Core {
            context: "scaling the held-out input for the stress check",
            source,
        })
}

/// The outputs of `net`'s hybrid (`domain` outside its box) run free on `exp` from `x0`,
/// by the guard's simulator; an error (divergence, a failed run, a non-finite output) in
/// words.
fn stress_run(
    spec: &ModelSpec,
    net: &Mlp,
    x0: &[f64],
    exp: &Experiment,
    dt: f64,
    substeps: usize,
    domain: nn::Domain,
) -> std::result::Result<DMatrix<f64>, String> {
    let (_, loaded) =
        hybrid_loaded(spec, net, x0, dt, substeps, domain).map_err(|e| e.to_string())?;
    let j = crate::model::judge_free_run(
        &loaded,
        exp,
        &loaded.outputs(),
        &InitialRule::Given(x0.to_vec()),
    )
    .map_err(|e| e.to_string())?;
    if j.outputs.iter().all(|v| v.is_finite()) {
        Ok(j.outputs)
    } else {
        Err("non-finite output on the stress input".into())
    }
}

/// The stress check's rule: a candidate whose stress run failed, or whose output differs
/// from the physics alone's (`physics`, `outputs × samples`, rows named by `names`) by an
/// RMS larger than the RMS of the physics output's deviation from its own mean on any
/// output (the network changed the response by more than the response's own size),
/// fails and holds; otherwise it passes and extrapolates.
pub(crate) fn stress_check(
    candidate: GuardCandidate,
    names: &[String],
    physics: &DMatrix<f64>,
    network: std::result::Result<DMatrix<f64>, String>,
) -> StressCheck {
    let failed = |why: String| StressCheck {
        candidate,
        verdict: StressVerdict::Failed,
        channels: BTreeMap::new(),
        failure: Some(why),
        domain: nn::Domain::Hold,
    };
    let y = match network {
        Ok(y) if y.shape() == physics.shape() => y,
        Ok(y) => {
            return failed(format!(
                "its stress run gave {:?} outputs × samples, the physics alone {:?}",
                y.shape(),
                physics.shape()
            ));
        }
        Err(why) => return failed(format!("its stress run failed: {why}")),
    };
    let n = physics.ncols().max(1) as f64;
    let mut channels = BTreeMap::new();
    let mut pass = true;
    for (j, name) in names.iter().enumerate().take(physics.nrows()) {
        let p = physics.row(j);
        let mean = p.mean();
        let (mut change, mut spread) = (0.0, 0.0);
        for (a, b) in y.row(j).iter().zip(p.iter()) {
            change += (a - b).powi(2);
            spread += (b - mean).powi(2);
        }
        let v = StressChannel {
            change_rms: (change / n).sqrt(),
            response_rms: (spread / n).sqrt(),
        };
        // Written so that a NaN fails.
        pass &= v.change_rms <= v.response_rms;
        channels.insert(name.clone(), v);
    }
    let (verdict, domain) = if pass {
        (StressVerdict::Passed, nn::Domain::Extrapolate)
    } else {
        (StressVerdict::Failed, nn::Domain::Hold)
    };
    StressCheck {
        candidate,
        verdict,
        channels,
        failure: None,
        domain,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guard_held_out_reads_and_writes_its_spellings() {
        assert_eq!("last-fifth".parse(), Ok(GuardHeldOut::LastFifth));
        assert_eq!("5-fold".parse(), Ok(GuardHeldOut::Folds(5)));
        assert_eq!(
            "last-fifth-retrained".parse(),
            Ok(GuardHeldOut::LastFifthRetrained)
        );
        assert_eq!(
            GuardHeldOut::LastFifthRetrained.to_string(),
            "last-fifth-retrained"
        );
        for bad in ["1-fold", "0-fold", "five-fold", "5", "", "5-folds"] {
            assert!(bad.parse::<GuardHeldOut>().is_err(), "{bad}");
        }
        assert_eq!(GuardHeldOut::Folds(7).to_string(), "7-fold");
        assert_eq!(GuardHeldOut::LastFifth.to_string(), "last-fifth");
    }
    use nn::Architecture;
    use sysid_core::{Channel, Experiment};

    fn spec() -> ModelSpec {
        crate::model_file::parse_model(
            std::path::Path::new("test.toml"),
            "states = [\"x\"]\ninputs = [\"u\"]\nA = [[-1.0]]\nB = [[1.0]]\n\
             measured = [\"x\"]\ncorrected = [\"x\"]\nnoise_variance = [1e-6]\n",
        )
        .unwrap()
    }

    /// A network `(x, u) → d` whose output is the constant `c` (output bias 1, output
    /// scaler half-range `c`).
    fn constant(c: f64) -> Mlp {
        let arch = Architecture {
            inputs: 2,
            hidden: vec![1],
            outputs: 1,
        };
        let mut w = vec![0.0; arch.n_weights()];
        *w.last_mut().unwrap() = 1.0;
        Mlp::from_parts(
            arch,
            w,
            Scaler::identity(2),
            Scaler::new(vec![0.0], vec![c]).unwrap(),
        )
        .unwrap()
    }

    /// Data of `x' = −x + u` from x0 = 0 under a step u = 1: x = 1 − e^{−t} (analytic).
    fn data() -> Dataset {
        let n = 400;
        let dt = 0.05;
        let u = nalgebra::DMatrix::from_element(1, n, 1.0);
        let y = nalgebra::DMatrix::from_fn(1, n, |_, k| 1.0 - (-(k as f64) * dt).exp());
        one_record(dt, u, y)
    }

    /// One record of input `u` and measured state `x`, sampled every `dt`.
    fn one_record(dt: f64, u: nalgebra::DMatrix<f64>, y: nalgebra::DMatrix<f64>) -> Dataset {
        Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("x")],
            vec![Experiment::new(0.0, dt, u, y).unwrap()],
        )
        .unwrap()
    }

    /// `data`'s first record as held-out data, started from x = 0.
    fn held(data: Dataset) -> HeldOut {
        HeldOut {
            data,
            x0: vec![0.0],
            window: 10,
            description: "test".into(),
            subject: "the test record".into(),
        }
    }

    /// The candidates, every network extrapolating.
    fn extrapolating(candidates: Vec<(GuardCandidate, Mlp)>) -> Vec<Candidate> {
        candidates
            .into_iter()
            .map(|(c, n)| (c, n, nn::Domain::Extrapolate))
            .collect()
    }

    #[test]
    fn a_candidate_that_diverges_is_reported_with_its_time_and_never_kept() {
        let spec = spec();
        let data = data();
        let held = held(data.clone());
        let blow_up = constant(1e14);
        let (report, kept, _) = choose(
            &spec,
            extrapolating(vec![
                (
                    GuardCandidate::PhysicsAlone,
                    zero_network(&blow_up).unwrap(),
                ),
                (GuardCandidate::Network, blow_up.clone()),
                (GuardCandidate::Refined, constant(0.3)),
            ]),
            &held,
            0.05,
            4,
            DomainCheck::unchecked(DomainPolicy::Extrapolate),
        )
        .unwrap();
        let net = report.score(GuardCandidate::Network).unwrap();
        assert!(net.held_out_error.is_none());
        let why = net.failure.as_deref().unwrap();
        assert!(why.contains("diverged at t = "), "{why}");
        // A constant offset of 0.3 moves the steady state from 1 to 1.3: worse than the
        // exact physics, which is kept.
        assert_eq!(
            report.chosen,
            GuardCandidate::PhysicsAlone,
            "{}",
            report.reason
        );
        assert!(
            report
                .score(GuardCandidate::PhysicsAlone)
                .unwrap()
                .held_out_error
                .unwrap()
                < 1e-3
        );
        assert_eq!(kept.weights().iter().filter(|w| **w != 0.0).count(), 0);
        // The network before refinement failed, so whether refinement hurt is unknown.
        assert_eq!(report.refinement_hurt, None);
    }

    #[test]
    fn refinement_that_hurts_is_flagged_and_the_better_network_kept() {
        // Truth x' = −x + u + 0.5 (the physics misses the offset): a network giving 0.5
        // is exact, one giving 0.8 is worse than it but better than nothing.
        let spec = spec();
        let base = data();
        let e = &base.experiments()[0];
        let y = nalgebra::DMatrix::from_fn(1, e.len(), |_, k| {
            1.5 * (1.0 - (-(k as f64) * e.dt()).exp())
        });
        let data = Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("x")],
            vec![Experiment::new(0.0, e.dt(), e.inputs().clone(), y).unwrap()],
        )
        .unwrap();
        let held = held(data);
        let (report, _, _) = choose(
            &spec,
            extrapolating(vec![
                (
                    GuardCandidate::PhysicsAlone,
                    zero_network(&constant(0.5)).unwrap(),
                ),
                (GuardCandidate::Network, constant(0.5)),
                (GuardCandidate::Refined, constant(0.8)),
            ]),
            &held,
            0.05,
            4,
            DomainCheck::unchecked(DomainPolicy::Extrapolate),
        )
        .unwrap();
        assert_eq!(report.chosen, GuardCandidate::Network, "{}", report.reason);
        assert_eq!(report.refinement_hurt, Some(true));
        assert!(
            report
                .markdown()
                .contains("made the held-out free run worse")
        );
    }

    /// A network `(x, u) → d` that is (nearly) zero inside the box |x|, |u| ≤ 1 of its
    /// input scaler and `2a` where |u| > 1.1: `a·(tanh(50u − 55) + tanh(−50u − 55) + 2)`.
    fn edge_bump(a: f64) -> Mlp {
        let arch = Architecture {
            inputs: 2,
            hidden: vec![2],
            outputs: 1,
        };
        let w = vec![0.0, 50.0, -55.0, 0.0, -50.0, -55.0, 1.0, 1.0, 2.0];
        Mlp::from_parts(
            arch,
            w,
            Scaler::identity(2),
            Scaler::new(vec![0.0], vec![a]).unwrap(),
        )
        .unwrap()
    }

    /// `x' = −x + u` under u = sin t from x0 = 0 (20 s at 20 Hz): x = (sin t − cos t +
    /// e^{−t}) / 2 (analytic), inside the box |x|, |u| ≤ 1.
    fn sine_data() -> Dataset {
        let n = 400;
        let dt = 0.05;
        let u = nalgebra::DMatrix::from_fn(1, n, |_, k| (k as f64 * dt).sin());
        let y = nalgebra::DMatrix::from_fn(1, n, |_, k| {
            let t = k as f64 * dt;
            (t.sin() - t.cos() + (-t).exp()) / 2.0
        });
        one_record(dt, u, y)
    }

    /// The stress check's rule on a constructed case: a network that is nearly zero inside
    /// its box and huge beyond it passes the held-out data unseen (its held-out score is
    /// the physics' own), fails the stress check at 1.5× the input and is judged held; a
    /// network of the same shape, small beyond the box, passes and extrapolates.
    #[test]
    fn stress_check_holds_a_network_that_explodes_beyond_its_box_and_not_a_benign_one() {
        let spec = spec();
        let held = held(sine_data());
        let (huge, benign) = (edge_bump(50.0), edge_bump(0.01));
        let candidates = vec![
            (GuardCandidate::PhysicsAlone, zero_network(&huge).unwrap()),
            (GuardCandidate::Network, huge.clone()),
            (GuardCandidate::Refined, benign.clone()),
        ];
        // Unchecked, the held-out data cannot tell the exploding network from the physics.
        let (unchecked, _, _) = choose(
            &spec,
            extrapolating(candidates.clone()),
            &held,
            0.05,
            4,
            DomainCheck::unchecked(DomainPolicy::Extrapolate),
        )
        .unwrap();
        let error = |r: &GuardReport, c| r.score(c).unwrap().held_out_error.unwrap();
        // (The record is the response to the continuous sine; the model holds the input
        // over each sample: about 0.025.)
        let physics_error = error(&unchecked, GuardCandidate::PhysicsAlone);
        assert!(physics_error < 0.05, "{physics_error}");
        assert!(
            (error(&unchecked, GuardCandidate::Network)
                - error(&unchecked, GuardCandidate::PhysicsAlone))
            .abs()
                < 1e-3
        );
        let (checked, check) =
            check_domains(&spec, candidates, &held, 0.05, 4, DomainPolicy::Checked).unwrap();
        let domains: Vec<nn::Domain> = checked.iter().map(|c| c.2).collect();
        assert_eq!(
            domains,
            [
                nn::Domain::Extrapolate,
                nn::Domain::Hold,
                nn::Domain::Extrapolate
            ]
        );
        assert_eq!(check.checks.len(), 2);
        let (h, b) = (&check.checks[0], &check.checks[1]);
        assert_eq!(
            (h.candidate, h.verdict),
            (GuardCandidate::Network, StressVerdict::Failed)
        );
        assert_eq!(
            (b.candidate, b.verdict),
            (GuardCandidate::Refined, StressVerdict::Passed)
        );
        let (hx, bx) = (h.channels["x"], b.channels["x"]);
        // Beyond |u| = 1.1 the huge network adds 100 to ẋ: its response is tens, the
        // physics' about 0.5; the benign one adds at most 0.02.
        assert!(hx.change_rms > 10.0 * hx.response_rms, "{hx:?}");
        assert!(bx.change_rms < 0.1 * bx.response_rms, "{bx:?}");
        assert!((hx.response_rms - bx.response_rms).abs() < 1e-12);
        let lines = check.lines();
        assert!(
            lines[0].starts_with("stress check, network before trajectory training")
                && lines[0].contains("its domain became hold")
                && lines[1].contains("passed; it extrapolates"),
            "{lines:?}"
        );
        // Judged held, the exploding network scores inside the box as before.
        let (report, _, _) = choose(&spec, checked, &held, 0.05, 4, check).unwrap();
        let net = report.score(GuardCandidate::Network).unwrap();
        assert_eq!(net.domain, Some(nn::Domain::Hold));
        assert!(
            (net.held_out_error.unwrap() - error(&unchecked, GuardCandidate::Network)).abs() < 1e-9
        );
        assert!(report.markdown().contains("its domain became hold"));
        assert!(
            report
                .markdown()
                .contains("| network before trajectory training (held) |")
        );
    }

    /// A fixed policy runs no stress check and says so; a failed or non-finite stress run
    /// fails the check.
    #[test]
    fn fixed_domains_are_not_checked_and_failed_stress_runs_hold() {
        let spec = spec();
        let held = held(sine_data());
        let candidates = vec![
            (
                GuardCandidate::PhysicsAlone,
                zero_network(&edge_bump(50.0)).unwrap(),
            ),
            (GuardCandidate::Network, edge_bump(50.0)),
        ];
        for (policy, domain, words) in [
            (DomainPolicy::Hold, nn::Domain::Hold, "not needed"),
            (
                DomainPolicy::Extrapolate,
                nn::Domain::Extrapolate,
                "no stress check",
            ),
        ] {
            let (c, check) =
                check_domains(&spec, candidates.clone(), &held, 0.05, 4, policy).unwrap();
            assert!(c.iter().all(|c| c.2 == domain));
            assert!(check.checks.is_empty() && check.stress_input.is_none());
            assert!(check.lines()[0].contains(words), "{:?}", check.lines());
        }
        let physics = DMatrix::from_row_slice(1, 4, &[0.0, 1.0, 0.0, -1.0]);
        let names = ["x".to_string()];
        let diverged = stress_check(
            GuardCandidate::Network,
            &names,
            &physics,
            Err("diverged at t = 3 s".into()),
        );
        assert_eq!(
            (diverged.verdict, diverged.domain),
            (StressVerdict::Failed, nn::Domain::Hold)
        );
        let nan = DMatrix::from_row_slice(1, 4, &[0.0, f64::NAN, 0.0, -1.0]);
        assert_eq!(
            stress_check(GuardCandidate::Network, &names, &physics, Ok(nan)).verdict,
            StressVerdict::Failed
        );
        // A change as large as the response itself still passes; larger fails.
        let twice = &physics * 2.0;
        assert_eq!(
            stress_check(GuardCandidate::Network, &names, &physics, Ok(twice)).verdict,
            StressVerdict::Passed
        );
        let more = &physics * 2.01;
        assert_eq!(
            stress_check(GuardCandidate::Network, &names, &physics, Ok(more)).verdict,
            StressVerdict::Failed
        );
    }
}
