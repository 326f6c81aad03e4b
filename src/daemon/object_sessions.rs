//! The object sessions a daemon keeps in memory between updates (`object.kept_sessions`):
//! an object's `ObjectSession` (its scans' samples, merge grid and last fit) with what
//! each scan was when it went in, so that the next update of the object merges only
//! around the scans that changed and may refit the previous control mesh locally
//! (`pipeline::object_session`), instead of starting over from the folder.
//!
//! A kept session is a cache of the previous state, never the only copy of anything: the
//! folder's scans are read on every update, a session is taken out while a worker uses
//! it (a failed or panicking update simply loses it), and without one (a restart, an
//! evicted object, another config) the update starts a fresh session from all the scans.

use crate::mesh::rigid::RigidTransform;
use crate::pipeline::object_session::ObjectSession;
use std::collections::BTreeMap;
use std::sync::Mutex;

/// What a scan was when it went into a session: its bytes' hash and its transform.
pub(crate) type ScanKey = (u64, [u64; 16]);

/// The key of a scan read from `hash`'s bytes and registered by `transform`.
pub(crate) fn scan_key(hash: u64, transform: &RigidTransform) -> ScanKey {
    (hash, transform.to_row_major().map(f64::to_bits))
}

/// One object's session and what its scans were.
pub(crate) struct KeptSession {
    pub session: ObjectSession,
    /// Each scan id in the session and its key.
    pub scans: BTreeMap<String, ScanKey>,
    /// The object config (`DaemonConfig::object_fit_hash`) the session was made under.
    pub config_hash: u64,
}

/// The sessions of the objects updated last, at most `capacity` of them.
pub(crate) struct ObjectSessions {
    capacity: usize,
    /// Least recently used first.
    kept: Mutex<Vec<(String, KeptSession)>>,
}

impl ObjectSessions {
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            capacity,
            kept: Mutex::new(Vec::new()),
        }
    }

    /// Whether sessions are kept at all.
    pub(crate) fn enabled(&self) -> bool {
        self.capacity > 0
    }

    /// Takes the session of object `id` out (the caller puts it back after the update),
    /// if one is kept under the config `config_hash`.
    pub(crate) fn take(&self, id: &str, config_hash: u64) -> Option<KeptSession> {
        let mut kept = self.kept.lock().unwrap_or_else(|p| p.into_inner());
        let at = kept.iter().position(|(k, _)| k == id)?;
        let (_, session) = kept.remove(at);
        (session.config_hash == config_hash).then_some(session)
    }

    /// Keeps `session` as object `id`'s, the least recently used one dropped beyond the
    /// capacity.
    pub(crate) fn put(&self, id: &str, session: KeptSession) {
        if self.capacity == 0 {
            return;
        }
        let mut kept = self.kept.lock().unwrap_or_else(|p| p.into_inner());
        kept.retain(|(k, _)| k != id);
        kept.push((id.to_string(), session));
        while kept.len() > self.capacity {
            kept.remove(0);
        }
    }

    /// Forgets object `id`'s session (its outputs were removed).
    pub(crate) fn forget(&self, id: &str) {
        let mut kept = self.kept.lock().unwrap_or_else(|p| p.into_inner());
        kept.retain(|(k, _)| k != id);
    }
}

/// How an update applies a folder's scans to a kept session.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum SessionStep {
    /// One update of the kept session: these scans added (new ids, or new versions of ids
    /// it holds) and these removed. Both empty when no usable scan changed but the outputs
    /// are wanted again (a rejected scan came or went, an output is missing): the kept fit
    /// comes out again without a fit from scratch.
    Update {
        added: Vec<String>,
        removed: Vec<String>,
    },
    /// Start a fresh session from all the scans: no session kept.
    Fresh,
}

/// The step from the `kept` scans to the folder's `now` (id and key of every usable scan).
pub(crate) fn step(
    kept: &BTreeMap<String, ScanKey>,
    now: &BTreeMap<String, ScanKey>,
) -> SessionStep {
    let added = now
        .iter()
        .filter(|(id, key)| kept.get(*id) != Some(key))
        .map(|(id, _)| id.clone())
        .collect();
    let removed = kept
        .keys()
        .filter(|id| !now.contains_key(*id))
        .cloned()
        .collect();
    SessionStep::Update { added, removed }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(pairs: &[(&str, u64)]) -> BTreeMap<String, ScanKey> {
        pairs
            .iter()
            .map(|(id, h)| (id.to_string(), (*h, [0; 16])))
            .collect()
    }

    #[test]
    fn a_folder_change_becomes_one_session_update() {
        let kept = keys(&[("a", 1), ("b", 2)]);
        let update = |added: &[&str], removed: &[&str]| SessionStep::Update {
            added: added.iter().map(|s| s.to_string()).collect(),
            removed: removed.iter().map(|s| s.to_string()).collect(),
        };
        // A new scan, and a new version of one.
        assert_eq!(
            step(&kept, &keys(&[("a", 1), ("b", 2), ("c", 3)])),
            update(&["c"], &[])
        );
        assert_eq!(
            step(&kept, &keys(&[("a", 1), ("b", 5)])),
            update(&["b"], &[])
        );
        // A new transform is a new version too.
        let mut moved = kept.clone();
        moved.insert("a".into(), (1, [7; 16]));
        assert_eq!(step(&kept, &moved), update(&["a"], &[]));
        // One scan gone, gone and added at once (a scan renamed), two gone, or nothing
        // changed.
        assert_eq!(step(&kept, &keys(&[("b", 2)])), update(&[], &["a"]));
        assert_eq!(
            step(&kept, &keys(&[("b", 2), ("c", 3)])),
            update(&["c"], &["a"])
        );
        assert_eq!(step(&kept, &keys(&[])), update(&[], &["a", "b"]));
        assert_eq!(step(&kept, &kept), update(&[], &[]));
    }

    #[test]
    fn sessions_are_kept_for_the_objects_used_last_under_their_config() {
        let sessions = ObjectSessions::new(2);
        let kept = |config_hash| KeptSession {
            session: ObjectSession::new(Default::default()),
            scans: BTreeMap::new(),
            config_hash,
        };
        sessions.put("a", kept(1));
        sessions.put("b", kept(1));
        sessions.put("c", kept(1));
        // "a" was used least recently: dropped.
        assert!(sessions.take("a", 1).is_none());
        assert!(sessions.take("b", 1).is_some());
        // Taken out: gone until put back.
        assert!(sessions.take("b", 1).is_none());
        // Another config: not used (and dropped).
        assert!(sessions.take("c", 2).is_none());
        assert!(sessions.take("c", 1).is_none());
        sessions.put("d", kept(1));
        sessions.forget("d");
        assert!(sessions.take("d", 1).is_none());
        let off = ObjectSessions::new(0);
        off.put("a", kept(1));
        assert!(!off.enabled() && off.take("a", 1).is_none());
    }
}
