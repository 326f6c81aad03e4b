//! Warm-start states in the bucket. A state is loaded before a fit and stored after it by
//! compare-and-set on the revision seen at load: a worker whose claim was taken over (it
//! looked dead) never replaces what the new holder stored. A state over the payload limit
//! lives in a file on shared storage named after its job, so that a store that loses the
//! race never overwrites the winner's file; the file a stored state replaces is removed.

use super::context::Ctx;
use super::queue::states_dir;
use super::wire::{self, StateRecord};
use crate::daemon::state::PatchState;
use crate::pipeline::worker::WarmStart;
use async_nats::jetstream::kv;
use std::path::{Path, PathBuf};

/// A patch's state as a fit found it.
#[derive(Default)]
pub(super) struct Loaded {
    /// `None`: a cold start.
    pub(super) state: Option<PatchState>,
    /// The entry's revision at load; `None` when there was no entry (or it was deleted).
    rev: Option<u64>,
    /// The shared file holding that state, if it was too big for the bucket.
    file: Option<PathBuf>,
}

pub(super) fn state_key(id: &str) -> String {
    format!("state.{}", wire::token(id))
}

/// A read of a patch's state entry, in flight.
pub(super) type Fetch = tokio::task::JoinHandle<Result<Option<kv::Entry>, kv::EntryError>>;

/// Starts reading the patch's state entry. A worker starts it once the patch's record shows
/// no holder, beside its claim: a state is stored before its fit's record is released, so
/// the read sees it, and the claim's round trip hides the read's.
pub(super) fn fetch(ctx: &Ctx, id: &str) -> Fetch {
    let (kv, key) = (ctx.queue.kv.clone(), state_key(id));
    ctx.queue.rt.spawn(async move { kv.entry(key).await })
}

/// The patch's last state from the bucket (or the shared file it names). A state that
/// cannot be read is a cold start, and the next store replaces it.
pub(super) fn load(ctx: &Ctx, id: &str, fetch: Fetch) -> Loaded {
    let entry = match ctx.queue.block_on(fetch) {
        Ok(Ok(Some(e))) => e,
        Ok(Ok(None)) => return Loaded::default(),
        Ok(Err(e)) => {
            tracing::warn!(patch = id, error = %e, "cannot read the warm-start state; starting cold");
            return Loaded::default();
        }
        Err(e) => {
            tracing::warn!(patch = id, error = %e, "the warm-start read failed; starting cold");
            return Loaded::default();
        }
    };
    let mut loaded = Loaded {
        rev: Some(entry.revision).filter(|_| entry.operation == kv::Operation::Put),
        ..Loaded::default()
    };
    if loaded.rev.is_none() {
        return loaded;
    }
    match serde_json::from_slice::<StateRecord>(&entry.value) {
        Ok(StateRecord::Inline(s)) => loaded.state = Some(*s),
        Ok(StateRecord::File(path)) => {
            loaded.state = std::fs::read(&path)
                .ok()
                .and_then(|b| serde_json::from_slice(&b).ok());
            loaded.file = Some(path);
        }
        Err(e) => {
            tracing::warn!(patch = id, error = %e, "unreadable warm-start state; starting cold")
        }
    }
    loaded
}

/// The state a fit whose result was dropped as stale leaves for the next version.
///
/// The single daemon hands a stale fit's control net to the patch's next version (the
/// scheduler loop's `warm`): it is fitted to newer data than the last written state. Here
/// the next version may run on any worker, so it goes to the bucket; `store` writes it only
/// while the entry is still the one this fit started from, i.e. nothing newer was stored
/// meanwhile. The entry is also what tells an unchanged input (version, input hash, config,
/// outputs), and no output of the stale version was written: so those stay the last
/// written version's, and only the warm start changes. Without a written version the
/// entry lists no outputs, which no config's wanted outputs match, so nothing is ever
/// skipped as unchanged because of it.
pub(super) fn stale_warm(loaded: &Loaded, warm: WarmStart) -> PatchState {
    match &loaded.state {
        Some(s) => PatchState { warm, ..s.clone() },
        None => PatchState {
            version: String::new(),
            input_hash: 0,
            config_hash: 0,
            outputs: Vec::new(),
            warm,
        },
    }
}

/// A state encoded for the bucket, its file on shared storage already written if it was
/// too big to travel: what is left is the bucket's compare-and-set (`commit`).
pub(super) struct Prepared {
    record: Vec<u8>,
    file: Option<PathBuf>,
}

/// Encodes `state` once and, over the payload limit, writes it to a shared file named after
/// job `seq` (so that a store that loses the race never overwrites the winner's file).
/// Needs no connection: a fit runs it while the writer writes the outputs.
pub(super) fn prepare(
    out_dir: &Path,
    limit: usize,
    id: &str,
    seq: u64,
    state: &PatchState,
) -> Result<Prepared, String> {
    let encoded = serde_json::to_vec(state).map_err(|e| e.to_string())?;
    if encoded.len() + INLINE_WRAP.len() <= limit {
        return Ok(Prepared {
            record: inline_record(&encoded),
            file: None,
        });
    }
    let dir = states_dir(out_dir);
    let path = dir.join(format!("{}-{seq}.json", wire::token(id)));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    crate::io::write_atomic(&path, &encoded).map_err(|e| e.to_string())?;
    let record = serde_json::to_vec(&StateRecord::File(path.clone())).map_err(|e| e.to_string())?;
    Ok(Prepared {
        record,
        file: Some(path),
    })
}

/// What `StateRecord::Inline` adds around the state's own JSON (serde's externally tagged
/// form): wrapping the bytes already encoded spares encoding a ~1 MB state twice.
const INLINE_WRAP: &str = r#"{"Inline":}"#;

fn inline_record(state_json: &[u8]) -> Vec<u8> {
    let (head, tail) = INLINE_WRAP.split_at(INLINE_WRAP.len() - 1);
    let mut out = Vec::with_capacity(state_json.len() + INLINE_WRAP.len());
    out.extend_from_slice(head.as_bytes());
    out.extend_from_slice(state_json);
    out.extend_from_slice(tail.as_bytes());
    out
}

/// Drops a prepared state that will not be stored (its outputs were not written).
pub(super) fn discard(prepared: Prepared) {
    if let Some(f) = prepared.file {
        let _ = std::fs::remove_file(f);
    }
}

/// Stores `state` for patch `id` if the entry is still what `from` saw; `seq` names the
/// shared file of a large state. True when stored.
pub(super) fn store(ctx: &Ctx, id: &str, seq: u64, state: &PatchState, from: &Loaded) -> bool {
    let limit = ctx.cell.get().cluster.payload_limit;
    match prepare(&ctx.out_dir, limit, id, seq, state) {
        Ok(prepared) => commit(ctx, id, prepared, from),
        Err(e) => {
            tracing::warn!(patch = id, error = %e, "cannot save the warm-start state");
            false
        }
    }
}

/// Points the bucket's entry at a prepared state if the entry is still what `from` saw, and
/// removes the shared file it replaces. True when stored.
pub(super) fn commit(ctx: &Ctx, id: &str, prepared: Prepared, from: &Loaded) -> bool {
    let Prepared { record, file } = prepared;
    let key = state_key(id);
    let stored = ctx.queue.block_on(async {
        match from.rev {
            Some(r) => ctx
                .queue
                .kv
                .update(&key, record.into(), r)
                .await
                .map_err(|e| e.to_string()),
            None => ctx
                .queue
                .kv
                .create(&key, record.into())
                .await
                .map_err(|e| e.to_string()),
        }
    });
    match stored {
        Ok(_) => {
            // Only files of this folder: the path comes from the bucket.
            let ours =
                |o: &&PathBuf| Some(*o) != file.as_ref() && o.starts_with(states_dir(&ctx.out_dir));
            if let Some(old) = from.file.as_ref().filter(ours) {
                let _ = std::fs::remove_file(old);
            }
            true
        }
        Err(e) => {
            tracing::info!(patch = id, error = %e, "a newer warm-start state is stored; this one is dropped");
            if let Some(f) = file {
                let _ = std::fs::remove_file(f);
            }
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wrapped_state_reads_back_as_the_inline_record() {
        let state = crate::daemon::state::sample_state("p@2");
        let encoded = serde_json::to_vec(&state).expect("encodes");
        let record = inline_record(&encoded);
        assert_eq!(record.len(), encoded.len() + INLINE_WRAP.len());
        match serde_json::from_slice::<StateRecord>(&record).expect("decodes") {
            StateRecord::Inline(back) => {
                assert_eq!(back.version, "p@2");
                assert_eq!(back.input_hash, state.input_hash);
                assert_eq!(back.outputs, state.outputs);
                assert_eq!(back.warm.controls, state.warm.controls);
            }
            StateRecord::File(p) => panic!("read as a file record: {}", p.display()),
        }
    }
}
