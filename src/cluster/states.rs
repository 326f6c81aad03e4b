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
use std::path::PathBuf;

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

/// The patch's last state from the bucket (or the shared file it names). A state that
/// cannot be read is a cold start, and the next store replaces it.
pub(super) fn load(ctx: &Ctx, id: &str) -> Loaded {
    let entry = match ctx.queue.block_on(ctx.queue.kv.entry(state_key(id))) {
        Ok(Some(e)) => e,
        Ok(None) => return Loaded::default(),
        Err(e) => {
            tracing::warn!(patch = id, error = %e, "cannot read the warm-start state; starting cold");
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

/// Stores `state` for patch `id` if the entry is still what `from` saw; `seq` names the
/// shared file of a large state. True when stored.
pub(super) fn store(ctx: &Ctx, id: &str, seq: u64, state: &PatchState, from: &Loaded) -> bool {
    let limit = ctx.cell.get().cluster.payload_limit;
    let inline = StateRecord::Inline(Box::new(state.clone()));
    let mut bytes = serde_json::to_vec(&inline).unwrap_or_default();
    let mut file = None;
    if bytes.len() > limit {
        let dir = states_dir(&ctx.out_dir);
        let path = dir.join(format!("{}-{seq}.json", wire::token(id)));
        let written = std::fs::create_dir_all(&dir)
            .map_err(|e| e.to_string())
            .and_then(|_| {
                crate::io::write_atomic(&path, &serde_json::to_vec(state).unwrap_or_default())
                    .map_err(|e| e.to_string())
            });
        if let Err(e) = written {
            tracing::warn!(patch = id, error = %e, "cannot save the warm-start state");
            return false;
        }
        bytes = serde_json::to_vec(&StateRecord::File(path.clone())).unwrap_or_default();
        file = Some(path);
    }
    let key = state_key(id);
    let stored = ctx.queue.block_on(async {
        match from.rev {
            Some(r) => ctx
                .queue
                .kv
                .update(&key, bytes.into(), r)
                .await
                .map_err(|e| e.to_string()),
            None => ctx
                .queue
                .kv
                .create(&key, bytes.into())
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
