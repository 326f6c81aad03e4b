//! One claimed job: fit with the warm start from the bucket (the claim kept alive meanwhile),
//! write through the daemon's writer while the new state is encoded beside it, store that
//! state, commit the patch's record,
//! acknowledge, and tell a path job's source that its input is finished. The work the queue
//! adds around the fit is timed per job and logged as one `queue cost` line.

use super::context::{arrival, newer, payload, record_key, write, Ctx};
use super::queue::{now_ms, spool_dir, Queue};
use super::states::{self, Loaded};
use super::wire::{Completion, JobHeader, PatchRecord};
use crate::daemon::config::DaemonConfig;
use crate::daemon::job::{run_job, Job, JobDone, Outcome};
use crate::daemon::kinds::{rejection_kind, Cause};
use crate::daemon::object_sessions::ObjectSessions;
use crate::daemon::state::PatchState;
use crate::daemon::writer::{Keep, WriterMsg};
use crate::io::Format;
use crate::pipeline::worker::WarmStart;
use async_nats::jetstream::{kv, AckKind, Message};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Where a job's time went outside the fit, in ms.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Cost {
    /// From the source's publish to this worker holding the message (transport, and any
    /// wait in the stream for a free worker).
    pub(super) wait_ms: f64,
    /// Decoding, the look for a newer version, reading the record and the claim's
    /// compare-and-set.
    pub(super) claim_ms: f64,
    pub(super) state_load_ms: f64,
    /// The look for a newer version after the fit.
    pub(super) stale_check_ms: f64,
    /// The wait for the state's encoding and shared file beyond the writer's own time
    /// (both run at once), and the bucket's compare-and-set.
    pub(super) state_save_ms: f64,
    /// The heartbeat's end.
    pub(super) commit_ms: f64,
    /// The record's compare-and-set and the acknowledgement, sent together.
    pub(super) ack_ms: f64,
    pub(super) completion_ms: f64,
}

impl Cost {
    /// What the queue adds to a job on the worker, the wait in the stream aside.
    fn work_ms(&self) -> f64 {
        self.claim_ms
            + self.state_load_ms
            + self.stale_check_ms
            + self.state_save_ms
            + self.commit_ms
            + self.ack_ms
            + self.completion_ms
    }
}

/// Milliseconds since `t`, and `t` moved to now.
pub(super) fn lap(t: &mut Instant) -> f64 {
    let now = Instant::now();
    let ms = (now - *t).as_secs_f64() * 1e3;
    *t = now;
    ms
}

/// How a fit ended, for what follows the write.
enum Ending {
    /// A rejection: nothing to store, the input is not finished.
    Rejected,
    /// The content was fitted before: nothing to store, the input is finished.
    Unchanged,
    /// Handed to the writer: this state is stored once the writer has written the outputs.
    Fitted(Box<PatchState>),
    /// Dropped for a newer version: its warm start may still seed that version.
    Stale(Box<WarmStart>),
}

#[allow(clippy::too_many_arguments)]
pub(super) fn fit(
    ctx: &Ctx,
    msg: Message,
    h: JobHeader,
    (body, state): (Arc<Vec<u8>>, states::Fetch),
    seq: u64,
    claim: PatchRecord,
    rev: u64,
    mut cost: Cost,
) {
    let cfg = ctx.cell.get();
    let key = record_key(&h.id);
    let msg = Arc::new(msg);
    let beat = heartbeat(ctx, &msg, &key, &claim, rev);
    let mut t = Instant::now();
    let (to_writer, ending, loaded) =
        run(ctx, &h, (body, state), &cfg, (&msg.subject, seq), &mut cost);
    if beat.lost.load(Ordering::SeqCst) {
        tracing::warn!(patch = %h.id, version = %h.version, "the claim was taken over by another worker; result dropped");
        let _ = beat.end(&ctx.queue);
        return;
    }
    let limit = cfg.cluster.payload_limit;
    // The state is encoded (and a large one written to shared storage) while the writer
    // writes the outputs: the single daemon's writer does that work too, so only what
    // outlasts the writer counts as the queue's.
    let (prepared, write_ms, prepare_ms) = std::thread::scope(|scope| {
        let preparing = match &ending {
            Ending::Fitted(state) => Some(scope.spawn(|| {
                let start = Instant::now();
                let prepared = states::prepare(&ctx.out_dir, limit, &h.id, seq, state);
                (prepared, start.elapsed().as_secs_f64() * 1e3)
            })),
            _ => None,
        };
        write(ctx, to_writer);
        let write_ms = lap(&mut t);
        let joined = preparing.map(|p| {
            p.join()
                .unwrap_or_else(|_| (Err("the state encoder panicked".into()), f64::NAN))
        });
        cost.state_save_ms = lap(&mut t);
        match joined {
            Some((prepared, ms)) => (Some(prepared), write_ms, ms),
            None => (None, write_ms, 0.0),
        }
    });
    let Some(rev) = beat.end(&ctx.queue) else {
        tracing::warn!(patch = %h.id, version = %h.version, "the claim was taken over while writing");
        if let Some(Ok(p)) = prepared {
            states::discard(p);
        }
        return;
    };
    cost.commit_ms = lap(&mut t);
    // A stale result leaves the record's last written version as it was.
    let written = !matches!(ending, Ending::Stale(_));
    let finished = match ending {
        Ending::Rejected => false,
        Ending::Unchanged => true,
        Ending::Fitted(_) => {
            let outputs_written = ctx
                .store
                .load(&h.id)
                .is_some_and(|s| s.version == h.version);
            match (outputs_written, prepared) {
                (true, Some(Ok(p))) => {
                    states::commit(ctx, &h.id, p, &loaded);
                }
                (true, Some(Err(e))) => {
                    tracing::warn!(patch = %h.id, error = %e, "cannot save the warm-start state");
                }
                // The writer could not write the outputs: the old state stays.
                (false, Some(Ok(p))) => states::discard(p),
                _ => {}
            }
            outputs_written
        }
        Ending::Stale(warm) => {
            states::store(
                ctx,
                &h.id,
                seq,
                &states::stale_warm(&loaded, *warm),
                &loaded,
            );
            false
        }
    };
    cost.state_save_ms += lap(&mut t);
    let committed = match written {
        true => PatchRecord {
            holder: None,
            done_seq: seq,
            done_version: h.version.clone(),
            done_finished: finished,
            ..claim
        },
        false => PatchRecord {
            holder: None,
            ..claim
        },
    };
    let bytes = bytes::Bytes::from(serde_json::to_vec(&committed).unwrap_or_default());
    // Sent together: in either order a crash between the two is safe (a redelivery after the
    // commit is acknowledged as done; an acknowledged job whose claim was not released
    // holds the patch until the claim runs out), so the job waits for one round trip.
    ctx.queue.block_on(async {
        let (committed, acked) =
            tokio::join!(ctx.queue.kv.update(&key, bytes, rev), msg.double_ack());
        if let Err(e) = committed {
            tracing::warn!(patch = %h.id, error = %e, "cannot commit the patch's record");
        }
        if let Err(e) = acked {
            tracing::warn!(error = %e, "cannot acknowledge a job");
        }
    });
    cost.ack_ms = lap(&mut t);
    if finished {
        complete(&ctx.queue, &h, &ctx.out_dir);
    }
    cost.completion_ms = lap(&mut t);
    if let Some(path) = &h.path {
        if path.starts_with(spool_dir(&ctx.out_dir)) {
            let _ = std::fs::remove_file(path);
        }
    }
    tracing::info!(
        patch = %h.id, version = %h.version, seq,
        wait_ms = cost.wait_ms, claim_ms = cost.claim_ms, state_load_ms = cost.state_load_ms,
        stale_check_ms = cost.stale_check_ms, state_save_ms = cost.state_save_ms,
        commit_ms = cost.commit_ms, ack_ms = cost.ack_ms, completion_ms = cost.completion_ms,
        queue_ms = cost.work_ms(), write_ms, state_prepare_ms = prepare_ms,
        "queue cost"
    );
}

/// Reads, fits and checks for a newer version; returns what goes to the writer.
fn run(
    ctx: &Ctx,
    h: &JobHeader,
    (body, state): (Arc<Vec<u8>>, states::Fetch),
    cfg: &Arc<DaemonConfig>,
    (subject, seq): (&str, u64),
    cost: &mut Cost,
) -> (Vec<WriterMsg>, Ending, Loaded) {
    let data = match (h.format, payload(h, body, cfg.daemon.max_file_bytes)) {
        (None, _) => Err((
            rejection_kind(&Cause::UnknownFormat),
            format!("unknown extension ({})", Format::READABLE),
        )),
        (Some(_), d) => d,
    };
    let data = match data {
        Ok(d) => d,
        Err((kind, reason)) => {
            let reject = WriterMsg::Reject {
                id: h.id.clone(),
                label: h.label.clone(),
                keep: Keep::Nothing,
                kind,
                reason,
            };
            state.abort();
            return (vec![reject], Ending::Rejected, Loaded::default());
        }
    };
    let mut t = Instant::now();
    ctx.store.forget(&h.id);
    let loaded = states::load(ctx, &h.id, state);
    if let Some(state) = &loaded.state {
        ctx.store.remember(&h.id, state.clone());
    }
    cost.state_load_ms = lap(&mut t);
    let job = Job {
        arrival: arrival(h, data),
        cfg: Arc::clone(cfg),
        warm: None,
    };
    // Objects are not fitted through a queue (`object.folders` is refused with one): no
    // session to keep.
    let done: JobDone = run_job(job, &ctx.store, &ObjectSessions::new(0));
    lap(&mut t);
    let by = match &done.outcome {
        Outcome::Fitted { .. } => newer(ctx, subject, seq),
        _ => None,
    };
    cost.stale_check_ms = lap(&mut t);
    match (by, done.outcome) {
        // A newer version waits: writing this one would publish a result already out of
        // date.
        (Some(by), Outcome::Fitted { outputs, .. }) => {
            let loser = done.arrival;
            let superseded = WriterMsg::Superseded { loser, by };
            (
                vec![superseded],
                Ending::Stale(Box::new(outputs.warm)),
                loaded,
            )
        }
        (_, outcome) => {
            let ending = match &outcome {
                Outcome::Fitted { outputs, hash, .. } => {
                    Ending::Fitted(Box::new(PatchState::after_fit(
                        &h.version,
                        *hash,
                        cfg.state_fit(false),
                        outputs.warm.clone(),
                    )))
                }
                Outcome::Unchanged { .. } => Ending::Unchanged,
                _ => Ending::Rejected,
            };
            let done = WriterMsg::Done(JobDone { outcome, ..done });
            (vec![done], ending, loaded)
        }
    }
}

/// Tells the source of a path job that its input is finished (plain NATS, best effort: a
/// source that does not hear it leaves the file in place, never moves it early).
pub(super) fn complete(queue: &Queue, h: &JobHeader, out_dir: &std::path::Path) {
    let Some(path) = h
        .path
        .as_ref()
        .filter(|p| !p.starts_with(spool_dir(out_dir)))
    else {
        return;
    };
    if h.source.is_empty() {
        return;
    }
    let done = Completion {
        id: h.id.clone(),
        version: h.version.clone(),
        path: path.clone(),
    };
    let bytes = bytes::Bytes::from(serde_json::to_vec(&done).unwrap_or_default());
    let client = queue.js.client();
    if let Err(e) = queue.block_on(client.publish(queue.done_subject(&h.source), bytes)) {
        tracing::warn!(patch = %h.id, error = %e, "cannot report the input finished; it stays in place");
    }
}

/// Keeps the job alive and the claim fresh while the fit runs; sets `lost` when the claim
/// was taken over (this worker looked dead to the others).
struct Heartbeat {
    stop: tokio::sync::oneshot::Sender<()>,
    task: tokio::task::JoinHandle<()>,
    rev: Arc<AtomicU64>,
    lost: Arc<AtomicBool>,
}

fn heartbeat(ctx: &Ctx, msg: &Arc<Message>, key: &str, claim: &PatchRecord, rev: u64) -> Heartbeat {
    let (stop, mut stopped) = tokio::sync::oneshot::channel::<()>();
    let rev = Arc::new(AtomicU64::new(rev));
    let lost = Arc::new(AtomicBool::new(false));
    let claim_ms = ctx.cell.get().cluster.ack_wait_ms;
    let (msg, kv, key, mut claim) = (
        Arc::clone(msg),
        ctx.queue.kv.clone(),
        key.to_string(),
        claim.clone(),
    );
    let (r, l) = (Arc::clone(&rev), Arc::clone(&lost));
    let task = ctx.queue.rt.spawn(async move {
        let mut tick = tokio::time::interval(Duration::from_millis(claim_ms / 3));
        tick.tick().await;
        loop {
            tokio::select! {
                _ = &mut stopped => return,
                _ = tick.tick() => {}
            }
            let _ = msg.ack_with(AckKind::Progress).await;
            if let Some(h) = claim.holder.as_mut() {
                h.until_ms = now_ms() + claim_ms;
            }
            let bytes = bytes::Bytes::from(serde_json::to_vec(&claim).unwrap_or_default());
            match kv.update(&key, bytes, r.load(Ordering::SeqCst)).await {
                Ok(next) => r.store(next, Ordering::SeqCst),
                Err(e) if e.kind() == kv::UpdateErrorKind::WrongLastRevision => {
                    l.store(true, Ordering::SeqCst);
                    return;
                }
                // The server is away: the claim stays as it was, and runs out if this lasts.
                Err(_) => {}
            }
        }
    });
    Heartbeat {
        stop,
        task,
        rev,
        lost,
    }
}

impl Heartbeat {
    /// Stops renewing; returns the claim's revision, or `None` when it was taken over.
    fn end(self, queue: &Queue) -> Option<u64> {
        let _ = self.stop.send(());
        let _ = queue.block_on(self.task);
        (!self.lost.load(Ordering::SeqCst)).then(|| self.rev.load(Ordering::SeqCst))
    }
}
