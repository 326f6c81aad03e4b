//! The pipe source: newline-delimited JSON records on stdin or a FIFO, each
//! `{"patch": ID, "path": FILE}` or `{"patch": ID, "format": FMT, "bytes": N}` followed by
//! exactly N raw bytes. Either may add `"object": OBJ` (the record is scan PATCH of object
//! OBJ, kept in the state folder's `objects/` and merged with the object's other scans) and
//! then `"transform"`: 16 numbers, the scan's 4x4 rigid motion into the object's frame,
//! row by row. A bad record is reported and skipped while keeping the framing when
//! the header says how many bytes follow; bytes that came with a bad record are quarantined.
//! A length that cannot be read loses the framing: everything up to the next line that is a
//! record header goes, as one rejection, into one quarantine file.
//!
//! Memory: payloads read but not yet fitted are bounded by `daemon.max_file_bytes` (plus the
//! record being read); while the budget is full the reader stops reading, and the writer on
//! the other end of the pipe blocks.

use super::confine::Roots;
use super::kinds::{rejection_kind, Cause, RecordFault};
use super::messages::{sanitize_id, Msg, Source};
use super::object_store::{record_object, ObjectScan, RecordObject};
use super::reload::ConfigCell;
use super::scheduler::{Arrival, Input, VersionKey};
use super::writer::{Keep, WriterMsg};
use crate::io::Format;
use crossbeam_channel::Sender;
use std::cell::RefCell;
use std::io::{BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant, SystemTime};

/// Longer header lines are not records (a writer that forgot the framing sent raw bytes).
const MAX_LINE: usize = 64 * 1024;

/// Payload bytes are read in pieces of this size, so that a stop sees how far a record got.
const READ_PIECE: usize = 1 << 20;

/// Where pipe records come from.
#[derive(Clone, Debug)]
pub enum PipeSpec {
    /// The daemon's standard input; its EOF ends the daemon once the work is done.
    Stdin,
    /// A named pipe, opened again after each writer closes it.
    Fifo(PathBuf),
}

/// A record whose payload is being read: reported if the daemon stops before it is whole.
#[derive(Clone, Debug)]
pub(crate) struct Partial {
    pub(crate) id: String,
    pub(crate) label: String,
    pub(crate) got: u64,
    pub(crate) want: u64,
}

pub(crate) struct PipeSource {
    pub(crate) spec: PipeSpec,
    pub(crate) cell: Arc<ConfigCell>,
    pub(crate) once: bool,
    pub(crate) tx: Sender<Msg>,
    pub(crate) writer: Sender<WriterMsg>,
    pub(crate) stop: Arc<AtomicBool>,
    pub(crate) quarantine: PathBuf,
    /// Canonical; the default root of path records.
    pub(crate) watch_dir: PathBuf,
    pub(crate) partial: Arc<Mutex<Option<Partial>>>,
    /// Payloads handed on and possibly still held (by the scheduler, a worker or the
    /// writer): what the memory budget counts. Dead entries are dropped as they are seen.
    pub(crate) held: RefCell<Vec<Weak<Vec<u8>>>>,
}

/// What the reader does after a record.
enum After {
    Next,
    /// The stream ended inside the record.
    Ended,
    /// Resynchronising found this header line: it is the next record.
    Header(Vec<u8>),
}

/// A parsed header and what is already wrong with it.
struct Header {
    json: serde_json::Value,
    id: String,
    /// Kind and reason.
    problem: Option<(&'static str, String)>,
    stamp: String,
    /// `"object"` (sanitised) and its `"transform"`, when the record is a scan of one.
    object: RecordObject,
}

enum Line {
    Eof,
    Text(Vec<u8>),
    TooLong,
}

/// One header line, read without ever holding more than `MAX_LINE` bytes of it.
fn read_line(r: &mut impl BufRead) -> std::io::Result<Line> {
    let mut line = Vec::new();
    let (mut any, mut too_long) = (false, false);
    loop {
        let buf = match r.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if buf.is_empty() {
            return Ok(match (any, too_long) {
                (false, _) => Line::Eof,
                (true, true) => Line::TooLong,
                (true, false) => Line::Text(line),
            });
        }
        any = true;
        let (chunk, used, done) = match buf.iter().position(|&b| b == b'\n') {
            Some(i) => (&buf[..i], i + 1, true),
            None => (buf, buf.len(), false),
        };
        if line.len() + chunk.len() > MAX_LINE {
            too_long = true;
        } else {
            line.extend_from_slice(chunk);
        }
        r.consume(used);
        if done {
            return Ok(if too_long {
                Line::TooLong
            } else {
                Line::Text(line)
            });
        }
    }
}

fn unix_ms() -> u128 {
    SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis())
}

impl PipeSource {
    pub(crate) fn run(self) {
        let name = match &self.spec {
            PipeSpec::Stdin => "stdin".to_string(),
            PipeSpec::Fifo(p) => p.display().to_string(),
        };
        let mut record = 0u64;
        match &self.spec {
            PipeSpec::Stdin => {
                let mut r = std::io::stdin().lock();
                self.records(&mut r, &name, &mut record);
            }
            PipeSpec::Fifo(path) => loop {
                // Opening blocks until a writer opens its end; EOF means the writer closed,
                // and the next writer needs the FIFO opened again.
                match std::fs::File::open(path) {
                    Ok(f) => {
                        let mut r = std::io::BufReader::with_capacity(1 << 16, f);
                        self.records(&mut r, &name, &mut record);
                    }
                    Err(e) => {
                        tracing::error!(error = %e, pipe = %name, "cannot open the pipe; retrying");
                        std::thread::sleep(Duration::from_secs(1));
                    }
                }
                if self.once || self.stop.load(Ordering::Relaxed) {
                    break;
                }
            },
        }
        tracing::info!(pipe = %name, records = record, "pipe ended");
        let _ = self.tx.send(Msg::SourceDone(match self.spec {
            PipeSpec::Stdin => Source::Stdin,
            PipeSpec::Fifo(_) => Source::Fifo,
        }));
    }

    /// Reads records until EOF (or a read error, which ends this opening of the pipe).
    pub(crate) fn records(&self, r: &mut impl BufRead, name: &str, record: &mut u64) {
        let mut found: Option<Vec<u8>> = None;
        while !self.stop.load(Ordering::Relaxed) {
            let line = match found.take() {
                Some(header) => Line::Text(header),
                None => match read_line(r) {
                    Ok(l) => l,
                    Err(e) => {
                        tracing::error!(error = %e, pipe = name, "pipe read failed");
                        return;
                    }
                },
            };
            *record += 1;
            let label = format!("pipe:{name}#{record}");
            let text = match line {
                Line::Eof => {
                    *record -= 1;
                    return;
                }
                Line::TooLong => {
                    let reason = format!(
                        "header line longer than {MAX_LINE} bytes; skipped to the next newline"
                    );
                    self.reject_record("", &label, Keep::Nothing, RecordFault::LineTooLong, reason);
                    continue;
                }
                Line::Text(t) if t.iter().all(|b| b.is_ascii_whitespace()) => {
                    *record -= 1;
                    continue;
                }
                Line::Text(t) => t,
            };
            match self.record(r, &text, &label, *record) {
                After::Next => {}
                After::Ended => return,
                After::Header(h) => found = Some(h),
            }
        }
    }

    /// Handles one record.
    fn record(&self, r: &mut impl BufRead, text: &[u8], label: &str, seq: u64) -> After {
        let Some(header) = self.header(text, label, seq) else {
            return After::Next;
        };
        if header.json.get("bytes").is_some() {
            self.inline_record(r, text, header, label, seq)
        } else {
            self.path_record(text, header, label, seq);
            After::Next
        }
    }

    /// Parses the header line and finds what is wrong with its id and keys; `None` when it
    /// is not a JSON object at all (rejected here).
    fn header(&self, text: &[u8], label: &str, seq: u64) -> Option<Header> {
        let stamp = format!("{}-{seq}", unix_ms());
        let kept = || Keep::Bytes(Arc::new(text.to_vec()), format!("pipe-{stamp}.record"));
        let json: serde_json::Value = match serde_json::from_slice(text) {
            Ok(v @ serde_json::Value::Object(_)) => v,
            Ok(_) => {
                let reason = "record is not a JSON object".into();
                self.reject_record("", label, kept(), RecordFault::NotJson, reason);
                return None;
            }
            Err(e) => {
                let reason = format!("record is not JSON: {e}");
                self.reject_record("", label, kept(), RecordFault::NotJson, reason);
                return None;
            }
        };
        let raw_id = json["patch"].as_str();
        let id = raw_id.and_then(sanitize_id);
        let unknown: Vec<&String> = json
            .as_object()
            .map(|o| {
                o.keys()
                    .filter(|k| {
                        !matches!(
                            k.as_str(),
                            "patch" | "path" | "format" | "bytes" | "object" | "transform"
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        let problem = match (raw_id, &id) {
            (None, _) => Some((
                record_kind(RecordFault::NoPatch),
                "record has no \"patch\" string".into(),
            )),
            (Some(raw), None) => Some((
                record_kind(RecordFault::NoPatch),
                format!("patch id {raw:?} has no usable characters"),
            )),
            _ if !unknown.is_empty() => Some((
                record_kind(RecordFault::UnknownKeys),
                format!("unknown record keys {unknown:?}"),
            )),
            _ => None,
        };
        let (object, object_problem) = match record_object(&json) {
            Ok(o) => (o, None),
            Err(reason) => (None, Some((record_kind(RecordFault::BadObject), reason))),
        };
        Some(Header {
            id: id.unwrap_or_default(),
            json,
            problem: problem.or(object_problem),
            stamp,
            object,
        })
    }

    /// `{"patch", "path"}`: the file must be a regular file under the pipe roots; anything
    /// else is refused and left alone (never moved to quarantine, never deleted).
    fn path_record(&self, text: &[u8], h: Header, label: &str, seq: u64) {
        let Some(path) = h.json["path"].as_str() else {
            let (kind, reason) = h.problem.unwrap_or((
                record_kind(RecordFault::NoPathNorBytes),
                "record has neither \"path\" nor \"bytes\"".into(),
            ));
            let keep = Keep::Bytes(Arc::new(text.to_vec()), format!("pipe-{}.record", h.stamp));
            self.reject(&h.id, label, keep, kind, reason);
            return;
        };
        if let Some((kind, reason)) = h.problem.or_else(|| {
            h.json.get("format").map(|_| {
                (
                    record_kind(RecordFault::BadFormat),
                    "a path record takes no \"format\" (the extension says it)".into(),
                )
            })
        }) {
            self.reject(&h.id, label, Keep::Nothing, kind, reason);
            return;
        }
        let cfg = self.cell.get();
        let path = match Roots::new(&self.watch_dir, &cfg.daemon.pipe_roots)
            .confine(Path::new(path), &self.watch_dir)
        {
            Ok(p) => p,
            Err(refusal) => {
                let kind = rejection_kind(&Cause::Path(&refusal));
                self.reject(&h.id, label, Keep::Nothing, kind, refusal.to_string());
                return;
            }
        };
        let version = path
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let a = Arrival {
            id: h.id,
            input: Input::File(path.clone()),
            key: self.key(seq),
            version,
            label: format!("{label} ({})", path.display()),
            detected: Instant::now(),
        };
        self.arrive_as(a, h.object);
    }

    /// `{"patch", "format", "bytes": N}` and N raw bytes.
    fn inline_record(
        &self,
        r: &mut impl BufRead,
        text: &[u8],
        mut h: Header,
        label: &str,
        seq: u64,
    ) -> After {
        let bytes = &h.json["bytes"];
        let Some(n) = bytes.as_u64() else {
            let reason = format!("\"bytes\" must be a non-negative integer, got {bytes}");
            return self.resync(r, text, &h, label, reason);
        };
        let ext = h.json["format"].as_str().unwrap_or("");
        // A payload has no folder for a .gltf's external buffers: binary glTF instead.
        let format = Format::from_extension(ext).filter(|f| *f != Format::Gltf);
        let max = self.cell.get().daemon.max_file_bytes;
        if h.problem.is_none() {
            h.problem = match (format, h.json.get("path")) {
                (None, _) => Some((
                    record_kind(RecordFault::BadFormat),
                    format!(
                        "\"format\" must be one of ply, glb, obj, stl, off, xyz, pts, pcd; got {}",
                        h.json["format"]
                    ),
                )),
                (_, Some(_)) => Some((
                    record_kind(RecordFault::PathAndBytes),
                    "a record has \"path\" or \"bytes\", not both".into(),
                )),
                _ if n > max => Some((
                    rejection_kind(&Cause::TooLarge),
                    format!("{n} bytes exceeds daemon.max_file_bytes = {max}"),
                )),
                _ => None,
            };
        }
        let prefix = if h.id.is_empty() {
            "pipe"
        } else {
            h.id.as_str()
        };
        let safe_ext = if format.is_some() { ext } else { "bin" };
        let name = format!("{prefix}@pipe-{}.{safe_ext}", h.stamp);
        if let Some((kind, reason)) = h.problem.take() {
            return self.skip_payload(r, n, &h.id, label, &name, kind, reason);
        }
        let Some(format) = format else {
            return After::Next;
        };
        if !self.wait_for_budget(n, max) {
            return After::Ended;
        }
        let object = h.object.take();
        self.read_payload(r, n, format, (h.id, object), label, name, seq)
    }

    /// The header is bad but says how long the payload is: streams it to quarantine without
    /// holding it (it may be over the size limit) and keeps the framing.
    #[allow(clippy::too_many_arguments)]
    fn skip_payload(
        &self,
        r: &mut impl BufRead,
        n: u64,
        id: &str,
        label: &str,
        name: &str,
        kind: &'static str,
        reason: String,
    ) -> After {
        let target = self.quarantine.join(name);
        let kept = std::fs::create_dir_all(&self.quarantine)
            .and_then(|_| std::fs::File::create(&target))
            .and_then(|mut f| {
                let copied = std::io::copy(&mut r.by_ref().take(n), &mut f)?;
                f.sync_all()?;
                Ok(copied)
            });
        let (keep, complete) = match kept {
            Ok(c) => (Keep::Already(target), c == n),
            Err(e) => {
                tracing::error!(error = %e, "cannot quarantine pipe bytes; discarding them to keep the framing");
                let skipped =
                    std::io::copy(&mut r.by_ref().take(n), &mut std::io::sink()).unwrap_or(0);
                (Keep::Nothing, skipped == n)
            }
        };
        self.reject(id, label, keep, kind, reason);
        if complete {
            After::Next
        } else {
            After::Ended
        }
    }

    /// The length is unreadable, so where the payload ends is unknown: everything up to the
    /// next line that is a record header (a JSON object with a "patch") is this record's,
    /// kept in one quarantine file and reported once. Rejecting those lines one by one would
    /// turn one bad record into thousands of rejections.
    fn resync(
        &self,
        r: &mut impl BufRead,
        text: &[u8],
        h: &Header,
        label: &str,
        reason: String,
    ) -> After {
        let target = self.quarantine.join(format!("pipe-{}.record", h.stamp));
        let mut file = std::fs::create_dir_all(&self.quarantine)
            .and_then(|_| std::fs::File::create(&target))
            .map_err(|e| tracing::error!(error = %e, "cannot quarantine a bad pipe record"))
            .ok();
        let mut keep = |line: &[u8]| {
            if let Some(f) = file.as_mut() {
                if f.write_all(line).and_then(|_| f.write_all(b"\n")).is_err() {
                    file = None;
                }
            }
        };
        keep(text);
        let (mut skipped, mut next) = (0u64, After::Ended);
        while !self.stop.load(Ordering::Relaxed) {
            match read_line(r) {
                Ok(Line::Text(t)) if is_header(&t) => {
                    next = After::Header(t);
                    break;
                }
                Ok(Line::Text(t)) => {
                    skipped += t.len() as u64 + 1;
                    keep(&t);
                }
                Ok(Line::TooLong) => skipped += MAX_LINE as u64,
                Ok(Line::Eof) | Err(_) => break,
            }
        }
        let kept = file.take().and_then(|f| f.sync_all().ok()).map(|_| target);
        let reason = format!("{reason}; skipped {skipped} bytes to the next record header");
        let kind = rejection_kind(&Cause::Record(RecordFault::BadLength));
        let keep = kept.map_or(Keep::Nothing, Keep::Already);
        self.reject(&h.id, label, keep, kind, reason);
        next
    }

    /// Waits while the payloads still held plus this one would exceed the budget; one
    /// payload is always let through, so a record of `max_file_bytes` never waits forever.
    /// False when the daemon stops while waiting.
    fn wait_for_budget(&self, n: u64, budget: u64) -> bool {
        let mut told = false;
        loop {
            let live: u64 = {
                let mut held = self.held.borrow_mut();
                held.retain(|w| w.strong_count() > 0);
                held.iter()
                    .filter_map(Weak::upgrade)
                    .map(|d| d.len() as u64)
                    .sum()
            };
            if live == 0 || live.saturating_add(n) <= budget {
                return true;
            }
            if self.stop.load(Ordering::Relaxed) {
                return false;
            }
            if !told {
                tracing::info!(
                    held = live,
                    next = n,
                    budget,
                    "pipe payload budget full; pausing reads"
                );
                told = true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn read_payload(
        &self,
        r: &mut impl BufRead,
        n: u64,
        format: Format,
        (id, object): (String, RecordObject),
        label: &str,
        name: String,
        seq: u64,
    ) -> After {
        tracing::debug!(patch = %id, bytes = n, "reading a record's payload");
        // n <= max_file_bytes here, so reserving it is within the configured budget.
        let mut data = Vec::with_capacity(n as usize);
        self.set_partial(Some(Partial {
            id: id.clone(),
            label: label.to_string(),
            got: 0,
            want: n,
        }));
        let mut failure = None;
        while (data.len() as u64) < n {
            let piece = (n - data.len() as u64).min(READ_PIECE as u64);
            match r.by_ref().take(piece).read_to_end(&mut data) {
                Ok(0) => break,
                Ok(_) => {
                    if let Some(p) = self
                        .partial
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .as_mut()
                    {
                        p.got = data.len() as u64;
                    }
                }
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        self.set_partial(None);
        let k = data.len();
        if k as u64 == n {
            let data = Arc::new(data);
            self.held.borrow_mut().push(Arc::downgrade(&data));
            let a = Arrival {
                id,
                input: Input::Inline { data, format },
                key: self.key(seq),
                version: name,
                label: label.to_string(),
                detected: Instant::now(),
            };
            self.arrive_as(a, object);
            return After::Next;
        }
        let reason = match failure {
            Some(e) => format!("read failed after {k} of {n} bytes: {e}"),
            None => format!("stream ended after {k} of {n} bytes"),
        };
        let kind = rejection_kind(&Cause::Record(RecordFault::Truncated));
        self.reject(&id, label, Keep::Bytes(Arc::new(data), name), kind, reason);
        After::Ended
    }

    fn set_partial(&self, p: Option<Partial>) {
        *self.partial.lock().unwrap_or_else(|e| e.into_inner()) = p;
    }

    /// Later records are newer versions, whatever the files' mtimes say.
    fn key(&self, seq: u64) -> VersionKey {
        VersionKey {
            time: SystemTime::now(),
            tie: format!("pipe-{seq:012}"),
        }
    }

    /// A patch's version goes to the scheduler; an object's scan to the writer, which
    /// keeps it with the object's scans before the object is refitted (scans of one object
    /// are not versions of one another: none may replace another while it waits).
    fn arrive_as(&self, a: Arrival, object: RecordObject) {
        match object {
            None => {
                let _ = self.tx.send(Msg::Arrivals(vec![a]));
            }
            Some((object, transform)) => {
                let cfg = self.cell.get();
                if cfg.cluster.url.is_some() {
                    // An object's fit reads all its scans, which a queue's workers do not
                    // hold: refused once, never queued to fail again and again.
                    let keep = match &a.input {
                        Input::Inline { data, .. } => {
                            Keep::Bytes(Arc::clone(data), a.version.clone())
                        }
                        _ => Keep::Nothing,
                    };
                    let reason = "objects are not fitted through a queue (cluster.url, --queue)";
                    self.reject_record(
                        &object,
                        &a.label,
                        keep,
                        RecordFault::BadObject,
                        reason.into(),
                    );
                    return;
                }
                let scan = ObjectScan {
                    object,
                    scan: a,
                    transform,
                    max_bytes: cfg.daemon.max_file_bytes,
                };
                let _ = self.writer.send(WriterMsg::ObjectScan(Box::new(scan)));
            }
        }
    }

    fn reject_record(&self, id: &str, label: &str, keep: Keep, fault: RecordFault, reason: String) {
        self.reject(
            id,
            label,
            keep,
            rejection_kind(&Cause::Record(fault)),
            reason,
        );
    }

    fn reject(&self, id: &str, label: &str, keep: Keep, kind: &'static str, reason: String) {
        let _ = self.writer.send(WriterMsg::Reject {
            id: id.to_string(),
            label: label.to_string(),
            keep,
            kind,
            reason,
        });
    }
}

fn record_kind(fault: RecordFault) -> &'static str {
    rejection_kind(&Cause::Record(fault))
}

/// Whether a line is a record header: a JSON object naming a patch.
fn is_header(line: &[u8]) -> bool {
    serde_json::from_slice::<serde_json::Value>(line)
        .is_ok_and(|v| v.get("patch").is_some_and(serde_json::Value::is_string))
}

#[cfg(test)]
mod tests;
