//! The hook through which jobs leave the process instead of going to local worker threads
//! (`watch --queue`): the daemon only knows this shape, not the queue behind it, so that the
//! cluster code depends on the daemon and never the other way round.

use super::job::Job;
use super::messages::Msg;
use super::ops::metrics::Metrics;
use crossbeam_channel::{Receiver, Sender};
use std::sync::Arc;

/// Starts the thread(s) that take jobs off the daemon; each job taken is answered on the
/// `Msg` channel with `Msg::Queued` (handed on) or `Msg::Fitted` (an `Incomplete` outcome:
/// read again later).
pub(crate) type StartOffload =
    Box<dyn FnOnce(Receiver<Job>, Sender<Msg>, Arc<Metrics>) -> std::io::Result<()> + Send>;

/// Where jobs go instead of the local worker pool.
pub(crate) struct Offload {
    /// Jobs handed out and not yet answered, at most: versions beyond it wait (and
    /// coalesce) in the scheduler, so the sources never block on the queue.
    pub(crate) capacity: usize,
    /// Called once at start-up.
    pub(crate) start: StartOffload,
}
