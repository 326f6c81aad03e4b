//! Scale-out on NATS JetStream: sources publish jobs to a work-queue stream (one subject per
//! patch), workers on any machine take them, claim the patch in a key-value bucket (the
//! entry's revision is the compare-and-set token), fit with the warm start stored there,
//! write to the shared OUT as the single daemon does, and acknowledge.
//!
//! tokio lives only here, in a small runtime of the `Queue`; the rest of the daemon stays
//! synchronous and calls in through `Queue::block_on`.
#![warn(missing_docs)]

mod publisher;
mod queue;
mod wire;
mod worker;

pub(crate) use publisher::offload;
pub use queue::ClusterError;
pub use worker::{run_worker, WorkerOptions, WorkerSummary};
