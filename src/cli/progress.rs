//! A one-line progress display on stderr for long fits, drawn by `indicatif` (which keeps it
//! off when stderr is not a terminal, limits the redraw rate and erases it cleanly). It
//! appears only once the fit has run for half a second, so short fits stay quiet, and is
//! erased when the fit ends so that the final messages are not interleaved with it.

use crate::fit::StepStats;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

const QUIET_FOR: Duration = Duration::from_millis(500);
const REDRAWS_PER_SECOND: u8 = 10;
const BAR_WIDTH: usize = 24;

/// The progress line of one fit; `on_step` may be called from any thread.
pub struct Progress {
    enabled: bool,
    start: Instant,
    max_iterations: usize,
    /// The bar once shown; `None` while nothing is on screen.
    bar: Mutex<Option<ProgressBar>>,
}

impl Progress {
    /// Enabled when stderr is a terminal.
    pub fn new(max_iterations: usize) -> Self {
        Self::with_output(max_iterations, std::io::stderr().is_terminal())
    }

    /// Enabled or not as told (tests use this to avoid depending on the terminal).
    pub fn with_output(max_iterations: usize, enabled: bool) -> Self {
        Self {
            enabled,
            start: Instant::now(),
            max_iterations: max_iterations.max(1),
            bar: Mutex::new(None),
        }
    }

    /// Updates the line for this step (indicatif redraws it at most ten times a second),
    /// unless the fit is too young to show one.
    pub fn on_step(&self, s: &StepStats) {
        let elapsed = self.start.elapsed();
        if !self.enabled || elapsed < QUIET_FOR {
            return;
        }
        let Ok(mut bar) = self.bar.lock() else {
            return;
        };
        let bar = bar.get_or_insert_with(|| self.show(elapsed));
        // Scans run their steps on through the correction rounds: the bar saturates.
        bar.set_position(s.k.min(self.max_iterations) as u64);
        bar.set_message(render(s, self.max_iterations));
    }

    fn show(&self, elapsed: Duration) -> ProgressBar {
        let target = ProgressDrawTarget::stderr_with_hz(REDRAWS_PER_SECOND);
        let bar = ProgressBar::with_draw_target(Some(self.max_iterations as u64), target)
            .with_elapsed(elapsed);
        let template = format!("fitting [{{bar:{BAR_WIDTH}}}] {{msg}}  {{elapsed}}");
        if let Ok(style) = ProgressStyle::with_template(&template) {
            bar.set_style(style.progress_chars("#>."));
        }
        bar
    }

    /// Erases the line if one was drawn.
    pub fn finish(&self) {
        if let Ok(mut bar) = self.bar.lock() {
            if let Some(b) = bar.take() {
                b.finish_and_clear();
            }
        }
    }

    /// Whether a line is on screen now.
    pub fn has_drawn(&self) -> bool {
        self.bar.lock().map(|b| b.is_some()).unwrap_or(false)
    }
}

/// The line's text after the bar: `step 31/100  max 1.2e-3  rms 4.5e-5`.
pub fn render(s: &StepStats, max_iterations: usize) -> String {
    format!(
        "step {}/{}  max {:.2e}  rms {:.2e}",
        s.k, max_iterations, s.max_error, s.rms_error,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn stats(k: usize) -> StepStats {
        StepStats::from_residuals(k, &[DVec3::new(0.003, 0.0, 0.0)], 1e-3, 0.0)
    }

    #[test]
    fn the_line_shows_step_and_errors() {
        let line = render(&stats(25), 100);
        assert!(line.contains("step 25/100"), "{line}");
        assert!(line.contains("max 3.00e-3"), "{line}");
    }

    #[test]
    fn quiet_when_not_a_terminal_or_short_and_erased_at_the_end() {
        let off = Progress::with_output(10, false);
        off.on_step(&stats(1));
        assert!(!off.has_drawn());
        // Enabled, but the fit has not run for half a second yet.
        let short = Progress::with_output(10, true);
        short.on_step(&stats(1));
        assert!(!short.has_drawn());
        // Past the quiet time the bar exists (saturated beyond max) until finish.
        let long = Progress {
            start: Instant::now() - 2 * QUIET_FOR,
            ..Progress::with_output(10, true)
        };
        long.on_step(&stats(25));
        assert!(long.has_drawn());
        let position = long
            .bar
            .lock()
            .ok()
            .and_then(|b| b.as_ref().map(ProgressBar::position));
        assert_eq!(position, Some(10));
        long.finish();
        assert!(!long.has_drawn());
    }
}
