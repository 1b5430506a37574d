//! Progress lines on stderr: one per experiment start and end, with the elapsed time of
//! the experiment and of the whole run.

use std::time::Instant;

/// Clock of the whole run.
#[derive(Debug, Clone, Copy)]
pub struct Progress {
    start: Instant,
    quiet: bool,
}

impl Progress {
    /// Start the clock.
    pub fn start(quiet: bool) -> Self {
        Self {
            start: Instant::now(),
            quiet,
        }
    }

    /// Seconds since the run started.
    pub fn elapsed(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Print one line `[  12.3 s] what: message`.
    #[allow(clippy::print_stderr)]
    pub fn line(&self, what: &str, message: &str) {
        if !self.quiet {
            eprintln!("[{:>7.1} s] {what}: {message}", self.elapsed());
        }
    }
}
