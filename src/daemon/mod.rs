//! The daemon: sources (folder watcher, pipe) -> scheduler (coalescing by patch id, on the
//! calling thread) -> bounded job queue -> worker pool -> writer thread. See ARCHITECTURE.md
//! for the threads and their invariants.
#![warn(missing_docs)]

mod cad;
mod cluster_config;
pub mod config;
mod confine;
pub(crate) mod coordinator;
mod event_log;
mod ids;
pub(crate) mod job;
pub(crate) mod kinds;
pub(crate) mod layout;
mod mesh_file;
pub(crate) mod messages;
mod object_config;
mod object_job;
pub(crate) mod object_sessions;
mod object_store;
pub(crate) mod offload;
mod open_files;
pub(crate) mod ops;
mod outcome;
pub(crate) mod pipe;
mod publish;
pub(crate) mod reload;
pub(crate) mod scheduler;
pub mod state;
mod watcher;
pub(crate) mod writer;

use config::DaemonConfig;
use coordinator::{Loop, Sources};
use crossbeam_channel::{Receiver, Sender};
use job::Job;
use messages::Msg;
pub use messages::{Control, Summary};
use ops::metrics::Metrics;
use ops::sdnotify;
use pipe::PipeSource;
pub use pipe::PipeSpec;
use reload::{ConfigCell, Reloader};
use state::StateStore;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use watcher::FolderWatcher;
use writer::{Writer, WriterMsg};

/// Why the daemon could not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DaemonError {
    /// A folder it needs cannot be created, listed or resolved.
    #[error("{}: {source}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// What the filesystem said.
        #[source]
        source: std::io::Error,
    },
    /// The metrics address cannot be bound (taken, not permitted).
    #[error("metrics on {addr}: {source}")]
    Metrics {
        /// The configured address.
        addr: String,
        /// What binding said.
        #[source]
        source: std::io::Error,
    },
    /// `output.quarantine_dir` could coincide with a patch's folder (inside OUT, outside
    /// `OUT/quarantine`) or is the watch folder.
    #[error("output.quarantine_dir {}: {reason}", path.display())]
    QuarantineDir {
        /// The configured folder.
        path: PathBuf,
        /// Why it is refused.
        reason: String,
    },
    /// A thread could not be started (a process or memory limit).
    #[error("cannot start the {name} thread: {source}")]
    Spawn {
        /// The thread's name.
        name: String,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
}

impl DaemonError {
    /// A machine-readable name of the failure.
    pub fn kind(&self) -> &'static str {
        match self {
            DaemonError::Folder { .. } => "folder",
            DaemonError::Metrics { .. } => "metrics_bind",
            DaemonError::QuarantineDir { .. } => "quarantine_dir",
            DaemonError::Spawn { .. } => "thread_spawn",
        }
    }
}

fn folder_err(path: &Path) -> impl FnOnce(std::io::Error) -> DaemonError + '_ {
    move |source| DaemonError::Folder {
        path: path.to_path_buf(),
        source,
    }
}

/// What `run` is asked to do.
pub struct DaemonOptions {
    /// The folder whose mesh files are fitted.
    pub watch_dir: PathBuf,
    /// Where the outputs, the event log and the quarantine go.
    pub out_dir: PathBuf,
    /// Warm-start states.
    pub state_dir: PathBuf,
    /// Fit what is there (and what the pipe sends until it ends), then return.
    pub once: bool,
    /// The config in effect at the start.
    pub config: DaemonConfig,
    /// Watched for changes and re-read on SIGHUP.
    pub config_path: Option<PathBuf>,
    /// A pipe to read records from as well.
    pub pipe: Option<PipeSpec>,
    /// Jobs go to this instead of local worker threads (the cluster queue of `--queue`).
    pub(crate) offload: Option<offload::Offload>,
}

/// Temp files of writes cut short by a crash: never outputs, removed at start-up.
fn remove_stale_temps(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().to_string();
        if p.is_dir() && !name.starts_with('.') {
            remove_stale_temps(&p);
        } else if name.starts_with(".trispline-") && name.ends_with(".tmp") {
            let _ = std::fs::remove_file(&p);
        }
    }
}

/// Runs the daemon until a stop (or, with `once`, until the work is done).
pub fn run(opts: DaemonOptions, ctl: &Control) -> Result<Summary, DaemonError> {
    let opts = prepare_folders(opts)?;
    let configured = opts.config.output.quarantine_dir.as_deref();
    let quarantine = layout::quarantine_folder(configured, &opts.out_dir, &opts.watch_dir)
        .map_err(|e| DaemonError::QuarantineDir {
            path: configured.map(Path::to_path_buf).unwrap_or_default(),
            reason: e.to_string(),
        })?;
    let workers = match &opts.offload {
        Some(o) => o.capacity,
        None => opts.config.worker_threads(),
    };
    let metrics = Arc::new(Metrics::default());
    if let Some(addr) = &opts.config.daemon.metrics_addr {
        let local = ops::http::serve(addr, Arc::clone(&metrics)).map_err(|source| {
            DaemonError::Metrics {
                addr: addr.clone(),
                source,
            }
        })?;
        tracing::info!(addr = %local, "serving /metrics and /healthz");
    }
    let kind = opts.config.daemon.watcher;
    let cell = Arc::new(ConfigCell::new(opts.config.clone()));
    let store = Arc::new(StateStore::new(opts.state_dir.clone()));
    let (tx, inbox) = crossbeam_channel::unbounded::<Msg>();
    let (wtx, wrx) = crossbeam_channel::unbounded::<WriterMsg>();
    let writer = Writer {
        out_dir: opts.out_dir.clone(),
        watch_dir: opts.watch_dir.clone(),
        quarantine: quarantine.clone(),
        store: Arc::clone(&store),
        metrics: Arc::clone(&metrics),
        acks: tx.clone(),
        summary: Summary::default(),
        cell: Arc::clone(&cell),
        seen: writer::SeenVersions::load(&opts.state_dir),
        node: None,
    };
    let writer = spawn("writer", move || writer.run(wrx))?;
    // Pipe objects are refused with a queue, and the stored ones wait for a daemon without.
    let queued = opts.offload.is_some();
    let job_tx = match opts.offload {
        Some(o) => {
            let (job_tx, job_rx) = crossbeam_channel::bounded::<Job>(workers);
            (o.start)(job_rx, tx.clone(), wtx.clone(), Arc::clone(&metrics)).map_err(|source| {
                DaemonError::Spawn {
                    name: "queue publisher".into(),
                    source,
                }
            })?;
            job_tx
        }
        None => {
            let sessions = Arc::new(object_sessions::ObjectSessions::new(
                opts.config.object.kept_sessions,
            ));
            start_workers(workers, (&store, &sessions), &tx)?
        }
    };
    // Before any source starts, so that they are in the inbox ahead of a source's end.
    if !queued {
        let stored = object_store::stored_objects(&store.objects_dir());
        if !stored.is_empty() {
            let _ = tx.send(Msg::Arrivals(stored));
        }
    }
    let intake_stop = Arc::new(AtomicBool::new(false));
    let partial = Arc::new(Mutex::new(None));
    let (ready_tx, ready_rx) = crossbeam_channel::bounded(1);
    let mut sources = Sources {
        open: 1,
        stdin_done: false,
    };
    let folder = FolderWatcher {
        dir: opts.watch_dir.clone(),
        cell: Arc::clone(&cell),
        kind,
        once: opts.once,
        tx: tx.clone(),
        writer: wtx.clone(),
        stop: Arc::clone(&intake_stop),
        ready: ready_tx,
        recursive: opts.config.daemon.recursive || opts.config.object.folders,
        objects: opts.config.object.folders,
        exclude: [&opts.out_dir, &opts.state_dir, &quarantine]
            .into_iter()
            .filter_map(|d| std::fs::canonicalize(d).ok())
            .collect(),
    };
    spawn("watcher", move || folder.run())?;
    if let Some(spec) = opts.pipe.clone() {
        sources.open += 1;
        let source = PipeSource {
            spec,
            cell: Arc::clone(&cell),
            once: opts.once,
            tx: tx.clone(),
            writer: wtx.clone(),
            stop: Arc::clone(&intake_stop),
            quarantine,
            watch_dir: opts.watch_dir.clone(),
            partial: Arc::clone(&partial),
            held: Default::default(),
        };
        // Never joined: it may sit in a blocking read of a pipe nobody writes to.
        spawn("pipe", move || source.run())?;
    }
    drop(tx);
    tracing::info!(
        dir = %opts.watch_dir.display(), out = %opts.out_dir.display(), workers, "started"
    );
    announce_ready(&ready_rx);
    let mut lp = Loop::new(cell, metrics, wtx, job_tx, workers);
    let mut reloader = Reloader::new(opts.config_path.clone());
    lp.drive(
        &inbox,
        ctl,
        &mut reloader,
        &intake_stop,
        opts.once,
        &mut sources,
    );
    // Sources may still hold writer senders (a pipe thread blocked in a read), so the
    // writer is told to finish rather than waiting for every sender to go.
    intake_stop.store(true, Ordering::Relaxed);
    report_partial_record(&partial, &lp.wtx);
    drop(lp.job_tx);
    let _ = lp.wtx.send(WriterMsg::Shutdown);
    let summary = writer.join().unwrap_or_default();
    tracing::info!(
        fitted = summary.fitted,
        rejected = summary.rejected,
        superseded = summary.superseded,
        unchanged = summary.unchanged,
        "stopped"
    );
    Ok(summary)
}

/// Creates OUT and the state folder, cleans up after a crash, and resolves the watch
/// folder.
fn prepare_folders(opts: DaemonOptions) -> Result<DaemonOptions, DaemonError> {
    for d in [&opts.out_dir, &opts.state_dir] {
        std::fs::create_dir_all(d).map_err(folder_err(d))?;
        remove_stale_temps(d);
    }
    publish::repair(&opts.out_dir);
    std::fs::read_dir(&opts.watch_dir).map_err(folder_err(&opts.watch_dir))?;
    // Once, here: the watcher hears absolute, symlink-free paths from inotify, and matching
    // them against a relative or symlinked folder name would miss every renamed-in file.
    let watch_dir = std::fs::canonicalize(&opts.watch_dir).map_err(folder_err(&opts.watch_dir))?;
    Ok(DaemonOptions { watch_dir, ..opts })
}

/// The worker pool; returns the job queue's sender.
fn start_workers(
    workers: usize,
    (store, sessions): (&Arc<StateStore>, &Arc<object_sessions::ObjectSessions>),
    tx: &Sender<Msg>,
) -> Result<Sender<Job>, DaemonError> {
    // Capacity = workers: the scheduler only hands out a job when a worker is free, so this
    // never blocks it, and versions wait in the scheduler where they can still coalesce.
    let (job_tx, job_rx) = crossbeam_channel::bounded::<Job>(workers);
    for k in 0..workers {
        let (rx, tx, store) = (job_rx.clone(), tx.clone(), Arc::clone(store));
        let sessions = Arc::clone(sessions);
        spawn(&format!("worker-{k}"), move || {
            for job in rx {
                if tx
                    .send(Msg::Fitted(Box::new(job::run_job(job, &store, &sessions))))
                    .is_err()
                {
                    break;
                }
            }
        })?;
    }
    Ok(job_tx)
}

/// READY only once files renamed in from now on are certain to be seen.
fn announce_ready(ready: &Receiver<()>) {
    if ready.recv_timeout(Duration::from_secs(30)).is_err() {
        tracing::warn!("the folder watcher is slow to start");
    }
    sdnotify::notify(sdnotify::State::Ready);
}

/// A pipe record whose payload was still arriving when the daemon stopped: its bytes go
/// with the process, so at least the event log says so.
fn report_partial_record(partial: &Mutex<Option<pipe::Partial>>, wtx: &Sender<WriterMsg>) {
    let taken = partial.lock().unwrap_or_else(|e| e.into_inner()).take();
    if let Some(p) = taken {
        let _ = wtx.send(WriterMsg::Reject {
            id: p.id,
            label: p.label,
            keep: writer::Keep::Nothing,
            kind: kinds::rejection_kind(&kinds::Cause::Record(kinds::RecordFault::Truncated)),
            reason: format!(
                "the daemon stopped after {} of {} bytes of the record; resend it",
                p.got, p.want
            ),
        });
    }
}

fn spawn<T: Send + 'static>(
    name: &str,
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<std::thread::JoinHandle<T>, DaemonError> {
    std::thread::Builder::new()
        .name(name.to_string())
        .spawn(f)
        .map_err(|source| DaemonError::Spawn {
            name: name.to_string(),
            source,
        })
}
