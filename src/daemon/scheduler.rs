//! Coalescing by patch id: at most one waiting version per patch (the newest), and at most
//! one version of a patch in the hands of a worker or the writer at any time.
//!
//! Pure bookkeeping with no threads or IO, so that the ordering rules can be tested alone.

use crate::io::Format;
use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Instant, SystemTime};

/// Where the bytes of a version are.
#[derive(Clone, Debug)]
pub enum Input {
    File(PathBuf),
    /// Sent inline on the pipe; held in memory until fitted, quarantined or spilled.
    Inline {
        data: Arc<Vec<u8>>,
        format: Format,
    },
    /// An object folder (`[object] folders`): its scans as they are when it is fitted.
    Object(PathBuf),
}

/// Which of two versions of a patch is newer: the file's mtime (or the arrival time of a
/// pipe record), then the name, so that `ear@0003` < `ear@0004` when the clock is too coarse
/// to tell them apart.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct VersionKey {
    pub time: SystemTime,
    pub tie: String,
}

#[derive(Clone, Debug)]
pub struct Arrival {
    pub id: String,
    pub input: Input,
    pub key: VersionKey,
    /// The version's name (file name, or the name a pipe record is spilled under).
    pub version: String,
    /// How the input is shown in events: the path, or `pipe:<source>#<record>`.
    pub label: String,
    pub detected: Instant,
}

impl Arrival {
    fn same_source(&self, other: &Arrival) -> bool {
        match (&self.input, &other.input) {
            (Input::File(a), Input::File(b)) => a == b,
            // A change of an object's folder: the fit reads the whole folder, so a newer
            // change replaces a waiting one and never loses to a running one.
            (Input::Object(a), Input::Object(b)) => a == b,
            _ => false,
        }
    }
}

/// A version that lost to a newer one: recorded, never fitted, left where it is.
#[derive(Debug)]
pub struct Superseded {
    pub loser: Arrival,
    pub by: String,
}

#[derive(Default)]
pub struct Scheduler {
    pending: HashMap<String, Arrival>,
    /// Patch ids with a waiting version, oldest first, so that a busy patch cannot starve
    /// the others.
    order: VecDeque<String>,
    busy: HashMap<String, Arrival>,
    /// The newest version handed out per patch, so that a late older version loses to it.
    started: HashMap<String, Arrival>,
}

impl Scheduler {
    /// Queues a version; returns the version that lost, if any.
    pub fn add(&mut self, a: Arrival) -> Option<Superseded> {
        if let Some(s) = self.started.get(&a.id) {
            // Rewriting the same file is always a new version, whatever its mtime says.
            if a.key < s.key && !a.same_source(s) {
                let by = s.label.clone();
                return Some(Superseded { loser: a, by });
            }
        }
        match self.pending.remove(&a.id) {
            None => {
                self.order.push_back(a.id.clone());
                self.pending.insert(a.id.clone(), a);
                None
            }
            Some(old) if old.same_source(&a) => {
                // The same file changed again before it was fitted: one version, not two.
                self.pending.insert(a.id.clone(), a);
                None
            }
            Some(old) => {
                let (winner, loser) = if a.key >= old.key { (a, old) } else { (old, a) };
                let by = winner.label.clone();
                self.pending.insert(winner.id.clone(), winner);
                Some(Superseded { loser, by })
            }
        }
    }

    /// The next version to fit: the oldest waiting patch that is not busy.
    pub fn next_ready(&mut self) -> Option<Arrival> {
        let pos = self
            .order
            .iter()
            .position(|id| !self.busy.contains_key(id))?;
        let id = self.order.remove(pos)?;
        let a = self.pending.remove(&id)?;
        self.busy.insert(id.clone(), a.clone());
        self.started.insert(id, a.clone());
        Some(a)
    }

    /// Whether a version newer than `key` waits for patch `id`: a fit of `key` that just
    /// finished is then stale.
    pub fn has_newer(&self, id: &str, key: &VersionKey) -> Option<String> {
        self.pending
            .get(id)
            .filter(|p| p.key >= *key)
            .map(|p| p.label.clone())
    }

    /// The patch's version is fitted and written (or dropped): the next may start.
    pub fn finish(&mut self, id: &str) {
        self.busy.remove(id);
    }

    pub fn pending_len(&self) -> usize {
        self.pending.len()
    }

    pub fn busy_len(&self) -> usize {
        self.busy.len()
    }

    pub fn idle(&self) -> bool {
        self.pending.is_empty() && self.busy.is_empty()
    }

    /// Everything still waiting (at a stop).
    pub fn drain_pending(&mut self) -> Vec<Arrival> {
        self.order.clear();
        self.pending.drain().map(|(_, a)| a).collect()
    }

    /// Versions handed out and not finished (at a stop that ran out of time).
    pub fn busy(&self) -> impl Iterator<Item = &Arrival> {
        self.busy.values()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn file(id: &str, name: &str, t: u64) -> Arrival {
        Arrival {
            id: id.into(),
            input: Input::File(PathBuf::from(name)),
            key: VersionKey {
                time: SystemTime::UNIX_EPOCH + Duration::from_millis(t),
                tie: name.into(),
            },
            version: name.into(),
            label: name.into(),
            detected: Instant::now(),
        }
    }

    #[test]
    fn newest_waiting_version_wins_and_losers_are_reported() {
        let mut s = Scheduler::default();
        assert!(s.add(file("ear", "ear@2", 20)).is_none());
        let lost = s.add(file("ear", "ear@1", 10)).expect("older loses");
        assert_eq!(
            (lost.loser.version.as_str(), lost.by.as_str()),
            ("ear@1", "ear@2")
        );
        let lost = s.add(file("ear", "ear@3", 30)).expect("newer wins");
        assert_eq!(lost.loser.version, "ear@2");
        assert_eq!(s.next_ready().map(|a| a.version), Some("ear@3".into()));
        assert!(s.next_ready().is_none());
    }

    #[test]
    fn equal_times_are_ordered_by_name() {
        let mut s = Scheduler::default();
        s.add(file("ear", "ear@0004", 5));
        let lost = s.add(file("ear", "ear@0003", 5)).expect("one loses");
        assert_eq!(lost.loser.version, "ear@0003");
    }

    #[test]
    fn a_busy_patch_waits_while_others_run() {
        let mut s = Scheduler::default();
        s.add(file("a", "a@1", 1));
        s.add(file("b", "b@1", 2));
        let first = s.next_ready().expect("a");
        assert_eq!(first.id, "a");
        s.add(file("a", "a@2", 3));
        // a is busy: b goes first even though a@2 is waiting.
        assert_eq!(s.next_ready().map(|x| x.id), Some("b".into()));
        assert!(s.next_ready().is_none(), "a is never fitted twice at once");
        assert_eq!(s.has_newer("a", &first.key), Some("a@2".into()));
        s.finish("a");
        assert_eq!(s.next_ready().map(|x| x.version), Some("a@2".into()));
        s.finish("a");
        s.finish("b");
        assert!(s.idle());
    }

    #[test]
    fn a_late_older_version_loses_to_the_one_started() {
        let mut s = Scheduler::default();
        s.add(file("a", "a@5", 50));
        let started = s.next_ready().expect("a@5");
        s.finish(&started.id);
        let lost = s.add(file("a", "a@4", 40)).expect("late and older");
        assert_eq!(lost.by, "a@5");
        // The same file rewritten is new even with an older mtime (cp -p).
        assert!(s.add(file("a", "a@5", 10)).is_none());
    }

    #[test]
    fn the_same_file_changing_twice_while_waiting_is_one_version() {
        let mut s = Scheduler::default();
        s.add(file("a", "a.ply", 1));
        assert!(s.add(file("a", "a.ply", 2)).is_none());
        assert_eq!(s.pending_len(), 1);
    }
}
