//! The pipe source: newline-delimited JSON records on stdin or a FIFO, each
//! `{"patch": ID, "path": FILE}` or `{"patch": ID, "format": FMT, "bytes": N}` followed by
//! exactly N raw bytes. A bad record is reported and skipped while keeping the framing when
//! the header says how many bytes follow; bytes that came with a bad record are quarantined.

use super::reload::ConfigCell;
use super::scheduler::{Arrival, Input, VersionKey};
use super::writer::{Keep, WriterMsg};
use super::{sanitize_id, Msg, Source};
use crate::io::Format;
use crossbeam_channel::Sender;
use std::io::{BufRead, Read};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

/// Longer header lines are not records (a writer that forgot the framing sent raw bytes).
const MAX_LINE: usize = 64 * 1024;

#[derive(Clone, Debug)]
pub enum PipeSpec {
    Stdin,
    Fifo(PathBuf),
}

pub struct PipeSource {
    pub spec: PipeSpec,
    pub cell: Arc<ConfigCell>,
    pub once: bool,
    pub tx: Sender<Msg>,
    pub writer: Sender<WriterMsg>,
    pub stop: Arc<AtomicBool>,
    pub quarantine: PathBuf,
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
    pub fn run(self) {
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
    fn records(&self, r: &mut impl BufRead, name: &str, record: &mut u64) {
        while !self.stop.load(Ordering::Relaxed) {
            let line = match read_line(r) {
                Ok(l) => l,
                Err(e) => {
                    tracing::error!(error = %e, pipe = name, "pipe read failed");
                    return;
                }
            };
            *record += 1;
            let label = format!("pipe:{name}#{record}");
            let text = match line {
                Line::Eof => {
                    *record -= 1;
                    return;
                }
                Line::TooLong => {
                    self.reject(
                        "",
                        &label,
                        Keep::Nothing,
                        format!(
                            "header line longer than {MAX_LINE} bytes; skipped to the next newline"
                        ),
                    );
                    continue;
                }
                Line::Text(t) if t.iter().all(|b| b.is_ascii_whitespace()) => {
                    *record -= 1;
                    continue;
                }
                Line::Text(t) => t,
            };
            if !self.record(r, &text, &label, *record) {
                return;
            }
        }
    }

    /// Handles one record; false when the stream ended inside it.
    fn record(&self, r: &mut impl BufRead, text: &[u8], label: &str, seq: u64) -> bool {
        let stamp = format!("{}-{seq}", unix_ms());
        let header: serde_json::Value = match serde_json::from_slice(text) {
            Ok(v @ serde_json::Value::Object(_)) => v,
            Ok(_) => {
                let keep = Keep::Bytes(Arc::new(text.to_vec()), format!("pipe-{stamp}.record"));
                self.reject("", label, keep, "record is not a JSON object".into());
                return true;
            }
            Err(e) => {
                let keep = Keep::Bytes(Arc::new(text.to_vec()), format!("pipe-{stamp}.record"));
                self.reject("", label, keep, format!("record is not JSON: {e}"));
                return true;
            }
        };
        let raw_id = header["patch"].as_str();
        let id = raw_id.and_then(sanitize_id);
        let bytes = header.get("bytes");
        let unknown: Vec<&String> = header
            .as_object()
            .map(|o| {
                o.keys()
                    .filter(|k| !matches!(k.as_str(), "patch" | "path" | "format" | "bytes"))
                    .collect()
            })
            .unwrap_or_default();
        let mut problem = match (raw_id, &id) {
            (None, _) => Some("record has no \"patch\" string".to_string()),
            (Some(raw), None) => Some(format!("patch id {raw:?} has no usable characters")),
            _ => None,
        };
        if problem.is_none() && !unknown.is_empty() {
            problem = Some(format!("unknown record keys {unknown:?}"));
        }
        let id = id.unwrap_or_default();
        let Some(bytes) = bytes else {
            // A path record.
            let Some(path) = header["path"].as_str() else {
                let p =
                    problem.unwrap_or_else(|| "record has neither \"path\" nor \"bytes\"".into());
                self.reject(
                    &id,
                    label,
                    Keep::Bytes(Arc::new(text.to_vec()), format!("pipe-{stamp}.record")),
                    p,
                );
                return true;
            };
            if let Some(p) = problem.or_else(|| {
                header
                    .get("format")
                    .map(|_| "a path record takes no \"format\" (the extension says it)".into())
            }) {
                self.reject(&id, label, Keep::Nothing, p);
                return true;
            }
            let path = PathBuf::from(path);
            match std::fs::metadata(&path) {
                Ok(m) if m.is_file() => {}
                Ok(_) => {
                    self.reject(
                        &id,
                        label,
                        Keep::Nothing,
                        format!("{} is not a file", path.display()),
                    );
                    return true;
                }
                Err(e) => {
                    self.reject(
                        &id,
                        label,
                        Keep::Nothing,
                        format!("{}: {e}", path.display()),
                    );
                    return true;
                }
            }
            let version = path
                .file_name()
                .map(|n| n.to_string_lossy().to_string())
                .unwrap_or_default();
            self.arrive(Arrival {
                id,
                input: Input::File(path.clone()),
                key: self.key(seq),
                version,
                label: format!("{label} ({})", path.display()),
                detected: Instant::now(),
            });
            return true;
        };
        let Some(n) = bytes.as_u64() else {
            // The length is unreadable: the framing is lost; the following raw bytes will be
            // rejected line by line until a record parses again.
            self.reject(
                &id,
                label,
                Keep::Bytes(Arc::new(text.to_vec()), format!("pipe-{stamp}.record")),
                format!("\"bytes\" must be a non-negative integer, got {bytes}"),
            );
            return true;
        };
        let ext = header["format"].as_str().unwrap_or("");
        let format = match ext {
            "ply" => Some(Format::Ply),
            "glb" => Some(Format::Glb),
            "obj" => Some(Format::Obj),
            "stl" => Some(Format::Stl),
            "off" => Some(Format::Off),
            _ => None,
        };
        let max = self.cell.get().daemon.max_file_bytes;
        if problem.is_none() {
            problem = match (format, header.get("path")) {
                (None, _) => Some(format!(
                    "\"format\" must be one of ply, glb, obj, stl, off; got {}",
                    header["format"]
                )),
                (_, Some(_)) => Some("a record has \"path\" or \"bytes\", not both".into()),
                _ if n > max => Some(format!("{n} bytes exceeds daemon.max_file_bytes = {max}")),
                _ => None,
            };
        }
        let prefix = if id.is_empty() {
            "pipe".to_string()
        } else {
            id.clone()
        };
        let safe_ext = if format.is_some() { ext } else { "bin" };
        let name = format!("{prefix}@pipe-{stamp}.{safe_ext}");
        if let Some(reason) = problem {
            // The header is bad but says how long the payload is: stream it to quarantine
            // without holding it (it may be over the size limit) and keep the framing.
            let target = self.quarantine.join(&name);
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
            self.reject(&id, label, keep, reason);
            return complete;
        }
        let Some(format) = format else { return true };
        // n <= max_file_bytes here, so reserving it is within the configured budget.
        let mut data = Vec::with_capacity(n as usize);
        let got = r.by_ref().take(n).read_to_end(&mut data);
        match got {
            Ok(k) if k as u64 == n => {
                self.arrive(Arrival {
                    id,
                    input: Input::Inline {
                        data: Arc::new(data),
                        format,
                    },
                    key: self.key(seq),
                    version: name,
                    label: label.to_string(),
                    detected: Instant::now(),
                });
                true
            }
            Ok(k) => {
                let reason = format!("stream ended after {k} of {n} bytes");
                self.reject(&id, label, Keep::Bytes(Arc::new(data), name), reason);
                false
            }
            Err(e) => {
                let reason = format!("read failed after {} of {n} bytes: {e}", data.len());
                self.reject(&id, label, Keep::Bytes(Arc::new(data), name), reason);
                false
            }
        }
    }

    /// Later records are newer versions, whatever the files' mtimes say.
    fn key(&self, seq: u64) -> VersionKey {
        VersionKey {
            time: SystemTime::now(),
            tie: format!("pipe-{seq:012}"),
        }
    }

    fn arrive(&self, a: Arrival) {
        let _ = self.tx.send(Msg::Arrivals(vec![a]));
    }

    fn reject(&self, id: &str, label: &str, keep: Keep, reason: String) {
        let _ = self.writer.send(WriterMsg::Reject {
            id: id.to_string(),
            label: label.to_string(),
            keep,
            reason,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_bounded_and_framing_survives_a_long_one() {
        let mut input = vec![b'x'; MAX_LINE + 10];
        input.extend_from_slice(b"\n{\"a\":1}\nlast");
        let mut r = std::io::BufReader::with_capacity(1000, input.as_slice());
        assert!(matches!(read_line(&mut r).expect("reads"), Line::TooLong));
        assert!(matches!(read_line(&mut r).expect("reads"), Line::Text(t) if t == b"{\"a\":1}"));
        assert!(matches!(read_line(&mut r).expect("reads"), Line::Text(t) if t == b"last"));
        assert!(matches!(read_line(&mut r).expect("reads"), Line::Eof));
    }
}
