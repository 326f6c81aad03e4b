//! What a worker does with an object folder (`[object] folders`): every mesh in the folder
//! is a registered scan of one object (its file stem up to `@` is the scan id, the newest
//! version of each id counts), registered by `io::registration` (a sidecar `.xf`, a `.conf`
//! of the folder naming the file, else the identity). The scans are merged and fitted by a
//! fresh `ObjectSession`.
//!
//! Each update reads the folder as it is and fits the merge of all its scans cold, so the
//! surface is a function of the folder's scans and the config alone: a restarted daemon
//! resumes an object by reading its folder again (when nothing changed the stored content
//! hash says so, and nothing is refitted), and the order in which scans arrived or the
//! daemon was stopped cannot matter. A warm start would save little: every new view
//! changes the object's coverage, and `ObjectSession` refits cold then anyway.
//!
//! A scan that cannot be read, parsed or registered (a `.conf` naming it with bad numbers
//! is an error, never the identity) is rejected alone and left where it is (moving it out
//! of the folder would change the object); the other scans are fitted. A scan still being
//! written (a process holds it open for writing) is not read: the watcher
//! queues the object again once it hands that file on. When no scan is left at all (all
//! deleted, or the folder gone), the object's outputs and state are removed
//! (`Outcome::Emptied`): they would describe data that no longer exists.

use super::config::DaemonConfig;
use super::ids::{ignored, patch_id};
use super::kinds::{rejection_kind, Cause};
use super::mesh_file::{parse_mesh, read_file_bytes, Refused};
use super::object_sessions::{scan_key, step, KeptSession, ObjectSessions, ScanKey, SessionStep};
use super::open_files::{open_for_writing, still_changing};
use super::outcome::{Outcome, ScanRejection, Timings};
use super::scheduler::Arrival;
use super::state::{content_hash, StateStore};
use crate::io::registration::{registration_for, Registration};
use crate::mesh::rigid::RigidTransform;
use crate::pipeline::object_session::{ObjectSession, SessionError, SessionOptions, SessionUpdate};
use crate::pipeline::worker::{InputOutputs, PartOutputs};
use crate::TriMesh;
use serde_json::json;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

/// A scan read, parsed and registered.
struct ReadScan {
    id: String,
    file: PathBuf,
    mesh: TriMesh,
    registration: Registration,
}

/// The newest version of every scan id in `folder`: (mtime, name) decides, as for patches.
/// A file still being written is no scan yet, as the watcher would not have handed it on:
/// a process holds it open for writing. It is left out (an older version of its id
/// counts), and its object is queued again when the watcher takes it after its close. (An
/// age rule would contradict the watcher, which takes a file at its close without waiting.)
fn newest_scans(folder: &Path) -> std::io::Result<BTreeMap<String, PathBuf>> {
    let folder = std::fs::canonicalize(folder)?;
    let mut files = Vec::new();
    for entry in std::fs::read_dir(&folder)?.flatten() {
        let path = entry.path();
        let Ok(meta) = std::fs::metadata(&path) else {
            continue;
        };
        if ignored(&path) || !meta.is_file() {
            continue;
        }
        if let (Some(id), Ok(mtime)) = (patch_id(&path), meta.modified()) {
            let name = entry.file_name().to_string_lossy().to_string();
            files.push((id, mtime, name, path));
        }
    }
    let paths: Vec<&Path> = files.iter().map(|f| f.3.as_path()).collect();
    let writers = open_for_writing(&paths);
    let mut newest: BTreeMap<String, (SystemTime, String, PathBuf)> = BTreeMap::new();
    for (id, mtime, name, path) in files {
        if writers.writing(&path) == Some(true) {
            tracing::info!(scan = %path.display(), "still being written; left out of this update");
            continue;
        }
        let newer = newest
            .get(&id)
            .is_none_or(|(t, n, _)| (mtime, &name) > (*t, n));
        if newer {
            newest.insert(id, (mtime, name, path));
        }
    }
    Ok(newest.into_iter().map(|(id, (_, _, p))| (id, p)).collect())
}

/// What reading one scan file gave.
enum ScanRead {
    Read(Box<ReadScan>, u64),
    Rejected(ScanRejection, Option<u64>),
    /// Changed while it was read: the object is read again once it settles.
    Changing(String),
    /// A glTF scan whose buffer may still be on its way (`Refused::awaiting_buffer`): the
    /// object waits for it as a patch would.
    Waiting(Outcome),
}

/// Reads, parses and registers one scan through the daemon's checked read (`mesh_file`),
/// the same that patches go through.
fn read_scan(id: &str, file: &Path, cfg: &DaemonConfig) -> ScanRead {
    let limits = &cfg.daemon;
    let rejected = |r: Refused, hash| {
        ScanRead::Rejected(
            ScanRejection {
                file: file.to_path_buf(),
                kind: r.kind,
                reason: r.reason,
            },
            hash,
        )
    };
    let read = match read_file_bytes(file, limits) {
        Ok(read) => read,
        Err(r) => return rejected(r, None),
    };
    let hash = content_hash(&read.bytes);
    let label = file.display().to_string();
    let parsed = parse_mesh(&read.bytes, read.format, &label, limits, file.parent());
    if still_changing(file, read.stamp, read.bytes.len()) {
        return ScanRead::Changing(format!("scan {} changed while it was read", file.display()));
    }
    let mesh = match parsed {
        Ok(mesh) => mesh,
        Err(r) => match r.awaiting_buffer(file) {
            Some(incomplete) => return ScanRead::Waiting(incomplete),
            None => return rejected(r, Some(hash)),
        },
    };
    match registration_for(file, id) {
        Ok(registration) => ScanRead::Read(
            Box::new(ReadScan {
                id: id.to_string(),
                file: file.to_path_buf(),
                mesh,
                registration,
            }),
            hash,
        ),
        Err(e) => ScanRead::Rejected(
            ScanRejection {
                file: file.to_path_buf(),
                kind: rejection_kind(&Cause::Parse(&e)),
                reason: format!("no usable registration: {e}"),
            },
            Some(hash),
        ),
    }
}

/// A scan an update left out, and why.
struct ScanLeftOut {
    id: String,
    kind: &'static str,
    reason: String,
}

/// The object `id`'s update to `scans` (with their keys): one update of its kept session
/// when one is kept (under the same config), else a fresh session of all of them; the
/// session is kept for the next update when it succeeds. A scan the session finds no
/// surface in (only degenerate faces, a point cloud that is no view's height field) is
/// left out and returned in `left_out`, so that it is rejected alone and the others are
/// fitted (a failed staging leaves the session as it was).
fn update_session(
    id: &str,
    cfg: &DaemonConfig,
    (scans, mut keys): (&[ReadScan], BTreeMap<String, ScanKey>),
    config_hash: u64,
    sessions: &ObjectSessions,
    left_out: &mut Vec<ScanLeftOut>,
) -> Result<SessionUpdate, SessionError> {
    let fresh = || {
        ObjectSession::new(SessionOptions {
            merge: cfg.object.merge.clone(),
            worker: cfg.worker_config(),
            measure_scans: cfg.object.measure_scans,
            // Without kept sessions no merge grid or fit is kept for a next update.
            cold: !sessions.enabled(),
        })
    };
    let staged = |only: &[String]| -> Vec<(&str, &TriMesh, RigidTransform)> {
        scans
            .iter()
            .filter(|s| only.contains(&s.id))
            .map(|s| (s.id.as_str(), &s.mesh, s.registration.transform))
            .collect()
    };
    // A fresh session is made by the `Fresh` step only, never up front to be replaced.
    let (mut session, kept_scans) = match sessions.take(id, config_hash) {
        Some(kept) => (Some(kept.session), Some(kept.scans)),
        None => (None, None),
    };
    let update = loop {
        let step = match &kept_scans {
            Some(kept) => step(kept, &keys),
            None => SessionStep::Fresh,
        };
        tracing::debug!(object = %id, ?step, "object update");
        let update = match (&step, session.as_mut()) {
            (SessionStep::Update { added, removed }, Some(kept)) => {
                let removed: Vec<&str> = removed.iter().map(String::as_str).collect();
                kept.change_scans(&staged(added), &removed)
            }
            _ => {
                let all: Vec<String> = keys.keys().cloned().collect();
                session.insert(fresh()).add_scans(&staged(&all))
            }
        };
        let refused = match &update {
            Err(
                e @ (SessionError::EmptyScan { id: scan }
                | SessionError::PointCloud { id: scan, .. }),
            ) if keys.len() > 1 && keys.contains_key(scan) => Some(ScanLeftOut {
                id: scan.clone(),
                kind: e.kind(),
                reason: e.to_string(),
            }),
            _ => None,
        };
        match refused {
            Some(scan) => {
                keys.remove(&scan.id);
                left_out.push(scan);
            }
            None => break update,
        }
    };
    if let (Ok(_), Some(session)) = (&update, session) {
        let kept = KeptSession {
            session,
            scans: keys,
            config_hash,
        };
        sessions.put(id, kept);
    }
    update
}

/// Fits the object whose scans are the meshes of `folder` (see the module docs).
pub(crate) fn fit_object(
    a: &Arrival,
    cfg: &DaemonConfig,
    folder: &Path,
    (store, sessions): (&StateStore, &ObjectSessions),
    t: &mut Timings,
) -> Outcome {
    let start = Instant::now();
    let listed = match newest_scans(folder) {
        Ok(l) => l,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound && store.load(&a.id).is_some() => {
            return Outcome::Emptied {
                reason: "the object folder is gone".into(),
            }
        }
        Err(e) => {
            return Outcome::Rejected {
                kind: rejection_kind(&Cause::Read(&e)),
                reason: format!("cannot list the object folder: {e}"),
                unsupported: false,
                input_hash: None,
            }
        }
    };
    let mut scans = Vec::new();
    let mut rejected = Vec::new();
    // What the fit depends on, in scan-id order: each scan's bytes and transform.
    let mut key = String::new();
    let mut keys = BTreeMap::new();
    for (id, file) in &listed {
        match read_scan(id, file, cfg) {
            ScanRead::Read(scan, hash) => {
                let held = scan_key(hash, &scan.registration.transform);
                key.push_str(&format!("{id}\t{hash:016x}\t{:?}\n", held.1));
                keys.insert(id.clone(), held);
                scans.push(*scan);
            }
            ScanRead::Rejected(r, hash) => {
                key.push_str(&format!("{id}\trejected\t{hash:?}\t{}\n", r.reason));
                rejected.push(r);
            }
            ScanRead::Changing(reason) => return Outcome::Incomplete { reason, wait: None },
            ScanRead::Waiting(incomplete) => return incomplete,
        }
    }
    let hash = content_hash(key.as_bytes());
    t.read_ms = start.elapsed().as_secs_f64() * 1e3;
    let config_hash = cfg.object_fit_hash();
    let wanted = cfg.wanted_outputs();
    let previous = store.load(&a.id);
    if previous.as_ref().is_some_and(|p| {
        p.input_hash == hash
            && p.config_hash == config_hash
            && wanted.iter().all(|w| p.outputs.contains(w))
    }) {
        return Outcome::Unchanged { hash };
    }
    if scans.is_empty() && rejected.is_empty() && previous.is_some() {
        sessions.forget(&a.id);
        return Outcome::Emptied {
            reason: "no scan left in the object folder".into(),
        };
    }
    if scans.is_empty() {
        // Only broken scans: like a broken new version of a patch, they are reported and
        // the surface of the last good scans stays.
        let reason = match rejected.first() {
            Some(r) => format!(
                "no usable scan in the object folder (first: {}: {})",
                r.file.display(),
                r.reason
            ),
            None => "no scan in the object folder".to_string(),
        };
        return Outcome::Rejected {
            kind: "no_scans",
            reason,
            unsupported: false,
            input_hash: Some(hash),
        };
    }
    let fit_start = Instant::now();
    let mut left_out = Vec::new();
    let update = update_session(
        &a.id,
        cfg,
        (&scans, keys),
        config_hash,
        sessions,
        &mut left_out,
    );
    t.fit_ms = fit_start.elapsed().as_secs_f64() * 1e3;
    for scan in left_out {
        if let Some(k) = scans.iter().position(|s| s.id == scan.id) {
            rejected.push(ScanRejection {
                file: scans.remove(k).file,
                kind: scan.kind,
                reason: format!("left out of the object: {}", scan.reason),
            });
        }
    }
    let mut update = match update {
        Ok(u) => u,
        Err(e) => {
            return Outcome::Rejected {
                kind: e.kind(),
                reason: e.to_string(),
                unsupported: true,
                input_hash: Some(hash),
            }
        }
    };
    let report = &mut update.outputs.report;
    report["session"]["files"] = json!(scans
        .iter()
        .map(|s| json!({"id": s.id, "file": s.file, "registration": s.registration.source}))
        .collect::<Vec<_>>());
    report["session"]["rejected_scans"] = json!(rejected
        .iter()
        .map(|r| json!({"file": r.file, "kind": r.kind, "reason": r.reason}))
        .collect::<Vec<_>>());
    let warm = update.outputs.warm.clone();
    Outcome::Fitted {
        outputs: Box::new(InputOutputs {
            parts: vec![PartOutputs {
                suffix: String::new(),
                outputs: update.outputs,
            }],
            failed: Vec::new(),
            warm,
        }),
        hash,
        rejected_scans: rejected,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn write_aged(path: &Path, age: Duration) {
        std::fs::write(path, b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").expect("write");
        let file = std::fs::File::options()
            .write(true)
            .open(path)
            .expect("open");
        file.set_modified(SystemTime::now() - age).expect("mtime");
    }

    /// A scan held open for writing is no scan of this update: the older version of its
    /// id counts instead, until the writer closes it.
    #[test]
    fn scans_still_being_written_are_left_out_for_their_older_version() {
        let dir = tempfile::tempdir().expect("tmp");
        let folder = std::fs::canonicalize(dir.path()).expect("canonical");
        write_aged(&folder.join("a@1.off"), Duration::from_secs(60));
        write_aged(&folder.join("a@2.off"), Duration::from_secs(1));
        write_aged(&folder.join("b.off"), Duration::from_secs(60));
        let mut child = std::process::Command::new("sh")
            .arg("-c")
            .arg(format!(
                "exec 3>>'{}'; exec sleep 30",
                folder.join("a@2.off").display()
            ))
            .spawn()
            .expect("sh runs");
        let deadline = Instant::now() + Duration::from_secs(20);
        let mut listed = newest_scans(&folder).expect("listed");
        while listed.get("a") != Some(&folder.join("a@1.off")) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
            listed = newest_scans(&folder).expect("listed");
        }
        let _ = child.kill();
        let _ = child.wait();
        assert_eq!(
            listed.get("a"),
            Some(&folder.join("a@1.off")),
            "a@2 held open"
        );
        assert_eq!(listed.get("b"), Some(&folder.join("b.off")));
        let closed = newest_scans(&folder).expect("listed");
        assert_eq!(closed.get("a"), Some(&folder.join("a@2.off")));
    }
}
