//! Curvature analysis timings (the document: 0.35 s at 41 x 41, 5.7 s at 201 x 201 in
//! Matlab with finite differences). Prints the median of repeated runs per phase.
//!
//!     cargo run --release --example curvature_bench

use std::time::Instant;
use trispline::bspline::basis::ParamMethod;
use trispline::bspline::fit::{fit_grid, interpolate_grid, Grid, GridMethod};
use trispline::curvature::regions::{analyze, AnalysisOptions};
use trispline::curvature::{BezierPatch, DerivativeSurface, RegionKind, Triangular};
use trispline::surface::bezier::{lattice_points, BezierTriangle};
use trispline::DVec3;

fn sin_sin_bspline() -> trispline::bspline::BSplineSurface {
    let (rows, cols) = (121, 41);
    let pts: Vec<DVec3> = (0..rows * cols)
        .map(|k| {
            let x = -3.0 + 6.0 * (k / cols) as f64 / (rows - 1) as f64;
            let y = 0.1 + 1.3 * (k % cols) as f64 / (cols - 1) as f64;
            DVec3::new(x, y, x.sin() * y.sin())
        })
        .collect();
    let grid = Grid {
        rows,
        cols,
        points: &pts,
    };
    interpolate_grid(&grid, (3, 3), ParamMethod::Uniform)
        .expect("fit")
        .surface
}

fn bunny_bspline() -> Option<trispline::bspline::BSplineSurface> {
    let path = trispline::testdata::shared_data("range_scans/bun000_range_grid.ply")?;
    let g = trispline::io::read_mesh_file(&path, &Default::default())
        .ok()?
        .grid?;
    let pts: Vec<DVec3> = (0..900)
        .map(|k| g.points[(98 + k / 30) * g.cols + 192 + k % 30])
        .collect::<Option<Vec<_>>>()?;
    let grid = Grid {
        rows: 30,
        cols: 30,
        points: &pts,
    };
    fit_grid(
        &grid,
        (12, 12),
        (3, 3),
        ParamMethod::ChordLength,
        GridMethod::Lsq,
    )
    .ok()
    .map(|f| f.surface)
}

fn bezier_triangle(n: usize) -> Triangular<BezierTriangle> {
    let controls = lattice_points(n)
        .into_iter()
        .map(|(i, j)| {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            DVec3::new(x, y, (6.0 * x).sin() * (5.0 * y).cos() * 0.2)
        })
        .collect();
    Triangular {
        surface: BezierTriangle::new(n),
        controls,
    }
}

fn bench(label: &str, s: &dyn DerivativeSurface, grid: usize) {
    let o = AnalysisOptions {
        grid,
        ..Default::default()
    };
    let first = Instant::now();
    let a = analyze(s, &o);
    let first_ms = first.elapsed().as_secs_f64() * 1e3;
    let mut runs = Vec::new();
    let t = Instant::now();
    while t.elapsed().as_secs_f64() < 1.0 || runs.len() < 5 {
        let s0 = Instant::now();
        let a = analyze(s, &o);
        runs.push((s0.elapsed().as_secs_f64() * 1e3, a.timings_ms));
    }
    runs.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (med, ph) = runs[runs.len() / 2];
    println!(
        "| {label} | {grid}x{grid} | {med:.2} | {:.2} / {:.2} / {:.2} | {first_ms:.2} | {} / {} / {} |",
        ph.sampling,
        ph.labelling,
        ph.tracing,
        a.count(RegionKind::Convex),
        a.count(RegionKind::Concave),
        a.count(RegionKind::Saddle)
    );
}

fn main() {
    println!(
        "rayon threads: {}; median of repeated runs (first run separately)\n",
        rayon::current_num_threads()
    );
    println!("| surface | samples | median ms | sampling / labelling / tracing | first run ms | convex / concave / saddle |");
    println!("|---|---|---:|---|---:|---|");
    let s = sin_sin_bspline();
    for g in [41, 201] {
        bench("bicubic B-spline 121x41, sin x sin y", &s, g);
    }
    if let Some(b) = bunny_bspline() {
        for g in [41, 201] {
            bench("bicubic B-spline 12x12, bun000 window", &b, g);
        }
    }
    let t = bezier_triangle(16);
    for g in [41, 201] {
        bench("triangular Bezier degree 16 (basis rows)", &t, g);
    }
    let fast = BezierPatch {
        degree: 16,
        controls: t.controls.clone(),
    };
    for g in [41, 201] {
        bench("triangular Bezier degree 16 (de Casteljau)", &fast, g);
    }
}
