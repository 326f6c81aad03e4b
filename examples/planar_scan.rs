//! Issue 24's acceptance on real range scans: the worker's DMS fits (degree 2 and 3) and a
//! B-patch against the Loop grid fit at a similar control count (`fit.scan.
//! target_controls_pct` sets both), geometric RMS / max (foot-point distances of every data
//! point), wall time through `pipeline::worker::fit_patch` and the speed of evaluating the
//! fitted surface per point (values with first and second derivatives, one thread and all).
//!
//! Run: cargo run --release --example planar_scan [-- FILE... ]
//! (default: range_scans/bun045_tri.ply and range_scans/registered/bun180.ply).

use std::time::Instant;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::pipeline::worker::{fit_patch, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::surface::SurfaceParam;
use trispline::testdata::shared_data;

fn row(label: &str, mesh: &trispline::TriMesh, cfg: &WorkerConfig, loop_rms: Option<f64>) -> f64 {
    let t = Instant::now();
    let fitted = match fit_patch(mesh, None, cfg) {
        Ok(f) => f,
        Err(e) => {
            println!("| {label} | failed: {e} |");
            return f64::NAN;
        }
    };
    let wall = t.elapsed().as_secs_f64() * 1e3;
    let f = &fitted.fit;
    let rms = f.geometric_rms();
    let surface = f.model.as_surface();
    let eval = surface.evaluator(&f.controls);
    let params: &[SurfaceParam] = &f.params;
    let t = Instant::now();
    let mut acc = 0.0;
    for p in params {
        acc += eval(*p).position.x;
    }
    let one = t.elapsed().as_secs_f64() * 1e6 / params.len().max(1) as f64;
    std::hint::black_box(acc);
    let faces = surface.domain_face_count();
    let ratio = loop_rms.map_or(String::from("1"), |l| format!("{:.2}", rms / l));
    println!(
        "| {label} | {} | {} | {faces} | {:.1} | {:.3} | {ratio} | {:?} | {} | {wall:.0} | {one:.2} |",
        f.data.len(),
        f.controls.len(),
        rms * 1e6,
        f.geometric_max() * 1e3,
        f.outcome.status,
        f.outcome.iterations,
    );
    rms
}

/// `PLANAR_SWEEP=1`: DMS degree 2 (direct) on the first file over knot spreads, smoothing
/// weights and control shares, with the RMS after each round: what limits DMS on scans.
fn sweep(mesh: &trispline::TriMesh) {
    println!("| degree | spread | smoothing | controls % | controls | triangles | rms um per round | fit ms |");
    println!("|---|---|---|---|---|---|---|---|");
    let cases: [(usize, f64, f64, f64); 9] = [
        (2, 0.3, 1e-5, 5.0),
        (2, 0.1, 1e-5, 5.0),
        (2, 0.6, 1e-5, 5.0),
        (2, 0.9, 1e-5, 5.0),
        (2, 0.3, 0.0, 5.0),
        (2, 0.3, 1e-3, 5.0),
        (2, 0.3, 1e-5, 10.0),
        (2, 0.3, 1e-5, 20.0),
        (3, 0.3, 1e-5, 10.0),
    ];
    for (degree, spread, smoothing, pct) in cases {
        let mut cfg = WorkerConfig::default();
        cfg.fit.surface = SurfaceKind::Dms;
        cfg.fit.method = trispline::fit::Method::Direct;
        cfg.fit.dms.degree = degree;
        cfg.fit.dms.knot_spread = spread;
        cfg.fit.scan.smoothing = smoothing;
        cfg.fit.scan.target_controls_pct = pct;
        let t = Instant::now();
        match fit_patch(mesh, None, &cfg) {
            Ok(f) => {
                let rounds: Vec<String> = f
                    .scattered
                    .as_ref()
                    .map(|i| {
                        i.correction_rms
                            .iter()
                            .map(|r| format!("{:.1}", r * 1e6))
                            .collect()
                    })
                    .unwrap_or_default();
                println!(
                    "| {degree} | {spread} | {smoothing:e} | {pct} | {} | {} | {} | {:.0} |",
                    f.fit.controls.len(),
                    f.fit.model.as_surface().domain_face_count(),
                    rounds.join(" "),
                    t.elapsed().as_secs_f64() * 1e3
                );
            }
            Err(e) => println!("| {degree} | {spread} | {smoothing:e} | {pct} | failed: {e} |"),
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let files: Vec<std::path::PathBuf> = if args.is_empty() {
        [
            "range_scans/bun045_tri.ply",
            "range_scans/registered/bun180.ply",
        ]
        .iter()
        .filter_map(|r| shared_data(r))
        .collect()
    } else {
        args.iter().map(Into::into).collect()
    };
    for file in files {
        let mesh = match read_mesh_file(&file, &LoadOptions::default()) {
            Ok(l) => l.mesh,
            Err(e) => {
                println!("{}: {e}", file.display());
                continue;
            }
        };
        println!("\n{} ({} vertices)", file.display(), mesh.positions.len());
        if std::env::var("PLANAR_SWEEP").is_ok_and(|v| v == "1") {
            sweep(&mesh);
            return;
        }
        println!("| surface | points | controls | domain faces | rms um | max mm | rms / loop | status | steps (last round) | fit ms | eval us/point (1 thread, with derivatives) |");
        println!("|---|---|---|---|---|---|---|---|---|---|---|");
        let mut cfg = WorkerConfig::default();
        cfg.fit.surface = SurfaceKind::Loop;
        let loop_rms = row("loop (grid)", &mesh, &cfg, None);
        for degree in [2, 3] {
            for method in [trispline::fit::Method::Cg, trispline::fit::Method::Direct] {
                let mut cfg = WorkerConfig::default();
                cfg.fit.surface = SurfaceKind::Dms;
                cfg.fit.dms.degree = degree;
                cfg.fit.method = method;
                row(
                    &format!("dms {degree} ({method:?})"),
                    &mesh,
                    &cfg,
                    Some(loop_rms),
                );
            }
        }
        let mut cfg = WorkerConfig::default();
        cfg.fit.surface = SurfaceKind::Bpatch;
        row("bpatch 8", &mesh, &cfg, Some(loop_rms));
    }
}
