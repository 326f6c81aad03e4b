//! Issue 24's speed goal on the product path: `pipeline::worker::fit_patch` with a DMS
//! surface on the 40k-point range scans bun045_tri and registered bun180, per stage (the
//! scan's preparation and domain, the first fit, the foot points, the rounds' collocation
//! rows and their solves), wall and process CPU time, min of N runs, with the load average
//! before the runs (the machine may be shared: CPU time is the figure that load does not
//! inflate much).
//!
//! Run: cargo run --release --example dms_stages [-- --degree 3] [--runs N] [FILE...]

use std::time::Instant;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::pipeline::scattered::{process_cpu_ms, PlanarStages, StageTime};
use trispline::pipeline::worker::{fit_patch, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::testdata::shared_data;

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "?".into())
}

/// One run's figures: total wall, total CPU, prepare wall, and the stages.
struct Run {
    wall: f64,
    cpu: f64,
    prepare: f64,
    stages: PlanarStages,
    rms: Vec<f64>,
    controls: usize,
    points: usize,
}

fn min_of(runs: &[Run], f: impl Fn(&Run) -> f64) -> f64 {
    runs.iter().map(f).fold(f64::INFINITY, f64::min)
}

fn stage_cell(runs: &[Run], stage: impl Fn(&PlanarStages) -> StageTime) -> String {
    let calls = runs.first().map_or(0, |r| stage(&r.stages).calls);
    format!(
        "{:.0} / {:.0} ({calls}x)",
        min_of(runs, |r| stage(&r.stages).wall_ms),
        min_of(runs, |r| stage(&r.stages).cpu_ms)
    )
}

fn measure(label: &str, mesh: &trispline::TriMesh, cfg: &WorkerConfig, runs: usize) {
    let load = load_average();
    let mut done = Vec::new();
    for _ in 0..runs {
        let (t, c) = (Instant::now(), process_cpu_ms());
        let fitted = match fit_patch(mesh, None, cfg) {
            Ok(f) => f,
            Err(e) => {
                println!("| {label} | failed: {e} |");
                return;
            }
        };
        let (wall, cpu) = (t.elapsed().as_secs_f64() * 1e3, process_cpu_ms() - c);
        let Some(info) = fitted.scattered.as_ref() else {
            println!("| {label} | no planar-fit info |");
            return;
        };
        done.push(Run {
            wall,
            cpu,
            prepare: fitted.fit.prepare_ms,
            stages: info.stages,
            rms: info.correction_rms.clone(),
            controls: fitted.fit.controls.len(),
            points: fitted.fit.data.len(),
        });
    }
    let Some(last) = done.last() else { return };
    let rms: Vec<String> = last.rms.iter().map(|r| format!("{:.1}", r * 1e6)).collect();
    println!(
        "| {label} | {} | {} | {load} -> {} | {:.0} / {:.0} | {:.0} | {} | {} | {} | {} | {} |",
        last.points,
        last.controls,
        load_average(),
        min_of(&done, |r| r.wall),
        min_of(&done, |r| r.cpu),
        min_of(&done, |r| r.prepare),
        stage_cell(&done, |s| s.first_fit),
        stage_cell(&done, |s| s.feet),
        stage_cell(&done, |s| s.rows),
        stage_cell(&done, |s| s.solves),
        rms.join(" -> "),
    );
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut degree = 2;
    let mut runs = 5;
    let mut files = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--degree" => degree = it.next().and_then(|v| v.parse().ok()).unwrap_or(2),
            "--runs" => runs = it.next().and_then(|v| v.parse().ok()).unwrap_or(5),
            f => files.push(std::path::PathBuf::from(f)),
        }
    }
    if files.is_empty() {
        files.extend(
            [
                "range_scans/bun045_tri.ply",
                "range_scans/registered/bun180.ply",
            ]
            .iter()
            .filter_map(|f| shared_data(f)),
        );
    }
    let mut cfg = WorkerConfig::default();
    cfg.fit.surface = SurfaceKind::Dms;
    cfg.fit.dms.degree = degree;
    println!(
        "DMS degree {degree} through fit_patch, min of {runs} runs; times in ms as wall / process CPU; stage calls in brackets; rms in um after the first fit and each round"
    );
    println!("| scan | points | controls | load before -> after | total | prepare (wall) | first fit | foot points | round rows | round solves | rms |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for file in &files {
        let mesh = match read_mesh_file(file, &LoadOptions::default()) {
            Ok(l) => l.mesh,
            Err(e) => {
                println!("{}: {e}", file.display());
                continue;
            }
        };
        let label = file
            .file_stem()
            .map_or_else(|| "?".into(), |s| s.to_string_lossy().into_owned());
        measure(&label, &mesh, &cfg, runs);
    }
}
