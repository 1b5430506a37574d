//! The μ schedules of [`Damping`]: how μ changes after an accepted or a rejected trial step
//! of one Levenberg–Marquardt epoch.

use crate::config::{Damping, LmConfig};

/// μ never drops below this: far below any useful damping, it only stops μ from
/// underflowing after long runs of accepted steps.
const MU_FLOOR: f64 = 1e-20;

/// Delayed gratification (Transtrum, Machta & Sethna, PRE 83, 036701, 2011; Transtrum &
/// Sethna, arXiv:1201.5885, 2012): μ is multiplied by this after a rejected step…
const DELAYED_UP: f64 = 2.0;
/// …and divided by this after an accepted one.
const DELAYED_DOWN: f64 = 3.0;

/// [`Damping::TrainlmThenGainRatio`] follows `trainlm` for this many accepted steps.
const TRAINLM_PHASE: usize = 10;

/// μ's state across the trial steps of a training run.
pub(super) struct Schedule {
    damping: Damping,
    /// [`LmConfig::mu_decrease`].
    decrease: f64,
    /// [`LmConfig::mu_increase`].
    increase: f64,
    /// Nielsen's factor applied to μ after a rejected step (2, doubled on each further
    /// rejection, reset to 2 after an accepted one).
    nu: f64,
    /// Accepted steps so far.
    accepted: usize,
}

impl Schedule {
    pub(super) fn new(config: &LmConfig) -> Self {
        Self {
            damping: config.damping,
            decrease: config.mu_decrease,
            increase: config.mu_increase,
            nu: 2.0,
            accepted: 0,
        }
    }

    /// The rule in force now: [`Damping::TrainlmThenGainRatio`] is `trainlm` until
    /// [`TRAINLM_PHASE`] steps have been accepted, [`Damping::GainRatio`] afterwards.
    fn rule(&self) -> Damping {
        match self.damping {
            Damping::TrainlmThenGainRatio if self.accepted < TRAINLM_PHASE => Damping::Trainlm,
            Damping::TrainlmThenGainRatio => Damping::GainRatio,
            other => other,
        }
    }

    /// Whether steps may take geodesic acceleration now: not during the `trainlm` phase of
    /// [`Damping::TrainlmThenGainRatio`], which takes `trainlm`'s plain steps.
    pub(super) fn accelerates(&self) -> bool {
        !(self.damping == Damping::TrainlmThenGainRatio && self.rule() == Damping::Trainlm)
    }

    /// Whether the schedule needs the gain ratio of the next accepted step.
    pub(super) fn uses_gain(&self) -> bool {
        matches!(
            self.rule(),
            Damping::Nielsen | Damping::NielsenMarquardt | Damping::GainRatio
        )
    }

    /// μ after an accepted step with gain ratio `gain` (actual over predicted decrease;
    /// only read when [`Schedule::uses_gain`]).
    pub(super) fn accepted(&mut self, mu: f64, gain: f64) -> f64 {
        let rule = self.rule();
        self.nu = 2.0;
        self.accepted += 1;
        // Nielsen's factor 1 − (2ϱ − 1)³: 1 at ϱ = 1/2, falling to 0 as ϱ → 1.
        let nielsen = 1.0 - (2.0 * gain - 1.0).powi(3);
        match rule {
            Damping::Trainlm | Damping::TrainlmThenGainRatio => mu * self.decrease,
            Damping::Nielsen | Damping::NielsenMarquardt => mu * nielsen.max(1.0 / 3.0),
            Damping::GainRatio => mu * nielsen.max(self.decrease),
            Damping::DelayedGratification => mu / DELAYED_DOWN,
        }
        .max(MU_FLOOR)
    }

    /// μ after a rejected step (or a failed factorisation).
    pub(super) fn rejected(&mut self, mu: f64) -> f64 {
        match self.rule() {
            Damping::Trainlm | Damping::TrainlmThenGainRatio => mu * self.increase,
            Damping::Nielsen | Damping::NielsenMarquardt | Damping::GainRatio => {
                let up = mu * self.nu;
                self.nu *= 2.0;
                up
            }
            Damping::DelayedGratification => mu * DELAYED_UP,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schedule(damping: Damping) -> Schedule {
        Schedule::new(&LmConfig {
            damping,
            ..LmConfig::default()
        })
    }

    #[test]
    fn factors_follow_the_documented_rules() {
        // Exact factors by hand; 0.1, 1/3 and powers of two are the documented constants,
        // compared with a relative 1e-15 (one rounding of the product).
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs();
        let mut t = schedule(Damping::Trainlm);
        assert!(close(t.accepted(1.0, f64::NAN), 0.1));
        assert!(close(t.rejected(1.0), 10.0));
        assert!(close(t.rejected(1.0), 10.0));

        let mut d = schedule(Damping::DelayedGratification);
        assert!(close(d.accepted(3.0, f64::NAN), 1.0));
        assert!(close(d.rejected(1.0), 2.0));
        assert!(close(d.rejected(2.0), 4.0));

        // Gain ratio: ϱ = 1 (the linear model exact) is capped at trainlm's 0.1 here and
        // at 1/3 for Nielsen; ϱ = 1/2 keeps μ; ϱ = 3/4 gives 1 − 1/8.
        let mut g = schedule(Damping::GainRatio);
        let mut n = schedule(Damping::Nielsen);
        assert!(close(g.accepted(1.0, 1.0), 0.1));
        assert!(close(n.accepted(1.0, 1.0), 1.0 / 3.0));
        assert!(close(g.accepted(1.0, 0.5), 1.0));
        assert!(close(g.accepted(1.0, 0.75), 0.875));
        // A near-zero gain raises μ up to twofold.
        assert!(close(g.accepted(1.0, 0.0), 2.0));
        // Rejections: ×2, ×4, ×8, and back to ×2 after an acceptance.
        assert!(close(g.rejected(1.0), 2.0));
        assert!(close(g.rejected(1.0), 4.0));
        assert!(close(g.rejected(1.0), 8.0));
        g.accepted(1.0, 0.5);
        assert!(close(g.rejected(1.0), 2.0));
        // μ never underflows.
        assert!(close(g.accepted(1e-20, 1.0), MU_FLOOR));
    }

    #[test]
    fn two_phase_schedule_switches_after_the_trainlm_phase() {
        // The first TRAINLM_PHASE accepted steps follow trainlm (×0.1, ×10 whatever the
        // gain), the ones after follow GainRatio (ϱ = 1/2 keeps μ, rejections ×2, ×4).
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs();
        let mut s = schedule(Damping::TrainlmThenGainRatio);
        for _ in 0..TRAINLM_PHASE {
            assert!(s.rule() == Damping::Trainlm && !s.uses_gain());
            assert!(close(s.rejected(1.0), 10.0));
            assert!(close(s.rejected(1.0), 10.0));
            assert!(close(s.accepted(1.0, 0.5), 0.1));
        }
        assert!(s.uses_gain());
        assert!(close(s.rejected(1.0), 2.0));
        assert!(close(s.rejected(1.0), 4.0));
        assert!(close(s.accepted(1.0, 0.5), 1.0));
        assert!(close(s.accepted(1.0, 1.0), 0.1));
    }
}
