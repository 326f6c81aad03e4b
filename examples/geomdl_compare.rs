//! Side by side with NURBS-Python (geomdl) `approximate_surface`: the same 30 x 30 grid,
//! a 12 x 12 bicubic control net, on a synthetic surface and on a 30 x 30 window of
//! `bun000_range_grid.ply` (coordinates scaled to millimetres). Both control nets are
//! measured by the same routine: distance at the data parameters (chord-length averaged,
//! which is what both programs use) and the true point-to-surface distance (Newton
//! foot points).
//!
//!     cargo run --release --example geomdl_compare
//!
//! Needs python3; `examples/geomdl_compare.py` installs geomdl with pip when missing.

use std::path::Path;
use std::process::Command;
use std::time::Instant;
use trispline::bspline::basis::ParamMethod;
use trispline::bspline::fit::{fit_grid, grid_parameters, ErrorStats, Grid, GridMethod};
use trispline::bspline::scattered::{fit_scattered, ScatteredOptions, ScatteredSolver};
use trispline::bspline::BSplineSurface;
use trispline::io::surface_json::{parse_surface_json, SurfaceDescription};
use trispline::DVec3;

const N: usize = 30;
const C: usize = 12;

fn synthetic() -> Vec<DVec3> {
    // A 60 mm square patch with two bumps and a fold: more detail than 12 x 12 can carry.
    (0..N * N)
        .map(|k| {
            let (x, y) = ((k / N) as f64 * 2.0, (k % N) as f64 * 2.0);
            let z = 6.0 * (-((x - 20.0).powi(2) + (y - 35.0).powi(2)) / 120.0).exp()
                - 4.0 * (-((x - 42.0).powi(2) + (y - 18.0).powi(2)) / 60.0).exp()
                + 1.5 * (x / 7.0).sin() * (y / 11.0).cos();
            DVec3::new(x, y, z)
        })
        .collect()
}

/// A fully valid N x N window of the range grid, the one nearest the middle of the
/// scanned cells, in millimetres.
fn bunny_window() -> Option<(Vec<DVec3>, (usize, usize))> {
    let path = trispline::testdata::shared_data("range_scans/bun000_range_grid.ply")?;
    let loaded = trispline::io::read_mesh_file(&path, &Default::default()).ok()?;
    let g = loaded.grid?;
    let valid = |r: usize, c: usize| g.points[r * g.cols + c].is_some();
    let (mut sr, mut sc, mut n) = (0.0, 0.0, 0.0);
    for r in 0..g.rows {
        for c in 0..g.cols {
            if valid(r, c) {
                sr += r as f64;
                sc += c as f64;
                n += 1.0;
            }
        }
    }
    let (mr, mc) = (sr / n, sc / n);
    // Summed-area table of valid cells: a window is complete when its sum is N * N.
    let w = g.cols + 1;
    let mut sat = vec![0u32; (g.rows + 1) * w];
    for r in 0..g.rows {
        for c in 0..g.cols {
            sat[(r + 1) * w + c + 1] =
                valid(r, c) as u32 + sat[r * w + c + 1] + sat[(r + 1) * w + c] - sat[r * w + c];
        }
    }
    let mut best: Option<(f64, usize, usize)> = None;
    for r in 0..=g.rows - N {
        for c in 0..=g.cols - N {
            let s = sat[(r + N) * w + c + N] + sat[r * w + c]
                - sat[r * w + c + N]
                - sat[(r + N) * w + c];
            if s as usize == N * N {
                let d = (r as f64 + N as f64 / 2.0 - mr).hypot(c as f64 + N as f64 / 2.0 - mc);
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, r, c));
                }
            }
        }
    }
    let (_, r0, c0) = best?;
    let pts = (0..N * N)
        .filter_map(|k| g.points[(r0 + k / N) * g.cols + c0 + k % N])
        .map(|p| p * 1000.0)
        .collect();
    Some((pts, (r0, c0)))
}

struct Measured {
    param: ErrorStats,
    geometric: ErrorStats,
}

/// The one error routine applied to every control net.
fn measure(s: &BSplineSurface, pts: &[DVec3], us: &[f64], vs: &[f64]) -> Measured {
    let mut pe = Vec::new();
    let mut ge = Vec::new();
    for (k, d) in pts.iter().enumerate() {
        let (u, v) = (us[k / N], vs[k % N]);
        pe.push((s.point(u, v) - *d).length());
        ge.push(s.closest_point(*d, (u, v)).1);
    }
    Measured {
        param: ErrorStats::of(&pe),
        geometric: ErrorStats::of(&ge),
    }
}

fn time_ours(grid: &Grid, method: GridMethod) -> (f64, BSplineSurface) {
    let run = || fit_grid(grid, (C, C), (3, 3), ParamMethod::ChordLength, method).expect("fit");
    let mut s = run().surface;
    let mut per_call = Vec::new();
    let t_all = Instant::now();
    while t_all.elapsed().as_secs_f64() < 0.5 || per_call.len() < 5 {
        let t = Instant::now();
        for _ in 0..50 {
            s = std::hint::black_box(run()).surface;
        }
        per_call.push(t.elapsed().as_secs_f64() * 1e3 / 50.0);
    }
    per_call.sort_by(f64::total_cmp);
    (per_call[per_call.len() / 2], s)
}

fn run_geomdl(dir: &Path, name: &str, pts: &[DVec3]) -> Option<(f64, BSplineSurface, String)> {
    let grid_file = dir.join(format!("{name}.txt"));
    let mut text = format!("{N} {N}\n");
    for p in pts {
        text.push_str(&format!("{:.17e} {:.17e} {:.17e}\n", p.x, p.y, p.z));
    }
    std::fs::write(&grid_file, text).ok()?;
    let out = dir.join(format!("{name}_geomdl.json"));
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/geomdl_compare.py");
    let status = Command::new("python3")
        .arg(&script)
        .arg(&grid_file)
        .arg(&out)
        .args(["12", "12", "3", "3", "20"])
        .status();
    if !status.as_ref().is_ok_and(|s| s.success()) {
        eprintln!("geomdl run failed ({status:?}); is python3 with pip available?");
        return None;
    }
    let bytes = std::fs::read(&out).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&bytes).ok()?;
    // Reuse our schema reader: the peer's JSON has the same keys plus a schema tag.
    let mut tagged = v.clone();
    tagged["schema"] = "trispline.surface/1".into();
    tagged["kind"] = "bspline".into();
    let s = match parse_surface_json(&serde_json::to_vec(&tagged).ok()?, "geomdl").ok()? {
        SurfaceDescription::BSpline(s) => s,
        _ => return None,
    };
    let version = format!(
        "geomdl {} (python {})",
        v["geomdl_version"].as_str()?,
        v["python"].as_str()?
    );
    Some((v["ms_median"].as_f64()?, s, version))
}

fn report(label: &str, pts: &[DVec3]) {
    let grid = Grid {
        rows: N,
        cols: N,
        points: pts,
    };
    let (us, vs) = grid_parameters(&grid, ParamMethod::ChordLength);
    let dir = tempfile::tempdir().expect("temp dir");
    println!("\n## {label}: {N}x{N} grid -> {C}x{C} bicubic\n");
    println!("| fit | time (ms) | max err (param) | RMS (param) | max err (geometric) | RMS (geometric) |");
    println!("|---|---:|---:|---:|---:|---:|");
    let mut ours = Vec::new();
    for (name, method) in [
        ("trispline lsq", GridMethod::Lsq),
        ("trispline two-pass", GridMethod::TwoPass),
    ] {
        let (ms, s) = time_ours(&grid, method);
        let m = measure(&s, pts, &us, &vs);
        println!(
            "| {name} | {ms:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
            m.param.max_error, m.param.rms_error, m.geometric.max_error, m.geometric.rms_error
        );
        ours.push((name, ms, m, s));
    }
    // The full least-squares fit with the grid parameters as a start and two rounds of
    // foot-point parameter correction (the grid structure is given up after the first).
    let params: Vec<(f64, f64)> = us
        .iter()
        .flat_map(|&u| vs.iter().map(move |&v| (u, v)))
        .collect();
    let o = ScatteredOptions {
        counts: (C, C),
        degrees: (3, 3),
        smoothing: 0.0,
        solver: ScatteredSolver::Direct,
        parameter_correction: 2,
    };
    let t = Instant::now();
    let mut reps = 0;
    let mut fit = None;
    while t.elapsed().as_secs_f64() < 0.5 || reps < 3 {
        fit = Some(fit_scattered(pts, &params, &o).expect("fit"));
        reps += 1;
    }
    let ms = t.elapsed().as_secs_f64() * 1e3 / reps as f64;
    if let Some(f) = fit {
        let m = measure(&f.surface, pts, &us, &vs);
        let name = "trispline lsq + 2 parameter corrections";
        println!(
            "| {name} | {ms:.4} | {:.4} | {:.4} | {:.4} | {:.4} |",
            m.param.max_error, m.param.rms_error, m.geometric.max_error, m.geometric.rms_error
        );
        ours.push((name, ms, m, f.surface));
    }
    match run_geomdl(dir.path(), label, pts) {
        Some((ms, s, version)) => {
            let m = measure(&s, pts, &us, &vs);
            println!(
                "| {version} approximate_surface | {ms:.3} | {:.4} | {:.4} | {:.4} | {:.4} |",
                m.param.max_error, m.param.rms_error, m.geometric.max_error, m.geometric.rms_error
            );
            for (name, t, mm, so) in &ours {
                let net = so
                    .controls()
                    .iter()
                    .zip(s.controls())
                    .map(|(a, b)| (*a - *b).length())
                    .fold(0.0, f64::max);
                println!(
                    "\n{name}: {:.0}x faster than geomdl; max error (geometric) {:.4} vs {:.4} ({}); control nets differ by up to {net:.2e} mm",
                    ms / t,
                    mm.geometric.max_error,
                    m.geometric.max_error,
                    if mm.geometric.max_error <= m.geometric.max_error * (1.0 + 1e-9) { "equal or lower" } else { "HIGHER" }
                );
            }
        }
        None => println!("\n(geomdl not run)"),
    }
}

fn main() {
    println!("errors in mm; time per fit (median); ours includes computing its errors");
    println!("param: |S(u_k, v_k) - D_k| at the grid's averaged chord-length parameters (the data");
    println!("parameters of both grid fits; not the corrected ones of the last trispline row);");
    println!(
        "geometric: distance to the Newton foot point started there (same routine for every net)"
    );
    report("synthetic", &synthetic());
    match bunny_window() {
        Some((pts, (r, c))) => report(
            &format!("bun000 rows {r}..{} cols {c}..{}", r + N, c + N),
            &pts,
        ),
        None => println!("\n(bun000_range_grid.ply not found: bunny window skipped)"),
    }
}
