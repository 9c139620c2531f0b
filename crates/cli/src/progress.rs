//! What a long command shows while it works. On a terminal: a bar for counted work (frames) and
//! a spinner with the elapsed time for a phase that cannot be counted (meshing, saving). In a
//! log (standard error not a terminal, where both are hidden): a line when a phase begins and
//! one every few seconds while counted work or a phase lasts.

use std::io::IsTerminal;
use std::sync::Mutex;
use std::sync::mpsc::{self, RecvTimeoutError, Sender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressStyle};

/// Seconds between lines in a log: often enough to see a run is alive, rarely enough for a log.
const EVERY_S: f64 = 5.0;

/// Whether progress is drawn (a terminal) rather than written as lines.
fn on_terminal() -> bool {
    std::io::stderr().is_terminal()
}

/// Progress lines for counted work when standard error is not a terminal: a line every few
/// seconds with the count, the rate and the time left.
pub struct ProgressLines {
    /// What is counted, as the line starts: "frame", "rendering frame".
    what: &'static str,
    total: usize,
    start: Instant,
    last: Instant,
    enabled: bool,
}

impl ProgressLines {
    pub fn new(what: &'static str, total: usize) -> Self {
        let now = Instant::now();
        Self {
            what,
            total,
            start: now,
            last: now,
            enabled: !on_terminal(),
        }
    }

    pub fn done(&mut self, done: usize) {
        if !self.enabled || done >= self.total {
            return;
        }
        if self.last.elapsed().as_secs_f64() >= EVERY_S {
            self.last = Instant::now();
            let rate = done as f64 / self.start.elapsed().as_secs_f64();
            let left = (self.total - done) as f64 / rate.max(1e-9);
            eprintln!(
                "{} {done}/{}: {rate:.1} frames/s, about {left:.0} s left",
                self.what, self.total
            );
        }
    }
}

/// Counted work: a bar on a terminal, [`ProgressLines`] in a log. Shareable between threads.
/// Nothing shows until the first unit is done: work that never starts says nothing.
pub struct Counter {
    bar: ProgressBar,
    lines: Mutex<ProgressLines>,
    /// The log's first line, until it is written.
    first: Mutex<Option<String>>,
}

impl Counter {
    /// `label` names the work on the bar and in the log's first line ("mapping"); `what`
    /// starts each later log line ("frame").
    pub fn new(label: &str, what: &'static str, total: usize) -> Self {
        let bar = ProgressBar::new(total as u64).with_style(
            ProgressStyle::with_template(
                "{msg} [{bar:40}] {pos}/{len} frames, {per_sec}, eta {eta}",
            )
            .expect("static template")
            .progress_chars("=> "),
        );
        bar.set_message(label.to_owned());
        let lines = ProgressLines::new(what, total);
        let first = lines.enabled.then(|| format!("{label}: {total} frames"));
        Self {
            bar,
            lines: Mutex::new(lines),
            first: Mutex::new(first),
        }
    }

    /// `done` of the total are done.
    pub fn set(&self, done: usize) {
        self.bar.set_position(done as u64);
        self.log(done);
    }

    /// One more is done (for work done in parallel, in any order).
    pub fn inc(&self) {
        self.bar.inc(1);
        self.log(self.bar.position() as usize);
    }

    fn log(&self, done: usize) {
        if let Some(line) = self.first.lock().ok().and_then(|mut f| f.take()) {
            eprintln!("{line}");
        }
        if let Ok(mut lines) = self.lines.lock() {
            lines.done(done);
        }
    }

    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// A phase that cannot be counted, shown from [`Phase::start`] until it is dropped.
pub struct Phase {
    spinner: Option<ProgressBar>,
    /// The log's ticker thread: dropping the sender stops it.
    ticker: Option<(Sender<()>, JoinHandle<()>)>,
}

impl Phase {
    /// Announces `name` ("extracting the mesh"): a spinner on a terminal; in a log, a line now
    /// and "still NAME (N s)" every few seconds until the phase ends.
    pub fn start(name: &str) -> Self {
        if on_terminal() {
            let spinner = ProgressBar::new_spinner().with_style(
                ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
                    .expect("static template"),
            );
            spinner.set_message(name.to_owned());
            spinner.enable_steady_tick(Duration::from_millis(120));
            return Self {
                spinner: Some(spinner),
                ticker: None,
            };
        }
        eprintln!("{name}");
        let (stop, stopped) = mpsc::channel::<()>();
        let name = name.to_owned();
        let start = Instant::now();
        let ticker = std::thread::spawn(move || {
            while let Err(RecvTimeoutError::Timeout) =
                stopped.recv_timeout(Duration::from_secs_f64(EVERY_S))
            {
                eprintln!("still {name} ({:.0} s)", start.elapsed().as_secs_f64());
            }
        });
        Self {
            spinner: None,
            ticker: Some((stop, ticker)),
        }
    }
}

impl Drop for Phase {
    fn drop(&mut self) {
        if let Some(spinner) = self.spinner.take() {
            spinner.finish_and_clear();
        }
        if let Some((stop, ticker)) = self.ticker.take() {
            drop(stop);
            // A ticker that panicked only loses progress lines.
            let _ = ticker.join();
        }
    }
}

/// Phases one after another: starting one ends the one before.
#[derive(Default)]
pub struct Phases {
    current: Option<Phase>,
}

impl Phases {
    pub fn start(&mut self, name: &str) {
        // The old phase's line or spinner goes before the new one's.
        self.current = None;
        self.current = Some(Phase::start(name));
    }

    pub fn end(&mut self) {
        self.current = None;
    }
}
