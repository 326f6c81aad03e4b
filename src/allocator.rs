//! The allocator settings the binary (and the examples that time it) run with.

/// `mi_option_purge_delay` in mimalloc's option enum (`mimalloc.h`, v2 and v3 alike; the
/// sys crate names the options around it but not this one).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Keeps memory the process frees for its own reuse instead of returning it to the system
/// after mimalloc's purge delay. A fit frees and allocates tens of MB per round; returned
/// memory comes back as fresh pages the kernel must fault in and zero again, which took
/// ~20 % of the CPU time of repeated 40k-point fits in one process on the 2-core test
/// machine (task-clock 3.74 -> 3.00 s over 12 cold fits). The price: a long-running
/// daemon keeps its high-water mark (about one fit's working set per worker: ten 40k-point
/// fits in one process peak at ~110 MB resident with mimalloc v2, ~180 MB with v3).
pub fn keep_freed_memory() {
    // SAFETY: sets one integer option of the allocator; mimalloc reads it when deciding
    // whether to purge, and any value (-1: never) is valid at any time.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
}
