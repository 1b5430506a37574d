//! Progress of long jobs, reported through a small callback so that the library never
//! prints: the `mmenn` binary turns reports into a terminal bar or plain log lines, tests
//! and library users pass [`NoProgress`] or a closure.
//!
//! Reporting only observes a job: it never changes what the job computes. Any workflow
//! of this crate (fit's sizing sweep and trajectory refinement, estimate's phases, and
//! discovery later) takes a `&dyn ProgressSink`.

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
}

impl Progress {
    /// A report of `done` of `total` steps.
    pub fn new(task: impl Into<String>, done: usize, total: Option<usize>) -> Self {
        Self {
            task: task.into(),
            done,
            total,
            note: String::new(),
        }
    }

    /// The same report with a note.
    pub fn with_note(mut self, note: impl Into<String>) -> Self {
        self.note = note.into();
        self
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
}
