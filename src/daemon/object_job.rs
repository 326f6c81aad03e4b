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
//! of the folder would change the object); the other scans are fitted.

use super::config::DaemonConfig;
use super::ids::{ignored, patch_id};
use super::kinds::{rejection_kind, Cause};
use super::open_files::still_changing;
use super::outcome::{Outcome, ScanRejection, Timings};
use super::scheduler::Arrival;
use super::state::{content_hash, StateStore};
use crate::io::registration::{registration_for, Registration};
use crate::io::{read_mesh_bytes_in, Format, LoadOptions};
use crate::mesh::rigid::RigidTransform;
use crate::pipeline::object_session::{ObjectSession, SessionOptions};
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
fn newest_scans(folder: &Path) -> std::io::Result<BTreeMap<String, PathBuf>> {
    let mut newest: BTreeMap<String, (SystemTime, String, PathBuf)> = BTreeMap::new();
    for entry in std::fs::read_dir(folder)?.flatten() {
        let path = entry.path();
        if ignored(&path) || !std::fs::metadata(&path).is_ok_and(|m| m.is_file()) {
            continue;
        }
        let (Some(id), Ok(mtime)) = (
            patch_id(&path),
            std::fs::metadata(&path).and_then(|m| m.modified()),
        ) else {
            continue;
        };
        let name = entry.file_name().to_string_lossy().to_string();
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
}

fn read_scan(id: &str, file: &Path, cfg: &DaemonConfig) -> ScanRead {
    let limits = &cfg.daemon;
    let rejected = |kind: &'static str, reason: String, hash| {
        ScanRead::Rejected(
            ScanRejection {
                file: file.to_path_buf(),
                kind,
                reason,
            },
            hash,
        )
    };
    let Some(format) = Format::from_path(file) else {
        return rejected(
            rejection_kind(&Cause::UnknownFormat),
            "unknown extension".into(),
            None,
        );
    };
    let meta = match std::fs::metadata(file) {
        Ok(m) if m.len() > limits.max_file_bytes => {
            let reason = format!(
                "{} bytes exceeds daemon.max_file_bytes = {}",
                m.len(),
                limits.max_file_bytes
            );
            return rejected(rejection_kind(&Cause::TooLarge), reason, None);
        }
        Ok(m) => m,
        Err(e) => {
            return rejected(
                rejection_kind(&Cause::Read(&e)),
                format!("cannot read: {e}"),
                None,
            )
        }
    };
    let bytes = match std::fs::read(file) {
        Ok(b) => b,
        Err(e) => {
            return rejected(
                rejection_kind(&Cause::Read(&e)),
                format!("cannot read: {e}"),
                None,
            )
        }
    };
    if still_changing(file, (meta.len(), meta.modified().ok()), bytes.len()) {
        return ScanRead::Changing(format!("scan {} changed while it was read", file.display()));
    }
    let hash = content_hash(&bytes);
    let label = file.display().to_string();
    let load = LoadOptions::with_limits(limits.max_file_bytes, limits.max_vertices);
    let folder = file.parent().unwrap_or(Path::new("."));
    let mesh = match read_mesh_bytes_in(&bytes, format, &label, &load, folder) {
        Ok(l) if l.mesh.positions.len() > limits.max_vertices => {
            let reason = format!(
                "{} vertices exceeds daemon.max_vertices = {}",
                l.mesh.positions.len(),
                limits.max_vertices
            );
            return rejected(rejection_kind(&Cause::TooManyVertices), reason, Some(hash));
        }
        Ok(l) => l.mesh,
        Err(e) => return rejected(rejection_kind(&Cause::Parse(&e)), e.to_string(), Some(hash)),
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
        Err(e) => rejected(
            rejection_kind(&Cause::Parse(&e)),
            format!("no usable registration: {e}"),
            Some(hash),
        ),
    }
}

/// Fits the object whose scans are the meshes of `folder` (see the module docs).
pub(crate) fn fit_object(
    a: &Arrival,
    cfg: &DaemonConfig,
    folder: &Path,
    store: &StateStore,
    t: &mut Timings,
) -> Outcome {
    let start = Instant::now();
    let listed = match newest_scans(folder) {
        Ok(l) => l,
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
    for (id, file) in &listed {
        match read_scan(id, file, cfg) {
            ScanRead::Read(scan, hash) => {
                let matrix = scan.registration.transform.to_row_major().map(f64::to_bits);
                key.push_str(&format!("{id}\t{hash:016x}\t{matrix:?}\n"));
                scans.push(*scan);
            }
            ScanRead::Rejected(r, hash) => {
                key.push_str(&format!("{id}\trejected\t{hash:?}\t{}\n", r.reason));
                rejected.push(r);
            }
            ScanRead::Changing(reason) => return Outcome::Incomplete { reason },
        }
    }
    let hash = content_hash(key.as_bytes());
    t.read_ms = start.elapsed().as_secs_f64() * 1e3;
    let config_hash = cfg.fit_hash();
    let wanted = cfg.wanted_outputs();
    let previous = store.load(&a.id);
    if previous.as_ref().is_some_and(|p| {
        p.input_hash == hash
            && p.config_hash == config_hash
            && wanted.iter().all(|w| p.outputs.contains(w))
    }) {
        return Outcome::Unchanged { hash };
    }
    if scans.is_empty() {
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
    let mut session = ObjectSession::new(SessionOptions {
        merge: cfg.object.merge.clone(),
        worker: cfg.worker_config(),
        measure_scans: cfg.object.measure_scans,
        // A fresh session per update: no merge grid or fit is kept for a next one.
        cold: true,
    });
    let staged: Vec<(&str, &TriMesh, RigidTransform)> = scans
        .iter()
        .map(|s| (s.id.as_str(), &s.mesh, s.registration.transform))
        .collect();
    let fit_start = Instant::now();
    let update = session.add_scans(&staged);
    t.fit_ms = fit_start.elapsed().as_secs_f64() * 1e3;
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
