//! The scheduler loop: hears arrivals, finished fits and the writer's acknowledgements,
//! coalesces versions by patch id and hands jobs to the pool; stops, reloads.

use super::job::{Job, JobDone, Outcome};
use super::messages::{Control, Msg, Source};
use super::ops::metrics::Metrics;
use super::ops::sdnotify;
use super::reload::{ConfigCell, Reloaded, Reloader};
use super::scheduler::{Arrival, Input, Scheduler};
use super::writer::WriterMsg;
use crate::pipeline::worker::WarmStart;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use serde_json::json;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The scheduler loop's state.
pub(crate) struct Loop {
    pub(crate) sched: Scheduler,
    /// Versions a worker holds: bounds dispatch to the pool size.
    pub(crate) in_flight: usize,
    /// Warm starts of fits dropped as stale, for the next version of the same patch.
    pub(crate) warm: HashMap<String, WarmStart>,
    pub(crate) cell: Arc<ConfigCell>,
    pub(crate) metrics: Arc<Metrics>,
    pub(crate) wtx: Sender<WriterMsg>,
    pub(crate) job_tx: Sender<Job>,
    pub(crate) workers: usize,
    /// Files that changed while they were read and did not parse, with when to read them
    /// again (the settle time later).
    pub(crate) retries: Vec<(Instant, Arrival)>,
    /// The `incomplete` reason last written per patch, until its version is done.
    pub(crate) told_incomplete: HashMap<String, String>,
    pub(crate) watchdog: sdnotify::Watchdog,
}

/// The newer version waiting for `arrival`'s patch, when that makes its `fitted` result
/// not worth writing. Never for objects: an object's fit is of its folder as read, and its
/// kept session already holds those scans; unwritten, the state would lag the session, so
/// the next update would find no step from the session yet a change against the state,
/// and start the object over.
fn superseded_by(sched: &Scheduler, arrival: &Arrival, fitted: bool) -> Option<String> {
    match &arrival.input {
        Input::Object(_) => None,
        _ if fitted => sched.has_newer(&arrival.id, &arrival.key),
        _ => None,
    }
}

/// The sources still open and whether stdin ended (which ends the daemon once idle).
#[derive(Default)]
pub(crate) struct Sources {
    pub(crate) open: usize,
    pub(crate) stdin_done: bool,
}

impl Loop {
    /// A loop with nothing queued, in flight or waiting yet.
    pub(crate) fn new(
        cell: Arc<ConfigCell>,
        metrics: Arc<Metrics>,
        wtx: Sender<WriterMsg>,
        job_tx: Sender<Job>,
        workers: usize,
    ) -> Self {
        Loop {
            sched: Scheduler::default(),
            in_flight: 0,
            warm: HashMap::new(),
            cell,
            metrics,
            wtx,
            job_tx,
            workers,
            retries: Vec::new(),
            told_incomplete: HashMap::new(),
            watchdog: sdnotify::Watchdog::from_env(),
        }
    }

    /// Runs until the work is done (`--once`, stdin ended) or a stop has waited for the
    /// fits in progress (or for its time bound).
    pub(crate) fn drive(
        &mut self,
        inbox: &Receiver<Msg>,
        ctl: &Control,
        reloader: &mut Reloader,
        intake_stop: &AtomicBool,
        once: bool,
        sources: &mut Sources,
    ) {
        let mut stop_by: Option<Instant> = None;
        let tick = Duration::from_millis(100);
        loop {
            self.watchdog.tick();
            match inbox.recv_timeout(tick) {
                Ok(m) => {
                    self.handle(m, stop_by.is_some(), sources);
                    // Take everything already waiting before handing out jobs: versions that
                    // arrived together coalesce.
                    while let Ok(m) = inbox.try_recv() {
                        self.handle(m, stop_by.is_some(), sources);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            if stop_by.is_none() && ctl.stop.load(Ordering::Relaxed) {
                stop_by = Some(self.begin_stop(intake_stop));
            }
            let reload_asked = ctl.reload.swap(false, Ordering::Relaxed);
            if stop_by.is_none() && (reload_asked || reloader.file_changed()) {
                self.reload(reloader, ctl);
            }
            if stop_by.is_none() {
                self.requeue_due();
                self.dispatch();
            }
            self.metrics
                .queue_depth
                .set(self.sched.pending_len() as i64);
            self.metrics.in_flight.set(self.sched.busy_len() as i64);
            let done = match stop_by {
                Some(deadline) => self.stopped_by(deadline),
                None => {
                    self.sched.idle()
                        && self.retries.is_empty()
                        && ((once && sources.open == 0) || sources.stdin_done)
                }
            };
            if done {
                break;
            }
        }
    }

    /// Closes intake and spills what waits; returns when the stop's time bound runs out.
    fn begin_stop(&mut self, intake_stop: &AtomicBool) -> Instant {
        sdnotify::notify(sdnotify::State::Stopping);
        self.metrics.stopping.store(true, Ordering::Relaxed);
        intake_stop.store(true, Ordering::Relaxed);
        let bound = Duration::from_millis(self.cell.get().daemon.stop_timeout_ms);
        let waiting = self.sched.drain_pending();
        tracing::info!(
            in_flight = self.sched.busy_len(),
            waiting = waiting.len(),
            "stopping: intake closed, waiting for fits in progress"
        );
        for a in waiting {
            self.spill(a);
        }
        Instant::now() + bound
    }

    /// Whether a stop is complete: nothing in progress, or the time bound reached (what
    /// is still in progress is then spilled).
    fn stopped_by(&mut self, deadline: Instant) -> bool {
        if self.sched.busy_len() == 0 {
            return true;
        }
        if Instant::now() < deadline {
            return false;
        }
        tracing::warn!(
            in_flight = self.sched.busy_len(),
            "stop bound reached; leaving fits in progress"
        );
        let busy: Vec<Arrival> = self.sched.busy().cloned().collect();
        for a in busy {
            self.spill(a);
        }
        true
    }

    fn handle(&mut self, m: Msg, stopping: bool, sources: &mut Sources) {
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
                sources.open = sources.open.saturating_sub(1);
                sources.stdin_done |= kind == Source::Stdin;
            }
            Msg::Fitted(done) => {
                let done = *done;
                self.in_flight = self.in_flight.saturating_sub(1);
                if let Outcome::Incomplete { reason, wait } = &done.outcome {
                    self.retry_later(&done.arrival, reason, *wait);
                    return;
                }
                self.told_incomplete.remove(&done.arrival.id);
                let fitted = matches!(done.outcome, Outcome::Fitted { .. });
                let stale = superseded_by(&self.sched, &done.arrival, fitted);
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
            Msg::Queued(id) => {
                self.in_flight = self.in_flight.saturating_sub(1);
                self.sched.finish(&id);
            }
        }
    }

    /// A version read while its file still changed: the patch is free again, and the file
    /// is read again after the settle time (the folder watcher also hands it on again once
    /// it is complete; the scheduler keeps one of the two).
    /// The event is written once per reason: a glTF waiting for its buffer is read again
    /// every second for up to a minute.
    fn retry_later(&mut self, a: &Arrival, reason: &str, wait: Option<Duration>) {
        self.sched.finish(&a.id);
        let told = self.told_incomplete.get(&a.id).is_some_and(|r| r == reason);
        if !told {
            tracing::info!(patch = %a.id, version = %a.version, reason, "incomplete; will read it again");
            let _ = self.wtx.send(WriterMsg::Event(json!({
                "patch": a.id, "version": a.version, "input": a.label, "status": "incomplete", "reason": reason,
            })));
            self.told_incomplete
                .insert(a.id.clone(), reason.to_string());
        }
        let settle = Duration::from_millis(self.cell.get().daemon.settle_ms.max(50));
        self.retries
            .push((Instant::now() + wait.unwrap_or(settle), a.clone()));
    }

    /// Queues the retries that are due, keyed by the file's mtime now.
    fn requeue_due(&mut self) {
        let now = Instant::now();
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.retries)
            .into_iter()
            .partition(|(at, _)| *at <= now);
        self.retries = later;
        for (_, mut a) in due {
            a.key.time = match &a.input {
                Input::File(path) => match std::fs::metadata(path).and_then(|m| m.modified()) {
                    Ok(mtime) => mtime,
                    // Gone: nothing to read any more, and a file of its name that comes
                    // later is new, its reason worth saying again.
                    Err(_) => {
                        self.told_incomplete.remove(&a.id);
                        continue;
                    }
                },
                // The folder is read whole again: newer than anything before.
                Input::Object(_) => std::time::SystemTime::now(),
                Input::Inline { .. } => continue,
            };
            if let Some(s) = self.sched.add(a) {
                let _ = self.wtx.send(WriterMsg::Superseded {
                    loser: s.loser,
                    by: s.by,
                });
            }
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
        reload_config(reloader, &self.cell, ctl, &self.metrics, &self.wtx);
    }
}

/// Re-reads the config into `cell` and reports the outcome (log, metrics, event): the
/// daemon's reload, shared with `trispline worker`.
pub(crate) fn reload_config(
    reloader: &mut Reloader,
    cell: &ConfigCell,
    ctl: &Control,
    metrics: &Metrics,
    wtx: &Sender<WriterMsg>,
) {
    sdnotify::notify(sdnotify::State::Reloading);
    match reloader.reload(cell) {
        Reloaded::Applied { restart_needed } => {
            let cfg = cell.get();
            if let Some(set) = &ctl.set_log_level {
                if let Err(e) = set(&cfg.log.level) {
                    tracing::warn!(error = %e, "cannot apply log.level");
                }
            }
            metrics.reloads.inc();
            if restart_needed.is_empty() {
                tracing::info!("config reloaded");
            } else {
                tracing::warn!(
                    ?restart_needed,
                    "config reloaded; some changes need a restart"
                );
            }
            let _ = wtx.send(WriterMsg::Event(json!({
                "status": "config_reloaded", "restart_needed": restart_needed,
            })));
        }
        Reloaded::Refused { reason } => {
            tracing::error!(%reason, "config reload refused; the old config stays");
            metrics.reload_failures.inc();
            metrics.error("config_rejected");
            let _ = wtx.send(WriterMsg::Event(json!({
                "status": "config_rejected", "reason": reason,
            })));
        }
    }
    sdnotify::notify(sdnotify::State::Ready);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::object_store::object_arrival;
    use crate::daemon::scheduler::VersionKey;
    use std::path::PathBuf;
    use std::time::SystemTime;

    fn file(id: &str, name: &str) -> Arrival {
        Arrival {
            id: id.into(),
            input: Input::File(PathBuf::from(name)),
            key: VersionKey {
                time: SystemTime::now(),
                tie: name.into(),
            },
            version: name.into(),
            label: name.into(),
            detected: Instant::now(),
        }
    }

    #[test]
    fn a_patch_fit_with_a_newer_version_waiting_is_stale_but_an_object_fit_never_is() {
        let mut sched = Scheduler::default();
        let running = file("ear", "ear@1");
        sched.add(running.clone());
        let started = sched.next_ready().expect("ear@1 starts");
        sched.add(file("ear", "ear@2"));
        assert_eq!(superseded_by(&sched, &started, true), Some("ear@2".into()));
        // A rejection is written whatever waits.
        assert_eq!(superseded_by(&sched, &started, false), None);

        let folder = PathBuf::from("inbox/bunny");
        let update = |what: &str| {
            object_arrival("bunny".into(), folder.clone(), what.into(), "bunny".into())
        };
        sched.add(update("bun000.ply"));
        let started = sched.next_ready().expect("the object's update starts");
        sched.add(update("bun045.xf"));
        assert!(sched.has_newer("bunny", &started.key).is_some());
        assert_eq!(superseded_by(&sched, &started, true), None);
    }
}
