//! The source side of `watch --queue`: jobs the scheduler hands out are read and published
//! to the work-queue stream instead of being fitted here. The scheduler keeps coalescing
//! while a publish waits (a server away, even at start-up, means versions wait and coalesce
//! locally; the sources never block on the queue). The processed-file policy applies here,
//! where the input's folders are known: to a job that carries its bytes once the server has
//! stored it, to a job that carries a path once a worker reports it finished.

use super::queue::{now_us, process_name, spool_dir, ClusterError, Queue, REQUEST_TIMEOUT};
use super::wire::{encode, Completion, JobHeader};
use crate::daemon::config::{ClusterSection, DaemonConfig, ProcessedPolicy};
use crate::daemon::job::{still_changing, Job, JobDone, Outcome, Timings};
use crate::daemon::messages::Msg;
use crate::daemon::offload::Offload;
use crate::daemon::ops::metrics::Metrics;
use crate::daemon::scheduler::Input;
use crate::daemon::state::content_hash;
use crate::daemon::writer::WriterMsg;
use crate::io::Format;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use futures_util::StreamExt;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Publishes in flight at most: beyond it versions wait in the scheduler, where a newer one
/// of the same patch replaces an older one before it costs a message.
const IN_FLIGHT: usize = 16;

/// The longest wait between two tries to reach a server that is down.
const MAX_BACKOFF: Duration = Duration::from_secs(5);

/// Path jobs published and not yet reported finished: input -> (version, policy).
type Pending = Arc<Mutex<HashMap<PathBuf, (String, ProcessedPolicy)>>>;

/// Returns the hook that sends the daemon's jobs to `url`. `out_dir` is the shared OUT:
/// pipe records too big for a message are spooled there. A server that is not up yet is
/// waited for in the background; faults of the configuration itself (credentials, limits)
/// end the start-up when the server answers.
pub(crate) fn offload(
    url: &str,
    cfg: &DaemonConfig,
    out_dir: &std::path::Path,
) -> Result<Offload, ClusterError> {
    let spool = spool_dir(out_dir);
    let name = process_name();
    let first = match Queue::connect(url, &cfg.cluster, &name) {
        Ok(q) => Some(q),
        Err(e @ ClusterError::Connect { .. }) => {
            tracing::warn!(error = %e, "queue server not reachable; versions wait and coalesce here until it is");
            None
        }
        Err(e) => return Err(e),
    };
    let (url, cluster) = (url.to_string(), cfg.cluster.clone());
    Ok(Offload {
        capacity: IN_FLIGHT,
        start: Box::new(move |jobs, tx, wtx, metrics| {
            std::thread::Builder::new()
                .name("queue-publisher".into())
                .spawn(move || {
                    metrics.queue_configured.store(true, Ordering::Relaxed);
                    metrics.queue_reachable.set(first.is_some() as i64);
                    let queue = match first {
                        Some(q) => q,
                        None => connect_with_backoff(&url, &cluster, &name, &metrics),
                    };
                    let pending = Pending::default();
                    listen_for_completions(&queue, &name, &pending, &wtx);
                    let out = Outlets {
                        tx,
                        wtx,
                        pending,
                        name,
                    };
                    publish_loop(&queue, &jobs, &out, &metrics, spool)
                })
                .map(|_| ())
        }),
    })
}

/// Tries until the server answers, waiting longer each time (up to `MAX_BACKOFF`).
fn connect_with_backoff(url: &str, cfg: &ClusterSection, name: &str, metrics: &Metrics) -> Queue {
    let mut delay = Duration::from_millis(100);
    loop {
        match Queue::connect(url, cfg, name) {
            Ok(q) => {
                tracing::info!(url, "queue server reached");
                return q;
            }
            Err(e) => {
                metrics.queue_reachable.set(0);
                metrics.error("queue_unreachable");
                tracing::warn!(error = %e, retry_in_ms = delay.as_millis() as u64, "queue server not reachable");
            }
        }
        std::thread::sleep(delay);
        delay = (delay * 2).min(MAX_BACKOFF);
    }
}

/// Applies the processed-file policy to path jobs that a worker reports finished. Only
/// inputs this process published and still waits for are touched, and the writer checks the
/// roots as for a local fit.
fn listen_for_completions(queue: &Queue, name: &str, pending: &Pending, wtx: &Sender<WriterMsg>) {
    let subject = queue.done_subject(name);
    let client = queue.js.client();
    let (pending, wtx) = (Arc::clone(pending), wtx.clone());
    queue.rt.spawn(async move {
        let mut sub = match client.subscribe(subject).await {
            Ok(s) => s,
            Err(e) => {
                tracing::warn!(error = %e, "cannot hear completions; queued inputs stay in place");
                return;
            }
        };
        while let Some(msg) = sub.next().await {
            let Ok(done) = serde_json::from_slice::<Completion>(&msg.payload) else {
                continue;
            };
            let mut waiting = pending.lock().unwrap_or_else(|p| p.into_inner());
            let ours = waiting
                .get(&done.path)
                .is_some_and(|(version, _)| *version == done.version);
            if let (true, Some((_, policy))) = (ours, waiting.remove(&done.path)) {
                let _ = wtx.send(WriterMsg::Processed(done.path, policy));
            }
        }
    });
}

/// Where the publisher reports: the scheduler, the writer, the completions awaited.
struct Outlets {
    tx: Sender<Msg>,
    wtx: Sender<WriterMsg>,
    pending: Pending,
    name: String,
}

fn publish_loop(
    queue: &Queue,
    jobs: &Receiver<Job>,
    out: &Outlets,
    metrics: &Metrics,
    spool: std::path::PathBuf,
) {
    loop {
        metrics.queue_reachable.set(queue.reachable() as i64);
        let job = match jobs.recv_timeout(Duration::from_millis(500)) {
            Ok(job) => job,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return,
        };
        let id = job.arrival.id.clone();
        match message(&job, queue.cfg.payload_limit, &spool, &out.name) {
            Err(reason) => {
                let done = JobDone {
                    arrival: job.arrival,
                    cfg: job.cfg,
                    outcome: Outcome::Incomplete { reason, wait: None },
                    timings: Timings::default(),
                };
                let _ = out.tx.send(Msg::Fitted(Box::new(done)));
            }
            Ok((header, payload)) => {
                let policy = job.cfg.output.processed;
                let input = match &job.arrival.input {
                    Input::File(p) if policy != ProcessedPolicy::Leave => Some(p.clone()),
                    _ => None,
                };
                let by_path = header.path.is_some();
                if let (Some(p), true) = (&input, by_path) {
                    // Before the publish: a quick worker's completion may come before its
                    // acknowledgement does.
                    out.pending
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .insert(p.clone(), (header.version.clone(), policy));
                }
                publish(queue, &header, payload, metrics);
                if let (Some(p), false) = (input, by_path) {
                    // The bytes are in the stream now, which keeps them until a worker is
                    // done: the file is no longer needed.
                    let _ = out.wtx.send(WriterMsg::Processed(p, policy));
                }
                if out.tx.send(Msg::Queued(id)).is_err() {
                    return;
                }
            }
        }
    }
}

/// The job's header and message; `Err` when the file changed while it was read (read
/// again once it settles, as the local worker does).
fn message(
    job: &Job,
    limit: usize,
    spool: &std::path::Path,
    source: &str,
) -> Result<(JobHeader, Vec<u8>), String> {
    let a = &job.arrival;
    let mut header = JobHeader {
        id: a.id.clone(),
        version: a.version.clone(),
        label: a.label.clone(),
        format: None,
        hash: String::new(),
        path: None,
        source: source.to_string(),
        published_us: now_us(),
    };
    match &a.input {
        Input::Inline { data, format } => {
            header.format = Some(*format);
            header.hash = format!("{:016x}", content_hash(data));
            if data.len() <= limit {
                return Ok((header.clone(), encode(&header, data)));
            }
            // A pipe record over the limit has no file of its own: it is spooled to the
            // shared OUT, where the worker reads it (and removes it once done).
            let spooled = spool.join(format!("{}-{}", super::wire::token(&a.id), header.hash));
            let written = std::fs::create_dir_all(spool)
                .map_err(|e| e.to_string())
                .and_then(|_| crate::io::write_atomic(&spooled, data).map_err(|e| e.to_string()));
            match written {
                Ok(()) => header.path = Some(spooled),
                Err(e) => return Err(format!("cannot spool the record to shared storage: {e}")),
            }
            Ok((header.clone(), encode(&header, &[])))
        }
        // Object folders are fitted by the daemon that watches them (`[object] folders`
        // is refused together with a queue).
        Input::Object(_) => Err("object folders are not fitted through the queue".into()),
        Input::File(path) => {
            header.format = Format::from_path(path);
            header.path = Some(path.clone());
            let Ok(meta) = std::fs::metadata(path) else {
                // Gone: the worker's read reports it.
                return Ok((header.clone(), encode(&header, &[])));
            };
            if meta.len() > limit as u64 {
                // Too big for a message: the worker reads it from the shared folder.
                return Ok((header.clone(), encode(&header, &[])));
            }
            let before = (meta.len(), meta.modified().ok());
            let Ok(bytes) = std::fs::read(path) else {
                return Ok((header.clone(), encode(&header, &[])));
            };
            if still_changing(path, before, bytes.len()) {
                return Err("changed while it was read; read again once it settles".into());
            }
            header.hash = format!("{:016x}", content_hash(&bytes));
            header.path = None;
            Ok((header.clone(), encode(&header, &bytes)))
        }
    }
}

/// Publishes until the server stores the job (retrying through a restart); the message id
/// lets the server drop a copy whose first acknowledgement was lost.
fn publish(queue: &Queue, header: &JobHeader, payload: Vec<u8>, metrics: &Metrics) {
    let subject = queue.subject(&header.id);
    let msg_id = format!(
        "{}:{}:{}:{}",
        header.id, header.version, header.hash, header.published_us
    );
    let t = Instant::now();
    let payload = bytes::Bytes::from(payload);
    let mut delay = Duration::from_millis(100);
    loop {
        let mut headers = async_nats::HeaderMap::new();
        headers.insert("Nats-Msg-Id", msg_id.as_str());
        let sent = queue.block_on(async {
            let ack = queue
                .js
                .publish_with_headers(subject.clone(), headers, payload.clone())
                .await
                .map_err(|e| e.to_string())?;
            tokio::time::timeout(REQUEST_TIMEOUT, ack)
                .await
                .map_err(|_| "no acknowledgement".to_string())?
                .map_err(|e| e.to_string())
        });
        match sent {
            Ok(ack) => {
                metrics.queue_reachable.set(1);
                let publish_ms = t.elapsed().as_secs_f64() * 1e3;
                tracing::info!(patch = %header.id, version = %header.version, seq = ack.sequence, publish_ms, "queued");
                return;
            }
            Err(e) => {
                metrics.queue_reachable.set(0);
                metrics.error("queue_unreachable");
                tracing::warn!(patch = %header.id, error = %e, "cannot queue; retrying");
                std::thread::sleep(delay);
                delay = (delay * 2).min(Duration::from_secs(2));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cluster::wire::decode;
    use crate::daemon::scheduler::{Arrival, VersionKey};
    use std::sync::Arc;
    use std::time::SystemTime;

    fn job(input: Input) -> Job {
        Job {
            arrival: Arrival {
                id: "ear".into(),
                input,
                key: VersionKey {
                    time: SystemTime::now(),
                    tie: "ear@1.ply".into(),
                },
                version: "ear@1.ply".into(),
                label: "ear@1.ply".into(),
                detected: Instant::now(),
            },
            cfg: Arc::new(DaemonConfig::embedded_default().expect("default config")),
            warm: None,
        }
    }

    /// Bytes under the limit travel in the message; a file over it travels as its path; a
    /// pipe record over it is spooled to the shared folder and travels as that path.
    #[test]
    fn small_inputs_travel_whole_and_large_ones_by_path() {
        let dir = tempfile::tempdir().expect("tmp");
        let spool = dir.path().join("spool");
        let small = dir.path().join("ear@1.ply");
        std::fs::write(&small, b"ply small").expect("write");
        let (h, msg) = message(&job(Input::File(small.clone())), 100, &spool, "me").expect("read");
        let (back, body) = decode(&msg).expect("decodes");
        assert_eq!((back, body), (h.clone(), b"ply small".as_slice()));
        assert_eq!(h.path, None);
        assert_eq!(h.hash, format!("{:016x}", content_hash(b"ply small")));
        assert_eq!(h.format, Some(Format::Ply));

        let (h, msg) = message(&job(Input::File(small.clone())), 4, &spool, "me").expect("read");
        assert_eq!(h.path.as_deref(), Some(small.as_path()));
        assert!(decode(&msg).expect("decodes").1.is_empty());

        let data = Arc::new(vec![7u8; 50]);
        let inline = Input::Inline {
            data: Arc::clone(&data),
            format: Format::Stl,
        };
        let (h, msg) = message(&job(inline), 10, &spool, "me").expect("spooled");
        let path = h.path.clone().expect("a spool path");
        assert!(path.starts_with(&spool));
        assert_eq!(std::fs::read(&path).expect("spooled bytes"), *data);
        assert!(decode(&msg).expect("decodes").1.is_empty());
    }
}
