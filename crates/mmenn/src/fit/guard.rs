//! The guard of `mmenn fit`: the hybrid is never kept when it is worse than the physics
//! it starts from. Three candidates — the assumed model alone (a network whose output is
//! zero), the network as trained on `d̂`, and the network after trajectory training —
//! are run free on held-out data (the validation record when given, else the last fifth
//! of the first training record, or K contiguous stretches of it with the networks
//! retrained per stretch: [`GuardHeldOut`]; never a test record) and the one with the
//! smallest normalised free-run error is kept, ties going to the simpler candidate.

use nn::{Mlp, Scaler};
use serde::Serialize;
use sysid_core::{Dataset, Judgement, MmeEstimate};

use crate::error::{MmennError, Result};
use crate::fit::{FitOptions, hybrid_loaded, judge_outputs};
use crate::model_file::ModelSpec;

/// Where the guard judges its candidates when no validation data is given.
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
                "| {} | {err} | {} |\n",
                c.candidate.describe(),
                crate::words::named_values(&c.rmse)
            ));
        }
        s.push_str(&format!(
            "\nKept: **{}** — {}.\n",
            self.chosen.describe(),
            self.reason
        ));
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

pub(super) fn score(candidate: GuardCandidate, judged: Result<Judgement>) -> CandidateScore {
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
            held_out_error: None,
            rmse: Default::default(),
            fit_percent: Default::default(),
            failure: Some(e.to_string()),
        },
    }
}

/// Judge every candidate on the held-out data and keep the best; returns the report and
/// the kept network. `candidates` are in the order physics alone, network, refined; a
/// later one is kept only when strictly better.
pub(crate) fn choose(
    spec: &ModelSpec,
    candidates: Vec<(GuardCandidate, Mlp)>,
    held: &HeldOut,
    dt: f64,
    substeps: usize,
    domain: nn::Domain,
) -> Result<(GuardReport, Mlp)> {
    let mut scores = Vec::with_capacity(candidates.len());
    for (c, net) in &candidates {
        let judged = hybrid_loaded(spec, net, &held.x0, dt, substeps, domain)
            .and_then(|(_, loaded)| judge_outputs(&loaded, &held.data, held.window));
        scores.push(score(*c, judged));
    }
    Ok(decide(
        scores,
        candidates,
        held.description.clone(),
        Vec::new(),
    ))
}

/// Keep the candidate with the smallest held-out error (a later one only when strictly
/// better; the physics alone when every one failed).
pub(super) fn decide(
    scores: Vec<CandidateScore>,
    candidates: Vec<(GuardCandidate, Mlp)>,
    held_out: String,
    folds: Vec<FoldScores>,
) -> (GuardReport, Mlp) {
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
    let network = candidates[index].1.clone();
    (
        GuardReport {
            held_out,
            candidates: scores,
            chosen,
            reason,
            refinement_hurt,
            folds,
        },
        network,
    )
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
        Dataset::new(
            vec![Channel::new("u")],
            vec![Channel::new("x")],
            vec![Experiment::new(0.0, dt, u, y).unwrap()],
        )
        .unwrap()
    }

    #[test]
    fn a_candidate_that_diverges_is_reported_with_its_time_and_never_kept() {
        let spec = spec();
        let data = data();
        let held = HeldOut {
            data: data.clone(),
            x0: vec![0.0],
            window: 10,
            description: "test".into(),
        };
        let blow_up = constant(1e14);
        let (report, kept) = choose(
            &spec,
            vec![
                (
                    GuardCandidate::PhysicsAlone,
                    zero_network(&blow_up).unwrap(),
                ),
                (GuardCandidate::Network, blow_up.clone()),
                (GuardCandidate::Refined, constant(0.3)),
            ],
            &held,
            0.05,
            4,
            nn::Domain::Extrapolate,
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
        let held = HeldOut {
            data,
            x0: vec![0.0],
            window: 10,
            description: "test".into(),
        };
        let (report, _) = choose(
            &spec,
            vec![
                (
                    GuardCandidate::PhysicsAlone,
                    zero_network(&constant(0.5)).unwrap(),
                ),
                (GuardCandidate::Network, constant(0.5)),
                (GuardCandidate::Refined, constant(0.8)),
            ],
            &held,
            0.05,
            4,
            nn::Domain::Extrapolate,
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
}
