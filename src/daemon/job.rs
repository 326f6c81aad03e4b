//! What a worker thread does with one version: read, skip when unchanged, parse, fit.
//! Writing is left to the writer thread; everything here runs under `catch_unwind`.

use super::config::DaemonConfig;
use super::kinds::{rejection_kind, Cause};
use super::mesh_file::{parse_mesh, read_file_bytes, too_large, Refused};
use super::object_job::fit_object;
use super::object_sessions::ObjectSessions;
pub(crate) use super::open_files::still_changing;
pub(crate) use super::outcome::{Outcome, Timings};
use super::scheduler::{Arrival, Input};
use super::state::{content_hash, StateStore};
use crate::io::Format;
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

/// `sessions`: the object sessions kept between updates (`object_sessions`).
pub(crate) fn run_job(job: Job, store: &StateStore, sessions: &ObjectSessions) -> JobDone {
    let span =
        tracing::info_span!("patch", patch = %job.arrival.id, version = %job.arrival.version);
    let _guard = span.enter();
    let mut timings = Timings {
        queued_ms: ms(job.arrival.detected),
        ..Timings::default()
    };
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let mut outcome = fit_one(&job, (store, sessions), &mut timings);
        if job.cfg.output.step {
            super::cad::add_step_files(&mut outcome, job.cfg.output.step_units);
        }
        outcome
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

fn fit_one(
    job: &Job,
    (store, sessions): (&StateStore, &ObjectSessions),
    t: &mut Timings,
) -> Outcome {
    let a = &job.arrival;
    let limits = &job.cfg.daemon;
    let refused = |r: Refused, input_hash: Option<u64>| Outcome::Rejected {
        kind: r.kind,
        reason: r.reason,
        unsupported: r.unsupported,
        input_hash,
    };
    let start = Instant::now();
    let mut read_stamp = None;
    let (bytes, format): (Arc<Vec<u8>>, Format) = match &a.input {
        Input::Inline { data, format } => (Arc::clone(data), *format),
        Input::Object(folder) => {
            return fit_object(&job.arrival, &job.cfg, folder, (store, sessions), t)
        }
        Input::File(path) => match read_file_bytes(path, limits) {
            Ok(read) => {
                read_stamp = Some(read.stamp);
                (Arc::new(read.bytes), read.format)
            }
            Err(r) => return refused(r, None),
        },
    };
    if bytes.len() as u64 > limits.max_file_bytes {
        return refused(too_large(bytes.len() as u64, limits), None);
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
    let start = Instant::now();
    let folder = match &a.input {
        Input::File(path) => path.parent(),
        Input::Inline { .. } | Input::Object(_) => None,
    };
    let read = parse_mesh(&bytes, format, &a.label, limits, folder);
    // A file that changed while it was read is a stale (often cut) copy, whether or not it
    // parsed (a cut OBJ can end on a whole line): read it again once it settles.
    if let (Input::File(path), Some(before)) = (&a.input, read_stamp) {
        if still_changing(path, before, bytes.len()) {
            let parsed = match &read {
                Ok(_) => "it parsed, but may be cut".to_string(),
                Err(r) => r.reason.clone(),
            };
            return Outcome::Incomplete {
                reason: format!("changed while it was read ({parsed}); read again once it settles"),
                wait: None,
            };
        }
    }
    if let (Input::File(path), Err(r)) = (&a.input, &read) {
        if let Some(incomplete) = r.awaiting_buffer(path) {
            return incomplete;
        }
    }
    let mesh = match read {
        Ok(mesh) => mesh,
        // A mesh the daemon will not fit is noted by its hash, so that it is not read again
        // until it or the config changes; a broken one is quarantined.
        Err(r) if r.unsupported => return refused(r, Some(hash)),
        Err(r) => return refused(r, None),
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
        Err(e) => Outcome::Rejected {
            kind: rejection_kind(&Cause::Pipeline(&e)),
            reason: e.to_string(),
            unsupported: true,
            input_hash: Some(hash),
        },
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
