//! Warm start measured on real data: bun000_tri.ply, then a second version of it with 20% of
//! the vertices cut away and up to 40 um of noise added; steps and time to reach the same budget,
//! cold (from the inverse-subdivided net) and warm (from the first version's controls).
//!
//! Run: cargo run --release --example warm_start [path/to/bun000_tri.ply]

use std::time::Instant;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::pipeline::worker::{run_patch, FitConfig, PatchOutputs, WarmStart, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::{DVec3, TriMesh};

fn second_version(mesh: &TriMesh) -> TriMesh {
    // Drop the 20% of vertices with the smallest x (a coherent cut, as a rescan that saw less
    // of the object would), jitter the rest by up to +-40 um.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut noise = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 80e-6
    };
    let mut xs: Vec<f64> = mesh.positions.iter().map(|p| p.x).collect();
    let cut_index = xs.len() / 5;
    let cut = *xs.select_nth_unstable_by(cut_index, f64::total_cmp).1;
    let keep: Vec<bool> = mesh.positions.iter().map(|p| p.x >= cut).collect();
    let triangles = mesh
        .triangles
        .iter()
        .copied()
        .filter(|t| t.iter().all(|&v| keep[v as usize]))
        .collect();
    let positions = mesh
        .positions
        .iter()
        .map(|p| *p + DVec3::new(noise(), noise(), noise()))
        .collect();
    TriMesh::new(positions, triangles)
}

// The allocator the `trispline` binary runs with, so that the figures are the binary's.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    trispline::allocator::keep_freed_memory();
    trispline::allocator::small_pages_only();
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "../shared/data/range_scans/bun000_tri.ply".into());
    let Ok(loaded) = read_mesh_file(std::path::Path::new(&path), &LoadOptions::default()) else {
        eprintln!("cannot read {path}");
        return;
    };
    let v1 = loaded.mesh;
    let v2 = second_version(&v1);
    let mut base = WorkerConfig {
        fit: FitConfig {
            surface: SurfaceKind::Loop,
            ..FitConfig::default()
        },
        ..WorkerConfig::default()
    };
    base.fit.budget.max_iterations = 2000;
    let (first, reference) = match (run_patch(&v1, None, &base), run_patch(&v2, None, &base)) {
        (Ok(a), Ok(b)) => (a, b),
        (Err(e), _) | (_, Err(e)) => {
            eprintln!("{e}");
            return;
        }
    };
    // Budgets: a mean error a little above what a long cold fit of version 2 reaches (2%,
    // then 0.5%), and with the default budget (the daemon's, no target beyond the caps).
    let best = reference.report["final"]["mean_error"]
        .as_f64()
        .unwrap_or(0.0);
    println!(
        "version 1: {} data points; version 2: {} data points; long cold fit of version 2: mean {:.2} um",
        first.report["data_points"],
        reference.report["data_points"],
        best * 1e6
    );
    // Steps: conjugate-gradient steps in all (the last iteration entry's k; each correction
    // round adds its CG steps and one entry).
    let steps = |o: &PatchOutputs| {
        o.report["iterations"]
            .as_array()
            .and_then(|a| a.last())
            .and_then(|s| s["k"].as_u64())
            .unwrap_or(0)
    };
    let budgets = [
        (
            "mean <= 1.02 x best",
            Some(best * 1.02),
            base.fit.budget.max_iterations,
        ),
        (
            "mean <= 1.005 x best",
            Some(best * 1.005),
            base.fit.budget.max_iterations,
        ),
        (
            "default budget",
            None,
            WorkerConfig::default().fit.budget.max_iterations,
        ),
    ];
    for (name, mean_error, max_iterations) in budgets {
        let mut budget = base.clone();
        budget.fit.budget.mean_error = mean_error;
        budget.fit.budget.max_iterations = max_iterations;
        let run = |warm: Option<&WarmStart>| {
            let t = Instant::now();
            let out = run_patch(&v2, warm, &budget).expect("version 2 fits");
            (t.elapsed().as_secs_f64() * 1e3, out)
        };
        let (cold_ms, cold) = run(None);
        let (warm_ms, warm) = run(Some(&first.warm));
        for (label, ms, o) in [("cold", cold_ms, &cold), ("warm", warm_ms, &warm)] {
            println!(
                "{name:22} {label}: {:5} CG steps, {:6.0} ms, status {}, geometric rms {:.1} um, reused controls {}",
                steps(o),
                ms,
                o.report["status"],
                o.report["final"]["geometric_rms_error"].as_f64().unwrap_or(0.0) * 1e6,
                o.report["reused_controls"],
            );
        }
    }
}
