//! Counters, gauges and the fit-duration histogram, kept and rendered (OpenMetrics text,
//! which Prometheus scrapes) by `prometheus-client`.

use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::metrics::histogram::Histogram;
use prometheus_client::registry::Registry;
use std::sync::atomic::{AtomicBool, AtomicU64};
use std::sync::Mutex;
use std::time::SystemTime;

/// Upper bounds of the fit-duration buckets, in seconds: a fit takes from milliseconds
/// (warm, small patch) to many seconds (cold, large scan).
const BUCKETS: [f64; 11] = [
    0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
];

/// The `Content-Type` of `render`'s text.
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// The only label: a kind from a fixed set of snake_case names (`kinds::rejection_kind`,
/// `write_failed`, ...), never a file name or a reason, which would make one series per
/// input.
#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct KindLabel {
    kind: &'static str,
}

/// The daemon's metrics; shared by the threads that count and the endpoint that renders.
pub struct Metrics {
    pub fitted: Counter,
    pub rejected: Counter,
    pub superseded: Counter,
    pub unchanged: Counter,
    pub queue_depth: Gauge,
    pub in_flight: Gauge,
    pub reloads: Counter,
    pub reload_failures: Counter,
    pub stopping: AtomicBool,
    /// Set when jobs go through a cluster queue: `/healthz` then reports whether it is
    /// reachable.
    pub queue_configured: AtomicBool,
    /// 1 while the cluster queue's server is connected.
    pub queue_reachable: Gauge,
    fit: Histogram,
    /// When the last error happened, labelled with its kind: one series at a time.
    last_error: Family<KindLabel, Gauge<f64, AtomicU64>>,
    /// Serialises the clear-and-set of `last_error`.
    last_error_lock: Mutex<()>,
    rejections: Family<KindLabel, Counter>,
    registry: Registry,
}

fn now_secs() -> f64 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

impl Default for Metrics {
    fn default() -> Self {
        let mut registry = Registry::default();
        let mut counter = |name: &str, help: &str| {
            let c = Counter::default();
            registry.register(name, help, c.clone());
            c
        };
        let fitted = counter("trispline_patches_fitted", "Versions fitted and written.");
        let rejected = counter(
            "trispline_patches_rejected",
            "Inputs or records rejected (quarantined or left in place).",
        );
        let superseded = counter(
            "trispline_patches_superseded",
            "Versions skipped for a newer one.",
        );
        let unchanged = counter(
            "trispline_patches_unchanged",
            "Inputs skipped as identical to the last fit.",
        );
        let reloads = counter("trispline_config_reloads", "Config reloads applied.");
        let reload_failures = counter(
            "trispline_config_reload_failures",
            "Config reloads refused.",
        );
        let queue_depth = Gauge::default();
        registry.register(
            "trispline_queue_depth",
            "Patches waiting for a worker.",
            queue_depth.clone(),
        );
        let in_flight = Gauge::default();
        registry.register(
            "trispline_in_flight",
            "Patches being fitted or written.",
            in_flight.clone(),
        );
        let queue_reachable = Gauge::default();
        registry.register(
            "trispline_queue_reachable",
            "1 while the cluster queue's server is connected (0 without a queue).",
            queue_reachable.clone(),
        );
        let fit = Histogram::new(BUCKETS);
        registry.register(
            "trispline_fit_duration_seconds",
            "Time inside the fitting worker per version.",
            fit.clone(),
        );
        let last_error = Family::default();
        registry.register(
            "trispline_last_error_timestamp_seconds",
            "When the last error happened; its kind is the label (the reason is in events.ndjson).",
            last_error.clone(),
        );
        let rejections = Family::default();
        registry.register(
            "trispline_rejections",
            "Inputs or records rejected, by kind.",
            rejections.clone(),
        );
        Self {
            fitted,
            rejected,
            superseded,
            unchanged,
            queue_depth,
            in_flight,
            reloads,
            reload_failures,
            stopping: AtomicBool::new(false),
            queue_configured: AtomicBool::new(false),
            queue_reachable,
            fit,
            last_error,
            last_error_lock: Mutex::new(()),
            rejections,
            registry,
        }
    }
}

impl Metrics {
    pub fn observe_fit(&self, seconds: f64) {
        self.fit.observe(seconds);
    }

    /// An error of this kind (a `kinds::rejection_kind`, or `write_failed`,
    /// `component_failed`, `config_rejected`) happened now.
    pub(crate) fn error(&self, kind: &'static str) {
        // A poisoned lock only means another thread panicked mid-update of plain numbers.
        let _one_at_a_time = self
            .last_error_lock
            .lock()
            .unwrap_or_else(|p| p.into_inner());
        self.last_error.clear();
        self.last_error
            .get_or_create(&KindLabel { kind })
            .set(now_secs());
    }

    /// A rejection of this kind (also counted as the last error).
    pub(crate) fn rejected(&self, kind: &'static str) {
        self.rejected.inc();
        self.rejections.get_or_create(&KindLabel { kind }).inc();
        self.error(kind);
    }

    /// The OpenMetrics text of every metric.
    pub fn render(&self) -> String {
        let mut s = String::new();
        if let Err(e) = prometheus_client::encoding::text::encode(&mut s, &self.registry) {
            tracing::warn!(error = %e, "cannot render the metrics");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_is_cumulative_and_labels_are_kinds() {
        let m = Metrics::default();
        m.observe_fit(0.003);
        m.observe_fit(0.2);
        m.fitted.inc_by(2);
        m.rejected("parse_failed");
        m.rejected("parse_failed");
        m.rejected("too_large");
        let text = m.render();
        assert!(text.contains("trispline_patches_fitted_total 2"), "{text}");
        assert!(
            text.contains("trispline_fit_duration_seconds_bucket{le=\"0.005\"} 1"),
            "{text}"
        );
        assert!(text.contains("trispline_fit_duration_seconds_bucket{le=\"0.25\"} 2"));
        assert!(text.contains("trispline_fit_duration_seconds_bucket{le=\"+Inf\"} 2"));
        assert!(text.contains("trispline_fit_duration_seconds_count 2"));
        assert!(text.contains("trispline_rejections_total{kind=\"parse_failed\"} 2"));
        assert!(text.contains("trispline_rejections_total{kind=\"too_large\"} 1"));
        assert!(text.contains("trispline_patches_rejected_total 3"));
        // One last-error series: the latest kind replaces the one before.
        assert!(
            text.contains("trispline_last_error_timestamp_seconds{kind=\"too_large\"}"),
            "{text}"
        );
        assert!(!text.contains("trispline_last_error_timestamp_seconds{kind=\"parse_failed\"}"));
        assert!(text.ends_with("# EOF\n"), "{text}");
    }
}
