//! The daemon: sources (folder watcher, pipe) -> scheduler (coalescing by patch id, on the
//! calling thread) -> bounded job queue -> worker pool -> writer thread. See ARCHITECTURE.md
//! for the threads and their invariants.

pub mod config;
mod job;
pub mod ops;
pub mod pipe;
mod reload;
pub mod scheduler;
pub mod state;
mod watcher;
mod writer;

use crate::io::Format;
use crate::pipeline::worker::WarmStart;
use config::DaemonConfig;
use crossbeam_channel::{RecvTimeoutError, Sender};
use job::{Job, JobDone, Outcome};
use ops::metrics::Metrics;
use ops::sdnotify;
use pipe::{PipeSource, PipeSpec};
use reload::{ConfigCell, Reloaded, Reloader};
use scheduler::{Arrival, Input, Scheduler};
use serde_json::json;
use state::StateStore;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use watcher::FolderWatcher;
use writer::{Writer, WriterMsg};

#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("{path}: {reason}")]
    Folder { path: String, reason: String },
    #[error("metrics on {addr}: {reason}")]
    Metrics { addr: String, reason: String },
}

pub struct DaemonOptions {
    pub watch_dir: PathBuf,
    pub out_dir: PathBuf,
    pub state_dir: PathBuf,
    pub once: bool,
    pub config: DaemonConfig,
    /// Watched for changes and re-read on SIGHUP.
    pub config_path: Option<PathBuf>,
    pub pipe: Option<PipeSpec>,
}

/// Signals from outside: set by signal handlers, read by the scheduler loop.
#[derive(Default)]
pub struct Control {
    pub stop: Arc<AtomicBool>,
    pub reload: Arc<AtomicBool>,
    /// Applies a new log filter (the subscriber belongs to the caller).
    #[allow(clippy::type_complexity)]
    pub set_log_level: Option<Box<dyn Fn(&str) -> Result<(), String> + Send + Sync>>,
}

/// What one run did, for `--once` callers and tests.
#[derive(Debug, Default, Clone)]
pub struct Summary {
    pub fitted: usize,
    pub rejected: usize,
    pub superseded: usize,
    pub unchanged: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    Folder,
    Stdin,
    Fifo,
}

/// Everything the scheduler loop hears about.
pub enum Msg {
    Arrivals(Vec<Arrival>),
    SourceDone(Source),
    Fitted(JobDone),
    /// The writer is done with the patch's version.
    Written(String),
}

/// A patch id from a pipe record or a file stem: restricted to [A-Za-z0-9_.-] so that it can
/// never escape the output folder. `None` when nothing usable is left.
pub fn sanitize_id(raw: &str) -> Option<String> {
    let id: String = raw
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let id = id.trim_matches('.').to_string();
    (!id.is_empty() && !id.contains("..") && id.len() <= 200).then_some(id)
}

/// Patch id of a file: the stem up to the first '@', sanitised.
pub fn patch_id(path: &Path) -> Option<String> {
    let stem = path.file_stem()?.to_str()?;
    sanitize_id(stem.split('@').next().unwrap_or(stem))
}

/// Names that are still being written or are not meshes.
pub fn ignored(path: &Path) -> bool {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return true;
    };
    name.starts_with('.')
        || name.ends_with(".tmp")
        || name.ends_with(".part")
        || Format::from_path(path).is_none()
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

pub fn run(opts: DaemonOptions, ctl: &Control) -> Result<Summary, DaemonError> {
    let folder_err = |p: &Path, e: &dyn std::fmt::Display| DaemonError::Folder {
        path: p.display().to_string(),
        reason: e.to_string(),
    };
    for d in [&opts.out_dir, &opts.state_dir] {
        std::fs::create_dir_all(d).map_err(|e| folder_err(d, &e))?;
        remove_stale_temps(d);
    }
    std::fs::read_dir(&opts.watch_dir).map_err(|e| folder_err(&opts.watch_dir, &e))?;
    let quarantine = opts
        .config
        .output
        .quarantine_dir
        .clone()
        .unwrap_or_else(|| opts.out_dir.join("quarantine"));
    let workers = opts.config.worker_threads();
    let kind = opts.config.daemon.watcher;
    let metrics_addr = opts.config.daemon.metrics_addr.clone();
    let cell = Arc::new(ConfigCell::new(opts.config));
    let metrics = Arc::new(Metrics::default());
    if let Some(addr) = &metrics_addr {
        let local =
            ops::http::serve(addr, Arc::clone(&metrics)).map_err(|e| DaemonError::Metrics {
                addr: addr.clone(),
                reason: e.to_string(),
            })?;
        tracing::info!(addr = %local, "serving /metrics and /healthz");
    }
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
    };
    let writer = spawn("writer", move || writer.run(wrx))?;
    // Capacity = workers: the scheduler only hands out a job when a worker is free, so this
    // never blocks it, and versions wait in the scheduler where they can still coalesce.
    let (job_tx, job_rx) = crossbeam_channel::bounded::<Job>(workers);
    for k in 0..workers {
        let (rx, tx, store) = (job_rx.clone(), tx.clone(), Arc::clone(&store));
        spawn(&format!("worker-{k}"), move || {
            for job in rx {
                if tx.send(Msg::Fitted(job::run_job(job, &store))).is_err() {
                    break;
                }
            }
        })?;
    }
    let intake_stop = Arc::new(AtomicBool::new(false));
    let mut open_sources = 1;
    let (ready_tx, ready_rx) = crossbeam_channel::bounded(1);
    let folder = FolderWatcher {
        dir: opts.watch_dir.clone(),
        cell: Arc::clone(&cell),
        kind,
        once: opts.once,
        tx: tx.clone(),
        writer: wtx.clone(),
        stop: Arc::clone(&intake_stop),
        ready: ready_tx,
    };
    spawn("watcher", move || folder.run())?;
    if let Some(spec) = opts.pipe.clone() {
        open_sources += 1;
        let source = PipeSource {
            spec,
            cell: Arc::clone(&cell),
            once: opts.once,
            tx: tx.clone(),
            writer: wtx.clone(),
            stop: Arc::clone(&intake_stop),
            quarantine,
        };
        // Never joined: it may sit in a blocking read of a pipe nobody writes to.
        spawn("pipe", move || source.run())?;
    }
    drop(tx);
    tracing::info!(
        dir = %opts.watch_dir.display(), out = %opts.out_dir.display(), workers, "started"
    );
    // READY only once files renamed in from now on are certain to be seen.
    if ready_rx.recv_timeout(Duration::from_secs(30)).is_err() {
        tracing::warn!("the folder watcher is slow to start");
    }
    sdnotify::notify("READY=1");
    let mut lp = Loop {
        sched: Scheduler::default(),
        in_flight: 0,
        warm: HashMap::new(),
        cell,
        metrics,
        wtx,
        job_tx,
        workers,
    };
    let mut reloader = Reloader::new(opts.config_path.clone());
    let mut stop_by: Option<Instant> = None;
    let mut stdin_done = false;
    let tick = Duration::from_millis(100);
    loop {
        match inbox.recv_timeout(tick) {
            Ok(m) => {
                lp.handle(m, stop_by.is_some(), &mut open_sources, &mut stdin_done);
                // Take everything already waiting before handing out jobs: versions that
                // arrived together coalesce.
                while let Ok(m) = inbox.try_recv() {
                    lp.handle(m, stop_by.is_some(), &mut open_sources, &mut stdin_done);
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
        if stop_by.is_none() && ctl.stop.load(Ordering::Relaxed) {
            sdnotify::notify("STOPPING=1");
            lp.metrics.stopping.store(true, Ordering::Relaxed);
            intake_stop.store(true, Ordering::Relaxed);
            let bound = Duration::from_millis(lp.cell.get().daemon.stop_timeout_ms);
            stop_by = Some(Instant::now() + bound);
            let waiting = lp.sched.drain_pending();
            tracing::info!(
                in_flight = lp.sched.busy_len(),
                waiting = waiting.len(),
                "stopping: intake closed, waiting for fits in progress"
            );
            for a in waiting {
                lp.spill(a);
            }
        }
        let reload_asked = ctl.reload.swap(false, Ordering::Relaxed);
        if stop_by.is_none() && (reload_asked || reloader.file_changed()) {
            lp.reload(&mut reloader, ctl);
        }
        if stop_by.is_none() {
            lp.dispatch();
        }
        lp.metrics
            .queue_depth
            .store(lp.sched.pending_len() as u64, Ordering::Relaxed);
        lp.metrics
            .in_flight
            .store(lp.sched.busy_len() as u64, Ordering::Relaxed);
        let idle = lp.sched.idle();
        if let Some(deadline) = stop_by {
            if lp.sched.busy_len() == 0 {
                break;
            }
            if Instant::now() >= deadline {
                tracing::warn!(
                    in_flight = lp.sched.busy_len(),
                    "stop bound reached; leaving fits in progress"
                );
                let busy: Vec<Arrival> = lp.sched.busy().cloned().collect();
                for a in busy {
                    lp.spill(a);
                }
                break;
            }
        } else if idle && ((opts.once && open_sources == 0) || stdin_done) {
            break;
        }
    }
    // Sources may still hold writer senders (a pipe thread blocked in a read), so the
    // writer is told to finish rather than waiting for every sender to go.
    intake_stop.store(true, Ordering::Relaxed);
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

fn spawn<T: Send + 'static>(
    name: &str,
    f: impl FnOnce() -> T + Send + 'static,
) -> Result<std::thread::JoinHandle<T>, DaemonError> {
    std::thread::Builder::new()
        .name(name.to_string())
        .spawn(f)
        .map_err(|e| DaemonError::Folder {
            path: format!("thread {name}"),
            reason: e.to_string(),
        })
}

/// The scheduler loop's state.
struct Loop {
    sched: Scheduler,
    /// Versions a worker holds: bounds dispatch to the pool size.
    in_flight: usize,
    /// Warm starts of fits dropped as stale, for the next version of the same patch.
    warm: HashMap<String, WarmStart>,
    cell: Arc<ConfigCell>,
    metrics: Arc<Metrics>,
    wtx: Sender<WriterMsg>,
    job_tx: Sender<Job>,
    workers: usize,
}

impl Loop {
    fn handle(&mut self, m: Msg, stopping: bool, open: &mut usize, stdin_done: &mut bool) {
        match m {
            Msg::Arrivals(batch) => {
                for a in batch {
                    if stopping {
                        // Intake is closed: files stay for the next start, records spill.
                        self.spill(a);
                    } else if let Some(s) = self.sched.add(a) {
                        let _ = self.wtx.send(WriterMsg::Superseded {
                            loser: s.loser,
                            by: s.by,
                        });
                    }
                }
            }
            Msg::SourceDone(kind) => {
                *open = open.saturating_sub(1);
                *stdin_done |= kind == Source::Stdin;
            }
            Msg::Fitted(done) => {
                self.in_flight = self.in_flight.saturating_sub(1);
                let stale = match &done.outcome {
                    Outcome::Fitted { .. } => {
                        self.sched.has_newer(&done.arrival.id, &done.arrival.key)
                    }
                    _ => None,
                };
                match (stale, done.outcome) {
                    (Some(by), Outcome::Fitted { outputs, .. }) => {
                        // A newer version waits: writing this one would only publish a
                        // result already out of date. Its control net still seeds the next.
                        self.warm.insert(done.arrival.id.clone(), outputs.warm);
                        self.sched.finish(&done.arrival.id);
                        let _ = self.wtx.send(WriterMsg::Superseded {
                            loser: done.arrival,
                            by,
                        });
                    }
                    (_, outcome) => {
                        let _ = self.wtx.send(WriterMsg::Done(JobDone { outcome, ..done }));
                    }
                }
            }
            Msg::Written(id) => self.sched.finish(&id),
        }
    }

    fn dispatch(&mut self) {
        while self.in_flight < self.workers {
            let Some(a) = self.sched.next_ready() else {
                break;
            };
            self.in_flight += 1;
            let job = Job {
                warm: self.warm.remove(&a.id),
                arrival: a,
                cfg: self.cell.get(),
            };
            if let Err(e) = self.job_tx.try_send(job) {
                // Cannot happen while in_flight bounds the queue; if it does, the version
                // goes back to wait rather than being lost.
                tracing::error!("job queue refused a job; retrying later");
                let job = e.into_inner();
                self.in_flight -= 1;
                self.sched.finish(&job.arrival.id);
                if let Some(w) = job.warm {
                    self.warm.insert(job.arrival.id.clone(), w);
                }
                self.sched.add(job.arrival);
                break;
            }
        }
    }

    fn spill(&mut self, a: Arrival) {
        if matches!(a.input, Input::Inline { .. }) {
            let _ = self.wtx.send(WriterMsg::Spill(a));
        }
    }

    fn reload(&mut self, reloader: &mut Reloader, ctl: &Control) {
        sdnotify::notify("RELOADING=1");
        match reloader.reload(&self.cell) {
            Reloaded::Applied { restart_needed } => {
                let cfg = self.cell.get();
                if let Some(set) = &ctl.set_log_level {
                    if let Err(e) = set(&cfg.log.level) {
                        tracing::warn!(error = %e, "cannot apply log.level");
                    }
                }
                self.metrics.reloads.fetch_add(1, Ordering::Relaxed);
                if restart_needed.is_empty() {
                    tracing::info!("config reloaded");
                } else {
                    tracing::warn!(
                        ?restart_needed,
                        "config reloaded; some changes need a restart"
                    );
                }
                let _ = self.wtx.send(WriterMsg::Event(json!({
                    "status": "config_reloaded", "restart_needed": restart_needed,
                })));
            }
            Reloaded::Refused { reason } => {
                tracing::error!(%reason, "config reload refused; the old config stays");
                self.metrics.reload_failures.fetch_add(1, Ordering::Relaxed);
                self.metrics.error(&format!("config reload: {reason}"));
                let _ = self.wtx.send(WriterMsg::Event(json!({
                    "status": "config_rejected", "reason": reason,
                })));
            }
        }
        sdnotify::notify("READY=1");
    }
}
