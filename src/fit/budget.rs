//! Error budgets and fit statuses.

use glam::DVec3;
use rayon::prelude::*;

/// Residual statistics of more points than this are computed in parallel chunks.
const STATS_CHUNK: usize = 1 << 16;

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
/// When a fit may stop: error targets (any one met stops it) and limits.
pub struct Budget {
    /// Absolute tolerance behind `within_tolerance_pct` (already resolved from a relative one).
    pub tolerance: f64,
    /// Target for the largest error.
    pub max_error: Option<f64>,
    /// Target for the mean error.
    pub mean_error: Option<f64>,
    /// Target for the RMS error.
    pub rms_error: Option<f64>,
    /// Target share of points within `tolerance`, in percent.
    pub within_tolerance_pct: Option<f64>,
    /// Most steps.
    pub max_iterations: usize,
    /// Most wall time, checked between steps.
    pub max_time_ms: Option<u64>,
    /// Stalled when the RMS improves by less than `stall_rel_improvement` (relative) over
    /// `stall_steps` consecutive steps.
    pub stall_steps: usize,
    /// See `stall_steps`.
    pub stall_rel_improvement: f64,
}

impl Default for Budget {
    fn default() -> Self {
        Self {
            tolerance: 0.0,
            max_error: None,
            mean_error: None,
            rms_error: None,
            within_tolerance_pct: None,
            max_iterations: 100,
            max_time_ms: None,
            stall_steps: 5,
            stall_rel_improvement: 1e-4,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
/// How a fit ended.
pub enum FitStatus {
    /// A target was met (or there were none and the iteration converged or ran its steps).
    Met,
    /// Stopped by the step or time limit before any target was met.
    Capped,
    /// Stopped because further steps no longer improved the fit.
    Stalled,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
/// Residual statistics after one step.
pub struct StepStats {
    /// Step number (0 = the starting net).
    pub k: usize,
    /// Largest point error.
    pub max_error: f64,
    /// Mean point error.
    pub mean_error: f64,
    /// RMS point error.
    pub rms_error: f64,
    /// Share of points within the budget's tolerance, in percent.
    pub within_tolerance_pct: f64,
    /// Milliseconds since the fit started.
    pub elapsed_ms: f64,
}

/// Figures of a set of distances: the largest, their sum, the sum of their squares and
/// how many are within the tolerance.
type Sums = (f64, f64, f64, usize);

fn sums(distances: impl Iterator<Item = f64>, tolerance: f64) -> Sums {
    distances.fold((0.0f64, 0.0, 0.0, 0), |(max, sum, sum2, within), d| {
        (
            max.max(d),
            sum + d,
            sum2 + d * d,
            within + usize::from(d <= tolerance),
        )
    })
}

impl StepStats {
    /// The figures of point errors given as distances.
    pub(crate) fn from_distances(
        k: usize,
        distances: &[f64],
        tolerance: f64,
        elapsed_ms: f64,
    ) -> Self {
        let s = sums(distances.iter().copied(), tolerance);
        Self::from_sums(k, distances.len(), s, elapsed_ms)
    }

    fn from_sums(k: usize, count: usize, (max, sum, sum2, within): Sums, elapsed_ms: f64) -> Self {
        let n = count.max(1) as f64;
        Self {
            k,
            max_error: max,
            mean_error: sum / n,
            rms_error: (sum2 / n).sqrt(),
            within_tolerance_pct: 100.0 * within as f64 / n,
            elapsed_ms,
        }
    }

    pub(crate) fn from_residuals(
        k: usize,
        residuals: &[DVec3],
        tolerance: f64,
        elapsed_ms: f64,
    ) -> Self {
        let chunk = |rs: &[DVec3]| sums(rs.iter().map(|r| r.length()), tolerance);
        // Fixed chunks summed in order: the same figures whatever the thread count.
        let (max, sum, sum2, within) = if residuals.len() <= STATS_CHUNK {
            chunk(residuals)
        } else {
            let parts: Vec<_> = residuals.par_chunks(STATS_CHUNK).map(chunk).collect();
            parts.into_iter().fold((0.0f64, 0.0, 0.0, 0), |a, p| {
                (a.0.max(p.0), a.1 + p.1, a.2 + p.2, a.3 + p.3)
            })
        };
        Self::from_sums(k, residuals.len(), (max, sum, sum2, within), elapsed_ms)
    }
}

impl Budget {
    /// True when at least one target is set and all set targets hold.
    pub fn met(&self, s: &StepStats) -> bool {
        let targets = [
            self.max_error.map(|t| s.max_error <= t),
            self.mean_error.map(|t| s.mean_error <= t),
            self.rms_error.map(|t| s.rms_error <= t),
            self.within_tolerance_pct
                .map(|t| s.within_tolerance_pct >= t),
        ];
        targets.iter().any(Option::is_some) && targets.iter().all(|t| t.unwrap_or(true))
    }

    pub(crate) fn has_targets(&self) -> bool {
        self.max_error.is_some()
            || self.mean_error.is_some()
            || self.rms_error.is_some()
            || self.within_tolerance_pct.is_some()
    }

    /// Whether the RMS improved by less than `stall_rel_improvement` over the last `stall_steps` steps.
    pub fn stalled(&self, history: &[StepStats]) -> bool {
        if self.stall_steps == 0 || history.len() <= self.stall_steps {
            return false;
        }
        let last = history[history.len() - 1].rms_error;
        let before = history[history.len() - 1 - self.stall_steps].rms_error;
        before - last <= self.stall_rel_improvement * before.max(1e-300)
    }
}
