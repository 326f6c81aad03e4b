//! Counters and the fit-duration histogram, rendered as Prometheus text.

use std::fmt::Write;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::SystemTime;

/// Upper bounds of the fit-duration buckets, in seconds: a fit takes from milliseconds
/// (warm, small patch) to many seconds (cold, large scan).
const BUCKETS: [f64; 11] = [
    0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
];

#[derive(Default)]
struct Histogram {
    counts: [u64; BUCKETS.len()],
    count: u64,
    sum: f64,
}

#[derive(Default)]
pub struct Metrics {
    pub fitted: AtomicU64,
    pub rejected: AtomicU64,
    pub superseded: AtomicU64,
    pub unchanged: AtomicU64,
    pub queue_depth: AtomicU64,
    pub in_flight: AtomicU64,
    pub reloads: AtomicU64,
    pub reload_failures: AtomicU64,
    pub stopping: AtomicBool,
    fit: Mutex<Histogram>,
    /// When and of which kind the last error was.
    last_error: Mutex<Option<(f64, &'static str)>>,
    /// Rejections per kind: a fixed, small set of label values (never a file name or a
    /// reason, which would make one series per input).
    rejections: Mutex<std::collections::BTreeMap<&'static str, u64>>,
}

fn now_secs() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Prometheus label values escape backslash, quote and newline.
fn label(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars().take(300) {
        match c {
            '\\' => out.push_str("\\\\"),
            '"' => out.push_str("\\\""),
            '\n' => out.push_str("\\n"),
            c => out.push(c),
        }
    }
    out
}

impl Metrics {
    pub fn observe_fit(&self, seconds: f64) {
        // A poisoned lock only means another thread panicked mid-update of plain numbers.
        let mut h = self.fit.lock().unwrap_or_else(|p| p.into_inner());
        for (k, le) in BUCKETS.iter().enumerate() {
            if seconds <= *le {
                h.counts[k] += 1;
            }
        }
        h.count += 1;
        h.sum += seconds;
    }

    /// An error of this kind (a `kinds::rejection_kind`, or `write_failed`,
    /// `component_failed`, `config_rejected`) happened now.
    pub(crate) fn error(&self, kind: &'static str) {
        *self.last_error.lock().unwrap_or_else(|p| p.into_inner()) = Some((now_secs(), kind));
    }

    /// A rejection of this kind (also counted as the last error).
    pub(crate) fn rejected(&self, kind: &'static str) {
        self.rejected.fetch_add(1, Ordering::Relaxed);
        *self
            .rejections
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .entry(kind)
            .or_default() += 1;
        self.error(kind);
    }

    pub fn render(&self) -> String {
        let mut s = String::new();
        let counter = |s: &mut String, name: &str, help: &str, v: u64| {
            let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} counter\n{name} {v}");
        };
        let gauge = |s: &mut String, name: &str, help: &str, v: u64| {
            let _ = writeln!(s, "# HELP {name} {help}\n# TYPE {name} gauge\n{name} {v}");
        };
        let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
        counter(
            &mut s,
            "trispline_patches_fitted_total",
            "Versions fitted and written.",
            get(&self.fitted),
        );
        counter(
            &mut s,
            "trispline_patches_rejected_total",
            "Inputs or records rejected (quarantined).",
            get(&self.rejected),
        );
        counter(
            &mut s,
            "trispline_patches_superseded_total",
            "Versions skipped for a newer one.",
            get(&self.superseded),
        );
        counter(
            &mut s,
            "trispline_patches_unchanged_total",
            "Inputs skipped as identical to the last fit.",
            get(&self.unchanged),
        );
        counter(
            &mut s,
            "trispline_config_reloads_total",
            "Config reloads applied.",
            get(&self.reloads),
        );
        counter(
            &mut s,
            "trispline_config_reload_failures_total",
            "Config reloads refused.",
            get(&self.reload_failures),
        );
        gauge(
            &mut s,
            "trispline_queue_depth",
            "Patches waiting for a worker.",
            get(&self.queue_depth),
        );
        gauge(
            &mut s,
            "trispline_in_flight",
            "Patches being fitted or written.",
            get(&self.in_flight),
        );
        {
            let h = self.fit.lock().unwrap_or_else(|p| p.into_inner());
            let name = "trispline_fit_duration_seconds";
            let _ = writeln!(s, "# HELP {name} Time inside the fitting worker per version.\n# TYPE {name} histogram");
            for (k, le) in BUCKETS.iter().enumerate() {
                let _ = writeln!(s, "{name}_bucket{{le=\"{le}\"}} {}", h.counts[k]);
            }
            let _ = writeln!(s, "{name}_bucket{{le=\"+Inf\"}} {}", h.count);
            let _ = writeln!(s, "{name}_sum {}\n{name}_count {}", h.sum, h.count);
        }
        let last = *self.last_error.lock().unwrap_or_else(|p| p.into_inner());
        let name = "trispline_last_error_timestamp_seconds";
        let _ = writeln!(s, "# HELP {name} When the last error happened; its kind is the label (the reason is in events.ndjson).\n# TYPE {name} gauge");
        match last {
            Some((t, kind)) => {
                let _ = writeln!(s, "{name}{{kind=\"{}\"}} {t}", label(kind));
            }
            None => {
                let _ = writeln!(s, "{name}{{kind=\"\"}} 0");
            }
        }
        let name = "trispline_rejections_total";
        let _ = writeln!(
            s,
            "# HELP {name} Inputs or records rejected, by kind.\n# TYPE {name} counter"
        );
        let by_kind = self.rejections.lock().unwrap_or_else(|p| p.into_inner());
        for (kind, n) in by_kind.iter() {
            let _ = writeln!(s, "{name}{{kind=\"{}\"}} {n}", label(kind));
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_is_cumulative_and_labels_are_escaped() {
        let m = Metrics::default();
        m.observe_fit(0.003);
        m.observe_fit(0.2);
        m.fitted.fetch_add(2, Ordering::Relaxed);
        m.rejected("parse_failed");
        m.rejected("parse_failed");
        m.rejected("too_large");
        let text = m.render();
        assert!(text.contains("trispline_patches_fitted_total 2"));
        assert!(text.contains("trispline_fit_duration_seconds_bucket{le=\"0.005\"} 1"));
        assert!(text.contains("trispline_fit_duration_seconds_bucket{le=\"0.25\"} 2"));
        assert!(text.contains("trispline_fit_duration_seconds_bucket{le=\"+Inf\"} 2"));
        assert!(text.contains("trispline_rejections_total{kind=\"parse_failed\"} 2"));
        assert!(text.contains("trispline_rejections_total{kind=\"too_large\"} 1"));
        assert!(text.contains("trispline_patches_rejected_total 3"));
        assert!(
            text.contains("trispline_last_error_timestamp_seconds{kind=\"too_large\"}"),
            "{text}"
        );
        assert_eq!(label("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
    }
}
