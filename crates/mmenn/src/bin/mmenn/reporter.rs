//! Progress of long workflows on stderr ([`Reporter`], the binary's
//! [`ProgressSink`](mmenn::progress::ProgressSink)).

/// What the progress reporter is showing.
enum Shown {
    Nothing,
    /// A bar (or spinner) on the terminal.
    Bar(String, indicatif::ProgressBar),
    /// Plain lines: the task's latest report (its stage), when the task started, when the
    /// last line was due or printed, and whether any line was printed (short tasks print
    /// nothing).
    Lines(
        mmenn::progress::Progress,
        std::time::Instant,
        std::time::Instant,
        bool,
    ),
}

/// Progress on stderr: an `indicatif` bar with ETA on a terminal; otherwise a plain line
/// every few seconds of a task's progress reports (a task shorter than that prints
/// nothing, so a failing command's stderr stays its one error line), and for a step
/// that reports nothing while it runs (a `stage`, a long step of discover, or a long
/// Gauss–Newton iteration of MME) a line from a watcher thread every few seconds saying which stage it
/// is in and how long it has been running ([`mmenn::progress::Progress::running_line`]);
/// nothing with `--quiet`.
pub(crate) struct Reporter {
    quiet: bool,
    terminal: bool,
    shown: std::sync::Arc<std::sync::Mutex<Shown>>,
}

/// Seconds between plain progress lines when stderr is not a terminal, in a task's
/// first minute; after that a line every [`LATER_LINE_EVERY_SECONDS`].
const LINE_EVERY_SECONDS: u64 = 5;

/// Seconds between plain progress lines of a task running for over a minute.
const LATER_LINE_EVERY_SECONDS: u64 = 30;

/// Whether a plain line is due for a task that started at `start` and last printed (or
/// started) at `last`.
fn line_due(start: std::time::Instant, last: std::time::Instant) -> bool {
    let every = if start.elapsed().as_secs() < 60 {
        LINE_EVERY_SECONDS
    } else {
        LATER_LINE_EVERY_SECONDS
    };
    last.elapsed().as_secs() >= every
}

/// A finished task gets a "done in …" line when it took at least this long.
const WORTH_A_LINE_SECONDS: u64 = 2;

impl Reporter {
    pub(crate) fn new(quiet: bool) -> Self {
        use std::io::IsTerminal;
        let terminal = std::io::stderr().is_terminal();
        let shown = std::sync::Arc::new(std::sync::Mutex::new(Shown::Nothing));
        if !quiet && !terminal {
            // The watcher ends with the process; it only reads the clock and prints.
            let watched = std::sync::Arc::clone(&shown);
            let _ = std::thread::Builder::new()
                .name("progress lines".into())
                .spawn(move || Self::watch(&watched));
        }
        Self {
            quiet,
            terminal,
            shown,
        }
    }

    /// Once a second: a line for the task shown in plain lines when it has printed
    /// nothing for a while ([`line_due`]; no report came in that time), naming the stage
    /// of its latest report.
    #[allow(clippy::print_stderr)]
    fn watch(shown: &std::sync::Mutex<Shown>) {
        loop {
            std::thread::sleep(std::time::Duration::from_secs(1));
            let Ok(mut shown) = shown.lock() else {
                return;
            };
            if let Shown::Lines(latest, start, last, printed) = &mut *shown
                && line_due(*start, *last)
            {
                *last = std::time::Instant::now();
                *printed = true;
                eprintln!("{}", latest.running_line(start.elapsed().as_secs_f64()));
            }
        }
    }

    fn bar(p: &mmenn::progress::Progress) -> indicatif::ProgressBar {
        let (bar, template) = match p.total {
            Some(n) => (
                indicatif::ProgressBar::new(n as u64),
                "{prefix} [{bar:30}] {pos}/{len}, {elapsed} elapsed, ETA {eta}  {wide_msg}",
            ),
            None => (
                indicatif::ProgressBar::new_spinner(),
                "{prefix} {spinner} {elapsed}  {wide_msg}",
            ),
        };
        if let Ok(style) = indicatif::ProgressStyle::with_template(template) {
            bar.set_style(style.progress_chars("=> "));
        }
        bar.set_prefix(p.task.clone());
        bar.enable_steady_tick(std::time::Duration::from_millis(200));
        bar
    }
}

#[allow(clippy::print_stderr)]
impl mmenn::progress::ProgressSink for Reporter {
    fn report(&self, p: &mmenn::progress::Progress) {
        if self.quiet {
            return;
        }
        let Ok(mut shown) = self.shown.lock() else {
            return;
        };
        let same = match &*shown {
            Shown::Bar(t, _) => t == &p.task,
            Shown::Lines(latest, _, _, _) => latest.task == p.task,
            Shown::Nothing => false,
        };
        if !same {
            if let Shown::Bar(_, b) = &*shown {
                b.finish_and_clear();
            }
            *shown = if self.terminal {
                Shown::Bar(p.task.clone(), Self::bar(p))
            } else {
                let now = std::time::Instant::now();
                Shown::Lines(p.clone(), now, now, false)
            };
        }
        match &mut *shown {
            Shown::Bar(_, b) => {
                // A task's plan may change as it runs (discover's rounds stop early).
                if let Some(n) = p.total {
                    b.set_length(n as u64);
                }
                b.set_position(p.done as u64);
                b.set_message(p.message());
            }
            Shown::Lines(latest, start, last, printed) => {
                latest.clone_from(p);
                if line_due(*start, *last) {
                    *last = std::time::Instant::now();
                    *printed = true;
                    eprintln!("{}", p.line());
                }
            }
            Shown::Nothing => {}
        }
    }

    fn finish(&self, task: &str) {
        let Ok(mut shown) = self.shown.lock() else {
            return;
        };
        match &*shown {
            Shown::Bar(t, b) if t == task => {
                b.finish_and_clear();
                if b.elapsed().as_secs() >= WORTH_A_LINE_SECONDS {
                    eprintln!("{task}: done in {:.1} s", b.elapsed().as_secs_f64());
                }
            }
            Shown::Lines(latest, start, _, printed) if latest.task == task => {
                if *printed || start.elapsed().as_secs() >= WORTH_A_LINE_SECONDS {
                    eprintln!("{task}: done in {:.1} s", start.elapsed().as_secs_f64());
                }
            }
            _ => return,
        }
        *shown = Shown::Nothing;
    }
}
