//! What a worker thread does with one version: read, skip when unchanged, parse, fit.
//! Writing is left to the writer thread; everything here runs under `catch_unwind`.

use super::config::DaemonConfig;
use super::kinds::{rejection_kind, Cause};
use super::object_job::fit_object;
pub(crate) use super::open_files::still_changing;
pub(crate) use super::outcome::{Outcome, Timings};
use super::scheduler::{Arrival, Input};
use super::state::{content_hash, StateStore};
use crate::io::{read_mesh_bytes, read_mesh_bytes_in, Format, LoadOptions};
use crate::pipeline::worker::{run_input, WarmStart};
use std::sync::Arc;
use std::time::Instant;

pub(crate) struct Job {
    pub arrival: Arrival,
    pub cfg: Arc<DaemonConfig>,
    /// The warm start of a fit that was dropped as stale (a newer version was waiting): newer
    /// than what the state store holds.
    pub warm: Option<WarmStart>,
}

pub(crate) struct JobDone {
    pub arrival: Arrival,
    pub cfg: Arc<DaemonConfig>,
    pub outcome: Outcome,
    pub timings: Timings,
}

fn ms(since: Instant) -> f64 {
    since.elapsed().as_secs_f64() * 1e3
}

pub(crate) fn run_job(job: Job, store: &StateStore) -> JobDone {
    let span =
        tracing::info_span!("patch", patch = %job.arrival.id, version = %job.arrival.version);
    let _guard = span.enter();
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
            unsupported: false,
            input_hash: None,
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
        unsupported: matches!(cause, Cause::Pipeline(_) | Cause::TooManyVertices),
        kind: rejection_kind(&cause),
        reason,
        input_hash: None,
    };
    let start = Instant::now();
    let mut read_stamp = None;
    let (bytes, format): (Arc<Vec<u8>>, Format) = match &a.input {
        Input::Inline { data, format } => (Arc::clone(data), *format),
        Input::Object(folder) => return fit_object(&job.arrival, &job.cfg, folder, store, t),
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
                Ok(m) => read_stamp = Some((m.len(), m.modified().ok())),
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
    let config_hash = job.cfg.fit_hash();
    let wanted = job.cfg.wanted_outputs();
    if previous.as_ref().is_some_and(|p| {
        p.input_hash == hash
            && p.config_hash == config_hash
            && wanted.iter().all(|w| p.outputs.contains(w))
    }) {
        return Outcome::Unchanged { hash };
    }
    if store.still_unsupported(&a.id, hash, config_hash) {
        return Outcome::StillUnsupported;
    }
    let hashed = |o: Outcome| match o {
        Outcome::Rejected {
            kind,
            reason,
            unsupported,
            ..
        } => Outcome::Rejected {
            kind,
            reason,
            unsupported,
            input_hash: Some(hash),
        },
        other => other,
    };
    let start = Instant::now();
    let load = LoadOptions::with_limits(limits.max_file_bytes, limits.max_vertices);
    // A file's external glTF buffers lie beside it (the reader confines them to that
    // folder); pipe payloads have no folder and must embed theirs.
    let read = match &a.input {
        Input::File(path) => match path.parent() {
            Some(folder) => read_mesh_bytes_in(&bytes, format, &a.label, &load, folder),
            None => read_mesh_bytes(&bytes, format, &a.label, &load),
        },
        Input::Inline { .. } | Input::Object(_) => read_mesh_bytes(&bytes, format, &a.label, &load),
    };
    // A file that changed while it was read is a stale (often cut) copy, whether or not it
    // parsed (a cut OBJ can end on a whole line): read it again once it settles.
    if let (Input::File(path), Some(before)) = (&a.input, read_stamp) {
        if still_changing(path, before, bytes.len()) {
            let parsed = match &read {
                Ok(_) => "it parsed, but may be cut".to_string(),
                Err(e) => e.to_string(),
            };
            return Outcome::Incomplete {
                reason: format!("changed while it was read ({parsed}); read again once it settles"),
            };
        }
    }
    let mesh = match read {
        Ok(l) if l.mesh.positions.len() > limits.max_vertices => {
            return hashed(reject(
                Cause::TooManyVertices,
                format!(
                    "{} vertices exceeds daemon.max_vertices = {}",
                    l.mesh.positions.len(),
                    limits.max_vertices
                ),
            ))
        }
        Ok(l) => l.mesh,
        Err(e) => return reject(Cause::Parse(&e), e.to_string()),
    };
    drop(bytes);
    t.parse_ms = ms(start);
    tracing::info!(
        vertices = mesh.positions.len(),
        triangles = mesh.triangles.len(),
        "fitting"
    );
    let warm = job.warm.as_ref().or(previous.as_ref().map(|p| &p.warm));
    let start = Instant::now();
    let fitted = run_input(&mesh, warm, &job.cfg.worker_config());
    t.fit_ms = ms(start);
    match fitted {
        Ok(outputs) => Outcome::Fitted {
            outputs: Box::new(outputs),
            hash,
            rejected_scans: Vec::new(),
        },
        Err(e) => hashed(reject(Cause::Pipeline(&e), e.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_that_grew_or_went_since_the_read_is_still_changing() {
        let dir = tempfile::tempdir().expect("tmp");
        let path = dir.path().join("p.ply");
        std::fs::write(&path, b"ply\nformat ascii 1.0\n").expect("write");
        let m = std::fs::metadata(&path).expect("stat");
        let before = (m.len(), m.modified().ok());
        let read = std::fs::read(&path).expect("read").len();
        assert!(!still_changing(&path, before, read));
        // Read short of what the stat said: the read raced a writer.
        assert!(still_changing(&path, before, read - 1));
        let mut f = std::fs::OpenOptions::new()
            .append(true)
            .open(&path)
            .expect("open");
        std::io::Write::write_all(&mut f, b"element vertex 3\n").expect("append");
        assert!(still_changing(&path, before, read));
        std::fs::remove_file(&path).expect("remove");
        assert!(still_changing(&path, before, read));
    }
}
