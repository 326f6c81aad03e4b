//! Per-patch state for warm starts, one JSON file per patch, written atomically.

use crate::io::write_atomic;
use crate::pipeline::worker::WarmStart;
use std::path::PathBuf;

#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PatchState {
    pub version: String,
    pub input_hash: u64,
    /// `DaemonConfig::output_hash` of the fit: a config change refits an unchanged input.
    /// States written before it existed read as 0, which matches no config.
    #[serde(default)]
    pub config_hash: u64,
    pub warm: WarmStart,
}

pub struct StateStore {
    dir: PathBuf,
}

impl StateStore {
    pub fn new(dir: PathBuf) -> Self {
        Self { dir }
    }

    fn path(&self, id: &str) -> PathBuf {
        self.dir.join(format!("{id}.json"))
    }

    /// The saved state, or `None` (missing or unreadable state only costs a cold start).
    pub fn load(&self, id: &str) -> Option<PatchState> {
        serde_json::from_slice(&std::fs::read(self.path(id)).ok()?).ok()
    }

    pub fn save(&self, id: &str, state: &PatchState) -> Result<(), crate::io::IoError> {
        let bytes = serde_json::to_vec(state).unwrap_or_default();
        write_atomic(&self.path(id), &bytes)
    }
}

/// FNV-1a 64: stable across runs and platforms, enough to tell versions apart.
pub fn content_hash(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}
