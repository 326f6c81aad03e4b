//! The watch-folder daemon: polls a folder, waits until files are complete, coalesces
//! versions of a patch, fits the newest with a warm start from the previous fit, writes the
//! outputs atomically, appends events, and quarantines what it cannot read.

pub mod config;
pub mod state;

use crate::io::{read_mesh_bytes, write_atomic, Format, LoadOptions};
use crate::pipeline::worker::run_patch;
use config::DaemonConfig;
use serde_json::json;
use state::{content_hash, PatchState, StateStore};
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime};

#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("{path}: {reason}")]
    Folder { path: String, reason: String },
}

pub struct DaemonOptions {
    pub watch_dir: PathBuf,
    pub out_dir: PathBuf,
    pub state_dir: PathBuf,
    pub once: bool,
    pub config: DaemonConfig,
}

/// What one run did, for `--once` callers and tests.
#[derive(Debug, Default, Clone)]
pub struct Summary {
    pub fitted: usize,
    pub rejected: usize,
    pub superseded: usize,
    pub unchanged: usize,
}

/// Patch id: the file stem up to the first '@', restricted to [A-Za-z0-9_.-] so that it can
/// never escape the output folder. `None` when nothing usable is left.
pub fn patch_id(path: &Path) -> Option<String> {
    let stem = path.file_stem()?.to_str()?;
    let base = stem.split('@').next().unwrap_or(stem);
    let id: String = base
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let id = id.trim_matches('.').to_string();
    (!id.is_empty() && !id.contains("..")).then_some(id)
}

/// Names that are still being written or are not meshes.
pub fn ignored(path: &Path) -> bool {
    let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
        return true;
    };
    name.starts_with('.')
        || name.ends_with(".tmp")
        || name.ends_with(".part")
        || Format::from_path(path).is_none()
}

#[derive(Clone, Copy, PartialEq)]
struct Seen {
    size: u64,
    mtime: SystemTime,
    stable_since: Instant,
}

pub fn run(opts: &DaemonOptions, stop: &AtomicBool) -> Result<Summary, DaemonError> {
    let folder_err = |p: &Path, e: &dyn std::fmt::Display| DaemonError::Folder {
        path: p.display().to_string(),
        reason: e.to_string(),
    };
    for d in [&opts.out_dir, &opts.state_dir] {
        std::fs::create_dir_all(d).map_err(|e| folder_err(d, &e))?;
    }
    let quarantine = opts
        .config
        .output
        .quarantine_dir
        .clone()
        .unwrap_or_else(|| opts.out_dir.join("quarantine"));
    let store = StateStore::new(opts.state_dir.clone());
    let settle = Duration::from_millis(opts.config.daemon.settle_ms);
    let mut seen: HashMap<PathBuf, Seen> = HashMap::new();
    let mut done: HashSet<(PathBuf, u64, SystemTime)> = HashSet::new();
    let mut summary = Summary::default();
    tracing::info!(dir = %opts.watch_dir.display(), out = %opts.out_dir.display(), "watching");
    loop {
        let entries =
            std::fs::read_dir(&opts.watch_dir).map_err(|e| folder_err(&opts.watch_dir, &e))?;
        let now = Instant::now();
        let mut present = HashSet::new();
        let mut ready: BTreeMap<String, Vec<(SystemTime, PathBuf, u64)>> = BTreeMap::new();
        let mut pending = 0usize;
        for entry in entries.flatten() {
            let path = entry.path();
            let Ok(meta) = entry.metadata() else { continue };
            if !meta.is_file() || ignored(&path) {
                continue;
            }
            let mtime = meta.modified().unwrap_or(SystemTime::UNIX_EPOCH);
            let size = meta.len();
            present.insert(path.clone());
            if done.contains(&(path.clone(), size, mtime)) {
                continue;
            }
            let s = seen.entry(path.clone()).or_insert(Seen {
                size,
                mtime,
                stable_since: now,
            });
            if s.size != size || s.mtime != mtime {
                *s = Seen {
                    size,
                    mtime,
                    stable_since: now,
                };
            }
            if now.duration_since(s.stable_since) >= settle {
                let Some(id) = patch_id(&path) else {
                    reject(
                        &quarantine,
                        &opts.out_dir,
                        &path,
                        "",
                        "file name gives no usable patch id",
                        &mut summary,
                    );
                    done.insert((path.clone(), size, mtime));
                    continue;
                };
                ready.entry(id).or_default().push((mtime, path, size));
            } else {
                pending += 1;
            }
        }
        seen.retain(|p, _| present.contains(p));
        for (id, mut versions) in ready {
            // Newest version wins; the others are recorded and left in place.
            versions.sort();
            let Some((mtime, newest, size)) = versions.pop() else {
                continue;
            };
            for (m, p, s) in versions {
                event(
                    &opts.out_dir,
                    json!({"patch": id, "input": p.display().to_string(), "status": "superseded", "by": newest.display().to_string()}),
                );
                summary.superseded += 1;
                done.insert((p, s, m));
            }
            process(opts, &store, &quarantine, &id, &newest, &mut summary);
            done.insert((newest, size, mtime));
        }
        if stop.load(Ordering::Relaxed) || (opts.once && pending == 0) {
            break;
        }
        std::thread::sleep(Duration::from_millis(opts.config.daemon.poll_interval_ms));
    }
    tracing::info!(
        fitted = summary.fitted,
        rejected = summary.rejected,
        "stopped"
    );
    Ok(summary)
}

fn process(
    opts: &DaemonOptions,
    store: &StateStore,
    quarantine: &Path,
    id: &str,
    path: &Path,
    summary: &mut Summary,
) {
    let span = tracing::info_span!("patch", patch = id, input = %path.display());
    let _guard = span.enter();
    let start = Instant::now();
    let name = path.display().to_string();
    let bytes = match std::fs::metadata(path) {
        Ok(m) if m.len() > opts.config.daemon.max_file_bytes => {
            return reject(
                quarantine,
                &opts.out_dir,
                path,
                id,
                &format!("{} bytes exceeds daemon.max_file_bytes", m.len()),
                summary,
            );
        }
        _ => match std::fs::read(path) {
            Ok(b) => b,
            Err(e) => return reject(quarantine, &opts.out_dir, path, id, &e.to_string(), summary),
        },
    };
    let hash = content_hash(&bytes);
    let previous = store.load(id);
    if previous.as_ref().is_some_and(|p| p.input_hash == hash) {
        tracing::info!("unchanged since the last fit; skipped");
        summary.unchanged += 1;
        return;
    }
    let Some(format) = Format::from_path(path) else {
        return;
    };
    let mesh = match read_mesh_bytes(&bytes, format, &name, &LoadOptions::default()) {
        Ok(l) if l.mesh.positions.len() > opts.config.daemon.max_vertices => {
            return reject(
                quarantine,
                &opts.out_dir,
                path,
                id,
                "more vertices than daemon.max_vertices",
                summary,
            );
        }
        Ok(l) => l.mesh,
        Err(e) => return reject(quarantine, &opts.out_dir, path, id, &e.to_string(), summary),
    };
    let warm = previous.as_ref().map(|p| &p.warm);
    let cfg = opts.config.fit.clone();
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        run_patch(&mesh, warm, &cfg)
    }));
    let mut out = match result {
        Ok(Ok(o)) => o,
        Ok(Err(e)) => return reject(quarantine, &opts.out_dir, path, id, &e.to_string(), summary),
        Err(_) => {
            return reject(
                quarantine,
                &opts.out_dir,
                path,
                id,
                "the fitting worker panicked",
                summary,
            )
        }
    };
    let version = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("")
        .to_string();
    let warm_start = out.report["warm_start"].as_bool().unwrap_or(false);
    out.report["patch"] = json!(id);
    out.report["version"] = json!(version);
    out.report["input"] = json!(name);
    out.report["input_hash"] = json!(format!("{hash:016x}"));
    let dir = opts.out_dir.join(id);
    let written = std::fs::create_dir_all(&dir)
        .map_err(|e| e.to_string())
        .and_then(|_| write_atomic(&dir.join("surface.glb"), &out.glb).map_err(|e| e.to_string()))
        .and_then(|_| {
            write_atomic(
                &dir.join("report.json"),
                &serde_json::to_vec_pretty(&out.report).unwrap_or_default(),
            )
            .map_err(|e| e.to_string())
        })
        .and_then(|_| {
            write_atomic(
                &dir.join("surface.json"),
                &serde_json::to_vec_pretty(&out.surface).unwrap_or_default(),
            )
            .map_err(|e| e.to_string())
        });
    if let Err(e) = written {
        // The input is fine; the output folder is not. Leave the input in place.
        tracing::error!(error = %e, "cannot write outputs");
        return;
    }
    let state = PatchState {
        version: version.clone(),
        input_hash: hash,
        warm: out.warm.clone(),
    };
    if let Err(e) = store.save(id, &state) {
        tracing::warn!(error = %e, "cannot save warm-start state");
    }
    summary.fitted += 1;
    let wall_ms = start.elapsed().as_secs_f64() * 1e3;
    tracing::info!(status = ?out.status, wall_ms, warm_start, "fitted");
    event(
        &opts.out_dir,
        json!({
            "patch": id, "version": version, "input": name, "status": out.status,
            "errors": out.report["final"], "iterations": out.report["iterations"].as_array().map_or(0, |a| a.len().saturating_sub(1)),
            "warm_start": warm_start, "wall_ms": wall_ms,
            "paths": {"surface": dir.join("surface.json"), "glb": dir.join("surface.glb"), "report": dir.join("report.json")},
        }),
    );
}

/// Moves a bad input to quarantine with `<name>.error.json`, and records the event.
fn reject(
    quarantine: &Path,
    out: &Path,
    path: &Path,
    id: &str,
    reason: &str,
    summary: &mut Summary,
) {
    tracing::warn!(input = %path.display(), reason, "rejected");
    summary.rejected += 1;
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    let target = quarantine.join(&name);
    let moved = std::fs::create_dir_all(quarantine)
        .and_then(|_| std::fs::rename(path, &target))
        .is_ok();
    let note = json!({"input": path.display().to_string(), "patch": id, "reason": reason, "quarantined_as": moved.then(|| target.display().to_string())});
    let _ = write_atomic(
        &quarantine.join(format!("{name}.error.json")),
        &serde_json::to_vec_pretty(&note).unwrap_or_default(),
    );
    event(
        out,
        json!({"patch": id, "input": path.display().to_string(), "status": "rejected", "reason": reason}),
    );
}

fn event(out: &Path, mut line: serde_json::Value) {
    use std::io::Write;
    line["time"] = json!(SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0));
    let path = out.join("events.ndjson");
    let appended = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| {
            writeln!(f, "{line}")?;
            f.sync_data()
        });
    if let Err(e) = appended {
        tracing::error!(error = %e, path = %path.display(), "cannot append event");
    }
}
