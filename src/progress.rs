//! Long steps report progress and can be stopped.
//!
//! - [`Step`]: a progress bar with ETA on a terminal; when stderr is not a terminal (a log, CI),
//!   one summary line per step when it finishes, so redirected output stays readable.
//! - Ctrl-C ([`install_ctrl_c`]) raises one process-wide flag that long loops poll with
//!   [`cancelled`]; they return [`Cancelled`] before writing anything, so no file is left
//!   half-written. A second Ctrl-C leaves at once.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

static CANCELLED: AtomicBool = AtomicBool::new(false);

/// Exit status of a run stopped by Ctrl-C (128 + SIGINT, what shells report).
pub const CANCELLED_EXIT_CODE: u8 = 130;

/// The error of a step stopped by Ctrl-C.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("cancelled by Ctrl-C; no file was left half-written")]
pub struct Cancelled;

/// Makes Ctrl-C raise the cancel flag (the second one exits with status 130 at once).
pub fn install_ctrl_c() {
    let handler = || {
        if CANCELLED.swap(true, Ordering::Relaxed) {
            std::process::exit(CANCELLED_EXIT_CODE as i32);
        }
        eprintln!("\nCtrl-C: stopping at the next check (again to quit at once)");
    };
    if let Err(e) = ctrlc::set_handler(handler) {
        log::warn!("no Ctrl-C handler: {e}");
    }
}

/// The process-wide cancel flag, for code that takes an `&AtomicBool`.
pub fn cancel_flag() -> &'static AtomicBool {
    &CANCELLED
}

/// Whether Ctrl-C has been pressed.
pub fn cancelled() -> bool {
    CANCELLED.load(Ordering::Relaxed)
}

/// `Err(Cancelled)` once Ctrl-C has been pressed.
pub fn check() -> Result<(), Cancelled> {
    if cancelled() {
        Err(Cancelled)
    } else {
        Ok(())
    }
}

/// One long step: a bar on a terminal, else a summary line on stderr when it finishes.
pub struct Step {
    bar: indicatif::ProgressBar,
    message: String,
    started: Instant,
    /// Print the summary line at the end (enabled and stderr is not a terminal).
    summary: bool,
    enabled: bool,
    finished: bool,
}

/// Where an enabled [`Step`] stands: what a window shows while a worker thread builds a
/// method (an atlas bake's stages).
#[derive(Clone, Debug, PartialEq)]
pub struct StepProgress {
    pub message: String,
    pub done: u64,
    pub len: u64,
}

impl StepProgress {
    /// done / len in [0, 1] (0 for an empty step).
    pub fn fraction(&self) -> f32 {
        if self.len == 0 {
            0.0
        } else {
            (self.done as f64 / self.len as f64).clamp(0.0, 1.0) as f32
        }
    }
}

static LATEST: std::sync::Mutex<Option<StepProgress>> = std::sync::Mutex::new(None);

/// The enabled step that moved last, on any thread, until it ends.
pub fn latest() -> Option<StepProgress> {
    LATEST.lock().ok().and_then(|latest| latest.clone())
}

impl Step {
    /// A step of `len` units. `enabled = false` shows nothing at all (library callers that
    /// report their own way, tests).
    pub fn new(enabled: bool, len: u64, message: &str) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let bar = if enabled && terminal {
            let bar = indicatif::ProgressBar::new(len);
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "{msg} [{bar:40}] {pos}/{len} ({elapsed} elapsed, ETA {eta})",
            ) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar.set_message(message.to_string());
            bar
        } else {
            let bar = indicatif::ProgressBar::hidden();
            bar.set_length(len);
            bar
        };
        Self {
            bar,
            message: message.to_string(),
            started: Instant::now(),
            summary: enabled && !terminal,
            enabled,
            finished: false,
        }
    }

    pub fn inc(&self, units: u64) {
        self.bar.inc(units);
        self.publish();
    }

    pub fn set_position(&self, done: u64, len: u64) {
        self.bar.set_length(len);
        self.bar.set_position(done);
        self.publish();
    }

    /// Makes this step the one [`latest`] reports (enabled steps only: the silent ones of
    /// library callers and tests stay out of a window's way).
    fn publish(&self) {
        if !self.enabled {
            return;
        }
        if let Ok(mut latest) = LATEST.lock() {
            *latest = Some(StepProgress {
                message: self.message.clone(),
                done: self.bar.position(),
                len: self.bar.length().unwrap_or(0),
            });
        }
    }

    /// Clears the bar, or prints `message: done/len in T s`.
    pub fn finish(mut self) {
        self.end();
    }

    fn end(&mut self) {
        if self.finished {
            return;
        }
        self.finished = true;
        self.bar.finish_and_clear();
        if let Ok(mut latest) = LATEST.lock() {
            if latest.as_ref().is_some_and(|l| l.message == self.message) {
                *latest = None;
            }
        }
        if self.summary {
            let (done, len) = (self.bar.position(), self.bar.length().unwrap_or(0));
            let state = if cancelled() { ", cancelled" } else { "" };
            eprintln!(
                "{}: {done}/{len} in {:.1} s{state}",
                self.message,
                self.started.elapsed().as_secs_f64()
            );
        }
    }
}

impl Drop for Step {
    fn drop(&mut self) {
        self.end();
    }
}

/// Progress of a task reported as (stage, done, total), such as a bake: one [`Step`] per
/// stage, the previous one finished when the stage changes. `report` is `Sync`, so it can be
/// handed to code that reports from several threads.
pub struct Stages {
    prefix: String,
    current: std::sync::Mutex<Option<(String, Step)>>,
}

impl Stages {
    /// Steps named `prefix: stage`.
    pub fn new(prefix: &str) -> Self {
        Self {
            prefix: prefix.to_string(),
            current: std::sync::Mutex::new(None),
        }
    }

    pub fn report(&self, stage: &str, done: usize, total: usize) {
        let Ok(mut current) = self.current.lock() else {
            return;
        };
        if current.as_ref().is_none_or(|(name, _)| name != stage) {
            if let Some((_, step)) = current.take() {
                step.finish();
            }
            *current = Some((
                stage.to_string(),
                Step::new(true, total as u64, &format!("{}: {stage}", self.prefix)),
            ));
        }
        if let Some((_, step)) = current.as_ref() {
            step.set_position(done as u64, total as u64);
        }
    }

    /// Ends the last stage's step (its summary line comes now, not when `self` drops).
    pub fn finish(&self) {
        if let Some((_, step)) = self.current.lock().ok().and_then(|mut c| c.take()) {
            step.finish();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An enabled step is what `latest` reports while it moves, and nothing once it ends; a
    /// silent one is never reported.
    #[test]
    fn latest_follows_the_enabled_step_that_moved() {
        let silent = Step::new(false, 4, "progress test: silent");
        silent.set_position(1, 4);
        assert_ne!(
            latest().map(|l| l.message),
            Some("progress test: silent".to_string())
        );
        let step = Step::new(true, 10, "progress test: loud");
        // Other tests' enabled steps may move in between on other threads: try again then.
        let seen = (0..1000)
            .find_map(|_| {
                step.set_position(3, 10);
                latest().filter(|l| l.message == "progress test: loud")
            })
            .expect("the step in progress");
        assert_eq!((seen.done, seen.len), (3, 10));
        assert!((seen.fraction() - 0.3).abs() < 1e-6);
        step.finish();
        assert_ne!(
            latest().map(|l| l.message),
            Some("progress test: loud".to_string())
        );
    }
}
