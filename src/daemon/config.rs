//! Daemon configuration: TOML with unknown keys refused and ranges checked.

use crate::pipeline::worker::WorkerConfig;
use std::path::PathBuf;

pub const DEFAULT_CONFIG: &str = include_str!("../../config/default.toml");

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonConfig {
    pub fit: WorkerConfig,
    pub daemon: DaemonSection,
    #[serde(default)]
    pub output: OutputSection,
    #[serde(default)]
    pub log: LogSection,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonSection {
    pub settle_ms: u64,
    pub poll_interval_ms: u64,
    pub max_file_bytes: u64,
    pub max_vertices: usize,
    /// Fitting threads; 0 means one per available core. Needs a restart to change.
    #[serde(default)]
    pub workers: usize,
    /// Needs a restart to change.
    #[serde(default)]
    pub watcher: WatcherKind,
    /// How long a graceful stop waits for fits in progress.
    #[serde(default = "default_stop_timeout_ms")]
    pub stop_timeout_ms: u64,
    /// `/metrics` and `/healthz` on this loopback address; absent: off. Needs a restart.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub metrics_addr: Option<String>,
    /// Folders a pipe path record may name (and the processed policy may touch); empty:
    /// the watch folder only.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pipe_roots: Vec<PathBuf>,
}

fn default_stop_timeout_ms() -> u64 {
    30_000
}

/// `native`: inotify (rename-into and close-after-write count at once, settle time for the
/// rest); `poll`: directory scans every `poll_interval_ms`, for network filesystems where
/// change notifications do not arrive.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WatcherKind {
    #[default]
    Native,
    Poll,
}

/// What happens to an input once its content has been fitted. Inputs that were not fitted
/// (superseded, rejected) are never deleted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProcessedPolicy {
    #[default]
    Leave,
    /// Moved to OUT/processed.
    Move,
    Delete,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quarantine_dir: Option<PathBuf>,
    /// `surface.json` is always written (last, as the commit marker); these are optional.
    #[serde(default = "yes")]
    pub glb: bool,
    #[serde(default = "yes")]
    pub report: bool,
    #[serde(default)]
    pub processed: ProcessedPolicy,
}

impl Default for OutputSection {
    fn default() -> Self {
        Self {
            quarantine_dir: None,
            glb: true,
            report: true,
            processed: ProcessedPolicy::Leave,
        }
    }
}

fn yes() -> bool {
    true
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    #[default]
    Human,
    Json,
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LogSection {
    /// A tracing filter (`info`, `debug`, `trispline=debug,warn`); changes live.
    #[serde(default = "default_level")]
    pub level: String,
    /// Needs a restart to change.
    #[serde(default)]
    pub format: LogFormat,
}

impl Default for LogSection {
    fn default() -> Self {
        Self {
            level: default_level(),
            format: LogFormat::Human,
        }
    }
}

fn default_level() -> String {
    "info".to_string()
}

#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{source_name}: {message}")]
    Parse {
        source_name: String,
        message: String,
    },
    #[error("{source_name}: {key} = {value}: {reason}")]
    Range {
        source_name: String,
        key: String,
        value: String,
        reason: String,
    },
}

impl DaemonConfig {
    /// Parses and validates; `source_name` names the file in errors (toml reports the key,
    /// line and column of a bad entry).
    pub fn parse(text: &str, source_name: &str) -> Result<DaemonConfig, ConfigError> {
        let cfg: DaemonConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            source_name: source_name.to_string(),
            message: e.to_string(),
        })?;
        cfg.validate(source_name)?;
        Ok(cfg)
    }

    pub fn embedded_default() -> Result<DaemonConfig, ConfigError> {
        Self::parse(DEFAULT_CONFIG, "embedded config/default.toml")
    }

    fn validate(&self, source_name: &str) -> Result<(), ConfigError> {
        let bad = |key: &str, value: String, reason: &str| {
            Err(ConfigError::Range {
                source_name: source_name.to_string(),
                key: key.to_string(),
                value,
                reason: reason.to_string(),
            })
        };
        let f = &self.fit;
        if !(1..=6).contains(&f.levels) {
            return bad("fit.levels", f.levels.to_string(), "must be 1..=6");
        }
        if f.min_levels > 6 {
            return bad("fit.min_levels", f.min_levels.to_string(), "must be 0..=6");
        }
        if !(1..=64).contains(&f.lattice) {
            return bad("fit.lattice", f.lattice.to_string(), "must be 1..=64");
        }
        if f.max_iterations == 0 || f.max_iterations > 1_000_000 {
            return bad(
                "fit.max_iterations",
                f.max_iterations.to_string(),
                "must be 1..=1000000",
            );
        }
        if !(f.tolerance_rel > 0.0 && f.tolerance_rel < 1.0) {
            return bad(
                "fit.tolerance_rel",
                f.tolerance_rel.to_string(),
                "must be in (0, 1)",
            );
        }
        if let Some(t) = f.tolerance.filter(|t| !(*t > 0.0 && t.is_finite())) {
            return bad("fit.tolerance", t.to_string(), "must be positive");
        }
        if let Some(p) = f
            .within_tolerance_pct
            .filter(|p| !(0.0..=100.0).contains(p))
        {
            return bad("fit.within_tolerance_pct", p.to_string(), "must be 0..=100");
        }
        if !(f.smoothing >= 0.0 && f.smoothing.is_finite()) {
            return bad("fit.smoothing", f.smoothing.to_string(), "must be >= 0");
        }
        if let Some(n) = f.grid_segments.filter(|n| !(1..=4096).contains(n)) {
            return bad("fit.grid_segments", n.to_string(), "must be 1..=4096");
        }
        if !(f.target_controls_pct > 0.0 && f.target_controls_pct <= 100.0) {
            return bad(
                "fit.target_controls_pct",
                f.target_controls_pct.to_string(),
                "must be in (0, 100]",
            );
        }
        if !(0.0..=1.0).contains(&f.min_component_fraction) {
            return bad(
                "fit.min_component_fraction",
                f.min_component_fraction.to_string(),
                "must be 0..=1",
            );
        }
        if !(f.hole_bridge_edges > 0.0 && f.hole_bridge_edges.is_finite()) {
            return bad(
                "fit.hole_bridge_edges",
                f.hole_bridge_edges.to_string(),
                "must be a positive number",
            );
        }
        if f.min_component_vertices < 3 {
            return bad(
                "fit.min_component_vertices",
                f.min_component_vertices.to_string(),
                "must be at least 3",
            );
        }
        if !(0.0..1.0).contains(&f.correction_min_gain) {
            return bad(
                "fit.correction_min_gain",
                f.correction_min_gain.to_string(),
                "must be in [0, 1)",
            );
        }
        for (key, value) in [
            ("fit.correction_tangential", f.correction_tangential),
            (
                "fit.correction_tangential_edge",
                f.correction_tangential_edge,
            ),
        ] {
            if !(value > 0.0 && value <= 1.0) {
                return bad(key, value.to_string(), "must be in (0, 1]");
            }
        }
        if f.correction_rounds > 100 {
            return bad(
                "fit.correction_rounds",
                f.correction_rounds.to_string(),
                "must be 0..=100",
            );
        }
        if !(1..=2048).contains(&f.tessellation) {
            return bad(
                "fit.tessellation",
                f.tessellation.to_string(),
                "must be 1..=2048",
            );
        }
        if !(1..=60_000).contains(&self.daemon.poll_interval_ms) {
            return bad(
                "daemon.poll_interval_ms",
                self.daemon.poll_interval_ms.to_string(),
                "must be 1..=60000",
            );
        }
        if self.daemon.stop_timeout_ms > 3_600_000 {
            return bad(
                "daemon.stop_timeout_ms",
                self.daemon.stop_timeout_ms.to_string(),
                "must be at most 3600000",
            );
        }
        if self.daemon.max_file_bytes == 0 {
            return bad("daemon.max_file_bytes", "0".into(), "must be positive");
        }
        if self.daemon.workers > 256 {
            return bad(
                "daemon.workers",
                self.daemon.workers.to_string(),
                "must be 0..=256 (0: one per core)",
            );
        }
        if self.daemon.settle_ms > 3_600_000 {
            return bad(
                "daemon.settle_ms",
                self.daemon.settle_ms.to_string(),
                "must be at most 3600000",
            );
        }
        if let Some(addr) = &self.daemon.metrics_addr {
            match addr.parse::<std::net::SocketAddr>() {
                Err(e) => return bad("daemon.metrics_addr", addr.clone(), &e.to_string()),
                // The responder has no authentication: it must not be reachable from outside.
                Ok(a) if !a.ip().is_loopback() => {
                    return bad(
                        "daemon.metrics_addr",
                        addr.clone(),
                        "must be a loopback address (127.0.0.1 or ::1)",
                    )
                }
                Ok(_) => {}
            }
        }
        if let Err(e) = tracing_subscriber::EnvFilter::try_new(&self.log.level) {
            return bad("log.level", self.log.level.clone(), &e.to_string());
        }
        Ok(())
    }

    /// Workers actually started: the configured number, or one per available core.
    pub fn worker_threads(&self) -> usize {
        match self.daemon.workers {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n,
        }
    }

    /// Hash of everything that shapes the outputs of a fit: an unchanged input is refitted
    /// when this changes.
    pub fn output_hash(&self) -> u64 {
        let shaping = serde_json::json!({
            "fit": self.fit,
            "glb": self.output.glb,
            "report": self.output.report,
        });
        super::state::content_hash(shaping.to_string().as_bytes())
    }

    /// Keys whose change a reload cannot apply (threads, sockets and the watcher are set up
    /// once); reported so that nobody believes they took effect.
    pub fn restart_only_changes(&self, new: &DaemonConfig) -> Vec<&'static str> {
        let mut keys = Vec::new();
        if self.daemon.workers != new.daemon.workers {
            keys.push("daemon.workers");
        }
        if self.daemon.watcher != new.daemon.watcher {
            keys.push("daemon.watcher");
        }
        if self.daemon.metrics_addr != new.daemon.metrics_addr {
            keys.push("daemon.metrics_addr");
        }
        if self.log.format != new.log.format {
            keys.push("log.format");
        }
        if self.output.quarantine_dir != new.output.quarantine_dir {
            keys.push("output.quarantine_dir");
        }
        keys
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot print config: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_default_parses_and_round_trips() {
        let cfg = DaemonConfig::embedded_default().expect("valid default");
        let again = DaemonConfig::parse(&cfg.to_toml(), "printed").expect("printed config parses");
        assert_eq!(again.fit.lattice, cfg.fit.lattice);
    }

    #[test]
    fn unknown_key_is_named_with_line_and_column() {
        let text = DEFAULT_CONFIG.replace("lattice = 16", "latice = 16");
        let e = DaemonConfig::parse(&text, "my.toml")
            .expect_err("refused")
            .to_string();
        assert!(
            e.contains("my.toml") && e.contains("latice") && e.contains("line"),
            "{e}"
        );
    }

    #[test]
    fn out_of_range_value_is_refused() {
        let text = DEFAULT_CONFIG.replace("levels = 2", "levels = 9");
        let e = DaemonConfig::parse(&text, "my.toml")
            .expect_err("refused")
            .to_string();
        assert!(e.contains("fit.levels"), "{e}");
    }

    #[test]
    fn metrics_address_must_be_loopback() {
        let with = |addr: &str| {
            DEFAULT_CONFIG.replace(
                "# metrics_addr = \"127.0.0.1:9187\"",
                &format!("metrics_addr = \"{addr}\""),
            )
        };
        assert!(DaemonConfig::parse(&with("127.0.0.1:9187"), "m.toml").is_ok());
        assert!(DaemonConfig::parse(&with("[::1]:9187"), "m.toml").is_ok());
        let e = DaemonConfig::parse(&with("0.0.0.0:9187"), "m.toml")
            .expect_err("refused")
            .to_string();
        assert!(
            e.contains("daemon.metrics_addr") && e.contains("loopback"),
            "{e}"
        );
        assert!(DaemonConfig::parse(&with("localhost"), "m.toml").is_err());
    }

    #[test]
    fn new_keys_have_defaults_and_are_checked() {
        let old = "[fit]\nsurface = \"bezier\"\nlevels = 1\nmethod = \"cg\"\ninverse = \"exact\"\nmax_iterations = 5\ntolerance_rel = 1e-3\nlattice = 8\nsmoothing = 1e-5\ntessellation = 8\n[daemon]\nsettle_ms = 0\npoll_interval_ms = 50\nmax_file_bytes = 100\nmax_vertices = 100\n";
        let cfg = DaemonConfig::parse(old, "old.toml").expect("configs without the new keys");
        assert_eq!(cfg.daemon.watcher, WatcherKind::Native);
        assert_eq!(cfg.output.processed, ProcessedPolicy::Leave);
        assert!(cfg.output.glb && cfg.output.report);
        let e = DaemonConfig::parse(&format!("{old}watcher = \"smoke\"\n"), "w.toml")
            .expect_err("refused")
            .to_string();
        assert!(e.contains("watcher"), "{e}");
        let e = DaemonConfig::parse(&format!("{old}[log]\nlevel = \"=[\"\n"), "l.toml")
            .expect_err("refused")
            .to_string();
        assert!(e.contains("log.level"), "{e}");
    }

    #[test]
    fn output_hash_follows_the_fit_section_only() {
        let a = DaemonConfig::embedded_default().expect("default");
        let mut b = a.clone();
        b.daemon.settle_ms += 1;
        assert_eq!(a.output_hash(), b.output_hash());
        b.fit.max_iterations += 1;
        assert_ne!(a.output_hash(), b.output_hash());
    }
}
