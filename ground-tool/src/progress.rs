//! # Progress of the ground tool's long steps, on stderr
//!
//! Why: `ground-tool calibrate` on six months of telemetry ran for over a minute without a
//! word (issue 21), so a user could not tell a slow step from a hung one. The chain's steps
//! now name themselves ([`step`]); a command that wants them shown starts a [`Session`]
//! (`calibrate`, `diagnose`, `allan`), which draws one spinner line on stderr with the step and
//! its elapsed time and, when a step of a second or more ends, leaves a line with the step's
//! duration above it.
//!
//! What it must not do: change any output. It writes to stderr only, and only when stderr is
//! a terminal and `--quiet` was not given (otherwise [`Session::start`] installs nothing and
//! every [`step`] is a no-op). Library callers (tests, `calibration-loop`, `calibration-mc`)
//! that start no session see no progress at all.

use std::sync::Mutex;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// The session's bar and the step it shows.
struct Active {
    bar: ProgressBar,
    step: Option<(String, Instant)>,
}

static ACTIVE: Mutex<Option<Active>> = Mutex::new(None);

fn with_active(f: impl FnOnce(&mut Active)) {
    // A poisoned lock (a panic while drawing) only costs the progress display.
    if let Ok(mut guard) = ACTIVE.lock() {
        if let Some(a) = guard.as_mut() {
            f(a);
        }
    }
}

/// Steps shorter than this leave no line (a short run would otherwise list a dozen instant
/// steps).
const LOG_STEPS_LONGER_THAN: Duration = Duration::from_secs(1);

/// Ends the displayed step: a step that took a while leaves a line with its duration above
/// the spinner.
fn finish_step(a: &mut Active) {
    if let Some((name, started)) = a.step.take() {
        let took = started.elapsed();
        if took >= LOG_STEPS_LONGER_THAN {
            a.bar
                .println(format!("  done: {name} ({:.1} s)", took.as_secs_f64()));
        }
    }
}

/// A command's progress display; dropping it clears the spinner line.
#[must_use = "the progress display lasts as long as the session"]
pub struct Session {
    installed: bool,
}

impl Session {
    /// Show the steps of `command` on stderr when `enabled` (not `--quiet`) and stderr is a
    /// terminal; otherwise nothing is installed and [`step`] stays silent.
    pub fn start(command: &str, enabled: bool) -> Self {
        use std::io::IsTerminal as _;
        if !(enabled && std::io::stderr().is_terminal()) {
            return Self { installed: false };
        }
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        bar.set_style(
            ProgressStyle::with_template("{spinner} [{elapsed_precise}] {prefix}: {wide_msg}")
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.set_prefix(command.to_owned());
        bar.enable_steady_tick(Duration::from_millis(120));
        if let Ok(mut guard) = ACTIVE.lock() {
            *guard = Some(Active { bar, step: None });
        }
        Self { installed: true }
    }

    /// Whether a display was installed (stderr a terminal and not `--quiet`).
    #[must_use]
    pub fn is_shown(&self) -> bool {
        self.installed
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        if !self.installed {
            return;
        }
        if let Ok(mut guard) = ACTIVE.lock() {
            if let Some(mut a) = guard.take() {
                finish_step(&mut a);
                a.bar.finish_and_clear();
            }
        }
    }
}

/// Print a line (a warning, a note) on stderr above the progress line, which is then drawn
/// again below it; without a [`Session`], a plain `eprintln!`. The chain's messages go through
/// here ([`crate::note!`]) so that they are not written into the middle of the spinner line.
pub fn print_above(text: &str) {
    let mut printed = false;
    with_active(|a| {
        a.bar.suspend(|| eprintln!("{text}"));
        printed = true;
    });
    if !printed {
        eprintln!("{text}");
    }
}

/// `eprintln!` for library code: the line goes above the progress display when there is one
/// ([`print_above`]).
#[macro_export]
macro_rules! note {
    ($($arg:tt)*) => {
        $crate::progress::print_above(&format!($($arg)*))
    };
}

/// Start the step `name` (the previous one ends here); a no-op without a [`Session`].
pub fn step(name: &str) {
    with_active(|a| {
        finish_step(a);
        a.bar.set_message(name.to_owned());
        a.step = Some((name.to_owned(), Instant::now()));
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_a_terminal_nothing_is_installed_and_steps_are_silent() {
        // Test processes' stderr is captured (not a terminal): a session must not install
        // a display even when enabled, and steps must then do nothing.
        use std::io::IsTerminal as _;
        if std::io::stderr().is_terminal() {
            return; // run by hand in a terminal: the premise does not hold
        }
        let s = Session::start("test", true);
        assert!(!s.is_shown());
        step("a step");
        assert!(ACTIVE.lock().map(|g| g.is_none()).unwrap_or(false));
        let q = Session::start("test", false);
        assert!(!q.is_shown());
    }
}
