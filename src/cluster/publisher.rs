//! The source side of `watch --queue`: jobs the scheduler hands out are read and published
//! to the work-queue stream instead of being fitted here. The scheduler keeps coalescing
//! while a publish waits (a server away means versions wait and coalesce locally; the
//! sources never block on the queue).

use super::queue::{now_ms, spool_dir, ClusterError, Queue, REQUEST_TIMEOUT};
use super::wire::{encode, JobHeader};
use crate::daemon::config::DaemonConfig;
use crate::daemon::job::{still_changing, Job, JobDone, Outcome, Timings};
use crate::daemon::messages::Msg;
use crate::daemon::offload::Offload;
use crate::daemon::ops::metrics::Metrics;
use crate::daemon::scheduler::Input;
use crate::daemon::state::content_hash;
use crate::io::Format;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Publishes in flight at most: beyond it versions wait in the scheduler, where a newer one
/// of the same patch replaces an older one before it costs a message.
const IN_FLIGHT: usize = 16;

/// Connects to `url` and returns the hook that sends the daemon's jobs there. `out_dir` is
/// the shared OUT: pipe records too big for a message are spooled there.
pub(crate) fn offload(
    url: &str,
    cfg: &DaemonConfig,
    out_dir: &std::path::Path,
) -> Result<Offload, ClusterError> {
    let spool = spool_dir(out_dir);
    let name = format!("trispline-source-{}", std::process::id());
    let queue = Queue::connect(url, &cfg.cluster, &name)?;
    Ok(Offload {
        capacity: IN_FLIGHT,
        start: Box::new(move |jobs, tx, metrics| {
            std::thread::Builder::new()
                .name("queue-publisher".into())
                .spawn(move || publish_loop(&queue, &jobs, &tx, &metrics, spool))
                .map(|_| ())
        }),
    })
}

fn publish_loop(
    queue: &Queue,
    jobs: &Receiver<Job>,
    tx: &Sender<Msg>,
    metrics: &Metrics,
    spool: std::path::PathBuf,
) {
    metrics.queue_configured.store(true, Ordering::Relaxed);
    loop {
        metrics.queue_reachable.set(queue.reachable() as i64);
        let job = match jobs.recv_timeout(Duration::from_millis(500)) {
            Ok(job) => job,
            Err(RecvTimeoutError::Timeout) => continue,
            Err(RecvTimeoutError::Disconnected) => return,
        };
        let id = job.arrival.id.clone();
        match message(&job, queue.cfg.payload_limit, &spool) {
            Err(reason) => {
                let done = JobDone {
                    arrival: job.arrival,
                    cfg: job.cfg,
                    outcome: Outcome::Incomplete { reason },
                    timings: Timings::default(),
                };
                let _ = tx.send(Msg::Fitted(Box::new(done)));
            }
            Ok((header, payload)) => {
                publish(queue, &header, payload, metrics);
                if tx.send(Msg::Queued(id)).is_err() {
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
) -> Result<(JobHeader, Vec<u8>), String> {
    let a = &job.arrival;
    let mut header = JobHeader {
        id: a.id.clone(),
        version: a.version.clone(),
        label: a.label.clone(),
        format: None,
        hash: String::new(),
        path: None,
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
        header.id,
        header.version,
        header.hash,
        now_ms()
    );
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
                tracing::info!(patch = %header.id, version = %header.version, seq = ack.sequence, "queued");
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
    use std::time::{Instant, SystemTime};

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
        let (h, msg) = message(&job(Input::File(small.clone())), 100, &spool).expect("read");
        let (back, body) = decode(&msg).expect("decodes");
        assert_eq!((back, body), (h.clone(), b"ply small".as_slice()));
        assert_eq!(h.path, None);
        assert_eq!(h.hash, format!("{:016x}", content_hash(b"ply small")));
        assert_eq!(h.format, Some(Format::Ply));

        let (h, msg) = message(&job(Input::File(small.clone())), 4, &spool).expect("read");
        assert_eq!(h.path.as_deref(), Some(small.as_path()));
        assert!(decode(&msg).expect("decodes").1.is_empty());

        let data = Arc::new(vec![7u8; 50]);
        let inline = Input::Inline {
            data: Arc::clone(&data),
            format: Format::Stl,
        };
        let (h, msg) = message(&job(inline), 10, &spool).expect("spooled");
        let path = h.path.clone().expect("a spool path");
        assert!(path.starts_with(&spool));
        assert_eq!(std::fs::read(&path).expect("spooled bytes"), *data);
        assert!(decode(&msg).expect("decodes").1.is_empty());
    }
}
