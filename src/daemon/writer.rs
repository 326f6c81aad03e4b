//! The writer thread: the only one that changes OUT, the state folder and the inputs
//! (quarantine, processed-file policy), so that events.ndjson has a single appender and an
//! input is never moved while a worker reads it.

use super::config::DaemonConfig;
use super::config::{ProcessedPolicy, UnsupportedPolicy};
use super::confine::Roots;
use super::event_log::repair_cut_tail;
use super::job::{JobDone, Outcome, Timings};
use super::messages::{part_id, Msg, Summary};
use super::object_store::{id_held_by_object, store_scan, ObjectScan};
use super::ops::metrics::Metrics;
use super::publish::{publish, unpublish};
use super::reload::ConfigCell;
use super::scheduler::{Arrival, Input};
use super::state::content_hash;
use super::state::{PatchState, StateStore};
use crate::io::write_atomic;
use crate::pipeline::worker::{InputOutputs, PatchOutputs};
use crossbeam_channel::{Receiver, Sender};
use serde_json::json;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Instant, SystemTime};

/// What to do with the bytes of something rejected.
pub enum Keep {
    /// A file: moved into quarantine.
    Move(PathBuf),
    /// Bytes held in memory (a pipe record): written into quarantine under this name.
    Bytes(Arc<Vec<u8>>, String),
    /// Already written into quarantine by the pipe reader (streamed, too large to hold).
    Already(PathBuf),
    /// A valid input the pipeline cannot fit: left where it is (`daemon.unsupported`).
    InPlace(PathBuf),
    Nothing,
}

impl Keep {
    /// What to keep of a rejected input: a file as `file` decides, a pipe payload's bytes
    /// in quarantine under `version`, nothing of an object folder (an object's scans stay
    /// its scans: the folder is never moved).
    fn of_input(input: &Input, version: &str, file: impl FnOnce(&Path) -> Keep) -> Keep {
        match input {
            Input::File(p) => file(p),
            Input::Inline { data, .. } => Keep::Bytes(Arc::clone(data), version.to_string()),
            Input::Object(_) => Keep::Nothing,
        }
    }
}

pub enum WriterMsg {
    Done(JobDone),
    Superseded {
        loser: Arrival,
        by: String,
    },
    Reject {
        id: String,
        label: String,
        keep: Keep,
        /// Machine-readable (`kinds::rejection_kind`).
        kind: &'static str,
        reason: String,
    },
    Event(serde_json::Value),
    /// Stopping with an inline version not fitted: write it into the watch folder, where the
    /// next start finds it.
    Spill(Arrival),
    /// Everything sent before this is handled; the thread then returns.
    Shutdown,
    /// Everything sent before this is handled: answered on the channel (a cluster worker
    /// acknowledges a job only once its outputs and events are written).
    Barrier(Sender<()>),
    /// A scan for an object from a pipe record: stored with the object's scans, then the
    /// object is refitted.
    ObjectScan(Box<ObjectScan>),
    /// An input whose version was fitted elsewhere (`watch --queue`): the processed-file
    /// policy applies to it now, inside the same roots as a local fit's.
    Processed(PathBuf, ProcessedPolicy),
}

pub struct Writer {
    pub out_dir: PathBuf,
    pub watch_dir: PathBuf,
    pub quarantine: PathBuf,
    pub store: Arc<StateStore>,
    pub metrics: Arc<Metrics>,
    pub acks: Sender<Msg>,
    pub summary: Summary,
    /// For `daemon.pipe_roots`: inputs are moved or deleted only inside the roots.
    pub cell: Arc<ConfigCell>,
    pub seen: SeenVersions,
    /// A cluster worker's name, added to its events (several processes share the log).
    pub node: Option<String>,
}

/// Superseded file versions already in the event log, kept across starts in the state
/// folder: the older versions left in the watch folder lose again at every start, and the
/// log should say so once. A line per version: patch, path, mtime in ns; lines of files that
/// are gone are dropped when the list is read, so it stays as long as the folder's listing.
pub(crate) struct SeenVersions {
    path: PathBuf,
    keys: std::collections::HashSet<String>,
}

impl SeenVersions {
    pub(crate) fn load(state_dir: &Path) -> Self {
        let path = state_dir.join("superseded.tsv");
        let keys: std::collections::HashSet<String> = std::fs::read_to_string(&path)
            .unwrap_or_default()
            .lines()
            .filter(|l| l.split('\t').nth(1).is_some_and(|p| Path::new(p).exists()))
            .map(str::to_string)
            .collect();
        let text: String = keys.iter().map(|k| format!("{k}\n")).collect();
        if let Err(e) = write_atomic(&path, text.as_bytes()) {
            tracing::warn!(error = %e, "cannot rewrite the list of superseded versions");
        }
        Self { path, keys }
    }

    /// Whether this is the first time the version is recorded (pipe records always are).
    fn first_time(&mut self, a: &Arrival) -> bool {
        use std::io::Write;
        let Input::File(file) = &a.input else {
            return true;
        };
        let nanos = a
            .key
            .time
            .duration_since(SystemTime::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let key = format!("{}\t{}\t{nanos}", a.id, file.display());
        if key.contains('\n') {
            // Cannot be kept as a line: recorded every time rather than corrupting the list.
            return true;
        }
        if !self.keys.insert(key.clone()) {
            return false;
        }
        let appended = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&self.path)
            .and_then(|mut f| f.write_all(format!("{key}\n").as_bytes()));
        if let Err(e) = appended {
            tracing::warn!(error = %e, "cannot note a superseded version");
        }
        true
    }
}

/// How a fit ended, spelled as in events (`met`, `capped`, `stalled`).
fn status_name(status: crate::fit::FitStatus) -> String {
    serde_json::to_value(status)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

fn secs(t: SystemTime) -> f64 {
    t.duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

impl Writer {
    fn event_log(&self) -> PathBuf {
        self.out_dir.join("events.ndjson")
    }

    pub fn run(mut self, inbox: Receiver<WriterMsg>) -> Summary {
        let log = self.event_log();
        match repair_cut_tail(&log) {
            Ok(Some(bytes)) => tracing::warn!(
                bytes,
                path = %log.display(),
                "the event log ended in a cut line (a kill during an append); moved it to events.ndjson.torn"
            ),
            Ok(None) => {}
            Err(e) => {
                tracing::error!(error = %e, path = %log.display(), "cannot check the event log's last line")
            }
        }
        for msg in inbox {
            match msg {
                WriterMsg::Done(done) => {
                    let id = done.arrival.id.clone();
                    let state = self.finish(done);
                    // The scheduler keeps the patch busy until here, so a newer version
                    // starts from this fit's state; the state store serves it from memory
                    // already, and its file (~2 MB for a 40k-point scan) is written while
                    // that version fits.
                    let _ = self.acks.send(Msg::Written(id.clone()));
                    if let Some(state) = state {
                        if let Err(e) = self.store.persist(&id, &state) {
                            tracing::warn!(patch = %id, error = %e, "cannot save warm-start state");
                        }
                    }
                }
                WriterMsg::Superseded { loser, by } => {
                    tracing::info!(patch = %loser.id, input = %loser.label, by = %by, "superseded");
                    self.summary.superseded += 1;
                    self.metrics.superseded.inc();
                    if !self.seen.first_time(&loser) {
                        // The same file lost to a newer one at an earlier start already.
                        continue;
                    }
                    self.event(json!({"patch": loser.id, "version": loser.version, "input": loser.label, "status": "superseded", "by": by}));
                }
                WriterMsg::Reject {
                    id,
                    label,
                    keep,
                    kind,
                    reason,
                } => self.reject(&id, &label, keep, kind, &reason),
                WriterMsg::Event(v) => self.event(v),
                WriterMsg::Spill(a) => self.spill(&a),
                WriterMsg::ObjectScan(s) => self.object_scan(&s),
                WriterMsg::Shutdown => break,
                WriterMsg::Barrier(done) => {
                    let _ = done.send(());
                }
                WriterMsg::Processed(path, policy) => self.processed_path(&path, policy),
            }
        }
        self.summary
    }

    /// Handles a finished job; returns the state to write to the store's file when the
    /// outputs of a fit were written (it is already served from memory).
    fn finish(&mut self, done: JobDone) -> Option<Arc<PatchState>> {
        let a = &done.arrival;
        let span = tracing::info_span!("patch", patch = %a.id, version = %a.version);
        let _guard = span.enter();
        let taken = match done.outcome {
            Outcome::Fitted { .. } => self.id_taken(a, &done.cfg),
            _ => None,
        };
        match done.outcome {
            Outcome::Rejected {
                kind,
                reason,
                unsupported,
                input_hash,
            } => {
                let in_place = unsupported
                    && done.cfg.daemon.unsupported == UnsupportedPolicy::Keep
                    && matches!(a.input, Input::File(_));
                if let (true, Some(hash)) = (in_place, input_hash) {
                    let noted = self
                        .store
                        .note_unsupported(&a.id, hash, done.cfg.fit_hash());
                    if let Err(e) = noted {
                        tracing::warn!(error = %e, "cannot note an unsupported input");
                    }
                }
                let keep = Keep::of_input(&a.input, &a.version, |p| {
                    if in_place {
                        Keep::InPlace(p.to_path_buf())
                    } else {
                        Keep::Move(p.to_path_buf())
                    }
                });
                self.reject(&a.id, &a.label, keep, kind, &reason);
                None
            }
            Outcome::Emptied { reason } => {
                self.emptied(a, &reason);
                None
            }
            Outcome::StillUnsupported => {
                tracing::info!(
                    input = %a.label,
                    "unchanged since it was rejected as unsupported; left in place"
                );
                self.summary.unchanged += 1;
                self.metrics.unchanged.inc();
                None
            }
            Outcome::Incomplete { reason, .. } => {
                // The scheduler loop retries these and never sends them here.
                tracing::info!(reason, "incomplete");
                None
            }
            Outcome::Unchanged { hash } => {
                let input_hash = format!("{hash:016x}");
                tracing::info!(input_hash, "unchanged since the last fit; skipped");
                self.summary.unchanged += 1;
                self.metrics.unchanged.inc();
                // Its content was fitted, so the processed-file policy applies.
                self.processed(a, done.cfg.output.processed);
                None
            }
            Outcome::Fitted { .. } if taken.is_some() => {
                let reason = taken.unwrap_or_default();
                // Not broken: left where it is (a payload is kept in quarantine) until
                // renamed.
                let keep = Keep::of_input(&a.input, &a.version, |p| Keep::InPlace(p.to_path_buf()));
                self.reject(&a.id, &a.label, keep, "id_taken", &reason);
                None
            }
            Outcome::Fitted {
                outputs,
                hash,
                rejected_scans,
            } => {
                let start = Instant::now();
                for r in rejected_scans {
                    // Left in place: moving a scan out of its folder would change the object.
                    let label = r.file.display().to_string();
                    self.reject(&a.id, &label, Keep::InPlace(r.file), r.kind, &r.reason);
                }
                let InputOutputs {
                    parts,
                    failed,
                    warm,
                } = *outputs;
                let mut written_all = true;
                for part in parts {
                    let id = part_id(&a.id, &part.suffix);
                    written_all &= self.write_part(
                        a,
                        &done.cfg,
                        &done.timings,
                        &id,
                        part.outputs,
                        hash,
                        start,
                    );
                }
                for (suffix, reason) in failed {
                    // The input as a whole is fitted (some component is); this piece is
                    // reported, not quarantined, since the input stays in use.
                    let id = part_id(&a.id, &suffix);
                    tracing::warn!(patch = %id, reason, "component not fitted");
                    self.metrics.error("component_failed");
                    self.event(json!({"patch": id, "version": a.version, "input": a.label, "status": "component_failed", "reason": reason}));
                }
                if !written_all {
                    // Keep the old state: the next start refits this input.
                    return None;
                }
                let state = self.store.remember(
                    &a.id,
                    PatchState::after_fit(
                        &a.version,
                        hash,
                        done.cfg.state_fit(matches!(a.input, Input::Object(_))),
                        warm,
                    ),
                );
                self.processed(a, done.cfg.output.processed);
                Some(state)
            }
        }
    }

    /// Writes one surface's outputs to `OUT/<id>/` and its event line; false when the
    /// outputs could not be written.
    #[allow(clippy::too_many_arguments)]
    fn write_part(
        &mut self,
        a: &Arrival,
        cfg: &DaemonConfig,
        timings: &Timings,
        id: &str,
        mut outputs: PatchOutputs,
        hash: u64,
        start: Instant,
    ) -> bool {
        let warm_start = outputs.report["warm_start"].as_bool().unwrap_or(false);
        outputs.report["patch"] = json!(id);
        outputs.report["version"] = json!(a.version);
        outputs.report["input"] = json!(a.label);
        outputs.report["input_hash"] = json!(format!("{hash:016x}"));
        let dir = self.out_dir.join(id);
        let (glb, report) = (dir.join("surface.glb"), dir.join("report.json"));
        let surface = dir.join("surface.json");
        let out = &cfg.output;
        let to_json = |v: &serde_json::Value| serde_json::to_vec_pretty(v).unwrap_or_default();
        let surface_bytes = to_json(&outputs.surface);
        // So that a reader (and the crash tests) can check that the files belong together.
        let mut hashes = json!({"surface.json": format!("{:016x}", content_hash(&surface_bytes))});
        if out.glb {
            hashes["surface.glb"] = json!(format!("{:016x}", content_hash(&outputs.glb)));
            hashes["legend.svg"] =
                json!(format!("{:016x}", content_hash(outputs.legend.as_bytes())));
        }
        if let Some(step) = &outputs.step {
            hashes["surface.stp"] = json!(format!("{:016x}", content_hash(step)));
        }
        outputs.report["output_hashes"] = hashes;
        let report_bytes = out.report.then(|| to_json(&outputs.report));
        let mut group: Vec<(&str, &[u8])> = Vec::with_capacity(4);
        if out.glb {
            group.push(("surface.glb", &outputs.glb));
            group.push(("legend.svg", outputs.legend.as_bytes()));
        }
        if let Some(step) = &outputs.step {
            group.push(("surface.stp", step));
        }
        if let Some(r) = &report_bytes {
            group.push(("report.json", r));
        }
        group.push(("surface.json", &surface_bytes));
        let written = publish(&self.out_dir, id, &group, &mut |_| true).map_err(|e| e.to_string());
        // The part of the write that a client waiting for surface.json waits for.
        let outputs_ms = start.elapsed().as_secs_f64() * 1e3;
        if let Err(e) = written {
            // The input is fine and stays where it is; the output folder is not.
            tracing::error!(patch = id, error = %e, "cannot write outputs");
            self.metrics.error("write_failed");
            self.event(json!({"patch": id, "version": a.version, "input": a.label, "status": "write_failed", "reason": e}));
            return false;
        }
        let write_ms = start.elapsed().as_secs_f64() * 1e3;
        self.summary.fitted += 1;
        self.metrics.fitted.inc();
        self.metrics.observe_fit(timings.fit_ms / 1e3);
        let latency_ms = a.detected.elapsed().as_secs_f64() * 1e3;
        let last = &outputs.report["final"];
        let error = |geometric: &str, fallback: &str| {
            last[geometric]
                .as_f64()
                .or_else(|| last[fallback].as_f64())
                .unwrap_or(f64::NAN)
        };
        tracing::info!(
            patch = id,
            status = status_name(outputs.status),
            rms = error("geometric_rms_error", "rms_error"),
            max = error("geometric_max_error", "max_error"),
            controls = outputs.report["control_points"].as_u64().unwrap_or(0),
            fit_ms = timings.fit_ms,
            latency_ms,
            warm_start,
            "fitted"
        );
        let mut paths = json!({"surface": surface});
        if out.glb {
            paths["glb"] = json!(glb);
            paths["legend"] = json!(dir.join("legend.svg"));
        }
        if out.report {
            paths["report"] = json!(report);
        }
        if outputs.step.is_some() {
            paths["step"] = json!(dir.join("surface.stp"));
        }
        let mut line = json!({
            "patch": id, "version": a.version, "input": a.label, "status": outputs.status,
            "path": outputs.report["path"],
            "errors": outputs.report["final"],
            "iterations": outputs.report["iterations"].as_array().map_or(0, |i| i.len().saturating_sub(1)),
            "warm_start": warm_start, "wall_ms": latency_ms,
            "timings": {"queued_ms": timings.queued_ms, "read_ms": timings.read_ms,
                "parse_ms": timings.parse_ms, "fit_ms": timings.fit_ms, "outputs_ms": outputs_ms, "write_ms": write_ms},
            "paths": paths,
        });
        // A surface that strays past its bound from the data (over a coarse mesh's large
        // triangles, over a hole), and pieces of the input left out of it: said where the
        // fits are followed, not only in report.json.
        let stray = &outputs.report["stray"];
        if stray["within"] == json!(false) {
            line["stray"] = stray.clone();
        }
        let dropped = &outputs.report["dropped"];
        if dropped["pieces"].as_u64().is_some_and(|p| p > 0) {
            line["dropped"] = dropped.clone();
        }
        if let Some(scans) = outputs.report["session"]["scans"].as_array() {
            // An object's update: which scans its surface is fitted to.
            let ids: Vec<&serde_json::Value> = scans.iter().map(|s| &s["id"]).collect();
            line["scans"] = json!(ids);
        }
        self.event(line);
        true
    }

    /// Whether the writer may move or delete this input: the watch folder's files and pipe
    /// path records' files are under the roots when read, but the folders may have changed.
    fn may_touch(&self, path: &Path) -> bool {
        let cfg = self.cell.get();
        let inside = Roots::new(&self.watch_dir, &cfg.daemon.pipe_roots).holds_entry(path);
        if !inside {
            tracing::warn!(input = %path.display(), "outside the watch folder and pipe roots; left in place");
        }
        inside
    }

    fn processed(&self, a: &Arrival, policy: ProcessedPolicy) {
        if let Input::File(path) = &a.input {
            self.processed_path(path, policy);
        }
    }

    fn processed_path(&self, path: &Path, policy: ProcessedPolicy) {
        if policy == ProcessedPolicy::Leave || !self.may_touch(path) {
            return;
        }
        let result = match policy {
            ProcessedPolicy::Leave => return,
            ProcessedPolicy::Delete => std::fs::remove_file(path),
            ProcessedPolicy::Move => {
                let dir = self.out_dir.join("processed");
                std::fs::create_dir_all(&dir)
                    .and_then(|_| std::fs::rename(path, free_name(&dir, path)))
            }
        };
        if let Err(e) = result {
            tracing::warn!(error = %e, input = %path.display(), policy = policy.name(), "processed-file policy failed");
        }
    }

    /// Moves or writes the bad input to quarantine with `<name>.error.json`, and records it.
    fn reject(&mut self, id: &str, label: &str, keep: Keep, kind: &'static str, reason: &str) {
        let in_place = match &keep {
            Keep::InPlace(p) => Some(p.clone()),
            _ => None,
        };
        tracing::warn!(
            patch = id,
            input = label,
            kind,
            reason,
            kept_in_place = in_place.is_some(),
            "rejected"
        );
        self.summary.rejected += 1;
        self.metrics.rejected(kind);
        let q = &self.quarantine;
        let kept: Result<Option<PathBuf>, String> = match keep {
            Keep::Nothing | Keep::InPlace(_) => Ok(None),
            Keep::Already(p) => Ok(Some(p)),
            Keep::Move(path) if !self.may_touch(&path) => Ok(None),
            Keep::Move(path) => {
                let target = free_name(q, &path);
                std::fs::create_dir_all(q)
                    .and_then(|_| std::fs::rename(&path, &target))
                    .map(|_| Some(target))
                    .map_err(|e| e.to_string())
            }
            Keep::Bytes(data, name) => {
                let target = free_name(q, Path::new(&name));
                std::fs::create_dir_all(q)
                    .map_err(|e| e.to_string())
                    .and_then(|_| write_atomic(&target, &data).map_err(|e| e.to_string()))
                    .map(|_| Some(target))
            }
        };
        let kept = kept.unwrap_or_else(|e| {
            // The input stays where it was (a file) or is lost with the process (a record):
            // say so loudly.
            tracing::error!(error = %e, input = label, "cannot quarantine");
            None
        });
        if let Some(target) = &kept {
            let name = target
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default();
            let note = json!({"input": label, "patch": id, "kind": kind, "reason": reason, "quarantined_as": target});
            let _ = write_atomic(
                &q.join(format!("{name}.error.json")),
                &serde_json::to_vec_pretty(&note).unwrap_or_default(),
            );
        }
        let mut line = json!({"patch": id, "input": label, "status": "rejected", "kind": kind, "reason": reason, "quarantined_as": kept});
        if let Some(p) = in_place {
            line["kept_in_place"] = json!(p);
        }
        self.event(line);
    }

    fn spill(&mut self, a: &Arrival) {
        let Input::Inline { data, .. } = &a.input else {
            return;
        };
        let target = self.watch_dir.join(&a.version);
        match write_atomic(&target, data) {
            Ok(()) => {
                tracing::info!(patch = %a.id, path = %target.display(), "unfitted pipe record kept in the watch folder");
                self.event(json!({"patch": a.id, "version": a.version, "input": a.label, "status": "spilled", "path": target}));
            }
            Err(e) => {
                tracing::error!(error = %e, patch = %a.id, "cannot keep an unfitted pipe record")
            }
        }
    }

    /// Why `a` may not publish under its id: an object holds it (`id_held_by_object`).
    fn id_taken(&self, a: &Arrival, cfg: &DaemonConfig) -> Option<String> {
        let objects = self.store.objects_dir();
        id_held_by_object(
            &a.id,
            &a.input,
            &self.watch_dir,
            &objects,
            cfg.object.folders,
        )
    }

    /// Keeps a pipe record's scan with its object's scans and queues the object, unless an
    /// object folder holds that id.
    fn object_scan(&mut self, s: &ObjectScan) {
        let folders = self.cell.get().object.folders;
        let objects = self.store.objects_dir();
        let held = id_held_by_object(
            &s.object,
            &Input::Object(objects.join(&s.object)),
            &self.watch_dir,
            &objects,
            folders,
        );
        let stored = match held {
            Some(reason) => Err(("id_taken", reason)),
            None => store_scan(&objects, s).map_err(|r| ("object_store_failed", r)),
        };
        match stored {
            Ok(arrival) => {
                let _ = self.acks.send(Msg::Arrivals(vec![arrival]));
            }
            Err((kind, reason)) => {
                // A scan file stays where the pipe reader found it.
                let keep = Keep::of_input(&s.scan.input, &s.scan.version, |_| Keep::Nothing);
                self.reject(&s.object, &s.scan.label, keep, kind, &reason);
            }
        }
    }

    /// An object with no scans left: its outputs and state go, and an event says so.
    fn emptied(&mut self, a: &Arrival, reason: &str) {
        match unpublish(&self.out_dir, &a.id) {
            Ok(removed) => tracing::info!(removed, reason, "object has no scans left"),
            Err(e) => {
                tracing::error!(error = %e, "cannot remove the outputs of an emptied object");
                self.metrics.error("write_failed");
            }
        }
        self.store.forget(&a.id);
        self.event(json!({"patch": a.id, "version": a.version, "input": a.label, "status": "removed", "reason": reason}));
    }

    fn event(&self, mut line: serde_json::Value) {
        use std::io::Write;
        line["time"] = json!(secs(SystemTime::now()));
        if let Some(node) = &self.node {
            line["worker"] = json!(node);
        }
        let path = self.event_log();
        let appended = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .and_then(|mut f| {
                // One write of the whole line: a crash cannot leave half a line that a
                // formatter's piecewise writes could.
                f.write_all(format!("{line}\n").as_bytes())?;
                f.sync_data()
            });
        if let Err(e) = appended {
            tracing::error!(error = %e, path = %path.display(), "cannot append event");
        }
    }
}

/// `dir/<file name of path>`, or `dir/<stem>~N.<ext>` when that is taken: a second bad file
/// of the same name must not overwrite the first one in quarantine.
fn free_name(dir: &Path, path: &Path) -> PathBuf {
    let name = path.file_name().map(PathBuf::from).unwrap_or_default();
    let first = dir.join(&name);
    if !first.exists() {
        return first;
    }
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().to_string())
        .unwrap_or_default();
    let ext = path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    (1u64..)
        .map(|n| dir.join(format!("{stem}~{n}{ext}")))
        .find(|p| !p.exists())
        .unwrap_or(first)
}
