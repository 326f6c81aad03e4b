//! What an object session holds between updates (what the daemon keeps per object with
//! `object.kept_sessions`): the bunny's five registered scans added one by one, the heap
//! bytes the session holds after each update (its scans' samples, merge grid, merged mesh,
//! last fit and warm start), counted by a counting allocator.
//!
//!     cargo run --release --example session_memory [-- DATA_DIR]
//!
//! One fit runs before the count starts: the numeric crates reserve per-thread buffers
//! at their first use (mostly untouched, so not resident), which belong to the process,
//! not to a session.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use trispline::io::registration::registration_for;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::pipeline::object_session::{ObjectSession, SessionOptions};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);

// SAFETY: forwards every call to the system allocator unchanged, only counting bytes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        LIVE.fetch_add(layout.size(), Ordering::Relaxed);
        // SAFETY: the caller's layout contract is passed on.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        // SAFETY: `ptr` came from `alloc` above with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

fn mb(bytes: usize) -> f64 {
    bytes as f64 / 1e6
}

fn main() {
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let folder = root.join("range_scans/registered");
    let mut scans = Vec::new();
    for id in ["bun000", "bun045", "bun180", "bun270", "chin"] {
        let path = folder.join(format!("{id}.ply"));
        let read = read_mesh_file(&path, &LoadOptions::default())
            .map_err(|e| e.to_string())
            .and_then(|l| {
                let r = registration_for(&path, id).map_err(|e| e.to_string())?;
                Ok((l.mesh, r.transform))
            });
        match read {
            Ok((mesh, transform)) => scans.push((id, mesh, transform)),
            Err(e) => {
                eprintln!("{}: {e}", path.display());
                std::process::exit(1);
            }
        }
    }
    let options = SessionOptions {
        measure_scans: false,
        ..Default::default()
    };
    // The warm-up fit (see the module docs): two views, the grid path and its warm start.
    {
        let mut warm_up = ObjectSession::new(options.clone());
        for (id, mesh, t) in &scans[..2] {
            if let Err(e) = warm_up.add_scan(id, mesh, *t) {
                eprintln!("{id}: {e}");
                std::process::exit(1);
            }
        }
    }
    let base = LIVE.load(Ordering::Relaxed);
    let mut session = ObjectSession::new(options);
    for (id, mesh, t) in &scans {
        match session.add_scan(id, mesh, *t) {
            Ok(update) => {
                let path = update.path;
                drop(update);
                let held = LIVE.load(Ordering::Relaxed).saturating_sub(base);
                println!(
                    "+{id:7} path {path:6}  the session holds {:6.1} MB",
                    mb(held)
                );
            }
            Err(e) => {
                eprintln!("{id}: {e}");
                std::process::exit(1);
            }
        }
    }
    let before = LIVE.load(Ordering::Relaxed);
    drop(session);
    let freed = before.saturating_sub(LIVE.load(Ordering::Relaxed));
    println!("dropping the session frees {:.1} MB", mb(freed));
}
