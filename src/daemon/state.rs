//! Per-patch state for warm starts, one JSON file per patch, written atomically; and the
//! content hash that tells versions apart.

use crate::io::write_atomic;
use crate::pipeline::worker::WarmStart;
use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub(crate) struct PatchState {
    pub(crate) version: String,
    pub(crate) input_hash: u64,
    /// `DaemonConfig::fit_hash` of the fit: a change of the fit config refits an unchanged
    /// input. States written before it existed read as 0, which matches no config.
    #[serde(default)]
    pub(crate) config_hash: u64,
    /// The output files written (`DaemonConfig::wanted_outputs`): a config that asks for
    /// one more refits the input to produce it.
    #[serde(default)]
    pub(crate) outputs: Vec<String>,
    pub(crate) warm: WarmStart,
}

impl PatchState {
    /// The state a fit leaves once its outputs are written; `fit` gives the config's
    /// `(fit_hash, wanted_outputs)`.
    pub(crate) fn after_fit(
        version: &str,
        input_hash: u64,
        (config_hash, outputs): (u64, Vec<String>),
        warm: WarmStart,
    ) -> Self {
        Self {
            version: version.to_string(),
            input_hash,
            config_hash,
            outputs,
            warm,
        }
    }
}

pub(crate) struct StateStore {
    dir: PathBuf,
    /// False for a cluster worker, whose states live in the shared store: writing each one
    /// to a local file as well would cost a second encode and fsync per job for nothing.
    files: bool,
    /// The states of the most recently fitted patches: a new version's job reads its
    /// predecessor's state from here instead of parsing the file again (a scan's state
    /// carries its data points, ~2 MB of JSON, ~8 ms to parse).
    recent: Mutex<Recent>,
    /// Inputs rejected as unsupported and left in place: patch id -> (content hash, fit
    /// config hash), in `.unsupported.json` (ids never start with a dot), so that the same file is not rejected and
    /// reported again at every start.
    unsupported: Mutex<HashMap<String, (u64, u64)>>,
}

/// The file of `StateStore::unsupported`.
const UNSUPPORTED_FILE: &str = ".unsupported.json";

/// States kept in memory at most; older ones are read from their files again.
const RECENT_STATES: usize = 32;

/// Of those, the states whose fitted surface (`WarmStart::holds_surface`) is kept with
/// them, at most: the latest ones. A whole object's surface holds the quadtrees its fit
/// built (bun_zipper's: 16 MB besides a 2 MB state), which its next version takes over
/// instead of building them again (fertility's warm refit: 80 -> 70 ms); older states
/// drop theirs.
const KEPT_SURFACES: usize = 4;

#[derive(Default)]
struct Recent {
    states: HashMap<String, Arc<PatchState>>,
    order: VecDeque<String>,
    /// The ids of the states holding a surface, the latest last.
    with_surface: VecDeque<String>,
}

impl Recent {
    /// Drops state `id` from memory (its place in `order` is the caller's): gone, it no
    /// longer takes one of the surfaces' places.
    fn remove(&mut self, id: &str) {
        self.states.remove(id);
        self.with_surface.retain(|k| k != id);
    }

    fn insert(&mut self, id: &str, state: Arc<PatchState>) {
        let holds_surface = state.warm.holds_surface();
        // Least recently saved first: a patch updated often must not be evicted because it
        // was first seen long ago (its next version would read its file again).
        if self.states.insert(id.to_string(), state).is_some() {
            self.order.retain(|k| k != id);
        }
        self.order.push_back(id.to_string());
        while self.order.len() > RECENT_STATES {
            if let Some(old) = self.order.pop_front() {
                self.remove(&old);
            }
        }
        self.with_surface.retain(|k| k != id);
        if holds_surface {
            self.with_surface.push_back(id.to_string());
        }
        while self.with_surface.len() > KEPT_SURFACES {
            let Some(old) = self.with_surface.pop_front() else {
                break;
            };
            // A state a job still reads is copied (without the surface) rather than
            // changed under it.
            if let Some(state) = self.states.get_mut(&old) {
                Arc::make_mut(state).warm.drop_surfaces();
            }
        }
    }
}

impl StateStore {
    pub(crate) fn new(dir: PathBuf) -> Self {
        // Unreadable or absent: the inputs are only looked at once more.
        let unsupported = std::fs::read(dir.join(UNSUPPORTED_FILE))
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok())
            .unwrap_or_default();
        Self {
            dir,
            files: true,
            recent: Mutex::new(Recent::default()),
            unsupported: Mutex::new(unsupported),
        }
    }

    /// A store whose states stay in memory (`persist` writes nothing); `dir` still keeps
    /// the notes of unsupported inputs.
    pub(crate) fn in_memory(dir: PathBuf) -> Self {
        Self {
            files: false,
            ..Self::new(dir)
        }
    }

    /// Whether this content, under this fit config, was rejected as unsupported and left
    /// in place.
    pub(crate) fn still_unsupported(&self, id: &str, input_hash: u64, fit_hash: u64) -> bool {
        let known = self.unsupported.lock().unwrap_or_else(|e| e.into_inner());
        known.get(id) == Some(&(input_hash, fit_hash))
    }

    /// Notes an input rejected as unsupported and left in place (writer thread only).
    pub(crate) fn note_unsupported(
        &self,
        id: &str,
        input_hash: u64,
        fit_hash: u64,
    ) -> Result<(), crate::io::IoError> {
        let mut known = self.unsupported.lock().unwrap_or_else(|e| e.into_inner());
        known.insert(id.to_string(), (input_hash, fit_hash));
        let bytes = serde_json::to_vec(&*known).unwrap_or_default();
        write_atomic(&self.dir.join(UNSUPPORTED_FILE), &bytes)
    }

    /// Where the scans of objects fed through the pipe live (`object_store`).
    pub(crate) fn objects_dir(&self) -> PathBuf {
        self.dir.join("objects")
    }

    fn path(&self, id: &str) -> PathBuf {
        // Ids of files in subfolders hold `/`: one flat name per id.
        self.dir.join(format!("{}.json", super::publish::flat(id)))
    }

    fn recent(&self) -> std::sync::MutexGuard<'_, Recent> {
        // A panic while holding the lock leaves a consistent map: keep using it.
        self.recent.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The saved state, or `None` (missing or unreadable state only costs a cold start).
    pub(crate) fn load(&self, id: &str) -> Option<Arc<PatchState>> {
        if let Some(s) = self.recent().states.get(id) {
            return Some(Arc::clone(s));
        }
        let state: PatchState = serde_json::from_slice(&std::fs::read(self.path(id)).ok()?).ok()?;
        let state = Arc::new(state);
        self.recent().insert(id, Arc::clone(&state));
        Some(state)
    }

    /// Served from memory at once; `persist` writes it to its file. Until then (or if that
    /// fails) a restart finds the previous file and refits the input: nothing is lost.
    pub(crate) fn remember(&self, id: &str, state: PatchState) -> Arc<PatchState> {
        let state = Arc::new(state);
        self.recent().insert(id, Arc::clone(&state));
        state
    }

    /// Drops a patch's state from memory and its file: a cluster worker then holds only
    /// what the shared store says (which may be nothing).
    pub(crate) fn forget(&self, id: &str) {
        let mut recent = self.recent();
        recent.order.retain(|k| k != id);
        recent.remove(id);
        drop(recent);
        let _ = std::fs::remove_file(self.path(id));
    }

    /// Writes a state to its file (atomically).
    pub(crate) fn persist(&self, id: &str, state: &PatchState) -> Result<(), crate::io::IoError> {
        if !self.files {
            return Ok(());
        }
        let bytes = serde_json::to_vec(state).unwrap_or_default();
        write_atomic(&self.path(id), &bytes)
    }

    /// `remember` and `persist`.
    #[cfg(test)]
    pub(crate) fn save(&self, id: &str, state: PatchState) -> Result<(), crate::io::IoError> {
        let state = self.remember(id, state);
        self.persist(id, &state)
    }
}

/// A 64-bit hash of a file's bytes. FNV-1a 64 over little-endian 8-byte words (then the tail bytes), each step rotated so that
/// the multiplication's carries, which only run upwards, reach the low bits of later steps:
/// stable across runs and platforms, enough to tell versions apart, and 8x fewer
/// multiplications than byte-wise FNV (hashing a 1.7 MB scan took ~2 ms of every job's
/// latency).
pub fn content_hash(bytes: &[u8]) -> u64 {
    const PRIME: u64 = 0x0100_0000_01b3;
    let mut words = bytes.chunks_exact(8);
    let mut h = words.by_ref().fold(0xcbf2_9ce4_8422_2325u64, |h, w| {
        let mut word = [0u8; 8];
        word.copy_from_slice(w);
        (h ^ u64::from_le_bytes(word))
            .wrapping_mul(PRIME)
            .rotate_left(29)
    });
    for &b in words.remainder() {
        h = (h ^ b as u64).wrapping_mul(PRIME).rotate_left(29);
    }
    h
}

/// A small state for tests elsewhere in the crate.
#[cfg(test)]
pub(crate) fn sample_state(version: &str) -> PatchState {
    PatchState {
        version: version.into(),
        input_hash: 7,
        config_hash: 9,
        outputs: vec!["surface.json".into()],
        warm: WarmStart {
            surface: crate::pipeline::SurfaceKind::Loop,
            controls: vec![glam::DVec3::new(1.0, 2.0, 3.0)],
            frame: None,
            warp: None,
            domain: None,
            coords: Vec::new(),
            feet: None,
            parts: Vec::new(),
            object: None,
            scattered: None,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Any one changed byte, a dropped or an appended zero byte changes the hash; the
    /// same bytes hash the same.
    #[test]
    fn content_hash_tells_every_small_change_apart() {
        let base: Vec<u8> = (0..1000u32).map(|i| (i * 7 % 251) as u8).collect();
        let h = content_hash(&base);
        assert_eq!(h, content_hash(&base.clone()));
        let mut seen = std::collections::HashSet::new();
        seen.insert(h);
        for k in 0..base.len() {
            let mut changed = base.clone();
            changed[k] ^= 1;
            assert!(seen.insert(content_hash(&changed)), "byte {k}");
        }
        let mut longer = base.clone();
        longer.push(0);
        assert!(seen.insert(content_hash(&longer)));
        assert!(seen.insert(content_hash(&base[..999])));
        assert!(seen.insert(content_hash(&[])));
    }

    fn state(version: &str) -> PatchState {
        sample_state(version)
    }

    /// Saved states are served from memory, survive a restart through their files, and
    /// the memory holds only the most recent ones.
    #[test]
    fn recent_states_come_from_memory_and_all_from_disk() {
        let dir = tempfile::tempdir().expect("tmp");
        let store = StateStore::new(dir.path().to_path_buf());
        assert!(store.load("a").is_none());
        store.save("a", state("a@1")).expect("saves");
        let first = store.load("a").expect("cached");
        assert!(Arc::ptr_eq(&first, &store.load("a").expect("cached")));
        for k in 0..RECENT_STATES {
            store.save(&format!("p{k}"), state("p")).expect("saves");
        }
        assert!(!store.recent().states.contains_key("a"), "evicted");
        assert_eq!(store.recent().states.len(), RECENT_STATES);
        // Read back from its file, as after a restart.
        let again = store.load("a").expect("from disk");
        assert!(!Arc::ptr_eq(&first, &again));
        assert_eq!(again.version, "a@1");
        assert_eq!(again.warm.controls, first.warm.controls);
        let restarted = StateStore::new(dir.path().to_path_buf());
        assert_eq!(restarted.load("p3").expect("from disk").version, "p");
    }

    /// The memory evicts the state saved least recently, not the one first seen: a patch
    /// updated all along stays while patches saved once before its last version go.
    #[test]
    fn the_least_recently_saved_state_is_evicted_first() {
        let dir = tempfile::tempdir().expect("tmp");
        let store = StateStore::new(dir.path().to_path_buf());
        store.save("busy", state("busy@1")).expect("saves");
        for k in 0..RECENT_STATES - 1 {
            store.save(&format!("p{k}"), state("p")).expect("saves");
        }
        store.save("busy", state("busy@2")).expect("saves");
        store.save("late", state("late")).expect("saves");
        let recent = store.recent();
        assert!(recent.states.contains_key("busy"), "saved again: recent");
        assert!(
            !recent.states.contains_key("p0"),
            "the least recently saved"
        );
        assert!(recent.states.contains_key("p1"));
        assert_eq!(recent.states.len(), RECENT_STATES);
        assert_eq!(recent.order.len(), RECENT_STATES);
        assert_eq!(recent.order.back().map(String::as_str), Some("late"));
    }

    /// A state whose warm start keeps a fitted surface (an icosahedron's).
    fn state_with_surface(version: &str) -> PatchState {
        let (corners, faces) = crate::testdata::icosahedron();
        let surface = crate::surface::loop_limit::LoopLimitSurface::new(corners.len(), &faces)
            .expect("a closed manifold");
        let mut state = sample_state(version);
        state.warm.object = Some(crate::pipeline::worker::ObjectWarm {
            faces,
            feet: crate::pipeline::scan::WarmFeet {
                points: Vec::new(),
                params: Vec::new(),
                rms: 0.0,
            },
            feet_faces: Vec::new(),
            euler: 2,
            boundary_loops: 0,
            bounds: [glam::DVec3::ZERO, glam::DVec3::ONE],
            crease_edges: Vec::new(),
            surface: Some(Arc::new(surface)),
        });
        state
    }

    /// Only the latest `KEPT_SURFACES` states keep their surfaces; an older one drops its
    /// own, but a job still holding it keeps its copy whole, and the file never held it.
    #[test]
    fn only_the_latest_states_keep_their_surfaces() {
        let dir = tempfile::tempdir().expect("tmp");
        let store = StateStore::new(dir.path().to_path_buf());
        store.save("a", state_with_surface("a@1")).expect("saves");
        let held = store.load("a").expect("memory");
        for k in 0..KEPT_SURFACES {
            store
                .save(&format!("p{k}"), state_with_surface("p"))
                .expect("saves");
        }
        assert!(held.warm.holds_surface(), "a reader's copy is not changed");
        let a = store.load("a").expect("memory");
        assert!(!a.warm.holds_surface(), "the oldest surface is dropped");
        assert_eq!(a.warm.object.as_ref().map(|o| o.faces.len()), Some(20));
        for k in 0..KEPT_SURFACES {
            assert!(store
                .load(&format!("p{k}"))
                .expect("memory")
                .warm
                .holds_surface());
        }
        // A new version of `a` keeps its surface again, and the oldest other one drops.
        store.save("a", state_with_surface("a@2")).expect("saves");
        assert!(store.load("a").expect("memory").warm.holds_surface());
        assert!(!store.load("p0").expect("memory").warm.holds_surface());
        let restarted = StateStore::new(dir.path().to_path_buf());
        let from_disk = restarted.load("p3").expect("from disk");
        assert!(!from_disk.warm.holds_surface());
        assert!(from_disk.warm.object.is_some());
    }

    /// A state evicted from memory no longer counts among those keeping a surface: the
    /// next `KEPT_SURFACES` states with one all keep theirs.
    #[test]
    fn an_evicted_state_gives_up_its_place_among_the_surfaces() {
        let dir = tempfile::tempdir().expect("tmp");
        let store = StateStore::new(dir.path().to_path_buf());
        store.save("old", state_with_surface("old")).expect("saves");
        for k in 0..RECENT_STATES {
            store.save(&format!("p{k}"), state("p")).expect("saves");
        }
        assert!(store.recent().with_surface.is_empty());
        for k in 0..KEPT_SURFACES {
            store
                .save(&format!("s{k}"), state_with_surface("s"))
                .expect("saves");
        }
        for k in 0..KEPT_SURFACES {
            let s = store.load(&format!("s{k}")).expect("memory");
            assert!(s.warm.holds_surface(), "s{k}");
        }
    }

    /// A remembered state is served before its file exists (a newer version starts from it
    /// while the writer is still writing); a restart before `persist` finds the old file.
    #[test]
    fn a_remembered_state_serves_at_once_and_reaches_disk_on_persist() {
        let dir = tempfile::tempdir().expect("tmp");
        let store = StateStore::new(dir.path().to_path_buf());
        store.save("a", state("a@1")).expect("saves");
        let newer = store.remember("a", state("a@2"));
        assert_eq!(store.load("a").expect("memory").version, "a@2");
        let restarted = StateStore::new(dir.path().to_path_buf());
        assert_eq!(restarted.load("a").expect("disk").version, "a@1");
        store.persist("a", &newer).expect("writes");
        let restarted = StateStore::new(dir.path().to_path_buf());
        assert_eq!(restarted.load("a").expect("disk").version, "a@2");
    }
}
