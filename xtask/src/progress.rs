//! Progress on stderr: a line per experiment start and end with the elapsed time of the
//! experiment and of the whole run, how many experiments are done of how many, and an
//! estimate of the time left. On a terminal, a bar (done experiments weighted by their
//! expected cost) sits under the lines; elsewhere (CI logs, pipes) there are only lines;
//! `--quiet` prints nothing.
//!
//! The estimate of the time left: the run's elapsed time since the first experiment
//! started, times the expected cost still to run over the expected cost done (each job's
//! `cost`, the seconds a full run took on two cores). It is a guess from the costs, shown
//! only once an experiment has ended.

use std::sync::Mutex;
use std::time::Instant;

/// Experiments of the run: counts and expected costs.
#[derive(Debug, Default)]
struct Board {
    total: usize,
    total_cost: f64,
    done: usize,
    done_cost: f64,
    running: Vec<String>,
    started: Option<Instant>,
}

/// Clock of the whole run and its experiments.
#[derive(Debug)]
pub struct Progress {
    start: Instant,
    quiet: bool,
    board: Mutex<Board>,
    bar: Option<indicatif::ProgressBar>,
}

/// `1 min 05 s`, `12.3 s`.
pub fn duration(seconds: f64) -> String {
    if !seconds.is_finite() || seconds < 0.0 {
        return "–".into();
    }
    if seconds < 60.0 {
        return format!("{seconds:.1} s");
    }
    let s = seconds.round() as u64;
    if s < 3600 {
        format!("{} min {:02} s", s / 60, s % 60)
    } else {
        format!("{} h {:02} min", s / 3600, (s % 3600) / 60)
    }
}

/// Seconds left: `elapsed` × cost still to run / cost done (`None` before anything is done).
pub fn eta(elapsed: f64, done_cost: f64, total_cost: f64) -> Option<f64> {
    (done_cost > 0.0 && total_cost >= done_cost)
        .then(|| elapsed * (total_cost - done_cost) / done_cost)
}

impl Progress {
    /// Start the clock; a bar only when stderr is a terminal and not `quiet`.
    pub fn start(quiet: bool) -> Self {
        use std::io::IsTerminal;
        let terminal = std::io::stderr().is_terminal();
        Self {
            start: Instant::now(),
            quiet,
            board: Mutex::new(Board::default()),
            bar: (terminal && !quiet).then(indicatif::ProgressBar::hidden),
        }
    }

    /// Seconds since the run started.
    pub fn elapsed(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Print one line `[  12.3 s] what: message` (above the bar, when there is one).
    #[allow(clippy::print_stderr)]
    pub fn line(&self, what: &str, message: &str) {
        if self.quiet {
            return;
        }
        let text = format!("[{:>7.1} s] {what}: {message}", self.elapsed());
        match &self.bar {
            Some(bar) if !bar.is_hidden() => bar.println(text),
            _ => eprintln!("{text}"),
        }
    }

    /// The experiments about to run, with their expected costs.
    pub fn begin_jobs(&self, costs: &[f64]) {
        if let Ok(mut b) = self.board.lock() {
            *b = Board {
                total: costs.len(),
                total_cost: costs.iter().sum(),
                ..Board::default()
            };
        }
        if let Some(bar) = &self.bar {
            bar.set_length(1000);
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "{prefix} [{bar:30}] {elapsed} elapsed  {wide_msg}",
            ) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar.set_prefix("reproduce");
            bar.enable_steady_tick(std::time::Duration::from_millis(500));
            self.redraw();
        }
    }

    /// `3/17 done, ETA 2 min 10 s` (and the running experiments, on the bar).
    fn status(b: &Board, with_running: bool) -> String {
        let elapsed = b.started.map_or(0.0, |s| s.elapsed().as_secs_f64());
        let eta = eta(elapsed, b.done_cost, b.total_cost)
            .map_or("ETA after the first experiment ends".to_string(), |s| {
                format!("ETA {}", duration(s))
            });
        let mut s = format!("{}/{} experiments done, {eta}", b.done, b.total);
        if with_running && !b.running.is_empty() {
            s.push_str(&format!("; running: {}", b.running.join(", ")));
        }
        s
    }

    fn redraw(&self) {
        if let (Some(bar), Ok(b)) = (&self.bar, self.board.lock()) {
            let frac = if b.total_cost > 0.0 {
                b.done_cost / b.total_cost
            } else {
                0.0
            };
            bar.set_position((1000.0 * frac).round() as u64);
            bar.set_message(Self::status(&b, true));
        }
    }

    /// An experiment started.
    pub fn job_started(&self, name: &str) {
        if let Ok(mut b) = self.board.lock() {
            b.started.get_or_insert_with(Instant::now);
            b.running.push(name.to_string());
        }
        self.line(name, "started");
        self.redraw();
    }

    /// An experiment ended after `seconds` (`failure`: why it failed).
    pub fn job_finished(&self, name: &str, cost: f64, seconds: f64, failure: Option<&str>) {
        let status = match self.board.lock() {
            Ok(mut b) => {
                b.done += 1;
                b.done_cost += cost;
                b.running.retain(|r| r != name);
                Self::status(&b, false)
            }
            Err(_) => String::new(),
        };
        match failure {
            None => self.line(name, &format!("done in {} ({status})", duration(seconds))),
            Some(e) => self.line(
                name,
                &format!("FAILED after {}: {e} ({status})", duration(seconds)),
            ),
        }
        self.redraw();
    }

    /// The experiments are over: the bar goes.
    pub fn end_jobs(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_read_as_a_person_writes_them() {
        assert_eq!(duration(12.34), "12.3 s");
        assert_eq!(duration(65.0), "1 min 05 s");
        assert_eq!(duration(3725.0), "1 h 02 min");
        assert_eq!(duration(f64::NAN), "–");
    }

    #[test]
    fn eta_scales_the_elapsed_time_by_the_cost_left() {
        // A quarter of the cost done in 30 s: three quarters left take 90 s.
        assert_eq!(eta(30.0, 25.0, 100.0), Some(90.0));
        assert_eq!(eta(30.0, 0.0, 100.0), None);
        assert_eq!(eta(30.0, 100.0, 100.0), Some(0.0));
    }

    #[test]
    fn the_board_counts_jobs_and_cost() {
        let p = Progress::start(true);
        p.begin_jobs(&[10.0, 30.0]);
        p.job_started("a");
        p.job_started("b");
        p.job_finished("a", 10.0, 1.0, None);
        let b = p.board.lock().unwrap();
        assert_eq!((b.done, b.total), (1, 2));
        assert_eq!(b.running, vec!["b".to_string()]);
        assert!(Progress::status(&b, false).starts_with("1/2 experiments done, ETA "));
    }
}
