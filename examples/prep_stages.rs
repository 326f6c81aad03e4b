//! Per-stage times of the scan preparation and output stages (everything of a cold scan fit
//! but the fit itself), each run `REPEATS` times in a row: min and median per stage, and a
//! fingerprint of every stage's result so that a faster version can be checked to compute
//! the same bits.
//!
//!     cargo run --release --example prep_stages [-- DATA_DIR [REPEATS [STAGE]]]
//!
//! With STAGE (a stage name) only that stage is repeated, for a profiler's sake.

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::path::PathBuf;
use std::time::Instant;
use trispline::io::{read_mesh_file, write_atomic, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::inverse::InverseMethod;
use trispline::pipeline::output::{surface_json, tessellate, tessellated_glb, Coverage};
use trispline::pipeline::scan::components::cleaned_components;
use trispline::pipeline::scan::domain::{
    covered_cells, grid_initial_net, spacing_for_target, GridFrame,
};
use trispline::pipeline::scan::ScanConfig;
use trispline::pipeline::worker::{fit_patch, FitConfig, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::remesh::fill_holes;
use trispline::remesh::planar::{evened_out, planar_map, PlaneFrame};
use trispline::surface::grid_spline::GridSpline;
use trispline::TriMesh;

// The allocator the `trispline` binary runs with, so that the figures are the binary's.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() {
    trispline::allocator::keep_freed_memory();
    trispline::allocator::small_pages_only();
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let repeats: usize = std::env::args()
        .nth(2)
        .and_then(|r| r.parse().ok())
        .unwrap_or(7);
    let out = std::env::temp_dir().join(format!("trispline-prep-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&out);
    for name in [
        "bun000_tri",
        "bun045_tri",
        "chin_tri",
        "bun000_meshlab_triangulated",
        "bun000_range_grid",
    ] {
        let path = root.join(format!("range_scans/{name}.ply"));
        println!("== {name}");
        let mesh = stage("read", repeats, || {
            read_mesh_file(&path, &LoadOptions::default()).map(|l| l.mesh)
        });
        let Ok(mesh) = mesh else {
            println!("unreadable");
            continue;
        };
        print_hash("read", &mesh_bits(&mesh));
        let cleaned = stage("clean", repeats, || clean(&mesh, &CleanOptions::default()));
        print_hash("clean", &mesh_bits(&cleaned.mesh));
        let parts = stage("components", repeats, || cleaned_components(&cleaned));
        print_hash(
            "components",
            &parts.iter().map(mesh_bits).collect::<Vec<_>>(),
        );
        let Some(part) = parts.into_iter().next() else {
            continue;
        };
        let Ok(patch) = stage("fill_holes", repeats, || fill_holes(&part)) else {
            println!("fill_holes failed");
            continue;
        };
        print_hash(
            "fill_holes",
            &(mesh_bits(&patch.mesh), &patch.outer, &patch.hole_loops),
        );
        let Some(frame) = stage("frame", repeats, || PlaneFrame::fit_least_folds(&part)) else {
            continue;
        };
        let Ok(map) = stage("planar_map", repeats, || planar_map(&patch, &frame)) else {
            continue;
        };
        let map = stage("evened_out", repeats, || {
            evened_out(map.clone(), &patch, None)
        });
        let plane_bits: Vec<[u64; 2]> = map
            .plane
            .iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits()])
            .collect();
        print_hash("planar_map", &(mesh_bits(&map.mesh), plane_bits));
        let target = ScanConfig::default().target_controls_pct / 100.0 * patch.real_vertices as f64;
        let target = target.round() as usize;
        let spacing = stage("spacing_for_target", repeats, || {
            spacing_for_target(&map.plane, &map.mesh.triangles, target)
        });
        print_hash("spacing_for_target", &spacing.to_bits());
        let gf = GridFrame { spacing };
        let grid = stage("grid_new", repeats, || {
            GridSpline::new(covered_cells(&gf, &map.plane, &map.mesh.triangles))
        });
        print_hash("grid_new", &(grid.cells(), grid.control_coords()));
        let initial = stage("grid_initial_net", repeats, || {
            grid_initial_net(&map.mesh, &map.plane, &gf, &grid, 2, InverseMethod::Exact)
        });
        let ctl_bits: Vec<[u64; 3]> = initial
            .controls
            .iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
            .collect();
        print_hash(
            "grid_initial_net",
            &(ctl_bits, initial.resample_points, &initial.inverse),
        );

        // Outputs of a fit (the fit itself is not timed here).
        let cfg = WorkerConfig {
            fit: FitConfig {
                surface: SurfaceKind::Loop,
                ..FitConfig::default()
            },
            ..WorkerConfig::default()
        };
        let Ok(fitted) = fit_patch(&mesh, None, &cfg) else {
            println!("fit failed");
            continue;
        };
        let f = &fitted.fit;
        let Some(s) = fitted.scan.as_ref() else {
            continue;
        };
        println!("   ({} controls)", f.model.as_surface().control_count());
        let coverage = stage("coverage", repeats, || {
            Coverage::new(
                &s.mapping.filled.triangles,
                &f.params,
                &s.mapping.mapped_params,
                &s.mapping.near_fold,
            )
        });
        let tess = stage("tessellate", repeats, || {
            tessellate(f, cfg.tessellation, Some(&coverage))
        });
        let glb = stage("glb", repeats, || {
            tessellated_glb(f, &tess, fitted.budget.tolerance)
        });
        let report = serde_json::json!({"final": {}, "status": f.outcome.status});
        let value = stage("surface_json", repeats, || {
            surface_json(f, Some(s), &report)
        });
        let bytes = stage("json_bytes", repeats, || {
            serde_json::to_vec_pretty(&value).unwrap_or_default()
        });
        stage("write", repeats, || {
            write_atomic(&out.join("surface.glb"), &glb)
                .and_then(|_| write_atomic(&out.join("surface.json"), &bytes))
        })
        .ok();
        println!(
            "   outputs fingerprint: glb {} bytes, json {} bytes (fit-dependent)",
            glb.len(),
            bytes.len()
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

fn stage<T>(name: &str, repeats: usize, mut run: impl FnMut() -> T) -> T {
    let repeats = match std::env::args().nth(3) {
        Some(only) if only != name => 1,
        _ => repeats.max(1),
    };
    let mut times = Vec::with_capacity(repeats);
    let mut last = None;
    for _ in 0..repeats {
        let t = Instant::now();
        let r = run();
        times.push(t.elapsed().as_secs_f64() * 1e3);
        // Dropped outside the timed region: the pipeline keeps its results.
        last = Some(r);
    }
    times.sort_by(f64::total_cmp);
    println!(
        "   {name:<20} min {:8.2} ms  median {:8.2} ms",
        times[0],
        times[times.len() / 2]
    );
    match last {
        Some(r) => r,
        None => unreachable!("at least one repeat"),
    }
}

fn mesh_bits(m: &TriMesh) -> (Vec<[u64; 3]>, Vec<[u32; 3]>) {
    (
        m.positions
            .iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
            .collect(),
        m.triangles.clone(),
    )
}

fn print_hash(name: &str, value: &impl Hash) {
    let mut h = DefaultHasher::new();
    value.hash(&mut h);
    println!("   {name:<20} hash {:016x}", h.finish());
}
