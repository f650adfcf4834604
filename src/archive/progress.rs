//! Progress of a conversion: counters the run updates as subjects are calibrated and trials and
//! frames finish ([`Progress`]), and their display on stderr ([`Display`]): progress bars
//! (subjects calibrated, trials, frames with throughput) on a terminal, a plain status line every
//! few seconds otherwise; both say where the time went (calibration, solving).

use indicatif::{MultiProgress, ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::sync::mpsc::{channel, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What a run has done so far; shared between the workers and the display.
#[derive(Debug, Default)]
pub struct Progress {
    pub trials_total: AtomicU64,
    pub trials_done: AtomicU64,
    pub trials_failed: AtomicU64,
    /// Frames expected (from file headers), corrected as trials finish.
    pub frames_total: AtomicU64,
    /// Frames solved; the trial writer adds one per frame written (`archive::trial_job`).
    pub frames_done: AtomicU64,
    /// Subjects with trials to convert, being calibrated now, and calibrated (or failed to).
    pub subjects_total: AtomicU64,
    pub subjects_calibrating: AtomicU64,
    pub subjects_calibrated: AtomicU64,
    /// Time spent calibrating and solving so far, summed over subjects and trials (ms; the
    /// workers' time, not the wall's).
    pub calibration_ms: AtomicU64,
    pub solve_ms: AtomicU64,
    expected: Mutex<HashMap<String, u64>>,
}

/// The counters at one moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    pub trials_total: u64,
    pub trials_done: u64,
    pub trials_failed: u64,
    pub frames_total: u64,
    pub frames_done: u64,
    pub subjects_total: u64,
    pub subjects_calibrating: u64,
    pub subjects_calibrated: u64,
    pub calibration_s: f64,
    pub solve_s: f64,
}

impl Progress {
    /// Declares the trials to come: a key (e.g. `dataset/trial`) and the frames expected of each.
    pub fn plan(&self, trials: impl IntoIterator<Item = (String, u64)>) {
        let mut map = self.expected.lock().unwrap_or_else(|e| e.into_inner());
        for (k, frames) in trials {
            self.trials_total.fetch_add(1, Relaxed);
            self.frames_total.fetch_add(frames, Relaxed);
            map.insert(k, frames);
        }
    }

    /// Records that a subject's calibration starts.
    pub fn calibrating(&self) {
        self.subjects_calibrating.fetch_add(1, Relaxed);
    }

    /// Records that a subject's calibration ended after `seconds` (0 when it failed early).
    pub fn calibrated(&self, seconds: f64) {
        let _ = self.subjects_calibrating.fetch_update(Relaxed, Relaxed, |n| Some(n.saturating_sub(1)));
        self.subjects_calibrated.fetch_add(1, Relaxed);
        self.calibration_ms.fetch_add((seconds.max(0.0) * 1e3).round() as u64, Relaxed);
    }

    /// Adds a solved trial's solve time (s).
    pub fn solved_for(&self, seconds: f64) {
        self.solve_ms.fetch_add((seconds.max(0.0) * 1e3).round() as u64, Relaxed);
    }

    /// Records that trial `key` finished: `solved` frames when it was solved, `None` when it was
    /// skipped or failed before solving (its expected frames leave the total).
    pub fn finished(&self, key: &str, failed: bool, solved: Option<u64>) {
        let expected = self.expected.lock().unwrap_or_else(|e| e.into_inner()).remove(key).unwrap_or(0);
        let actual = solved.unwrap_or(0);
        if actual >= expected {
            self.frames_total.fetch_add(actual - expected, Relaxed);
        } else {
            let _ = self.frames_total.fetch_update(Relaxed, Relaxed, |t| Some(t.saturating_sub(expected - actual)));
        }
        self.trials_done.fetch_add(1, Relaxed);
        if failed {
            self.trials_failed.fetch_add(1, Relaxed);
        }
    }

    /// The counters now. The frame total is never below the frames done (a trial longer than its
    /// header said, or one that failed after writing frames, would otherwise overshoot it).
    pub fn snapshot(&self) -> Snapshot {
        let frames_done = self.frames_done.load(Relaxed);
        Snapshot {
            trials_total: self.trials_total.load(Relaxed),
            trials_done: self.trials_done.load(Relaxed),
            trials_failed: self.trials_failed.load(Relaxed),
            frames_total: self.frames_total.load(Relaxed).max(frames_done),
            frames_done,
            subjects_total: self.subjects_total.load(Relaxed),
            subjects_calibrating: self.subjects_calibrating.load(Relaxed),
            subjects_calibrated: self.subjects_calibrated.load(Relaxed),
            calibration_s: self.calibration_ms.load(Relaxed) as f64 * 1e-3,
            solve_s: self.solve_ms.load(Relaxed) as f64 * 1e-3,
        }
    }
}

/// The plain status line: subjects calibrated, trials done of total, failures, frames, wall
/// throughput, and where the workers' time went.
pub fn status_line(s: &Snapshot, elapsed_s: f64) -> String {
    let rate = if elapsed_s > 0.0 { s.frames_done as f64 / elapsed_s } else { 0.0 };
    format!(
        "{}/{} subjects calibrated, {}/{} trials ({} failed), {}/{} frames, {:.0} frames/s, {:.1} s ({})",
        s.subjects_calibrated,
        s.subjects_total,
        s.trials_done,
        s.trials_total,
        s.trials_failed,
        s.frames_done,
        s.frames_total,
        rate,
        elapsed_s,
        time_split(s)
    )
}

/// Where the workers' time went so far: `calibration 6.6 s, solving 5.8 s`.
pub fn time_split(s: &Snapshot) -> String {
    format!("calibration {:.1} s, solving {:.1} s", s.calibration_s, s.solve_s)
}

/// How progress is shown.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Mode {
    /// Progress bars (trials; frames with frames/s) on stderr, a terminal.
    Bars,
    /// A `progress:` line on stderr every `every`, a `done:` line at the end, and the run's
    /// own lines (one per trial).
    Lines { every: Duration },
    /// Nothing but what the caller prints itself.
    Quiet,
}

impl Mode {
    /// Bars when stderr is a terminal, plain lines every `every` otherwise; `Quiet` when `quiet`.
    pub fn auto(quiet: bool, every: Duration) -> Mode {
        use std::io::IsTerminal;
        match (quiet, std::io::stderr().is_terminal()) {
            (true, _) => Mode::Quiet,
            (false, true) => Mode::Bars,
            (false, false) => Mode::Lines { every },
        }
    }
}

/// A running display of a [`Progress`]; [`Display::finish`] ends it.
pub struct Display {
    mode: Mode,
    progress: Arc<Progress>,
    start: Instant,
    bars: Option<(MultiProgress, [ProgressBar; 3])>,
    stop: Option<Sender<()>>,
    ticker: Option<JoinHandle<()>>,
}

impl Display {
    pub fn start(progress: Arc<Progress>, mode: Mode) -> Display {
        let start = Instant::now();
        let bars = (mode == Mode::Bars).then(|| {
            let multi = MultiProgress::with_draw_target(ProgressDrawTarget::stderr());
            let style = |t: &str| ProgressStyle::with_template(t).unwrap_or_else(|_| ProgressStyle::default_bar());
            let subjects = multi.add(ProgressBar::new(0));
            subjects.set_style(style("subjects [{bar:32.yellow/blue}] {pos}/{len} calibrated {msg}"));
            let trials = multi.add(ProgressBar::new(0));
            trials.set_style(style("trials   [{bar:32.cyan/blue}] {pos}/{len} {msg} ({elapsed})"));
            let frames = multi.add(ProgressBar::new(0));
            frames.set_style(style("frames   [{bar:32.green/blue}] {human_pos}/{human_len} {msg} eta {eta}"));
            (multi, [subjects, trials, frames])
        });
        let (stop, rx) = channel::<()>();
        let tick = match mode {
            Mode::Bars => Some(Duration::from_millis(100)),
            Mode::Lines { every } => Some(every.max(Duration::from_millis(10))),
            Mode::Quiet => None,
        };
        let ticker = tick.map(|every| {
            let (p, b) = (progress.clone(), bars.as_ref().map(|(_, bars)| bars.clone()));
            std::thread::spawn(move || loop {
                match rx.recv_timeout(every) {
                    Err(RecvTimeoutError::Timeout) => {}
                    _ => return,
                }
                let s = p.snapshot();
                match &b {
                    Some(bars) => update_bars(bars, &s, start.elapsed().as_secs_f64()),
                    None => eprintln!("progress: {}", status_line(&s, start.elapsed().as_secs_f64())),
                }
            })
        });
        Display { mode, progress, start, bars, stop: Some(stop), ticker }
    }

    /// Prints a line of the run (a trial's fate, a note) without tearing the bars.
    pub fn println(&self, line: &str) {
        match (&self.bars, self.mode) {
            (_, Mode::Quiet) => {}
            (Some((m, _)), _) => {
                let _ = m.println(line);
            }
            (None, _) => eprintln!("{line}"),
        }
    }

    /// Stops the display; plain lines end with a `done:` line.
    pub fn finish(mut self) {
        drop(self.stop.take());
        if let Some(t) = self.ticker.take() {
            let _ = t.join();
        }
        let s = self.progress.snapshot();
        if let Some((_, bars)) = &self.bars {
            update_bars(bars, &s, self.start.elapsed().as_secs_f64());
            bars.iter().for_each(ProgressBar::finish);
        }
        if let Mode::Lines { .. } = self.mode {
            eprintln!("done: {}", status_line(&s, self.start.elapsed().as_secs_f64()));
        }
    }
}

fn update_bars([subjects, trials, frames]: &[ProgressBar; 3], s: &Snapshot, elapsed_s: f64) {
    subjects.set_length(s.subjects_total);
    subjects.set_position(s.subjects_calibrated);
    let now = if s.subjects_calibrating > 0 { format!("({} now) ", s.subjects_calibrating) } else { String::new() };
    subjects.set_message(format!("{now}— {}", time_split(s)));
    trials.set_length(s.trials_total);
    trials.set_position(s.trials_done);
    trials.set_message(if s.trials_failed > 0 { format!("{} failed", s.trials_failed) } else { String::new() });
    frames.set_length(s.frames_total.max(s.frames_done));
    frames.set_position(s.frames_done);
    frames.set_message(format!("{:.0} frames/s", s.frames_done as f64 / elapsed_s.max(1e-9)));
}

#[cfg(test)]
mod overshoot_tests {
    use super::*;

    #[test]
    fn frames_done_never_exceed_the_total_shown() {
        let p = Progress::default();
        p.plan([("a".to_string(), 200)]);
        p.frames_done.fetch_add(361, Relaxed);
        let s = p.snapshot();
        assert!(s.frames_done <= s.frames_total, "{s:?}");
        // A trial that failed after writing frames leaves the total, not the frames done.
        p.finished("a", true, None);
        let s = p.snapshot();
        assert!(s.frames_done <= s.frames_total, "{s:?}");
    }

    #[test]
    fn the_status_line_says_where_the_time_went() {
        let p = Progress::default();
        p.subjects_total.store(2, Relaxed);
        p.calibrating();
        p.calibrating();
        p.calibrated(0.25);
        p.solved_for(1.5);
        let s = p.snapshot();
        assert_eq!((s.subjects_calibrating, s.subjects_calibrated), (1, 1));
        let line = status_line(&s, 2.0);
        assert!(line.starts_with("1/2 subjects calibrated"), "{line}");
        assert!(line.ends_with("(calibration 0.2 s, solving 1.5 s)"), "{line}");
    }
}
