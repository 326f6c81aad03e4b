//! What a worker's fit of one version came to (`Outcome`), and its timings: shared by the
//! jobs of patches (`job`) and of objects (`object_job`) and read by the coordinator and
//! the writer.

use crate::pipeline::worker::InputOutputs;
use std::path::PathBuf;

/// A scan of an object that was left out of its fit.
#[derive(Clone, Debug)]
pub(crate) struct ScanRejection {
    /// The scan file.
    pub file: PathBuf,
    /// `kinds::rejection_kind` of the cause.
    pub kind: &'static str,
    pub reason: String,
}

pub(crate) enum Outcome {
    Fitted {
        outputs: Box<InputOutputs>,
        hash: u64,
        /// Scans of an object left out of its fit (each is rejected in place).
        rejected_scans: Vec<ScanRejection>,
    },
    /// Same content and same output-shaping config as the last fit.
    Unchanged { hash: u64 },
    Rejected {
        /// `kinds::rejection_kind` of the cause.
        kind: &'static str,
        reason: String,
        /// The input was read as a valid mesh that the pipeline cannot fit (a topology it
        /// does not support, too few points, over `max_vertices`): not broken, so it stays
        /// where it is unless `daemon.unsupported = "quarantine"`.
        unsupported: bool,
        /// The content hash, when the bytes were read.
        input_hash: Option<u64>,
    },
    /// Content and fit config are those of a version rejected as unsupported and left in
    /// place: not rejected (nor reported) again.
    StillUnsupported,
    /// An object none of whose scans is left (all deleted, or its folder gone): its
    /// outputs and state are removed, since they describe data that no longer exists.
    Emptied { reason: String },
    /// The file changed while it was read and did not parse: a writer is still at it, or
    /// a part of it (a glTF's buffer) has not arrived. Not a rejection; it is read again
    /// after `wait` (`None`: the settle time).
    Incomplete {
        reason: String,
        wait: Option<std::time::Duration>,
    },
}

#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub(crate) struct Timings {
    /// Detection to a worker picking it up.
    pub queued_ms: f64,
    pub read_ms: f64,
    pub parse_ms: f64,
    /// Inside `run_input`.
    pub fit_ms: f64,
}
