//! Progress of long jobs, reported through a small callback so that the library never
//! prints: the `mmenn` binary turns reports into a terminal bar or plain log lines, tests
//! and library users pass [`NoProgress`] or a closure.
//!
//! Reporting only observes a job: it never changes what the job computes. Any workflow
//! of this crate (fit's sizing sweep and trajectory refinement, compare's baselines,
//! estimate's phases, discover's workflow steps) takes a `&dyn ProgressSink`.
//!
//! # Reporting from a library function
//!
//! Take `progress: &dyn ProgressSink` as the last argument and keep the old entry point
//! as a wrapper passing [`NoProgress`], so callers that do not care change nothing. Name
//! each task in words a user understands, report `done` of `total` when the number of
//! steps is known (the terminal then shows a bar with ETA) and `total: None` otherwise (a
//! spinner), and call [`ProgressSink::finish`] when the task ends, or wrap a step that
//! has no inner steps in [`stage`]. The sink is `Sync`: worker threads (rayon) may report
//! through the same reference. A generic `P: ProgressSink` passes on as `&dyn` unchanged.
//!
//! `discover` reports one task, `"discover"`, whose total is the workflow's plan of steps
//! (the first MME run, four per round up to `--max-rounds`, three after the rounds;
//! `discovery::workflow::Observer::steps`), shrinking when the rounds stop early, with
//! the round and step that begins as the [`Progress::stage`] (named by the workflow,
//! `discovery::workflow::Observer::stage`); the MME runs of a step add their phase and
//! latest step as the note of that step's report ([`MmeProgress::within`]).
//!
//! # Stages
//!
//! A task that runs through named stages (discover's steps) says which one is running in
//! [`Progress::stage`], named by the code that runs it; `done` then counts the stages
//! finished, so the one running is `done + 1` of `total`. A task without stages is its
//! own stage (a [`stage`] such as "network sizing sweep"). An MME estimate ([`MME_TASK`])
//! runs through the estimator's phases ("noise-variance search", "W search", "final
//! solve"; [`MmeProgress`]), `total` unknown, its latest step the note. A display shows the stage in every
//! line, also in the "still running" line of a step that reports nothing for a while
//! ([`Progress::running_line`]).
//!
//! ```
//! use mmenn::progress::{NoProgress, Progress, ProgressSink, stage};
//!
//! /// A library job reporting each of its steps.
//! fn search(candidates: &[&str], progress: &dyn ProgressSink) -> usize {
//!     let task = "candidate search";
//!     for (k, c) in candidates.iter().enumerate() {
//!         // … judge candidate c …
//!         progress.report(&Progress::new(task, k + 1, Some(candidates.len())).with_note(*c));
//!     }
//!     progress.finish(task);
//!     candidates.len()
//! }
//!
//! /// A generic caller hands its sink on as `&dyn`.
//! fn outer<P: ProgressSink>(progress: &P) -> usize {
//!     stage(progress, "preparation", || ());
//!     search(&["cubic stiffness", "Coulomb friction"], progress)
//! }
//!
//! let lines = std::sync::Mutex::new(Vec::new());
//! let log = |p: &Progress| lines.lock().unwrap().push(format!("{} {}", p.task, p.done));
//! assert_eq!(outer(&log), 2);
//! assert_eq!(search(&["x"], &NoProgress), 1);
//! assert_eq!(lines.into_inner().unwrap().last().unwrap(), "candidate search 2");
//! ```

/// One report: `done` of `total` steps of `task` finished.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// What is running, in words ("network sizing sweep").
    pub task: String,
    /// Steps finished so far.
    pub done: usize,
    /// Steps in all, when known (`None`: an open-ended iteration such as an optimiser).
    pub total: Option<usize>,
    /// A short note about the latest step ("3 hidden units, test MSE 1.2e-3").
    pub note: String,
    /// The stage running, for a task that runs through named stages ("round 1: proposal
    /// from d̂"); empty when the task is its own stage. `done` counts the stages finished.
    pub stage: String,
}

impl Progress {
    /// A report of `done` of `total` steps.
    pub fn new(task: impl Into<String>, done: usize, total: Option<usize>) -> Self {
        Self {
            task: task.into(),
            done,
            total,
            note: String::new(),
            stage: String::new(),
        }
    }

    /// The same report with a note.
    pub fn with_note(mut self, note: impl Into<String>) -> Self {
        self.note = note.into();
        self
    }

    /// The same report in a named stage (`done` stages finished).
    pub fn with_stage(mut self, stage: impl Into<String>) -> Self {
        self.stage = stage.into();
        self
    }

    /// The stage and where it stands, "round 1: proposal from d̂ (step 3 of 15)" (no
    /// position once `done` reaches `total`); empty without a stage.
    pub fn position(&self) -> String {
        match self.total {
            _ if self.stage.is_empty() => String::new(),
            Some(n) if self.done < n => format!("{} (step {} of {n})", self.stage, self.done + 1),
            _ => self.stage.clone(),
        }
    }

    /// What a display shows beside the task: the stage with its position, then the note.
    pub fn message(&self) -> String {
        match (self.position(), self.note.as_str()) {
            (p, "") => p,
            (p, note) if p.is_empty() => note.to_owned(),
            (p, note) => format!("{p}: {note}"),
        }
    }

    /// A plain progress line: "discover: round 1: proposal from d̂ (step 3 of 15)" for a
    /// task in a stage, "network sizing sweep: 3 of 12 done  4 hidden, …" otherwise.
    pub fn line(&self) -> String {
        if self.stage.is_empty() {
            let of = self.total.map(|n| format!(" of {n}")).unwrap_or_default();
            format!("{}: {}{of} done  {}", self.task, self.done, self.note)
                .trim_end()
                .to_owned()
        } else {
            format!("{}: {}", self.task, self.message())
        }
    }

    /// The line for a task whose last report was this one and that has been running for
    /// `seconds` without another: it names the stage ("discover: round 1: free-run search
    /// over the catalogue (step 4 of 15), running for 35 s"); a task without stages is
    /// its own ("MME estimate: running for 35 s", with "3 of 12 done" when counted); the
    /// latest note follows in brackets ("MME estimate: W search (W trial 7 of at most 80:
    /// ratio 1.013 (target 1)), running for 35 s").
    pub fn running_line(&self, seconds: f64) -> String {
        let position = self.position();
        let note = if self.note.is_empty() {
            String::new()
        } else {
            format!(" ({})", self.note)
        };
        let at = if !position.is_empty() {
            format!("{position}{note}, ")
        } else if let Some(n) = self.total.filter(|_| self.done > 0) {
            format!("{} of {n} done{note}, ", self.done)
        } else if !self.note.is_empty() {
            format!("{}, ", self.note)
        } else {
            String::new()
        };
        format!("{}: {at}running for {seconds:.0} s", self.task)
    }
}

/// Receives progress reports, possibly from several worker threads at once.
pub trait ProgressSink: Sync {
    /// A task advanced (the first report of a task starts it).
    fn report(&self, progress: &Progress);
    /// A task ended (successfully or not); later reports of the same name start anew.
    fn finish(&self, _task: &str) {}
}

/// Ignores every report.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NoProgress;

impl ProgressSink for NoProgress {
    fn report(&self, _progress: &Progress) {}
}

impl<F: Fn(&Progress) + Sync> ProgressSink for F {
    fn report(&self, progress: &Progress) {
        self(progress)
    }
}

/// The task name of an MME estimate's reports ([`stage`] and [`MmeProgress`]).
pub const MME_TASK: &str = "MME estimate";

/// An MME estimate's steps (`mme_core::observe`) as reports of one task: the phase
/// running ("noise-variance search", "W search", "final solve", after a robust pass
/// "robust pass 2 of at most 30: W search") as the [`Progress::stage`], `done` counting
/// the phases finished, and the latest step as the note: "trial 7 of at most 80: ratio
/// 1.34 (target 1)", "Gauss–Newton iteration 3 of at most 50: J 412.7, relative change
/// 2.1e-4 (converged below 1e-10)", "likelihood evaluation 17, −2 log L 1.234e3 (the
/// search has no fixed count)". A fraction where the estimator has a bound, words where
/// it has none. Observing changes nothing the estimate computes.
///
/// Pass it to `mmenn::estimate::estimate_spec_observed` inside a [`stage`] of the same
/// task, which reports the start and the end. An estimate that is one step of a larger
/// task (discover's MME runs) reports [`MmeProgress::within`] that task's latest report
/// instead, the phase and step as its note ("MME W search: W trial 3 of at most 80: …").
pub struct MmeProgress<'a> {
    sink: &'a dyn ProgressSink,
    task: &'a str,
    /// The report of the enclosing task that the estimate's notes go into, if any.
    frame: Option<&'a (dyn Fn() -> Progress + Sync)>,
    state: std::sync::Mutex<MmeSeen>,
}

/// What [`MmeProgress`] has seen of the estimate so far.
#[derive(Default)]
struct MmeSeen {
    /// The phase running, if one was announced.
    phase: Option<mme_core::MmePhase>,
    /// Phases announced.
    phases: usize,
    /// `W` trials finished in the phase running.
    trials: usize,
    /// Robust passes finished, and the most there may be.
    passes: Option<(usize, usize)>,
}

impl<'a> MmeProgress<'a> {
    /// Reports of `task` (usually [`MME_TASK`]) to `sink`.
    pub fn new(sink: &'a dyn ProgressSink, task: &'a str) -> Self {
        Self {
            sink,
            task,
            frame: None,
            state: std::sync::Mutex::new(MmeSeen::default()),
        }
    }

    /// Reports of an estimate that is a step of another task: each is `frame()` (that
    /// task's latest report) with the estimate's phase and step as the note.
    pub fn within(sink: &'a dyn ProgressSink, frame: &'a (dyn Fn() -> Progress + Sync)) -> Self {
        Self {
            sink,
            task: "",
            frame: Some(frame),
            state: std::sync::Mutex::new(MmeSeen::default()),
        }
    }
}

/// A number for a progress note: three decimals between 1e-3 and 1e4, else three
/// significant digits with an exponent; trailing zeros dropped ("1", "0.42", "1e-10").
fn short(x: f64) -> String {
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if x == 0.0 || !x.is_finite() || (1e-3..1e4).contains(&x.abs()) {
        trim(&format!("{x:.3}"))
    } else {
        let s = format!("{x:.2e}");
        match s.split_once('e') {
            Some((mantissa, exponent)) => format!("{}e{exponent}", trim(mantissa)),
            None => s,
        }
    }
}

impl mme_core::MmeObserver for MmeProgress<'_> {
    fn event(&self, event: &mme_core::MmeEvent) {
        use mme_core::{MmeEvent, MmePhase};
        let Ok(mut seen) = self.state.lock() else {
            return;
        };
        let note = match *event {
            MmeEvent::Phase(phase) => {
                seen.phase = Some(phase);
                seen.phases += 1;
                seen.trials = 0;
                String::new()
            }
            MmeEvent::WTrial {
                trial,
                max_trials,
                ratio,
                target,
                ..
            } => {
                seen.trials = trial;
                let what = match seen.phase {
                    Some(MmePhase::NoiseVariance) => "covariance-constraint start, W trial",
                    _ => "W trial",
                };
                format!(
                    "{what} {trial} of at most {max_trials}: ratio {} (target {})",
                    short(ratio),
                    short(target)
                )
            }
            MmeEvent::NoiseStep {
                evaluation,
                neg2_log_likelihood,
            } => format!(
                "likelihood evaluation {evaluation}, −2 log L {} (the search has no fixed count)",
                short(neg2_log_likelihood)
            ),
            MmeEvent::Iteration {
                iteration,
                max_iterations,
                cost,
                relative_change,
                tolerance,
            } => {
                let of = match seen.phase {
                    Some(MmePhase::WeightSearch) => format!("W trial {}, ", seen.trials + 1),
                    _ => String::new(),
                };
                format!(
                    "{of}Gauss–Newton iteration {iteration} of at most {max_iterations}: J {}, \
                     relative change {} (converged below {})",
                    short(cost),
                    short(relative_change),
                    short(tolerance)
                )
            }
            MmeEvent::RobustPass {
                pass,
                max_passes,
                moved,
                tolerance,
            } => {
                seen.passes = Some((pass, max_passes));
                seen.phase = None;
                format!(
                    "robust pass {pass} of at most {max_passes} done: pseudo-observations \
                     moved up to {} σ (settled below {} σ)",
                    short(moved),
                    short(tolerance)
                )
            }
            _ => return,
        };
        let phase = match seen.phase {
            Some(MmePhase::NoiseVariance) => "noise-variance search",
            Some(MmePhase::WeightSearch) => "W search",
            Some(MmePhase::FinalSolve) => "final solve",
            _ => "",
        };
        let stage = match (seen.passes, phase) {
            (Some((done, max)), "") => format!("robust pass {done} of at most {max}"),
            (Some((done, max)), p) => format!("robust pass {} of at most {max}: {p}", done + 1),
            (None, p) => p.to_string(),
        };
        let done = seen.phases.saturating_sub(1);
        drop(seen);
        let report = match self.frame {
            Some(frame) => {
                let note = match (stage.is_empty(), note.is_empty()) {
                    (true, _) => note,
                    (false, true) => format!("MME {stage}"),
                    (false, false) => format!("MME {stage}: {note}"),
                };
                frame().with_note(note)
            }
            None => Progress::new(self.task, done, None)
                .with_stage(stage)
                .with_note(note),
        };
        self.sink.report(&report);
    }
}

/// Report a task's start, run it, and report its end whether it succeeded or not.
pub fn stage<T>(sink: &dyn ProgressSink, task: &str, job: impl FnOnce() -> T) -> T {
    sink.report(&Progress::new(task, 0, None));
    let out = job();
    sink.finish(task);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn closures_are_sinks_and_stages_report_start_and_end() {
        let seen = Mutex::new(Vec::new());
        let sink = |p: &Progress| {
            if let Ok(mut s) = seen.lock() {
                s.push((p.task.clone(), p.done, p.total));
            }
        };
        let v = stage(&sink, "job", || 41 + 1);
        assert_eq!(v, 42);
        sink.report(&Progress::new("job", 1, Some(2)).with_note("half"));
        NoProgress.report(&Progress::new("ignored", 0, None));
        let seen = seen.into_inner().unwrap_or_default();
        assert_eq!(
            seen,
            vec![("job".into(), 0, None), ("job".into(), 1, Some(2))]
        );
    }

    #[test]
    fn lines_name_the_stage_the_task_is_in() {
        let p = Progress::new("discover", 3, Some(15)).with_stage("round 1: proposal from d̂");
        assert_eq!(
            p.running_line(35.2),
            "discover: round 1: proposal from d̂ (step 4 of 15), running for 35 s"
        );
        assert_eq!(
            p.line(),
            "discover: round 1: proposal from d̂ (step 4 of 15)"
        );
        assert_eq!(p.message(), "round 1: proposal from d̂ (step 4 of 15)");
        // With a note, after the stage; at the end no position.
        let p = p.with_note("2 candidates");
        assert_eq!(
            p.message(),
            "round 1: proposal from d̂ (step 4 of 15): 2 candidates"
        );
        let end = Progress::new("discover", 15, Some(15)).with_stage("bootstrap judge");
        assert_eq!(
            end.running_line(5.0),
            "discover: bootstrap judge, running for 5 s"
        );
        // A task without stages is its own stage; a counted one says how far it is.
        let own = Progress::new("MME estimate", 0, None);
        assert_eq!(own.running_line(5.0), "MME estimate: running for 5 s");
        assert_eq!(own.line(), "MME estimate: 0 done");
        let counted = Progress::new("network sizing sweep", 3, Some(12)).with_note("4 hidden");
        assert_eq!(
            counted.running_line(61.0),
            "network sizing sweep: 3 of 12 done (4 hidden), running for 61 s"
        );
        // The latest note in brackets after the stage, or alone.
        let staged = Progress::new("MME estimate", 0, None)
            .with_stage("W search")
            .with_note("W trial 7 of at most 80: ratio 1.013 (target 1)");
        assert_eq!(
            staged.running_line(35.0),
            "MME estimate: W search (W trial 7 of at most 80: ratio 1.013 (target 1)), running for 35 s"
        );
        let noted = Progress::new("job", 0, None).with_note("warming up");
        assert_eq!(noted.running_line(5.0), "job: warming up, running for 5 s");
        assert_eq!(
            counted.line(),
            "network sizing sweep: 3 of 12 done  4 hidden"
        );
        assert_eq!(counted.message(), "4 hidden");
    }

    #[test]
    fn notes_write_numbers_short() {
        let cases = [
            (1.0, "1"),
            (0.42, "0.42"),
            (1.0134, "1.013"),
            (2499.855, "2499.855"),
            (1e-10, "1e-10"),
            (3.164e-6, "3.16e-6"),
            (123_456.0, "1.23e5"),
            (f64::INFINITY, "inf"),
            (0.0, "0"),
        ];
        for (x, text) in cases {
            assert_eq!(short(x), text, "{x}");
        }
    }

    #[test]
    fn one_sink_takes_reports_from_several_threads() {
        let count = std::sync::atomic::AtomicUsize::new(0);
        let sink = |_: &Progress| {
            count.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        };
        let dyn_sink: &dyn ProgressSink = &sink;
        std::thread::scope(|s| {
            for t in 0..4 {
                s.spawn(move || {
                    for k in 0..25 {
                        dyn_sink.report(&Progress::new(format!("worker {t}"), k, Some(25)));
                    }
                });
            }
        });
        assert_eq!(count.load(std::sync::atomic::Ordering::SeqCst), 100);
    }
}
