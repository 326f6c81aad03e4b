//! `trispline worker --queue`: takes jobs from the work-queue stream one at a time, claims
//! the patch in the bucket, fits with the warm start stored there, writes to the shared
//! OUT through the daemon's own writer, stores the new state, then acknowledges. A worker
//! that dies leaves the job unacknowledged: the server hands it to another after the ack
//! wait, and the claim (renewed while the fit runs) has run out by then.

use super::queue::{now_ms, spool_dir, states_dir, ClusterError, Queue};
use super::wire::{self, decide, Decision, JobHeader, PatchRecord, StateRecord};
use crate::daemon::config::DaemonConfig;
use crate::daemon::job::{run_job, Job, JobDone, Outcome};
use crate::daemon::kinds::{rejection_kind, Cause};
use crate::daemon::messages::{Control, Summary};
use crate::daemon::ops::metrics::Metrics;
use crate::daemon::reload::ConfigCell;
use crate::daemon::scheduler::{Arrival, Input, VersionKey};
use crate::daemon::state::{PatchState, StateStore};
use crate::daemon::writer::{Keep, SeenVersions, Writer, WriterMsg};
use crate::io::Format;
use async_nats::jetstream::consumer::{pull, AckPolicy};
use async_nats::jetstream::{kv, AckKind, Message};
use crossbeam_channel::Sender;
use futures_util::StreamExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

/// What `run_worker` is asked to do.
pub struct WorkerOptions {
    /// `nats://HOST:PORT`.
    pub url: String,
    /// The shared output folder (the same OUT as the sources').
    pub out_dir: PathBuf,
    /// The config: `[fit]`, `[output]`, limits and `[cluster]`.
    pub config: DaemonConfig,
    /// The name in events and claims (default host-pid).
    pub name: String,
}

/// What one worker did (the writer's counts).
pub type WorkerSummary = Summary;

/// A busy patch's job comes back after this.
const BUSY_RETRY: Duration = Duration::from_millis(250);

struct Ctx {
    queue: Queue,
    store: Arc<StateStore>,
    wtx: Sender<WriterMsg>,
    cell: Arc<ConfigCell>,
    name: String,
    out_dir: PathBuf,
}

/// Runs a worker until `ctl.stop`; the fit in progress finishes first.
pub fn run_worker(opts: WorkerOptions, ctl: &Control) -> Result<WorkerSummary, ClusterError> {
    let folder = |path: &Path| {
        let path = path.to_path_buf();
        move |source| ClusterError::Folder { path, source }
    };
    std::fs::create_dir_all(&opts.out_dir).map_err(folder(&opts.out_dir))?;
    // Its own scratch: the writer's local state files and superseded list. The states that
    // count are in the bucket.
    let scratch = tempfile::tempdir().map_err(folder(&opts.out_dir))?;
    let metrics = Arc::new(Metrics::default());
    metrics.queue_configured.store(true, Ordering::Relaxed);
    if let Some(addr) = &opts.config.daemon.metrics_addr {
        let local = crate::daemon::ops::http::serve(addr, Arc::clone(&metrics))
            .map_err(folder(Path::new(addr)))?;
        tracing::info!(addr = %local, "serving /metrics and /healthz");
    }
    let Some(queue) = connect_patiently(&opts, ctl)? else {
        return Ok(Summary::default());
    };
    let consumer = queue.block_on(queue.stream.get_or_create_consumer(
        "trispline-workers",
        pull::Config {
            durable_name: Some("trispline-workers".into()),
            ack_policy: AckPolicy::Explicit,
            ack_wait: Duration::from_millis(opts.config.cluster.ack_wait_ms),
            // Unbounded here: poison is told by the claim's attempt count, which a busy
            // patch's quick retries do not raise.
            max_deliver: -1,
            ..Default::default()
        },
    ));
    let consumer = consumer.map_err(|e| ClusterError::Setup {
        what: "consumer",
        reason: e.to_string(),
    })?;
    let quarantine = opts
        .config
        .output
        .quarantine_dir
        .clone()
        .unwrap_or_else(|| opts.out_dir.join("quarantine"));
    let cell = Arc::new(ConfigCell::new(opts.config.clone()));
    let store = Arc::new(StateStore::new(scratch.path().to_path_buf()));
    // Nobody listens: the scheduler that needs "written" lives in the source.
    let (acks, _) = crossbeam_channel::unbounded();
    let (wtx, wrx) = crossbeam_channel::unbounded();
    let writer = Writer {
        out_dir: opts.out_dir.clone(),
        watch_dir: scratch.path().to_path_buf(),
        quarantine,
        store: Arc::clone(&store),
        metrics: Arc::clone(&metrics),
        acks,
        summary: Summary::default(),
        cell: Arc::clone(&cell),
        seen: SeenVersions::load(scratch.path()),
        node: Some(opts.name.clone()),
    };
    let writer = std::thread::Builder::new()
        .name("writer".into())
        .spawn(move || writer.run(wrx))
        .map_err(folder(&opts.out_dir))?;
    let ctx = Ctx {
        queue,
        store,
        wtx,
        cell,
        name: opts.name.clone(),
        out_dir: opts.out_dir.clone(),
    };
    tracing::info!(name = %ctx.name, url = %opts.url, out = %opts.out_dir.display(), "worker started");
    crate::daemon::ops::sdnotify::notify(crate::daemon::ops::sdnotify::State::Ready);
    while !ctl.stop.load(Ordering::Relaxed) {
        metrics.queue_reachable.set(ctx.queue.reachable() as i64);
        let next = ctx.queue.block_on(async {
            let mut batch = consumer
                .batch()
                .max_messages(1)
                .expires(Duration::from_secs(1))
                .messages()
                .await
                .map_err(|e| e.to_string())?;
            batch.next().await.transpose().map_err(|e| e.to_string())
        });
        match next {
            Ok(Some(msg)) => handle(&ctx, msg),
            Ok(None) => {}
            Err(e) => {
                tracing::warn!(error = %e, "cannot take a job; retrying");
                metrics.queue_reachable.set(0);
                std::thread::sleep(Duration::from_millis(500));
            }
        }
    }
    let _ = ctx.wtx.send(WriterMsg::Shutdown);
    Ok(writer.join().unwrap_or_default())
}

/// A worker may start before the server (boot order, a server restart): it waits for it,
/// until stopped. Other failures (credentials, setup) end it.
fn connect_patiently(opts: &WorkerOptions, ctl: &Control) -> Result<Option<Queue>, ClusterError> {
    loop {
        match Queue::connect(&opts.url, &opts.config.cluster, &opts.name) {
            Ok(q) => return Ok(Some(q)),
            Err(e @ ClusterError::Connect { .. }) => {
                tracing::warn!(error = %e, "queue server not reachable yet; waiting");
            }
            Err(e) => return Err(e),
        }
        for _ in 0..10 {
            if ctl.stop.load(Ordering::Relaxed) {
                return Ok(None);
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// The job's version as the daemon's writer knows versions.
fn arrival(h: &JobHeader, data: Arc<Vec<u8>>) -> Arrival {
    Arrival {
        id: h.id.clone(),
        input: Input::Inline {
            data,
            format: h.format.unwrap_or(Format::Ply),
        },
        key: VersionKey {
            time: SystemTime::now(),
            tie: h.version.clone(),
        },
        version: h.version.clone(),
        label: h.label.clone(),
        detected: Instant::now(),
    }
}

fn record_key(id: &str) -> String {
    format!("patch.{}", wire::token(id))
}

fn state_key(id: &str) -> String {
    format!("state.{}", wire::token(id))
}

async fn ack(msg: &Message, kind: AckKind) {
    if let Err(e) = msg.ack_with(kind).await {
        tracing::warn!(error = %e, "cannot acknowledge a job");
    }
}

/// Sends to the writer and waits until it has handled everything sent so far.
fn write(ctx: &Ctx, msgs: Vec<WriterMsg>) {
    let (tx, rx) = crossbeam_channel::bounded(1);
    for m in msgs {
        let _ = ctx.wtx.send(m);
    }
    let _ = ctx.wtx.send(WriterMsg::Barrier(tx));
    let _ = rx.recv();
}

/// The version of the newest job still waiting on the patch's subject after `seq`.
fn newer(ctx: &Ctx, subject: &str, seq: u64) -> Option<String> {
    let last = ctx
        .queue
        .block_on(ctx.queue.stream.get_last_raw_message_by_subject(subject))
        .ok()?;
    if last.sequence <= seq {
        return None;
    }
    let version = wire::decode(&last.payload)
        .map(|(h, _)| h.version)
        .unwrap_or_else(|_| format!("job {}", last.sequence));
    Some(version)
}

fn handle(ctx: &Ctx, msg: Message) {
    let Ok(seq) = msg.info().map(|i| i.stream_sequence) else {
        return;
    };
    let (header, body) = match wire::decode(&msg.payload) {
        Ok((h, b)) => (h, b.to_vec()),
        Err(reason) => {
            tracing::error!(seq, reason, "dropped a message that is not a job");
            write(
                ctx,
                vec![WriterMsg::Reject {
                    id: String::new(),
                    label: format!("queue:{}#{seq}", msg.subject),
                    keep: Keep::Nothing,
                    kind: "queue_not_a_job",
                    reason,
                }],
            );
            ctx.queue.block_on(ack(&msg, AckKind::Term));
            return;
        }
    };
    let subject = msg.subject.to_string();
    let body = Arc::new(body);
    if let Some(by) = newer(ctx, &subject, seq) {
        let loser = arrival(&header, Arc::clone(&body));
        write(ctx, vec![WriterMsg::Superseded { loser, by }]);
        ctx.queue.block_on(ack(&msg, AckKind::Ack));
        return;
    }
    let key = record_key(&header.id);
    let cluster = &ctx.cell.get().cluster;
    let entry = ctx.queue.block_on(ctx.queue.kv.entry(&key));
    let (rec, rev) = match entry {
        Ok(Some(e)) if e.operation == kv::Operation::Put => (
            serde_json::from_slice::<PatchRecord>(&e.value).unwrap_or_default(),
            Some(e.revision),
        ),
        Ok(Some(e)) => (PatchRecord::default(), Some(e.revision)),
        Ok(None) => (PatchRecord::default(), None),
        Err(e) => {
            tracing::warn!(error = %e, "cannot read the patch's record; retrying");
            ctx.queue
                .block_on(ack(&msg, AckKind::Nak(Some(BUSY_RETRY))));
            return;
        }
    };
    let decision = decide(
        &rec,
        seq,
        &ctx.name,
        now_ms(),
        cluster.ack_wait_ms,
        cluster.max_deliveries,
    );
    match decision {
        Decision::AlreadyDone => ctx.queue.block_on(ack(&msg, AckKind::Ack)),
        Decision::Superseded(by) => {
            let loser = arrival(&header, body);
            write(ctx, vec![WriterMsg::Superseded { loser, by }]);
            ctx.queue.block_on(ack(&msg, AckKind::Ack));
        }
        Decision::Busy => ctx
            .queue
            .block_on(ack(&msg, AckKind::Nak(Some(BUSY_RETRY)))),
        Decision::Poison(n) => {
            let max_bytes = ctx.cell.get().daemon.max_file_bytes;
            let keep = match payload(&header, body, max_bytes) {
                Ok(data) if !data.is_empty() => Keep::Bytes(data, header.version.clone()),
                _ => Keep::Nothing,
            };
            write(
                ctx,
                vec![WriterMsg::Reject {
                    id: header.id.clone(),
                    label: header.label.clone(),
                    keep,
                    kind: "poison",
                    reason: format!("its fit was started {n} times and never finished (a worker died each time)"),
                }],
            );
            ctx.queue.block_on(ack(&msg, AckKind::Ack));
        }
        Decision::Claim(claim) => {
            let bytes = bytes::Bytes::from(serde_json::to_vec(&claim).unwrap_or_default());
            let taken = ctx.queue.block_on(async {
                match rev {
                    Some(r) => ctx
                        .queue
                        .kv
                        .update(&key, bytes, r)
                        .await
                        .map_err(|e| e.to_string()),
                    None => ctx
                        .queue
                        .kv
                        .create(&key, bytes)
                        .await
                        .map_err(|e| e.to_string()),
                }
            });
            match taken {
                Ok(r) => fit(ctx, msg, header, body, seq, claim, r),
                Err(e) => {
                    tracing::debug!(error = %e, "another worker claimed the patch first");
                    ctx.queue
                        .block_on(ack(&msg, AckKind::Nak(Some(BUSY_RETRY))));
                }
            }
        }
    }
}

/// The mesh bytes: in the message, or read from shared storage.
fn payload(
    h: &JobHeader,
    body: Arc<Vec<u8>>,
    max_bytes: u64,
) -> Result<Arc<Vec<u8>>, (&'static str, String)> {
    let Some(path) = h.path.as_ref().filter(|_| body.is_empty()) else {
        return Ok(body);
    };
    let read = std::fs::metadata(path).and_then(|m| {
        if m.len() > max_bytes {
            return Ok(None);
        }
        std::fs::read(path).map(Some)
    });
    match read {
        Ok(Some(b)) => Ok(Arc::new(b)),
        Ok(None) => Err((
            rejection_kind(&Cause::TooLarge),
            format!("exceeds daemon.max_file_bytes = {max_bytes}"),
        )),
        Err(e) => Err((
            rejection_kind(&Cause::Read(&e)),
            format!("cannot read {} from shared storage: {e}", path.display()),
        )),
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

fn fit(
    ctx: &Ctx,
    msg: Message,
    h: JobHeader,
    body: Arc<Vec<u8>>,
    seq: u64,
    claim: PatchRecord,
    rev: u64,
) {
    let cfg = ctx.cell.get();
    let key = record_key(&h.id);
    let msg = Arc::new(msg);
    let beat = heartbeat(ctx, &msg, &key, &claim, rev);
    let data = match (
        h.format,
        payload(&h, Arc::clone(&body), cfg.daemon.max_file_bytes),
    ) {
        (None, _) => Err((
            rejection_kind(&Cause::UnknownFormat),
            format!("unknown extension ({})", Format::READABLE),
        )),
        (Some(_), d) => d,
    };
    let mut to_writer = Vec::new();
    let mut fitted_state = false;
    // False when the result was dropped for a newer version: the record then keeps the
    // last version actually written.
    let mut result_written = true;
    match data {
        Err((kind, reason)) => to_writer.push(WriterMsg::Reject {
            id: h.id.clone(),
            label: h.label.clone(),
            keep: Keep::Nothing,
            kind,
            reason,
        }),
        Ok(data) => {
            ctx.store.forget(&h.id);
            if let Some(state) = load_state(ctx, &h.id) {
                ctx.store.remember(&h.id, state);
            }
            let job = Job {
                arrival: arrival(&h, data),
                cfg: Arc::clone(&cfg),
                warm: None,
            };
            let done: JobDone = run_job(job, &ctx.store);
            let fitted = matches!(done.outcome, Outcome::Fitted { .. });
            match newer(ctx, &msg.subject, seq).filter(|_| fitted) {
                // A newer version waits: writing this one would publish a result already out
                // of date.
                Some(by) => {
                    result_written = false;
                    to_writer.push(WriterMsg::Superseded {
                        loser: done.arrival,
                        by,
                    })
                }
                None => {
                    fitted_state = fitted;
                    to_writer.push(WriterMsg::Done(done));
                }
            }
        }
    }
    if beat.lost.load(Ordering::SeqCst) {
        tracing::warn!(patch = %h.id, version = %h.version, "the claim was taken over by another worker; result dropped");
        let _ = beat.end(&ctx.queue);
        return;
    }
    write(ctx, to_writer);
    let Some(rev) = beat.end(&ctx.queue) else {
        tracing::warn!(patch = %h.id, version = %h.version, "the claim was taken over while writing");
        return;
    };
    if fitted_state {
        save_state(ctx, &h);
    }
    let committed = match result_written {
        true => PatchRecord {
            holder: None,
            done_seq: seq,
            done_version: h.version.clone(),
            ..claim
        },
        false => PatchRecord {
            holder: None,
            ..claim
        },
    };
    let bytes = bytes::Bytes::from(serde_json::to_vec(&committed).unwrap_or_default());
    if let Err(e) = ctx.queue.block_on(ctx.queue.kv.update(&key, bytes, rev)) {
        tracing::warn!(patch = %h.id, error = %e, "cannot commit the patch's record");
    }
    ctx.queue.block_on(async {
        if let Err(e) = msg.double_ack().await {
            tracing::warn!(error = %e, "cannot acknowledge a job");
        }
    });
    if let Some(path) = &h.path {
        if path.starts_with(spool_dir(&ctx.out_dir)) {
            let _ = std::fs::remove_file(path);
        }
    }
}

/// The patch's last state from the bucket (or the shared file it names); `None` is a cold
/// start.
fn load_state(ctx: &Ctx, id: &str) -> Option<PatchState> {
    let bytes = match ctx.queue.block_on(ctx.queue.kv.get(state_key(id))) {
        Ok(b) => b?,
        Err(e) => {
            tracing::warn!(patch = id, error = %e, "cannot read the warm-start state; starting cold");
            return None;
        }
    };
    match serde_json::from_slice::<StateRecord>(&bytes).ok()? {
        StateRecord::Inline(s) => Some(*s),
        StateRecord::File(path) => serde_json::from_slice(&std::fs::read(path).ok()?).ok(),
    }
}

/// Stores the state the writer just made for this version: in the bucket, or on shared
/// storage with its path in the bucket when it is over the payload limit.
fn save_state(ctx: &Ctx, h: &JobHeader) {
    let Some(state) = ctx.store.load(&h.id) else {
        return;
    };
    if state.version != h.version {
        return;
    }
    let limit = ctx.cell.get().cluster.payload_limit;
    let mut bytes =
        serde_json::to_vec(&StateRecord::Inline(Box::new((*state).clone()))).unwrap_or_default();
    if bytes.len() > limit {
        let dir = states_dir(&ctx.out_dir);
        let path = dir.join(format!("{}.json", wire::token(&h.id)));
        let written = std::fs::create_dir_all(&dir)
            .map_err(|e| e.to_string())
            .and_then(|_| {
                crate::io::write_atomic(&path, &serde_json::to_vec(&*state).unwrap_or_default())
                    .map_err(|e| e.to_string())
            });
        if let Err(e) = written {
            tracing::warn!(patch = %h.id, error = %e, "cannot save the warm-start state");
            return;
        }
        bytes = serde_json::to_vec(&StateRecord::File(path)).unwrap_or_default();
    }
    if let Err(e) = ctx
        .queue
        .block_on(ctx.queue.kv.put(state_key(&h.id), bytes.into()))
    {
        tracing::warn!(patch = %h.id, error = %e, "cannot save the warm-start state");
    }
}
