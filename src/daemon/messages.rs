//! What the daemon's threads tell each other and the caller (`Msg`, `Source`, `Control`,
//! `Summary`), and how an input's name becomes a patch id. Kept apart from the start-up code
//! in `mod.rs` so that the sources, the coordinator and the writer can share it without
//! importing the module that starts them.

use super::job::JobDone;
use super::scheduler::Arrival;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

pub(crate) use super::ids::{ignored, part_id, relative_patch_id, sanitize_id};

/// Signals from outside: set by signal handlers, read by the scheduler loop.
#[derive(Default)]
pub struct Control {
    /// Stop gracefully (SIGTERM, SIGINT).
    pub stop: Arc<AtomicBool>,
    /// Re-read the config (SIGHUP).
    pub reload: Arc<AtomicBool>,
    /// Applies a new log filter (the subscriber belongs to the caller).
    #[allow(clippy::type_complexity)]
    pub set_log_level: Option<Box<dyn Fn(&str) -> Result<(), String> + Send + Sync>>,
}

/// What one run did, for `--once` callers and tests.
#[derive(Debug, Default, Clone)]
pub struct Summary {
    /// Surfaces fitted and written.
    pub fitted: usize,
    /// Inputs and records rejected.
    pub rejected: usize,
    /// Versions skipped for a newer one.
    pub superseded: usize,
    /// Inputs skipped as identical to their last fit.
    pub unchanged: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Source {
    Folder,
    Stdin,
    Fifo,
}

/// Everything the scheduler loop hears about.
pub(crate) enum Msg {
    Arrivals(Vec<Arrival>),
    SourceDone(Source),
    Fitted(Box<JobDone>),
    /// The writer is done with the patch's version.
    Written(String),
    /// The patch's version went to the cluster queue: a worker elsewhere fits it.
    Queued(String),
}
