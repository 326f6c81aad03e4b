//! A one-line progress display on stderr for long fits. Drawn only when stderr is a
//! terminal and the fit has run for half a second (short fits and pipes stay quiet),
//! redrawn at most ten times a second, and erased when the fit ends so that the final
//! messages are not interleaved with it.

use crate::fit::StepStats;
use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::time::{Duration, Instant};

const QUIET_FOR: Duration = Duration::from_millis(500);
const REDRAW_EVERY: Duration = Duration::from_millis(100);
const BAR_WIDTH: usize = 24;

/// The progress line of one fit; `on_step` may be called from any thread.
pub struct Progress {
    enabled: bool,
    start: Instant,
    max_iterations: usize,
    /// When the line was last drawn; `None` while nothing is on screen.
    drawn: Mutex<Option<Instant>>,
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
            drawn: Mutex::new(None),
        }
    }

    /// Redraws the line for this step, unless it is too early or too soon after the last draw.
    pub fn on_step(&self, s: &StepStats) {
        let elapsed = self.start.elapsed();
        if !self.enabled || elapsed < QUIET_FOR {
            return;
        }
        let Ok(mut drawn) = self.drawn.lock() else {
            return;
        };
        if drawn.is_some_and(|t| t.elapsed() < REDRAW_EVERY) {
            return;
        }
        let line = render(s, self.max_iterations, elapsed);
        let mut err = std::io::stderr().lock();
        // Progress is best effort: a closed stderr must not fail the fit.
        let _ = write!(err, "\r\x1b[2K{line}");
        let _ = err.flush();
        *drawn = Some(Instant::now());
    }

    /// Erases the line if one was drawn.
    pub fn finish(&self) {
        if let Ok(mut drawn) = self.drawn.lock() {
            if drawn.take().is_some() {
                let _ = write!(std::io::stderr().lock(), "\r\x1b[2K");
            }
        }
    }

    /// Whether a line is on screen now.
    pub fn has_drawn(&self) -> bool {
        self.drawn.lock().map(|d| d.is_some()).unwrap_or(false)
    }
}

/// `fitting [#######.................] step 31/100  max 1.2e-3  rms 4.5e-5  1.3 s`; for
/// scans the step count runs on through the correction rounds, so the bar saturates.
pub fn render(s: &StepStats, max_iterations: usize, elapsed: Duration) -> String {
    let frac = (s.k as f64 / max_iterations.max(1) as f64).clamp(0.0, 1.0);
    let filled = (frac * BAR_WIDTH as f64).round() as usize;
    format!(
        "fitting [{}{}] step {}/{}  max {:.2e}  rms {:.2e}  {:.1} s",
        "#".repeat(filled),
        ".".repeat(BAR_WIDTH - filled),
        s.k,
        max_iterations,
        s.max_error,
        s.rms_error,
        elapsed.as_secs_f64()
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
    fn the_line_shows_step_errors_and_a_bar_that_saturates() {
        let line = render(&stats(25), 100, Duration::from_millis(1250));
        assert!(line.contains("step 25/100"), "{line}");
        assert!(line.contains("max 3.00e-3"), "{line}");
        assert!(line.contains("1.2 s") || line.contains("1.3 s"), "{line}");
        assert_eq!(line.matches('#').count(), BAR_WIDTH / 4);
        let over = render(&stats(250), 100, Duration::ZERO);
        assert_eq!(over.matches('#').count(), BAR_WIDTH);
    }

    #[test]
    fn quiet_when_not_a_terminal_or_short() {
        let off = Progress::with_output(10, false);
        off.on_step(&stats(1));
        assert!(!off.has_drawn());
        // Enabled, but the fit has not run for half a second yet.
        let short = Progress::with_output(10, true);
        short.on_step(&stats(1));
        assert!(!short.has_drawn());
    }
}
