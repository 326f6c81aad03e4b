//! The connection to the server: the client on its own small runtime, the work-queue
//! stream and the key-value bucket; and the errors of setting them up.

use crate::daemon::config::ClusterSection;
use async_nats::jetstream::{self, kv, stream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// Why the queue could not be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ClusterError {
    /// The client's runtime could not start (a thread or descriptor limit).
    #[error("cannot start the queue client: {0}")]
    Runtime(#[source] std::io::Error),
    /// The credentials file cannot be read.
    #[error("credentials {}: {source}", path.display())]
    Credentials {
        /// The configured file.
        path: PathBuf,
        /// What reading it said.
        #[source]
        source: std::io::Error,
    },
    /// No server answered at the URL.
    #[error("cannot connect to {url}: {reason}")]
    Connect {
        /// The URL tried.
        url: String,
        /// What the client said.
        reason: String,
    },
    /// The stream, the consumer or the bucket cannot be created or opened.
    #[error("cannot set up the {what}: {reason}")]
    Setup {
        /// Which of them.
        what: &'static str,
        /// What the server said.
        reason: String,
    },
    /// A folder the worker needs cannot be created.
    #[error("{}: {source}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// What the filesystem said.
        #[source]
        source: std::io::Error,
    },
}

impl ClusterError {
    /// A machine-readable name of the failure.
    pub fn kind(&self) -> &'static str {
        match self {
            ClusterError::Runtime(_) => "queue_runtime",
            ClusterError::Credentials { .. } => "queue_credentials",
            ClusterError::Connect { .. } => "queue_connect",
            ClusterError::Setup { .. } => "queue_setup",
            ClusterError::Folder { .. } => "folder",
        }
    }
}

/// A connection to the server with the stream and the bucket opened (created when
/// missing), on a runtime of its own.
pub(crate) struct Queue {
    pub(crate) rt: tokio::runtime::Runtime,
    pub(crate) js: jetstream::Context,
    pub(crate) stream: stream::Stream,
    pub(crate) kv: kv::Store,
    pub(crate) cfg: ClusterSection,
    /// Follows the client's connect and disconnect events.
    reachable: Arc<AtomicBool>,
}

/// How long one request to the server may take before it counts as failed.
pub(crate) const REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

impl Queue {
    /// Connects to `url` and opens (or creates) the stream and the bucket of `cfg`.
    pub(crate) fn connect(
        url: &str,
        cfg: &ClusterSection,
        name: &str,
    ) -> Result<Queue, ClusterError> {
        let rt = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("nats")
            .enable_all()
            .build()
            .map_err(ClusterError::Runtime)?;
        let reachable = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&reachable);
        let client = rt.block_on(async {
            let mut opts = async_nats::ConnectOptions::new()
                .name(name)
                .connection_timeout(REQUEST_TIMEOUT)
                .request_timeout(Some(REQUEST_TIMEOUT))
                .event_callback(move |event| {
                    let flag = Arc::clone(&flag);
                    async move {
                        match event {
                            async_nats::Event::Connected => flag.store(true, Ordering::Relaxed),
                            async_nats::Event::Disconnected | async_nats::Event::Closed => {
                                tracing::warn!("queue server unreachable; reconnecting");
                                flag.store(false, Ordering::Relaxed)
                            }
                            _ => {}
                        }
                    }
                });
            if let Some(path) = &cfg.credentials {
                opts = opts.credentials_file(path).await.map_err(|source| {
                    ClusterError::Credentials {
                        path: path.clone(),
                        source,
                    }
                })?;
            }
            opts.connect(url).await.map_err(|e| ClusterError::Connect {
                url: url.to_string(),
                reason: e.to_string(),
            })
        })?;
        reachable.store(true, Ordering::Relaxed);
        // Room for the job header beside the mesh bytes.
        let server_max = client.server_info().max_payload;
        if cfg.payload_limit + 64 * 1024 > server_max {
            return Err(ClusterError::Setup {
                what: "payload limit",
                reason: format!(
                    "cluster.payload_limit = {} leaves no room for a job's header under the server's max_payload = {server_max}",
                    cfg.payload_limit
                ),
            });
        }
        // The context spawns its own tasks: it is made inside the runtime.
        let js = {
            let _inside = rt.enter();
            jetstream::new(client)
        };
        let (stream, kv) = rt.block_on(open(&js, cfg))?;
        Ok(Queue {
            rt,
            js,
            stream,
            kv,
            cfg: cfg.clone(),
            reachable,
        })
    }

    /// Runs a request to the server from synchronous code.
    pub(crate) fn block_on<F: std::future::Future>(&self, f: F) -> F::Output {
        self.rt.block_on(f)
    }

    /// Whether the client is connected now.
    pub(crate) fn reachable(&self) -> bool {
        self.reachable.load(Ordering::Relaxed)
    }

    /// The subject of a patch's jobs.
    pub(crate) fn subject(&self, id: &str) -> String {
        format!("{}.{}", self.cfg.subject, super::wire::token(id))
    }
}

/// The stream (work queue: a job leaves it when acknowledged) and the bucket (one revision
/// per key kept: the revision is what compare-and-set compares).
async fn open(
    js: &jetstream::Context,
    cfg: &ClusterSection,
) -> Result<(stream::Stream, kv::Store), ClusterError> {
    let stream = js
        .get_or_create_stream(stream::Config {
            name: cfg.stream.clone(),
            subjects: vec![format!("{}.>", cfg.subject)],
            retention: stream::RetentionPolicy::WorkQueue,
            storage: stream::StorageType::File,
            // Publishes retried after a lost acknowledgement are recognised by their id.
            duplicate_window: Duration::from_secs(120),
            ..Default::default()
        })
        .await
        .map_err(|e| ClusterError::Setup {
            what: "work-queue stream",
            reason: e.to_string(),
        })?;
    let kv = match js.get_key_value(&cfg.bucket).await {
        Ok(kv) => kv,
        Err(_) => {
            let created = js
                .create_key_value(kv::Config {
                    bucket: cfg.bucket.clone(),
                    history: 1,
                    storage: stream::StorageType::File,
                    ..Default::default()
                })
                .await;
            match created {
                Ok(kv) => kv,
                // Another process created it first.
                Err(e) => js
                    .get_key_value(&cfg.bucket)
                    .await
                    .map_err(|_| ClusterError::Setup {
                        what: "key-value bucket",
                        reason: e.to_string(),
                    })?,
            }
        }
    };
    Ok((stream, kv))
}

/// Where pipe records too big for a message wait for a worker, in the shared OUT.
pub(crate) fn spool_dir(out_dir: &std::path::Path) -> PathBuf {
    out_dir.join(".cluster").join("spool")
}

/// Where states too big for the bucket are kept, in the shared OUT.
pub(crate) fn states_dir(out_dir: &std::path::Path) -> PathBuf {
    out_dir.join(".cluster").join("states")
}

/// Unix time in ms.
pub(crate) fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}
