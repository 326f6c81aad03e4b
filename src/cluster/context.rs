//! What a worker's job steps share: the worker's connections and writer, and the small
//! reads every step makes (the job as an arrival, its payload, a newer version waiting).

use super::queue::Queue;
use super::wire::{self, JobHeader};
use crate::daemon::kinds::{rejection_kind, Cause};
use crate::daemon::reload::ConfigCell;
use crate::daemon::scheduler::{Arrival, Input, VersionKey};
use crate::daemon::state::StateStore;
use crate::daemon::writer::WriterMsg;
use crate::io::Format;
use crossbeam_channel::Sender;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Instant, SystemTime};

/// A worker's connections, writer and config, shared by the steps of each job.
pub(super) struct Ctx {
    pub(super) queue: Queue,
    pub(super) store: Arc<StateStore>,
    pub(super) wtx: Sender<WriterMsg>,
    pub(super) cell: Arc<ConfigCell>,
    pub(super) name: String,
    pub(super) out_dir: PathBuf,
}

/// The job's version as the daemon's writer knows versions.
pub(super) fn arrival(h: &JobHeader, data: Arc<Vec<u8>>) -> Arrival {
    Arrival {
        id: h.id.clone(),
        input: Input::Inline {
            data,
            format: h.format.unwrap_or(Format::Ply),
        },
        key: VersionKey {
            time: SystemTime::now(),
            tie: h.version.clone(),
        },
        version: h.version.clone(),
        label: h.label.clone(),
        detected: Instant::now(),
    }
}

pub(super) fn record_key(id: &str) -> String {
    format!("patch.{}", wire::token(id))
}

/// Sends to the writer and waits until it has handled everything sent so far.
pub(super) fn write(ctx: &Ctx, msgs: Vec<WriterMsg>) {
    let (tx, rx) = crossbeam_channel::bounded(1);
    for m in msgs {
        let _ = ctx.wtx.send(m);
    }
    let _ = ctx.wtx.send(WriterMsg::Barrier(tx));
    let _ = rx.recv();
}

/// The version of the newest job still waiting on the patch's subject after `seq`.
pub(super) fn newer(ctx: &Ctx, subject: &str, seq: u64) -> Option<String> {
    let last = ctx
        .queue
        .block_on(ctx.queue.stream.get_last_raw_message_by_subject(subject))
        .ok()?;
    if last.sequence <= seq {
        return None;
    }
    let version = wire::decode(&last.payload)
        .map(|(h, _)| h.version)
        .unwrap_or_else(|_| format!("job {}", last.sequence));
    Some(version)
}

/// The mesh bytes: in the message, or read from shared storage.
pub(super) fn payload(
    h: &JobHeader,
    body: Arc<Vec<u8>>,
    max_bytes: u64,
) -> Result<Arc<Vec<u8>>, (&'static str, String)> {
    let Some(path) = h.path.as_ref().filter(|_| body.is_empty()) else {
        return Ok(body);
    };
    let read = std::fs::metadata(path).and_then(|m| {
        if m.len() > max_bytes {
            return Ok(None);
        }
        std::fs::read(path).map(Some)
    });
    match read {
        Ok(Some(b)) => Ok(Arc::new(b)),
        Ok(None) => Err((
            rejection_kind(&Cause::TooLarge),
            format!("exceeds daemon.max_file_bytes = {max_bytes}"),
        )),
        Err(e) => Err((
            rejection_kind(&Cause::Read(&e)),
            format!("cannot read {} from shared storage: {e}", path.display()),
        )),
    }
}
