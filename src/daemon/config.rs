//! Daemon configuration: TOML with unknown keys refused and ranges checked.

pub use super::cluster_config::ClusterSection;
pub use super::object_config::ObjectSection;
use crate::io::iges::IgesUnits;
use crate::pipeline::scan::{CorrectionConfig, ScanConfig};
use crate::pipeline::worker::{FitConfig, WorkerConfig, DEFAULT_TESSELLATION};
use std::path::PathBuf;

/// The embedded default configuration (`config/default.toml`): what runs without `--config`.
pub const DEFAULT_CONFIG: &str = include_str!("../../config/default.toml");

/// The whole daemon configuration, one field per TOML table.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonConfig {
    /// `[fit]` and its sub-tables: what the worker does with every input.
    pub fit: FitConfig,
    /// `[daemon]`: intake, limits, threads.
    pub daemon: DaemonSection,
    /// `[output]`: which files are written and what happens to fitted inputs.
    #[serde(default)]
    pub output: OutputSection,
    /// `[log]`: filter and format of the log lines.
    #[serde(default)]
    pub log: LogSection,
    /// `[cluster]`: the shared work queue and state store (`--queue`).
    #[serde(default)]
    pub cluster: ClusterSection,
    /// `[object]`: subfolders as objects scanned view by view.
    #[serde(default)]
    pub object: ObjectSection,
}

/// The `[daemon]` table.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaemonSection {
    /// A file counts as arrived when its size and mtime stayed the same this long (files a
    /// writer keeps open, polling mode, files present at start-up).
    pub settle_ms: u64,
    /// Directory scan interval of the polling watcher.
    pub poll_interval_ms: u64,
    /// Larger inputs (and larger sums of pipe payloads held at once) are refused.
    pub max_file_bytes: u64,
    /// Inputs with more vertices are refused; the readers' allocation budgets derive from it.
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
    /// What happens to a valid input the pipeline cannot fit (a topology it does not
    /// support, too few points, over `max_vertices`). Broken files always go to quarantine.
    #[serde(default)]
    pub unsupported: UnsupportedPolicy,
    /// Files in subfolders of the watch folder are patches too (`sub/name`); `--recursive`
    /// sets it. Needs a restart to change.
    #[serde(default)]
    pub recursive: bool,
}

/// Where a valid but unsupported input goes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UnsupportedPolicy {
    /// Left in the watch folder, rejected with an event that gives the reason.
    #[default]
    Keep,
    /// Moved to quarantine like a broken file.
    Quarantine,
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
    /// inotify through `notify`.
    #[default]
    Native,
    /// Directory scans with the settle time only.
    Poll,
}

/// What happens to an input once its content has been fitted. Inputs that were not fitted
/// (superseded, rejected) are never deleted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProcessedPolicy {
    /// Left where it is.
    #[default]
    Leave,
    /// Moved to OUT/processed.
    Move,
    /// Removed (only inputs under the watch folder or the pipe roots).
    Delete,
}

impl ProcessedPolicy {
    /// The config spelling.
    pub fn name(self) -> &'static str {
        match self {
            ProcessedPolicy::Leave => "leave",
            ProcessedPolicy::Move => "move",
            ProcessedPolicy::Delete => "delete",
        }
    }
}

/// The `[output]` table.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    /// Tessellation segments per side of the shown surface in surface.glb.
    #[serde(default = "default_tessellation")]
    pub tessellation: usize,
    /// Where broken inputs go with their `.error.json`; absent: `OUT/quarantine`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quarantine_dir: Option<PathBuf>,
    /// Write `surface.glb` (`surface.json` is always written).
    #[serde(default = "yes")]
    pub glb: bool,
    /// Write `report.json`.
    #[serde(default = "yes")]
    pub report: bool,
    /// What happens to an input once its content was fitted.
    #[serde(default)]
    pub processed: ProcessedPolicy,
    /// Write `surface.stp` (STEP AP214) for surfaces over a control mesh (whole objects,
    /// inputs with subdivision connectivity): `trispline export`'s patchwork at its default
    /// split.
    #[serde(default)]
    pub step: bool,
    /// The length unit surface.stp declares (coordinates are written as fitted).
    #[serde(default = "metres")]
    pub step_units: IgesUnits,
}

impl Default for OutputSection {
    fn default() -> Self {
        Self {
            tessellation: DEFAULT_TESSELLATION,
            quarantine_dir: None,
            glb: true,
            report: true,
            processed: ProcessedPolicy::Leave,
            step: false,
            step_units: IgesUnits::M,
        }
    }
}

fn metres() -> IgesUnits {
    IgesUnits::M
}

fn default_tessellation() -> usize {
    DEFAULT_TESSELLATION
}

fn yes() -> bool {
    true
}

/// How log lines are written (`log.format`, or `--log-json`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// One readable line per event.
    #[default]
    Human,
    /// One JSON object per line.
    Json,
}

/// The `[log]` table.
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

/// Why a configuration is refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// Not TOML, or a key or type the schema does not have (toml names the key, line and
    /// column).
    #[error("{source_name}: {source}")]
    Parse {
        /// The file (or "embedded ...") the text came from.
        source_name: String,
        /// What the TOML parser found.
        source: toml::de::Error,
    },
    /// A value outside its range.
    #[error("{source_name}: {key} = {value}: {rule}")]
    Range {
        /// The file the text came from.
        source_name: String,
        /// The key, with its table (`fit.levels`).
        key: &'static str,
        /// The value given.
        value: String,
        /// The range it must be in.
        rule: &'static str,
    },
    /// A value of the right type that does not parse as what the key needs.
    #[error("{source_name}: {key} = {value}: {source}")]
    Invalid {
        /// The file the text came from.
        source_name: String,
        /// The key, with its table.
        key: &'static str,
        /// The value given.
        value: String,
        /// Why it does not parse.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

impl ConfigError {
    /// A stable snake_case name of the refusal, for machines.
    pub fn kind(&self) -> &'static str {
        match self {
            ConfigError::Parse { .. } => "config_parse",
            ConfigError::Range { .. } => "config_out_of_range",
            ConfigError::Invalid { .. } => "config_invalid_value",
        }
    }
}

/// A range check: `Err((key, value, rule))` when it fails.
type Check = Result<(), (&'static str, String, &'static str)>;

/// `Ok` when `ok` holds, else the key, value and rule for a `ConfigError::Range`.
fn check(ok: bool, key: &'static str, value: impl ToString, rule: &'static str) -> Check {
    match ok {
        true => Ok(()),
        false => Err((key, value.to_string(), rule)),
    }
}

impl DaemonConfig {
    /// Parses and validates; `source_name` names the file in errors (toml reports the key,
    /// line and column of a bad entry).
    ///
    /// A file may give only the keys it changes: what it leaves out comes from the embedded
    /// default (tables merged key by key). It is first read on its own, so that a bad key or
    /// type is reported with its line and column; only a missing key sends it through the
    /// merge (where an unknown key is still refused by name).
    pub fn parse(text: &str, source_name: &str) -> Result<DaemonConfig, ConfigError> {
        let parse_err = |source| ConfigError::Parse {
            source_name: source_name.to_string(),
            source,
        };
        let cfg = match toml::from_str::<DaemonConfig>(text) {
            Ok(cfg) => cfg,
            Err(e) if e.message().starts_with("missing field") => {
                let mine: toml::Table = toml::from_str(text).map_err(parse_err)?;
                let mut merged: toml::Table = toml::from_str(DEFAULT_CONFIG).map_err(parse_err)?;
                merge_tables(&mut merged, mine);
                toml::Value::Table(merged).try_into().map_err(parse_err)?
            }
            Err(e) => return Err(parse_err(e)),
        };
        cfg.validate(source_name)?;
        Ok(cfg)
    }

    /// The configuration built into the binary.
    pub fn embedded_default() -> Result<DaemonConfig, ConfigError> {
        Self::parse(DEFAULT_CONFIG, "embedded config/default.toml")
    }

    /// What the worker is told.
    pub fn worker_config(&self) -> WorkerConfig {
        WorkerConfig {
            fit: self.fit.clone(),
            tessellation: self.output.tessellation,
        }
    }

    fn validate(&self, source_name: &str) -> Result<(), ConfigError> {
        let ranges = validate_fit(&self.fit)
            .and_then(|()| validate_daemon(&self.daemon))
            .and_then(|()| super::cluster_config::validate_cluster(&self.cluster))
            .and_then(|()| super::object_config::validate_object(&self.object))
            .and_then(|()| {
                let t = self.output.tessellation;
                check(
                    (1..=2048).contains(&t),
                    "output.tessellation",
                    t,
                    "must be 1..=2048",
                )
            });
        if let Err((key, value, rule)) = ranges {
            return Err(ConfigError::Range {
                source_name: source_name.to_string(),
                key,
                value,
                rule,
            });
        }
        let invalid = |key, value: &str, source| ConfigError::Invalid {
            source_name: source_name.to_string(),
            key,
            value: value.to_string(),
            source,
        };
        if let Some(addr) = &self.daemon.metrics_addr {
            let key = "daemon.metrics_addr";
            let a = addr
                .parse::<std::net::SocketAddr>()
                .map_err(|e| invalid(key, addr, Box::new(e)))?;
            // The responder has no authentication: it must not be reachable from outside.
            if !a.ip().is_loopback() {
                return Err(ConfigError::Range {
                    source_name: source_name.to_string(),
                    key,
                    value: addr.clone(),
                    rule: "must be a loopback address (127.0.0.1 or ::1)",
                });
            }
        }
        tracing_subscriber::EnvFilter::try_new(&self.log.level)
            .map_err(|e| invalid("log.level", &self.log.level, Box::new(e)))?;
        Ok(())
    }

    /// Workers actually started: the configured number, or one per available core.
    pub fn worker_threads(&self) -> usize {
        match self.daemon.workers {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n,
        }
    }

    /// Hash of what changes a patch's fit (the `[fit]` tables): an unchanged input is
    /// refitted when this changes. `[output]` and `[log]` are left out on purpose: a new
    /// tessellation applies to the next version of each patch rather than refitting every
    /// patch at the next start; outputs newly asked for (`glb`, `report` turned on) are
    /// produced by a refit of the patches that lack them (`wanted_outputs`). `[object]`
    /// shapes only objects, so it is in `object_fit_hash` alone: a patch is not refitted
    /// when it changes, and an object always is, whether its scans come from a folder or
    /// from pipe records.
    pub fn fit_hash(&self) -> u64 {
        let shaping = serde_json::json!({ "fit": self.fit });
        super::state::content_hash(shaping.to_string().as_bytes())
    }

    /// Hash of what changes an object's fit: the `[fit]` tables and `[object]`.
    pub fn object_fit_hash(&self) -> u64 {
        let shaping = serde_json::json!({ "fit": self.fit, "object": self.object });
        super::state::content_hash(shaping.to_string().as_bytes())
    }

    /// The fit hash of an input: `object_fit_hash` for an object, else `fit_hash`.
    pub(crate) fn fit_hash_of(&self, object: bool) -> u64 {
        match object {
            true => self.object_fit_hash(),
            false => self.fit_hash(),
        }
    }

    /// What a fit's warm-start state records of this config: `(fit hash, wanted_outputs)`.
    pub(crate) fn state_fit(&self, object: bool) -> (u64, Vec<String>) {
        (self.fit_hash_of(object), self.wanted_outputs())
    }

    /// The output files a fit writes under this config.
    pub fn wanted_outputs(&self) -> Vec<String> {
        let mut files = vec!["surface.json".to_string()];
        if self.output.glb {
            files.push("surface.glb".into());
        }
        if self.output.report {
            files.push("report.json".into());
        }
        if self.output.step {
            files.push("surface.stp".into());
        }
        files
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
        if self.daemon.recursive != new.daemon.recursive {
            keys.push("daemon.recursive");
        }
        if self.object.folders != new.object.folders {
            keys.push("object.folders");
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
        if self.cluster != new.cluster {
            keys.push("cluster");
        }
        keys
    }

    /// The configuration as TOML (`--print-config`).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot print config: {e}"))
    }
}

/// `over`'s keys replace `base`'s, table by table (a sub-table given in part keeps the rest
/// of the default's).
fn merge_tables(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_tables(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Ranges of the `[fit]` table and its sub-tables.
fn validate_fit(f: &FitConfig) -> Check {
    check(
        (1..=6).contains(&f.levels),
        "fit.levels",
        f.levels,
        "must be 1..=6",
    )?;
    check(
        f.min_levels <= 6,
        "fit.min_levels",
        f.min_levels,
        "must be 0..=6",
    )?;
    let b = &f.budget;
    check(
        (1..=1_000_000).contains(&b.max_iterations),
        "fit.budget.max_iterations",
        b.max_iterations,
        "must be 1..=1000000",
    )?;
    check(
        b.tolerance_rel > 0.0 && b.tolerance_rel < 1.0,
        "fit.budget.tolerance_rel",
        b.tolerance_rel,
        "must be in (0, 1)",
    )?;
    if let Some(t) = b.tolerance {
        check(
            t > 0.0 && t.is_finite(),
            "fit.budget.tolerance",
            t,
            "must be positive",
        )?;
    }
    if let Some(p) = b.within_tolerance_pct {
        let key = "fit.budget.within_tolerance_pct";
        check((0.0..=100.0).contains(&p), key, p, "must be 0..=100")?;
    }
    check(
        (0.0..180.0).contains(&f.crease_angle_deg),
        "fit.crease_angle_deg",
        f.crease_angle_deg,
        "must be in [0, 180) (0: no creases)",
    )?;
    check(
        f.crease_relative_ratio == 0.0
            || (f.crease_relative_ratio > 1.0 && f.crease_relative_ratio.is_finite()),
        "fit.crease_relative_ratio",
        f.crease_relative_ratio,
        "must be 0 (off) or a finite number above 1",
    )?;
    validate_scan(&f.scan)?;
    validate_correction(&f.correction)?;
    validate_planar(f)?;
    let c = &f.components;
    check(
        c.min_vertices >= 3,
        "fit.components.min_vertices",
        c.min_vertices,
        "must be at least 3",
    )?;
    check(
        (0.0..=1.0).contains(&c.min_fraction),
        "fit.components.min_fraction",
        c.min_fraction,
        "must be 0..=1",
    )
}

/// The `[fit]` table's range checks for a `FitConfig` built elsewhere (`trispline fit`'s
/// flags), so that both refuse the same values: the key, value and rule of the first one
/// out of range.
pub fn fit_out_of_range(f: &FitConfig) -> Option<(&'static str, String, &'static str)> {
    validate_fit(f).err()
}

/// Ranges of `[fit.scan]`.
fn validate_scan(s: &ScanConfig) -> Check {
    check(
        (1..=64).contains(&s.lattice),
        "fit.scan.lattice",
        s.lattice,
        "must be 1..=64",
    )?;
    check(
        s.smoothing >= 0.0 && s.smoothing.is_finite(),
        "fit.scan.smoothing",
        s.smoothing,
        "must be >= 0",
    )?;
    if let Some(n) = s.grid_segments {
        check(
            (1..=4096).contains(&n),
            "fit.scan.grid_segments",
            n,
            "must be 1..=4096",
        )?;
    }
    check(
        s.target_controls_pct > 0.0 && s.target_controls_pct <= 100.0,
        "fit.scan.target_controls_pct",
        s.target_controls_pct,
        "must be in (0, 100]",
    )?;
    check(
        s.hole_bridge_edges > 0.0 && s.hole_bridge_edges.is_finite(),
        "fit.scan.hole_bridge_edges",
        s.hole_bridge_edges,
        "must be a positive number",
    )?;
    check(
        s.stray_budget_steps <= 4,
        "fit.scan.stray_budget_steps",
        s.stray_budget_steps,
        "must be 0..=4 (each step doubles the controls)",
    )
}

/// Ranges of `[fit.dms]` and `[fit.bpatch]`.
fn validate_planar(f: &FitConfig) -> Check {
    use crate::pipeline::scattered::{BPATCH_DEGREES, DMS_DEGREES};
    check(
        DMS_DEGREES.contains(&f.dms.degree),
        "fit.dms.degree",
        f.dms.degree,
        "must be 2 or 3",
    )?;
    check(
        f.dms.knot_spread > 0.0 && f.dms.knot_spread < 1.0,
        "fit.dms.knot_spread",
        f.dms.knot_spread,
        "must be in (0, 1)",
    )?;
    check(
        BPATCH_DEGREES.contains(&f.bpatch.degree),
        "fit.bpatch.degree",
        f.bpatch.degree,
        "must be 1..=20",
    )?;
    check(
        (0.0..=2.0).contains(&f.bpatch.knot_spread),
        "fit.bpatch.knot_spread",
        f.bpatch.knot_spread,
        "must be in [0, 2]",
    )
}

/// Ranges of `[fit.correction]`.
fn validate_correction(c: &CorrectionConfig) -> Check {
    check(
        c.rounds <= 100,
        "fit.correction.rounds",
        c.rounds,
        "must be 0..=100",
    )?;
    check(
        (0.0..1.0).contains(&c.min_gain),
        "fit.correction.min_gain",
        c.min_gain,
        "must be in [0, 1)",
    )?;
    for (key, value) in [
        ("fit.correction.tangential", c.tangential),
        ("fit.correction.tangential_edge", c.tangential_edge),
    ] {
        check(value > 0.0 && value <= 1.0, key, value, "must be in (0, 1]")?;
    }
    check(
        (0.0..1.0).contains(&c.curvature_floor),
        "fit.correction.curvature_floor",
        c.curvature_floor,
        "must be in [0, 1) (0: off)",
    )?;
    Ok(())
}

/// Ranges of `[daemon]`.
fn validate_daemon(d: &DaemonSection) -> Check {
    check(
        (1..=60_000).contains(&d.poll_interval_ms),
        "daemon.poll_interval_ms",
        d.poll_interval_ms,
        "must be 1..=60000",
    )?;
    check(
        d.stop_timeout_ms <= 3_600_000,
        "daemon.stop_timeout_ms",
        d.stop_timeout_ms,
        "must be at most 3600000",
    )?;
    check(
        d.max_file_bytes > 0,
        "daemon.max_file_bytes",
        d.max_file_bytes,
        "must be positive",
    )?;
    check(
        d.workers <= 256,
        "daemon.workers",
        d.workers,
        "must be 0..=256 (0: one per core)",
    )?;
    check(
        d.settle_ms <= 3_600_000,
        "daemon.settle_ms",
        d.settle_ms,
        "must be at most 3600000",
    )
}

#[cfg(test)]
#[path = "config_tests.rs"]
mod tests;
