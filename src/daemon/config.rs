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
}

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonSection {
    pub settle_ms: u64,
    pub poll_interval_ms: u64,
    pub max_file_bytes: u64,
    pub max_vertices: usize,
}

#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    pub quarantine_dir: Option<PathBuf>,
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
        if !(1..=2048).contains(&f.tessellation) {
            return bad(
                "fit.tessellation",
                f.tessellation.to_string(),
                "must be 1..=2048",
            );
        }
        if self.daemon.poll_interval_ms == 0 {
            return bad("daemon.poll_interval_ms", "0".into(), "must be positive");
        }
        if self.daemon.max_file_bytes == 0 {
            return bad("daemon.max_file_bytes", "0".into(), "must be positive");
        }
        Ok(())
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
}
