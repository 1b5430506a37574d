//! Progress of the workflow: the [`Observer`] a caller passes to [`super::run`], and the
//! plan that counts the workflow's steps for it.

/// Where the workflow is, for a progress display: `stage` names the step, `round` counts
/// from 1 (0 before the first round).
pub trait Observer: Sync {
    /// A step begins.
    fn stage(&self, round: usize, stage: &str);

    /// `done` of `total` steps are finished; called right after each [`Observer::stage`]
    /// and once at the end with `done == total`. `total` is the plan of [`super::run`]: the
    /// first MME run, [`STEPS_PER_ROUND`] per round up to `max_rounds`, and
    /// [`FINAL_STEPS`] after the rounds. It shrinks to what remains when the rounds stop
    /// early or a step is not needed, and grows by one for an ambiguity test; `done`
    /// never decreases and never exceeds `total`.
    fn steps(&self, _done: usize, _total: usize) {}
}

/// Steps of one full round in the plan [`Observer::steps`] counts: the noise floor, the
/// proposal, the free-run search and the proof.
pub const STEPS_PER_ROUND: usize = 4;
/// Steps after the rounds in that plan: the verdict's bootstrap judge, pruning passengers
/// and the flexible stand-in.
pub const FINAL_STEPS: usize = 3;

/// Counts the workflow's steps against its plan for [`Observer::steps`].
pub(super) struct Plan<'a> {
    observer: &'a dyn Observer,
    /// Steps begun.
    begun: std::cell::Cell<usize>,
    /// Steps planned.
    total: std::cell::Cell<usize>,
}

impl<'a> Plan<'a> {
    pub(super) fn new(observer: &'a dyn Observer, max_rounds: usize) -> Self {
        Self {
            observer,
            begun: std::cell::Cell::new(0),
            total: std::cell::Cell::new(1 + STEPS_PER_ROUND * max_rounds + FINAL_STEPS),
        }
    }

    /// A planned step begins: the steps before it are finished.
    pub(super) fn stage(&self, round: usize, stage: &str) {
        let done = self.begun.get();
        self.begun.set(done + 1);
        self.total.set(self.total.get().max(done + 1));
        self.observer.stage(round, stage);
        self.observer.steps(done, self.total.get());
    }

    /// A step outside the plan will run.
    pub(super) fn add(&self) {
        self.total.set(self.total.get() + 1);
    }

    /// After the rounds: what remains is the final steps.
    pub(super) fn rounds_over(&self) {
        self.total.set(self.begun.get() + FINAL_STEPS);
    }

    /// The run is over: every step begun is finished.
    pub(super) fn finish(&self) {
        let done = self.begun.get();
        self.total.set(done);
        self.observer.steps(done, done);
    }
}

/// An observer that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer for Silent {
    fn stage(&self, _round: usize, _stage: &str) {}
}
