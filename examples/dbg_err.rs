use trispline::io::{read_mesh_file, LoadOptions};
use trispline::pipeline::scan::{fit_scan, ScanOptions};
use trispline::pipeline::worker::{resolve_budget, WorkerConfig};
use trispline::pipeline::{FitOptions, SurfaceKind};
fn main() {
    let path = std::env::args().nth(1).unwrap();
    let m = read_mesh_file(std::path::Path::new(&path), &LoadOptions::default())
        .unwrap()
        .mesh;
    let cfg = WorkerConfig {
        surface: SurfaceKind::Loop,
        ..WorkerConfig::default()
    };
    let opts = FitOptions {
        surface: cfg.surface,
        levels: cfg.levels,
        method: cfg.method,
        inverse: cfg.inverse,
        budget: resolve_budget(&cfg, &m),
    };
    let pct: f64 = std::env::args()
        .nth(2)
        .map(|s| s.parse().unwrap())
        .unwrap_or(4.0);
    let sm: f64 = std::env::args()
        .nth(3)
        .map(|s| s.parse().unwrap())
        .unwrap_or(1e-5);
    let so = ScanOptions {
        lattice: 16,
        grid_segments: None,
        target_controls_pct: pct,
        smoothing: sm,
        correction_rounds: std::env::args()
            .nth(4)
            .map(|s| s.parse().unwrap())
            .unwrap_or(2),
        correction: if std::env::args().nth(5).is_some() {
            trispline::pipeline::scan::Correction::Parameters
        } else {
            trispline::pipeline::scan::Correction::Distance
        },
    };
    let s = fit_scan(&m, &opts, &so, None).unwrap();
    let f = &s.fit;
    let n = s.frame.normal();
    let mut e: Vec<(f64, f64)> = Vec::new();
    // per-vertex normal from data: use the surface normal at the param
    let surf = f.model.as_surface();
    for (k, p) in f.params.iter().enumerate() {
        let d = surf.evaluate(&f.controls, *p);
        let nn = d.du.cross(d.dv).normalize_or_zero();
        e.push((f.geometric_errors[k], nn.dot(n).abs()));
    }
    let mut sorted: Vec<f64> = e.iter().map(|x| x.0).collect();
    sorted.sort_by(f64::total_cmp);
    let q = |x: f64| sorted[((sorted.len() - 1) as f64 * x) as usize] * 1e6;
    eprintln!(
        "normal {:?} folds {} map {:?}",
        s.frame.normal(),
        s.folds_projected,
        s.map_method
    );
    println!(
        "controls {} rms {:.0} p50 {:.0} p90 {:.0} p99 {:.0} p999 {:.0} max {:.0}",
        f.controls.len(),
        f.geometric_rms() * 1e6,
        q(0.5),
        q(0.9),
        q(0.99),
        q(0.999),
        q(1.0)
    );
    // distance (in grid cells) to the nearest trim vertex, bucketed
    let trim = &s.trim;
    let mut by_d: Vec<Vec<f64>> = vec![Vec::new(); 6];
    for (k, p) in f.params.iter().enumerate() {
        let d = trim
            .iter()
            .map(|t| ((t.0 - p.u).powi(2) + (t.1 - p.v).powi(2)).sqrt())
            .fold(f64::MAX, f64::min);
        by_d[(d as usize).min(5)].push(f.geometric_errors[k]);
    }
    for (d, v) in by_d.iter().enumerate() {
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
        let big = v.iter().filter(|x| **x > 300e-6).count();
        println!(
            "cells from trim {d}: {} points rms {:.0} um, >300um: {}",
            v.len(),
            rms * 1e6,
            big
        );
    }
    for (lo, hi) in [(0.0, 0.3), (0.3, 0.5), (0.5, 0.7), (0.7, 0.9), (0.9, 1.01)] {
        let sel: Vec<f64> = e
            .iter()
            .filter(|x| x.1 >= lo && x.1 < hi)
            .map(|x| x.0)
            .collect();
        let rms = (sel.iter().map(|x| x * x).sum::<f64>() / sel.len().max(1) as f64).sqrt();
        println!(
            "|n.view| in [{lo},{hi}): {} points rms {:.0} um",
            sel.len(),
            rms * 1e6
        );
    }
}
