//! `trispline fit`: one patch in, `surface.json`, `surface.glb` and `report.json` out.

use super::progress::Progress;
use crate::fit::Method;
use crate::io::{read_mesh_file, write_atomic, write_atomic_group, LoadOptions};
use crate::mesh::inverse::InverseMethod;
use crate::pipeline::components::ComponentMode;
use crate::pipeline::worker::{self, run_input_with, PatchOutputs, WorkerConfig};
use crate::pipeline::{PipelineError, SurfaceKind};
use anyhow::Context;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
#[derive(clap::Args, Debug)]
pub struct FitArgs {
    pub input: PathBuf,
    #[arg(long, value_enum, default_value = "bezier")]
    pub surface: SurfaceKind,
    /// Levels of inverse subdivision (the input must have subdivision connectivity this deep).
    #[arg(long, default_value_t = 2)]
    pub levels: usize,
    /// Inputs with subdivision connectivity: when the budget is not met, refit with one level
    /// less (4x control points) down to this floor.
    #[arg(long, default_value_t = 1)]
    pub min_levels: usize,
    #[arg(long, default_value = "cg")]
    pub method: Method,
    #[arg(long, default_value = "exact")]
    pub inverse: InverseMethod,
    /// Maximum number of fitting steps.
    #[arg(long, default_value_t = 100)]
    pub iterations: usize,
    /// Absolute tolerance; the default is 1e-3 of the bounding-box diagonal.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Tolerance as a fraction of the bounding-box diagonal (ignored with --tolerance).
    #[arg(long, default_value_t = 1e-3)]
    pub tolerance_rel: f64,
    /// Targets; with none given the fit aims at max error <= tolerance.
    #[arg(long)]
    pub max_error: Option<f64>,
    #[arg(long)]
    pub mean_error: Option<f64>,
    #[arg(long)]
    pub within_tolerance_pct: Option<f64>,
    #[arg(long)]
    pub max_time_ms: Option<u64>,
    /// Scans without subdivision connectivity, `bezier`: control-net segments per side (the
    /// degree); `loop`: grid cells across the patch's longer side (default: chosen for
    /// --target-controls-pct).
    #[arg(long)]
    pub lattice: Option<usize>,
    /// Scans, `loop`: control points as a percentage of the data points.
    #[arg(long, default_value_t = worker::default_target_controls_pct())]
    pub target_controls_pct: f64,
    /// Scans: rounds of parameter correction (data parameters moved to foot points).
    #[arg(long, default_value_t = worker::default_correction_rounds())]
    pub corrections: usize,
    /// Scans: what a correction round refits: `distance` (squared-distance minimisation)
    /// or `parameters` (point-to-point again).
    #[arg(long, value_enum, default_value = "distance")]
    pub correction: crate::pipeline::scan::Correction,
    /// Scans: correction rounds stop once one lowers the geometric RMS by less than this
    /// fraction.
    #[arg(long, default_value_t = worker::default_correction_min_gain())]
    pub correction_min_gain: f64,
    /// Scans, distance rounds: share of the point-to-point term beside point-to-plane
    /// inside the data (smaller: rounds converge faster and further)...
    #[arg(long, default_value_t = worker::default_correction_tangential())]
    pub correction_tangential: f64,
    /// ... and within half a control spacing of the data's edges (smaller: the surface
    /// slides past the last points, higher maximum errors).
    #[arg(long, default_value_t = worker::default_correction_tangential_edge())]
    pub correction_tangential_edge: f64,
    /// Scans: fairness weight relative to the data.
    #[arg(long, default_value_t = 1e-5)]
    pub smoothing: f64,
    /// Scans: fit the largest component (`largest`) or every component big enough (`all`,
    /// written to OUT/c0, OUT/c1, ... largest first, with OUT/components.json).
    #[arg(long, value_enum, default_value = "largest")]
    pub components: ComponentMode,
    /// Scans: components with fewer vertices are not fitted.
    #[arg(long, default_value_t = 100)]
    pub min_component_vertices: usize,
    /// Scans, `--components all`: components under this fraction of the largest (in
    /// vertices) are not fitted.
    #[arg(long, default_value_t = 0.05)]
    pub min_component_fraction: f64,
    /// Scans with `--surface bezier`: `patches` (one quartic Bezier patch per grid cell,
    /// the Bezier form of the grid fit) or `single` (one patch of degree `--lattice`, 16 by
    /// default; implied by `--lattice`).
    #[arg(long, value_enum, default_value = "patches")]
    pub bezier_layout: crate::pipeline::scan::BezierLayout,
    /// Scans: holes whose bridging radius (largest distance from the hole's flat fill to
    /// its rim) exceeds this many median edge lengths of the data are trimmed out of the
    /// surface, narrower ones bridged; data triangles wider than that are trimmed too.
    #[arg(long, default_value_t = 1.5)]
    pub hole_bridge_edges: f64,
    /// Tessellation segments per side of the domain triangle in surface.glb.
    #[arg(long, default_value_t = 128)]
    pub tessellation: usize,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: &FitArgs) -> anyhow::Result<ExitCode> {
    let started = std::time::Instant::now();
    let mesh = read_mesh_file(&args.input, &LoadOptions::default())?.mesh;
    let read_ms = started.elapsed().as_secs_f64() * 1e3;
    let cfg = WorkerConfig {
        surface: args.surface,
        levels: args.levels,
        min_levels: args.min_levels,
        method: args.method,
        inverse: args.inverse,
        max_iterations: args.iterations,
        tolerance: args.tolerance,
        tolerance_rel: args.tolerance_rel,
        max_error: args.max_error,
        mean_error: args.mean_error,
        within_tolerance_pct: args.within_tolerance_pct,
        max_time_ms: args.max_time_ms,
        lattice: args.lattice.unwrap_or(16),
        // A degree given for `bezier` asks for one patch of that degree.
        bezier_layout: match (args.surface, args.lattice) {
            (SurfaceKind::Bezier, Some(_)) => crate::pipeline::scan::BezierLayout::Single,
            _ => args.bezier_layout,
        },
        grid_segments: args.lattice.filter(|_| args.surface == SurfaceKind::Loop),
        target_controls_pct: args.target_controls_pct,
        correction_rounds: args.corrections,
        correction: args.correction,
        correction_min_gain: args.correction_min_gain,
        correction_tangential: args.correction_tangential,
        correction_tangential_edge: args.correction_tangential_edge,
        smoothing: args.smoothing,
        tessellation: args.tessellation,
        components: args.components,
        min_component_vertices: args.min_component_vertices,
        min_component_fraction: args.min_component_fraction,
        hole_bridge_edges: args.hole_bridge_edges,
    };
    let progress = Progress::new(cfg.max_iterations);
    let on_step = |s: &crate::fit::StepStats| progress.on_step(s);
    let fitted = run_input_with(&mesh, None, &cfg, Some(&on_step));
    progress.finish();
    let input = match fitted {
        Ok(o) => o,
        Err(
            e @ (PipelineError::NoSubdivision(_)
            | PipelineError::NotALattice(_)
            | PipelineError::Unsupported(_)),
        ) => {
            eprintln!("{}: cannot fit: {e}", args.input.display());
            return Ok(ExitCode::from(2));
        }
        Err(e) => return Err(e).context(format!("{}: fit failed", args.input.display())),
    };
    let label = args.input.display().to_string();
    let source = Source {
        label: &label,
        read_ms,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    if args.components == ComponentMode::Largest {
        for part in input.parts {
            write_outputs(&args.out, part.outputs, &source)?;
        }
        return Ok(ExitCode::SUCCESS);
    }
    let mut listing = Vec::new();
    for part in input.parts {
        let name = part.suffix.trim_start_matches('.').to_string();
        listing.push(json!({
            "component": name,
            "status": part.outputs.status,
            "data_points": part.outputs.report["data_points"],
            "final": part.outputs.report["final"],
        }));
        write_outputs(&args.out.join(&name), part.outputs, &source)?;
    }
    for (suffix, reason) in &input.failed {
        eprintln!("{label}: component {suffix} not fitted: {reason}");
    }
    let failed: Vec<_> = input
        .failed
        .iter()
        .map(|(s, r)| json!({"component": s.trim_start_matches('.'), "reason": r}))
        .collect();
    write_atomic(
        &args.out.join("components.json"),
        &serde_json::to_vec_pretty(&json!({"input": label, "fitted": listing, "failed": failed}))?,
    )?;
    Ok(ExitCode::SUCCESS)
}

/// Where a fit's mesh came from, for its report.
struct Source<'a> {
    label: &'a str,
    /// Reading and parsing the input file (the report's `wall_ms` starts after it).
    read_ms: f64,
}

/// One surface's files; surface.json last, its presence marks a complete set.
fn write_outputs(dir: &Path, mut out: PatchOutputs, source: &Source) -> anyhow::Result<()> {
    out.report["input"] = json!(source.label);
    out.report["read_ms"] = json!(source.read_ms);
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let report = serde_json::to_vec_pretty(&out.report)?;
    let surface = serde_json::to_vec_pretty(&out.surface)?;
    // As the daemon writes them: the three synced at once, surface.json renamed last.
    write_atomic_group(
        dir,
        &[
            ("surface.glb", &out.glb),
            ("report.json", &report),
            ("surface.json", &surface),
        ],
    )?;
    Ok(())
}
