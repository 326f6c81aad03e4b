//! What a user sees of every Stanford scan, with the default settings: the worker's GLB
//! read back from its bytes, and the share of the fitted points within 1 mm of it (the
//! fitted points being the cleaned input's kept components, found here independently of
//! the report), for the component policies `largest` and `all`. Also: the share of all
//! input points within 1 mm of anything shown, the farthest shown vertex from the input
//! (garbage would be far), RMS, control points, dropped share and the worker's time.
//!
//!     cargo run --release --example shown_coverage [-- DATA_DIR [largest|all|both [SURFACE [FILE]]]]
//!
//! SURFACE: `loop` (default), `bezier`, `dms`, `bpatch`; FILE: only the scans whose path
//! contains it.

use rayon::prelude::*;
use std::path::PathBuf;
use std::time::Instant;
use trispline::io::{read_mesh_bytes, read_mesh_file, Format, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::scan::components::{cleaned_components, ComponentMode};
use trispline::pipeline::worker::{run_input, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::{DVec3, TriMesh};

#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

const NEAR: f64 = 1e-3;

fn main() {
    trispline::allocator::keep_freed_memory();
    trispline::allocator::small_pages_only();
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let modes: Vec<ComponentMode> = match std::env::args().nth(2).as_deref() {
        Some("largest") => vec![ComponentMode::Largest],
        Some("all") => vec![ComponentMode::All],
        _ => vec![ComponentMode::Largest, ComponentMode::All],
    };
    let surface: SurfaceKind = match std::env::args().nth(3) {
        Some(name) => name.parse().unwrap_or_else(|e| panic!("{e}")),
        None => SurfaceKind::Loop,
    };
    let only = std::env::args().nth(4);
    let files = trispline::testdata::STANFORD_SCANS;
    println!("| file | components | parts | fitted pts | fitted within 1 mm | input within 1 mm | not fitted (share) | worst rms um | max ctrl % | shown->input max um | worker ms |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for rel in files {
        if only.as_deref().is_some_and(|o| !rel.contains(o)) {
            continue;
        }
        let Ok(loaded) = read_mesh_file(&root.join(rel), &LoadOptions::default()) else {
            println!("| {rel} | missing |");
            continue;
        };
        for &mode in &modes {
            row(rel, &loaded.mesh, mode, surface);
        }
    }
}

fn row(rel: &str, mesh: &TriMesh, mode: ComponentMode, surface: SurfaceKind) {
    let mut cfg = WorkerConfig::default();
    cfg.fit.surface = surface;
    cfg.fit.components.mode = mode;
    let t = Instant::now();
    let outputs = match run_input(mesh, None, &cfg) {
        Ok(o) => o,
        Err(e) => {
            println!("| {rel} | {mode:?} | refused: {e} |");
            return;
        }
    };
    let worker_ms = t.elapsed().as_secs_f64() * 1e3;
    // The fitted points: what the worker's component policy keeps of the cleaned input.
    let cleaned = clean(mesh, &CleanOptions::default());
    let pieces = cleaned_components(&cleaned);
    let total: usize = pieces.iter().map(|p| p.positions.len()).sum();
    let fitted: Vec<TriMesh> = match mode {
        ComponentMode::Largest => pieces.into_iter().take(1).collect(),
        // The worker's filter: at least `min_vertices`, and `min_fraction` of the largest.
        ComponentMode::All => {
            let c = &cfg.fit.components;
            let largest = pieces.first().map_or(0, |p| p.positions.len()) as f64;
            pieces
                .into_iter()
                .filter(|p| {
                    let n = p.positions.len();
                    n >= c.min_vertices && n as f64 >= c.min_fraction * largest
                })
                .collect()
        }
    };
    let mut shown_all = TriMesh::default();
    let (mut within, mut points, mut worst_rms, mut max_ctrl) = (0usize, 0usize, 0.0f64, 0.0f64);
    for (part, data) in outputs.parts.iter().zip(&fitted) {
        let Ok(shown) = read_mesh_bytes(
            &part.outputs.glb,
            Format::Glb,
            "glb",
            &LoadOptions::default(),
        ) else {
            println!("| {rel} | {mode:?} | unreadable GLB |");
            return;
        };
        within += count_within(&shown.mesh, &data.positions);
        points += data.positions.len();
        let r = &part.outputs.report;
        worst_rms = worst_rms.max(
            r["final"]["geometric_rms_error"]
                .as_f64()
                .unwrap_or(f64::NAN),
        );
        let share =
            r["control_points"].as_f64().unwrap_or(0.0) / r["data_points"].as_f64().unwrap_or(1.0);
        max_ctrl = max_ctrl.max(share);
        append(&mut shown_all, &shown.mesh);
    }
    let input_within = count_within(&shown_all, &cleaned_positions(&cleaned));
    let garbage = farthest(&shown_all, mesh);
    println!(
        "| {rel} | {mode:?} | {} | {points} | {:.3}% | {:.3}% | {} ({:.2}%) | {:.1} | {:.2} | {:.0} | {worker_ms:.0} |",
        outputs.parts.len(),
        100.0 * within as f64 / points.max(1) as f64,
        100.0 * input_within as f64 / total.max(1) as f64,
        total - points,
        100.0 * (total - points) as f64 / total.max(1) as f64,
        worst_rms * 1e6,
        100.0 * max_ctrl,
        garbage * 1e6,
    );
}

fn cleaned_positions(cleaned: &trispline::mesh::clean::Cleaned) -> Vec<DVec3> {
    cleaned_components(cleaned)
        .into_iter()
        .flat_map(|p| p.positions)
        .collect()
}

fn count_within(shown: &TriMesh, points: &[DVec3]) -> usize {
    if shown.triangles.is_empty() {
        return 0;
    }
    let md = MeshDistance::new(shown);
    points
        .par_iter()
        .filter(|p| md.distance(**p).is_some_and(|d| d <= NEAR))
        .count()
}

/// The farthest shown vertex from the input mesh.
fn farthest(shown: &TriMesh, input: &TriMesh) -> f64 {
    let md = MeshDistance::new(input);
    shown
        .positions
        .par_iter()
        .filter_map(|p| md.distance(*p))
        .reduce(|| 0.0, f64::max)
}

fn append(to: &mut TriMesh, m: &TriMesh) {
    let base = to.positions.len() as u32;
    to.positions.extend_from_slice(&m.positions);
    to.triangles
        .extend(m.triangles.iter().map(|t| t.map(|v| v + base)));
}
