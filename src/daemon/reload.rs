//! Live configuration: a cell every thread reads a snapshot from, and the reload on SIGHUP
//! or on a change of the config file.

use super::config::DaemonConfig;
use super::state::content_hash;
use std::path::PathBuf;
use std::sync::{Arc, RwLock};

pub struct ConfigCell {
    inner: RwLock<Arc<DaemonConfig>>,
}

impl ConfigCell {
    pub fn new(cfg: DaemonConfig) -> Self {
        Self {
            inner: RwLock::new(Arc::new(cfg)),
        }
    }

    /// The config in effect now; a job keeps the snapshot it started with.
    pub fn get(&self) -> Arc<DaemonConfig> {
        // A poisoned lock still holds a complete config (it is replaced whole).
        Arc::clone(&self.inner.read().unwrap_or_else(|p| p.into_inner()))
    }

    fn set(&self, cfg: DaemonConfig) {
        *self.inner.write().unwrap_or_else(|p| p.into_inner()) = Arc::new(cfg);
    }
}

pub enum Reloaded {
    /// Applied; the keys listed changed in the file but need a restart.
    Applied { restart_needed: Vec<&'static str> },
    /// Refused; the old config stays.
    Refused { reason: String },
}

/// Watches the config file by content (editors replace files by rename, and mtimes can be
/// too coarse to see two quick saves).
pub struct Reloader {
    path: Option<PathBuf>,
    last_hash: Option<u64>,
    /// New content seen on the previous look: a file still being written in place changes
    /// between looks, and reading it half-written would only produce a refusal.
    candidate: Option<u64>,
}

impl Reloader {
    pub fn new(path: Option<PathBuf>) -> Self {
        let last_hash = path
            .as_ref()
            .and_then(|p| std::fs::read(p).ok())
            .map(|b| content_hash(&b));
        Self {
            path,
            last_hash,
            candidate: None,
        }
    }

    /// Whether the file's content changed since the last look (false without `--config`).
    pub fn file_changed(&mut self) -> bool {
        let Some(path) = &self.path else { return false };
        let now = std::fs::read(path).ok().map(|b| content_hash(&b));
        // A file that vanished for a moment (rename-replace) is not a change yet; new content
        // counts once it is the same on two consecutive looks.
        if now.is_none() || now == self.last_hash {
            self.candidate = None;
            return false;
        }
        if now != self.candidate {
            self.candidate = now;
            return false;
        }
        self.candidate = None;
        true
    }

    /// Reads and validates the file and, when good, puts it in the cell with the keys that
    /// need a restart kept at their running values. Without `--config` the embedded default
    /// is re-applied (a reload is then a no-op, but SIGHUP still answers).
    pub fn reload(&mut self, cell: &ConfigCell) -> Reloaded {
        let parsed = match &self.path {
            Some(p) => std::fs::read_to_string(p)
                .map_err(|e| format!("{}: {e}", p.display()))
                .and_then(|text| {
                    self.last_hash = Some(content_hash(text.as_bytes()));
                    DaemonConfig::parse(&text, &p.display().to_string()).map_err(|e| e.to_string())
                }),
            None => DaemonConfig::embedded_default().map_err(|e| e.to_string()),
        };
        let mut new = match parsed {
            Ok(c) => c,
            Err(reason) => return Reloaded::Refused { reason },
        };
        let old = cell.get();
        let restart_needed = old.restart_only_changes(&new);
        new.daemon.workers = old.daemon.workers;
        new.daemon.watcher = old.daemon.watcher;
        new.daemon.recursive = old.daemon.recursive;
        new.object.folders = old.object.folders;
        new.daemon.metrics_addr = old.daemon.metrics_addr.clone();
        new.log.format = old.log.format;
        new.output.quarantine_dir = old.output.quarantine_dir.clone();
        // The connection, stream and bucket are set up once, like the other keys above.
        new.cluster = old.cluster.clone();
        cell.set(new);
        Reloaded::Applied { restart_needed }
    }
}
