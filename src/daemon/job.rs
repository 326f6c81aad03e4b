//! What a worker thread does with one version: read, skip when unchanged, parse, fit.
//! Writing is left to the writer thread; everything here runs under `catch_unwind`.

use super::config::DaemonConfig;
use super::kinds::{rejection_kind, Cause};
use super::scheduler::{Arrival, Input};
use super::state::{content_hash, StateStore};
use crate::io::{read_mesh_bytes, read_mesh_bytes_in, Format, LoadOptions};
use crate::pipeline::worker::{run_input, InputOutputs, WarmStart};
use std::sync::Arc;
use std::time::Instant;

pub struct Job {
    pub arrival: Arrival,
    pub cfg: Arc<DaemonConfig>,
    /// The warm start of a fit that was dropped as stale (a newer version was waiting): newer
    /// than what the state store holds.
    pub warm: Option<WarmStart>,
}

pub enum Outcome {
    Fitted {
        outputs: Box<InputOutputs>,
        hash: u64,
    },
    /// Same content and same output-shaping config as the last fit.
    Unchanged { hash: u64 },
    Rejected {
        /// `kinds::rejection_kind` of the cause.
        kind: &'static str,
        reason: String,
    },
}

#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Timings {
    /// Detection to a worker picking it up.
    pub queued_ms: f64,
    pub read_ms: f64,
    pub parse_ms: f64,
    /// Inside `run_input`.
    pub fit_ms: f64,
}

pub struct JobDone {
    pub arrival: Arrival,
    pub cfg: Arc<DaemonConfig>,
    pub outcome: Outcome,
    pub timings: Timings,
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

pub fn run_job(job: Job, store: &StateStore) -> JobDone {
    let span =
        tracing::info_span!("patch", patch = %job.arrival.id, version = %job.arrival.version);
    let _guard = span.enter();
    tracing::debug!("fitting");
    let mut timings = Timings {
        queued_ms: ms(job.arrival.detected),
        ..Timings::default()
    };
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        fit_one(&job, store, &mut timings)
    }))
    .unwrap_or_else(|payload| {
        let what = payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        Outcome::Rejected {
            kind: rejection_kind(&Cause::Panic),
            reason: format!("the fitting worker panicked: {what}"),
        }
    });
    JobDone {
        arrival: job.arrival,
        cfg: job.cfg,
        outcome,
        timings,
    }
}

fn fit_one(job: &Job, store: &StateStore, t: &mut Timings) -> Outcome {
    let a = &job.arrival;
    let limits = &job.cfg.daemon;
    let reject = |cause: Cause, reason: String| Outcome::Rejected {
        kind: rejection_kind(&cause),
        reason,
    };
    let start = Instant::now();
    let (bytes, format): (Arc<Vec<u8>>, Format) = match &a.input {
        Input::Inline { data, format } => (Arc::clone(data), *format),
        Input::File(path) => {
            let Some(format) = Format::from_path(path) else {
                return reject(
                    Cause::UnknownFormat,
                    format!("unknown extension ({})", Format::READABLE),
                );
            };
            // Refuse before reading: the limit exists so that one file cannot exhaust memory.
            match std::fs::metadata(path) {
                Ok(m) if m.len() > limits.max_file_bytes => {
                    return reject(
                        Cause::TooLarge,
                        format!(
                            "{} bytes exceeds daemon.max_file_bytes = {}",
                            m.len(),
                            limits.max_file_bytes
                        ),
                    )
                }
                Ok(_) => {}
                Err(e) => return reject(Cause::Read(&e), format!("cannot read: {e}")),
            }
            match std::fs::read(path) {
                Ok(b) => (Arc::new(b), format),
                Err(e) => return reject(Cause::Read(&e), format!("cannot read: {e}")),
            }
        }
    };
    if bytes.len() as u64 > limits.max_file_bytes {
        return reject(
            Cause::TooLarge,
            format!(
                "{} bytes exceeds daemon.max_file_bytes = {}",
                bytes.len(),
                limits.max_file_bytes
            ),
        );
    }
    let hash = content_hash(&bytes);
    t.read_ms = ms(start);
    let previous = store.load(&a.id);
    let config_hash = job.cfg.output_hash();
    if previous
        .as_ref()
        .is_some_and(|p| p.input_hash == hash && p.config_hash == config_hash)
    {
        return Outcome::Unchanged { hash };
    }
    let start = Instant::now();
    let load = LoadOptions::with_limits(limits.max_file_bytes, limits.max_vertices);
    // A file's external glTF buffers lie beside it (the reader confines them to that
    // folder); pipe payloads have no folder and must embed theirs.
    let read = match &a.input {
        Input::File(path) => match path.parent() {
            Some(folder) => read_mesh_bytes_in(&bytes, format, &a.label, &load, folder),
            None => read_mesh_bytes(&bytes, format, &a.label, &load),
        },
        Input::Inline { .. } => read_mesh_bytes(&bytes, format, &a.label, &load),
    };
    let mesh = match read {
        Ok(l) if l.mesh.positions.len() > limits.max_vertices => {
            return reject(
                Cause::TooManyVertices,
                format!(
                    "{} vertices exceeds daemon.max_vertices = {}",
                    l.mesh.positions.len(),
                    limits.max_vertices
                ),
            )
        }
        Ok(l) => l.mesh,
        Err(e) => return reject(Cause::Parse(&e), e.to_string()),
    };
    drop(bytes);
    t.parse_ms = ms(start);
    let warm = job.warm.as_ref().or(previous.as_ref().map(|p| &p.warm));
    let start = Instant::now();
    let fitted = run_input(&mesh, warm, &job.cfg.worker_config());
    t.fit_ms = ms(start);
    match fitted {
        Ok(outputs) => Outcome::Fitted {
            outputs: Box::new(outputs),
            hash,
        },
        Err(e) => reject(Cause::Pipeline(&e), e.to_string()),
    }
}
