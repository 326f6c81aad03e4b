//! The real-scan acceptance table: every Stanford range scan and the camel head, fitted with
//! the default settings for `bezier` and `loop`, from file to written outputs, cold.
//!
//! Prints per file and surface: data points, control points (and their share of the data),
//! geometric max / RMS error, status, the time of each stage (read, prepare = clean + map +
//! domain + resample, fit, outputs = tessellation + GLB + JSON written atomically) and the
//! one-sided distance from the trimmed tessellation to the data mesh (max and 99.9th
//! percentile: over a hole the nearest data is the hole's rim, so the maximum there is
//! about the hole's radius even for a perfect fill). Then the meshes that must be refused.
//!
//!     cargo run --release --example scan_table [-- DATA_DIR [bezier|loop|both [ROUNDS [SMOOTHING]]]]

use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;
use trispline::io::{read_mesh_file, write_atomic, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::output::{surface_json, tessellate, tessellated_glb, Coverage};
use trispline::pipeline::scan::components::cleaned_components;
use trispline::pipeline::worker::{fit_patch, WorkerConfig};
use trispline::pipeline::SurfaceKind;

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
    let only = match std::env::args().nth(2).as_deref() {
        Some("bezier") => Some(SurfaceKind::Bezier),
        Some("loop") => Some(SurfaceKind::Loop),
        _ => None,
    };
    let files = [
        "range_scans/bun000_tri.ply",
        "range_scans/bun045_tri.ply",
        "range_scans/chin_tri.ply",
        "range_scans/bun000_meshlab_triangulated.ply",
        "range_scans/bun000_range_grid.ply",
        "range_scans/registered/bun000.ply",
        "range_scans/registered/bun045.ply",
        "range_scans/registered/bun180.ply",
        "range_scans/registered/bun270.ply",
        "range_scans/registered/chin.ply",
        "models/camelhead.off",
        "models/bun_zipper.ply",
    ];
    let out = std::env::temp_dir().join(format!("trispline-scan-table-{}", std::process::id()));
    pieces_table(&root, &files);
    println!(
        "| file | surface | data pts | ctrl (% data) | geo max | geo rms | status | read ms | prepare ms | fit ms | outputs ms | total ms | tess->data max | p99.9 | tess->filled max | p99.9 | fitted within 1 mm of tess | dropped (pieces, share) | map |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for rel in files {
        let path = root.join(rel);
        if !path.exists() {
            println!("| {rel} | missing | | | | | | | | | | | | | |");
            continue;
        }
        for surface in [SurfaceKind::Bezier, SurfaceKind::Loop] {
            if only.is_some_and(|o| o != surface) {
                continue;
            }
            row(&path, rel, surface, &out);
        }
    }
    for rel in ["models/decimated-max.obj", "models/fertility.off"] {
        let path = root.join(rel);
        let Ok(loaded) = read_mesh_file(&path, &LoadOptions::default()) else {
            println!("{rel}: unreadable");
            continue;
        };
        match fit_patch(&loaded.mesh, None, &WorkerConfig::default()) {
            Ok(_) => println!("{rel}: FITTED (expected a refusal)"),
            Err(e) => println!("{rel}: refused: {e}"),
        }
    }
    let _ = std::fs::remove_dir_all(&out);
}

fn row(path: &Path, rel: &str, surface: SurfaceKind, out: &Path) {
    // The Stanford files are in metres: errors in micrometres. Others in their own units,
    // relative to the bounding-box diagonal.
    let unit = if rel.starts_with("range_scans") || rel.contains("bun_zipper") {
        (1e6, "um")
    } else {
        (1.0, "")
    };
    let t0 = Instant::now();
    let Ok(loaded) = read_mesh_file(path, &LoadOptions::default()) else {
        println!("| {rel} | unreadable |");
        return;
    };
    let read_ms = ms(t0);
    let defaults = WorkerConfig::default();
    // Optional third argument: correction rounds instead of the default.
    let rounds = std::env::args()
        .nth(3)
        .and_then(|r| r.parse().ok())
        .unwrap_or(defaults.fit.correction.rounds);
    // Optional fourth argument: the fairness weight.
    let smoothing = std::env::args()
        .nth(4)
        .and_then(|r| r.parse().ok())
        .unwrap_or(defaults.fit.scan.smoothing);
    let mut cfg = defaults;
    cfg.fit.surface = surface;
    cfg.fit.correction.rounds = rounds;
    cfg.fit.scan.smoothing = smoothing;
    if let Some(b) = std::env::var("SCAN_TABLE_BRIDGE")
        .ok()
        .and_then(|b| b.parse().ok())
    {
        cfg.fit.scan.hole_bridge_edges = b;
    }
    let t1 = Instant::now();
    let fitted = match fit_patch(&loaded.mesh, None, &cfg) {
        Ok(f) => f,
        Err(e) => {
            println!("| {rel} | {surface:?} | refused: {e} |");
            return;
        }
    };
    let fit_total = ms(t1);
    let t2 = Instant::now();
    let f = &fitted.fit;
    let coverage = fitted.scan.as_ref().map(|s| Coverage::of(f, s));
    let tess = tessellate(f, cfg.tessellation, coverage.as_ref());
    let glb = tessellated_glb(f, &tess, fitted.budget.tolerance);
    let report = serde_json::json!({"final": {}, "status": f.outcome.status});
    let surface_value = surface_json(f, fitted.scan.as_ref(), &report);
    let dir = out.join(format!("{}-{surface:?}", rel.replace('/', "_")));
    let written = std::fs::create_dir_all(&dir).is_ok()
        && write_atomic(&dir.join("surface.glb"), &glb).is_ok()
        && write_atomic(
            &dir.join("surface.json"),
            &serde_json::to_vec(&surface_value).unwrap_or_default(),
        )
        .is_ok();
    let outputs_ms = ms(t2);
    let total_ms = ms(t0);
    // One-sided: trimmed tessellation vertices to the data mesh.
    let data = &loaded.mesh;
    let md = MeshDistance::new(data);
    let mut used = vec![false; tess.positions.len()];
    for t in &tess.triangles {
        for &v in t {
            used[v as usize] = true;
        }
    }
    let distances = |md: &MeshDistance| {
        let mut d: Vec<f64> = tess
            .positions
            .par_iter()
            .zip(used.par_iter())
            .filter(|(_, u)| **u)
            .filter_map(|(p, _)| md.distance(*p))
            .collect();
        d.sort_by(f64::total_cmp);
        d
    };
    let dist = distances(&md);
    let pct = |d: &[f64], q: f64| {
        d.get(((d.len().max(1) - 1) as f64 * q) as usize)
            .copied()
            .unwrap_or(0.0)
    };
    // Over holes the data mesh is far by construction; the filled patch (holes closed flat
    // in the plane) is what a surface without bulges stays near.
    let filled = fitted.scan.as_ref().map_or_else(
        || dist.clone(),
        |s| distances(&MeshDistance::new(&s.mapping.filled)),
    );
    // The other side: the fitted points to what is shown (the trimmed tessellation), the
    // share within 1 mm (Stanford scale; 1/1000 of the diagonal elsewhere).
    let shown = trispline::TriMesh {
        positions: tess.positions.clone(),
        triangles: tess.triangles.clone(),
    };
    let near = if unit.1 == "um" {
        1e-3
    } else {
        1e-3 * loaded.mesh.bounds_diagonal()
    };
    let within = shown_share(&shown, &f.data, near);
    let dropped = fitted.scan.as_ref().map_or_else(String::new, |s| {
        let d = s.preparation.dropped;
        format!(
            "{} of {}, {:.2}% (largest {})",
            d.pieces,
            s.preparation.components,
            100.0 * d.share,
            d.largest
        )
    });
    let (prepare_ms, fit_ms) = (f.prepare_ms, f.fit_ms);
    let map = fitted.scan.as_ref().map_or("subdivision".to_string(), |s| {
        format!(
            "{:?}, {} folds",
            s.mapping.method, s.mapping.folds_projected
        )
    });
    println!(
        "| {rel} | {surface:?} | {} | {} ({:.1}%) | {:.4} {u} | {:.4} {u} | {:?} | {read_ms:.0} | {prepare_ms:.0} | {fit_ms:.0} | {outputs_ms:.0}{} | {total_ms:.0} (fit_patch {fit_total:.0}) | {:.4} {u} | {:.4} {u} | {:.4} {u} | {:.4} {u} | {:.3}% | {dropped} | {map}; diagonal {:.4} |",
        f.data.len(),
        f.controls.len(),
        100.0 * f.controls.len() as f64 / f.data.len().max(1) as f64,
        f.geometric_max() * unit.0,
        f.geometric_rms() * unit.0,
        f.outcome.status,
        if written { "" } else { " (write failed)" },
        pct(&dist, 1.0) * unit.0,
        pct(&dist, 0.999) * unit.0,
        pct(&filled, 1.0) * unit.0,
        pct(&filled, 0.999) * unit.0,
        100.0 * within,
        loaded.mesh.bounds_diagonal() * unit.0,
        u = unit.1,
    );
}

/// Share of `points` within `near` of `shown` (none when nothing is shown).
fn shown_share(shown: &trispline::TriMesh, points: &[glam::DVec3], near: f64) -> f64 {
    if shown.triangles.is_empty() || points.is_empty() {
        return 0.0;
    }
    let md = MeshDistance::new(shown);
    let inside = points
        .par_iter()
        .filter(|p| md.distance(**p).is_some_and(|d| d <= near))
        .count();
    inside as f64 / points.len() as f64
}

/// Every scan's pieces after cleaning, largest first, and what fitting only the largest
/// leaves out: the numbers the component default is chosen on.
fn pieces_table(root: &Path, files: &[&str]) {
    println!(
        "| file | vertices | pieces | sizes (largest first, top 8) | `largest` drops | share |"
    );
    println!("|---|---|---|---|---|---|");
    for rel in files.iter().filter(|r| r.starts_with("range_scans")) {
        let Ok(loaded) = read_mesh_file(&root.join(rel), &LoadOptions::default()) else {
            println!("| {rel} | unreadable |");
            continue;
        };
        let cleaned = clean(&loaded.mesh, &CleanOptions::default());
        let sizes: Vec<usize> = cleaned_components(&cleaned)
            .iter()
            .map(|p| p.positions.len())
            .collect();
        let total: usize = sizes.iter().sum();
        let dropped: usize = sizes.iter().skip(1).sum();
        println!(
            "| {rel} | {total} | {} | {:?} | {dropped} | {:.2}% |",
            sizes.len(),
            &sizes[..sizes.len().min(8)],
            100.0 * dropped as f64 / total.max(1) as f64
        );
    }
    println!();
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
