//! Words for reports and the command line: how an enum reads to a person (never Rust's
//! debug text), and `name = value` lists.

use std::collections::BTreeMap;

use mme_core::NoiseMethod;
use sysid_core::Termination;

/// How a solve or search ended, in words.
pub fn termination(t: Option<Termination>) -> &'static str {
    match t {
        None => "not run",
        Some(Termination::Exact) => "solved exactly (one linear sweep)",
        Some(Termination::Converged) => "converged",
        Some(Termination::MaxIterations) => "stopped at the iteration limit (not converged)",
        Some(Termination::LineSearchFailed) => {
            "stopped: the line search could not lower the cost (not converged)"
        }
        Some(Termination::NotBracketed) => {
            "the target was never bracketed; the closest end of the search was used"
        }
        Some(Termination::NoDescent) => {
            "stopped: no damped step lowered the cost (a stationary point)"
        }
        Some(Termination::StoppedEarly) => "stopped early: the held-out cost stopped improving",
        Some(Termination::Diverged) => "not run: the model diverged at the starting point",
        Some(Termination::NoProgress) => {
            "stopped where it started (not converged): the cost did not move and the \
             Jacobian there is rank-deficient"
        }
        Some(_) => "ended for another reason",
    }
}

/// How the noise variance was obtained, in words.
pub fn noise_method(m: NoiseMethod) -> &'static str {
    match m {
        NoiseMethod::Given => "given in the model file",
        NoiseMethod::MarginalLikelihood => "estimated by maximum marginal likelihood",
        NoiseMethod::DifferenceBased => {
            "estimated from sample differences (the likelihood was degenerate)"
        }
        NoiseMethod::SpectralFloor => {
            "the spectral floor of the measurements (the likelihood was degenerate)"
        }
        _ => "estimated",
    }
}

/// What a classifier's per-class scores are, in words.
pub fn score_kind(k: condmon::ScoreKind) -> &'static str {
    match k {
        condmon::ScoreKind::Posterior => "posterior probability of each condition",
        condmon::ScoreKind::VoteShare => {
            "share of the nearest neighbours voting for each condition"
        }
    }
}

/// Numbers as `[1.2346e0, -3.0000e-1]` (four significant digits).
pub fn numbers(values: &[f64]) -> String {
    let v: Vec<String> = values.iter().map(|x| format!("{x:.4e}")).collect();
    format!("[{}]", v.join(", "))
}

/// What a network does outside the box of its training pairs, in words.
pub fn network_domain(d: nn::Domain) -> &'static str {
    match d {
        nn::Domain::Hold => "network held at its training box",
        nn::Domain::Extrapolate => "network extrapolating outside its training box",
    }
}

/// What the free-run metrics of a report mean (Markdown paragraph).
pub const METRICS_MEANING: &str = "\n*Fit %* = 100·(1 − ‖y − ŷ‖ / ‖y − mean(y)‖): 100 is a \
perfect match, 0 is no better than the record's mean, negative is worse. *R²* = 1 − \
Σ(y − ŷ)² / Σ(y − mean y)². *RMSE*: root mean square of y − ŷ, in the channel's unit. \
*Error variance*: variance of y − ŷ. ŷ is the model's simulation from the inputs (free run: \
no measurement used after the initial state; k-step: restarted from the measurements k \
samples back).\n";

/// `a = 1.2345e0, b = …` with four significant digits.
pub fn named_values(values: &BTreeMap<String, f64>) -> String {
    values
        .iter()
        .map(|(k, v)| format!("{k} = {v:.4e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A discover run's verdict with what it means for the way it was decided: a
/// force-space run (mass-matrix model) is judged against the fixed noise-level bound, not
/// by the bootstrap judge, so its words say what did decide it.
pub fn discover_verdict(s: &crate::discover::DiscoverSummary) -> &'static str {
    if !s.generalized_forces {
        return verdict(s.verdict);
    }
    match s.verdict {
        discovery::Verdict::Found => {
            "found (named joint forces, each with a 95 % interval that excludes zero, which \
             lowered the validation free-run cost when validation records were given and \
             bring the model to the noise level on the estimation records; judged by the \
             fixed bound, not by a bootstrap)"
        }
        discovery::Verdict::None => {
            "none (no catalogue force of a joint's own rate was kept, and the assumed model \
             simulates the estimation records to the noise level)"
        }
        discovery::Verdict::Unexplained => verdict(s.verdict),
    }
}

/// A discovery verdict as `discovery.json` spells it, with what it means.
pub fn verdict(v: discovery::Verdict) -> &'static str {
    match v {
        discovery::Verdict::Found => {
            "found (named effects bring the model to the noise level; claimed)"
        }
        discovery::Verdict::None => {
            "none (the model already simulates the data to the noise level)"
        }
        discovery::Verdict::Unexplained => {
            "unexplained (something remains that no claimed set of catalogue terms explains)"
        }
    }
}

/// A state's role as the model file's `[roles]` table writes it.
pub fn role(r: discovery::Role) -> &'static str {
    match r {
        discovery::Role::Position => "position",
        discovery::Role::Angle => "angle",
        discovery::Role::Velocity => "velocity",
        discovery::Role::Level => "level",
        discovery::Role::Other => "other",
    }
}

/// `state role, …` (`h1 level, h2 level`).
pub fn role_list<'a>(roles: impl IntoIterator<Item = (&'a String, &'a discovery::Role)>) -> String {
    roles
        .into_iter()
        .map(|(state, r)| format!("{state} {}", role(*r)))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_have_no_debug_text() {
        assert_eq!(termination(Some(Termination::Converged)), "converged");
        assert_eq!(termination(None), "not run");
        assert!(!noise_method(NoiseMethod::Given).contains("Given"));
        let m: BTreeMap<String, f64> = [("v".to_string(), 5.25)].into_iter().collect();
        assert_eq!(named_values(&m), "v = 5.2500e0");
        assert_eq!(numbers(&[1.0, -0.5]), "[1.0000e0, -5.0000e-1]");
        assert!(!score_kind(condmon::ScoreKind::VoteShare).contains("Vote"));
        assert!(!network_domain(nn::Domain::Hold).contains("Hold"));
        // The role words are the ones a `[roles]` table reads.
        use discovery::Role;
        for r in [
            Role::Position,
            Role::Angle,
            Role::Velocity,
            Role::Level,
            Role::Other,
        ] {
            assert_eq!(
                serde_json::to_string(&r).unwrap(),
                format!("\"{}\"", role(r))
            );
        }
    }
}
