//! `trispline worker --queue`: takes jobs from the work-queue stream one at a time, claims
//! the patch in the bucket, fits with the warm start stored there, writes to the shared
//! OUT through the daemon's own writer, stores the new state, then acknowledges. A worker
//! that dies leaves the job unacknowledged: the server hands it to another after the ack
//! wait, and the claim (renewed while the fit runs) has run out by then.

use super::context::{arrival, newer, payload, record_key, write, Ctx};
use super::fit::{complete, fit, lap, Cost};
use super::queue::{now_ms, now_us, ClusterError, Queue};
use super::states;
use super::wire::{self, decide, Decision, PatchRecord};
use crate::daemon::config::DaemonConfig;
use crate::daemon::coordinator::reload_config;
use crate::daemon::messages::{Control, Summary};
use crate::daemon::ops::metrics::Metrics;
use crate::daemon::reload::{ConfigCell, Reloader};
use crate::daemon::state::StateStore;
use crate::daemon::writer::{Keep, SeenVersions, Writer, WriterMsg};
use async_nats::jetstream::consumer::{pull, AckPolicy};
use async_nats::jetstream::{kv, AckKind, Message};
use futures_util::StreamExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What `run_worker` is asked to do.
pub struct WorkerOptions {
    /// `nats://HOST:PORT`.
    pub url: String,
    /// The shared output folder (the same OUT as the sources').
    pub out_dir: PathBuf,
    /// The config: `[fit]`, `[output]`, limits and `[cluster]`.
    pub config: DaemonConfig,
    /// Re-read on SIGHUP (`Control::reload`) and when it changes, as the daemon's.
    pub config_path: Option<PathBuf>,
    /// The name in events and claims (default host-pid).
    pub name: String,
}

/// What one worker did (the writer's counts).
pub type WorkerSummary = Summary;

/// A busy patch's job comes back after this.
const BUSY_RETRY: Duration = Duration::from_millis(250);

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
    let store = Arc::new(StateStore::in_memory(scratch.path().to_path_buf()));
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
    let mut reloader = Reloader::new(opts.config_path.clone());
    while !ctl.stop.load(Ordering::Relaxed) {
        // Between jobs, as the daemon between messages: a job keeps the config it began with.
        if ctl.reload.swap(false, Ordering::Relaxed) || reloader.file_changed() {
            reload_config(&mut reloader, &ctx.cell, ctl, &metrics, &ctx.wtx);
        }
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

async fn ack(msg: &Message, kind: AckKind) {
    if let Err(e) = msg.ack_with(kind).await {
        tracing::warn!(error = %e, "cannot acknowledge a job");
    }
}

fn handle(ctx: &Ctx, msg: Message) {
    let mut t = Instant::now();
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
    let mut cost = Cost {
        wait_ms: match header.published_us {
            0 => f64::NAN,
            at => now_us().saturating_sub(at) as f64 / 1e3,
        },
        ..Cost::default()
    };
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
        Decision::AlreadyDone => {
            if rec.done_finished {
                complete(&ctx.queue, &header, &ctx.out_dir);
            }
            ctx.queue.block_on(ack(&msg, AckKind::Ack));
        }
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
            let state = states::fetch(ctx, &header.id);
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
            cost.claim_ms = lap(&mut t);
            match taken {
                Ok(r) => fit(ctx, msg, header, (body, state), seq, claim, r, cost),
                Err(e) => {
                    state.abort();
                    tracing::debug!(error = %e, "another worker claimed the patch first");
                    ctx.queue
                        .block_on(ack(&msg, AckKind::Nak(Some(BUSY_RETRY))));
                }
            }
        }
    }
}
