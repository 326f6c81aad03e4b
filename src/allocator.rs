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
/// fits in one process peak at ~110 MB resident with mimalloc v2, ~180 MB with v3, both on
/// huge pages; ~95 MB with v2 on small pages, see `small_pages_only`).
pub fn keep_freed_memory() {
    // SAFETY: sets one integer option of the allocator; mimalloc reads it when deciding
    // whether to purge, and any value (-1: never) is valid at any time.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, -1) };
}

/// Asks the kernel for small (4 KiB) pages only in this process: mimalloc marks its arenas
/// `MADV_HUGEPAGE`, and each 2 MiB huge page a fit touches first must be a free 2 MiB block
/// of the guest. On the 2-core test VM (virtio-balloon with free page reporting) such blocks
/// are handed back to the host within seconds of idle, and touching one again costs the
/// host's fault and zeroing: a cold chin fit run after 4 s of idle took 378 ms (median of
/// 6, report wall) with huge pages against 256 ms without, its system time 0.21 against
/// 0.06 s. Run back to back (memory the host still backs) huge pages win, 205 against 249
/// ms, from ~16k small-page faults; a scanner's fits arrive after idle, and the daemon keeps
/// its memory after the first fit (`keep_freed_memory`), so small pages are the default.
/// `TRISPLINE_HUGE_PAGES=1` keeps the system's setting. Linux only; elsewhere it does nothing.
pub fn small_pages_only() {
    if huge_pages_kept() {
        return;
    }
    // SAFETY: PR_SET_THP_DISABLE takes one integer flag and sets a per-process bit the
    // kernel consults at page-fault time; it touches no memory of this process.
    #[cfg(target_os = "linux")]
    unsafe {
        libc::prctl(libc::PR_SET_THP_DISABLE, 1, 0, 0, 0)
    };
}

/// `TRISPLINE_HUGE_PAGES=1`: the system's huge-page setting stays.
fn huge_pages_kept() -> bool {
    std::env::var_os("TRISPLINE_HUGE_PAGES").is_some_and(|v| v == "1")
}

#[cfg(test)]
mod tests {
    #[test]
    #[cfg(target_os = "linux")]
    fn small_pages_only_turns_huge_pages_off_for_the_process() {
        if super::huge_pages_kept() {
            return;
        }
        super::small_pages_only();
        // SAFETY: PR_GET_THP_DISABLE only reads the process's flag.
        let disabled = unsafe { libc::prctl(libc::PR_GET_THP_DISABLE, 0, 0, 0, 0) };
        assert_eq!(disabled, 1);
    }
}
