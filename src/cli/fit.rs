//! `trispline fit`: one patch in, `surface.json`, `surface.glb` and `report.json` out.

use crate::fit::{Budget, Method, StepStats};
use crate::io::glb::{glb_bytes, GlbAttributes};
use crate::io::{read_mesh_file, LoadOptions};
use crate::mesh::inverse::InverseMethod;
use crate::pipeline::geometric::error_colour;
use crate::pipeline::scan::{fit_scan, ScanOptions};
use crate::pipeline::{fit_subdivided, FitOptions, PatchFit, PipelineError, SurfaceKind};
use crate::surface::bezier::{lattice_points, lattice_triangles, BezierTriangle};
use crate::surface::{SurfaceParam, TriSurface};
use crate::TriMesh;
use anyhow::Context;
use serde_json::json;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub struct FitArgs {
    pub input: PathBuf,
    #[arg(long, value_enum, default_value = "bezier")]
    pub surface: SurfaceKind,
    /// Levels of inverse subdivision (the input must have subdivision connectivity this deep).
    #[arg(long, default_value_t = 2)]
    pub levels: usize,
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
    /// Scans without subdivision connectivity: control-net segments per side (Bezier degree).
    #[arg(long, default_value_t = 16)]
    pub lattice: usize,
    /// Scans: fairness weight relative to the data.
    #[arg(long, default_value_t = 1e-5)]
    pub smoothing: f64,
    /// Tessellation segments per side of the domain triangle in surface.glb.
    #[arg(long, default_value_t = 128)]
    pub tessellation: usize,
    #[arg(long)]
    pub out: PathBuf,
}

pub fn run(args: &FitArgs) -> anyhow::Result<ExitCode> {
    let wall = Instant::now();
    let mesh = read_mesh_file(&args.input, &LoadOptions::default())?.mesh;
    let tolerance = args
        .tolerance
        .unwrap_or(args.tolerance_rel * mesh.bounds_diagonal());
    let mut budget = Budget {
        tolerance,
        max_error: args.max_error,
        mean_error: args.mean_error,
        within_tolerance_pct: args.within_tolerance_pct,
        max_iterations: args.iterations,
        max_time_ms: args.max_time_ms,
        ..Budget::default()
    };
    if !budget.has_targets() {
        budget.max_error = Some(tolerance);
    }
    let opts = FitOptions {
        surface: args.surface,
        levels: args.levels,
        method: args.method,
        inverse: args.inverse,
        budget: budget.clone(),
    };
    let refuse = |e: &dyn std::fmt::Display| {
        eprintln!("{}: cannot fit: {e}", args.input.display());
        Ok(ExitCode::from(2))
    };
    let mut scan_info = None;
    let fitted = match fit_subdivided(&mesh, &opts, None) {
        Ok(f) => f,
        Err(PipelineError::NoSubdivision(why)) if args.surface == SurfaceKind::Bezier => {
            // No subdivision connectivity: remesh the scan onto a lattice.
            let scan = ScanOptions {
                lattice: args.lattice,
                smoothing: args.smoothing,
            };
            match fit_scan(&mesh, &opts, &scan, None) {
                Ok(s) => {
                    let f = s.fit.clone();
                    scan_info = Some(s);
                    f
                }
                Err(e) => return refuse(&format!("{e} (and no subdivision connectivity: {why})")),
            }
        }
        Err(
            e @ (PipelineError::NoSubdivision(_)
            | PipelineError::NotALattice(_)
            | PipelineError::Unsupported(_)),
        ) => {
            return refuse(&e);
        }
        Err(e) => return Err(e).context(format!("{}: fit failed", args.input.display())),
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let trim = scan_info.as_ref().map(|s| s.prepared.trim.as_slice());
    let glb = tessellated_glb(&fitted, args.tessellation.max(1), tolerance, trim);
    write_atomic(&args.out.join("surface.glb"), &glb)?;
    let mut report = report_json(args, &fitted, &budget, wall.elapsed().as_secs_f64() * 1e3);
    if let Some(s) = &scan_info {
        report["remeshed"] = json!(true);
        report["components"] = json!(s.components);
        report["kept_vertices"] = json!(s.kept_vertices);
        report["holes_filled"] = json!(s.prepared.holes);
        report["flipped_triangles"] = json!(s.prepared.flipped_triangles);
        report["resample_segments"] = json!(s.prepared.segments);
        report["parameterization_ms"] = json!(s.prepared.parameterization_ms);
        report["resample_ms"] = json!(s.prepared.resample_ms);
    }
    write_atomic(
        &args.out.join("report.json"),
        &serde_json::to_vec_pretty(&report)?,
    )?;
    // surface.json last: its presence marks a complete set.
    let mut surface = surface_json(&fitted, &report);
    if let Some(s) = &scan_info {
        surface["trim"] = json!({
            "space": "barycentric (u, v) of the domain triangle",
            "outer": s.prepared.trim.iter().map(|&(u, v)| [u, v]).collect::<Vec<_>>(),
        });
    }
    write_atomic(
        &args.out.join("surface.json"),
        &serde_json::to_vec_pretty(&surface)?,
    )?;
    Ok(ExitCode::SUCCESS)
}

fn surface_json(f: &PatchFit, report: &serde_json::Value) -> serde_json::Value {
    json!({
        "schema": "trispline.surface/1",
        "kind": "bezier",
        "degree": f.degree,
        "domain": "reference triangle: barycentric (u, v, w = 1 - u - v)",
        "lattice_ordering": "control point P_{i,j,k} (i + j + k = degree) has weight degree!/(i! j! k!) u^i v^j w^k and sits at index j*(degree+1) - j*(j-1)/2 + i",
        "control_points": f.controls.iter().map(|p| [p.x, p.y, p.z]).collect::<Vec<_>>(),
        "fit": report["final"].clone(),
        "status": report["status"].clone(),
    })
}

fn step_json(s: &StepStats) -> serde_json::Value {
    json!({
        "k": s.k, "max_error": s.max_error, "mean_error": s.mean_error, "rms_error": s.rms_error,
        "within_tolerance_pct": s.within_tolerance_pct, "elapsed_ms": s.elapsed_ms,
    })
}

fn report_json(args: &FitArgs, f: &PatchFit, budget: &Budget, wall_ms: f64) -> serde_json::Value {
    let last = f.outcome.steps.last().map(step_json).unwrap_or(json!({}));
    let mut fin = last;
    fin["geometric_max_error"] = json!(f.geometric_max());
    fin["geometric_rms_error"] = json!(f.geometric_rms());
    json!({
        "input": args.input.display().to_string(),
        "surface": f.surface,
        "method": args.method,
        "levels": args.levels,
        "data_points": f.data.len(),
        "control_points": f.controls.len(),
        "degree": f.degree,
        "tolerance": budget.tolerance,
        "budget": budget,
        "status": f.outcome.status,
        "warm_start": f.warm_start,
        "prepare_ms": f.prepare_ms,
        "fit_ms": f.fit_ms,
        "wall_ms": wall_ms,
        "iterations": f.outcome.steps.iter().map(step_json).collect::<Vec<_>>(),
        "final": fin,
    })
}

/// The patch sampled on a regular sub-lattice, in the input's own coordinates, coloured by
/// the distance to the nearest data point's residual: each tessellation vertex takes the
/// fit error of the data point whose parameter is nearest (blue exact .. red 2x tolerance).
fn tessellated_glb(
    f: &PatchFit,
    segments: usize,
    tolerance: f64,
    trim: Option<&[(f64, f64)]>,
) -> Vec<u8> {
    let surface = BezierTriangle::new(f.degree);
    let pts = lattice_points(segments);
    let params: Vec<SurfaceParam> = pts
        .iter()
        .map(|&(i, j)| SurfaceParam {
            face: 0,
            u: i as f64 / segments as f64,
            v: j as f64 / segments as f64,
        })
        .collect();
    let evals: Vec<_> = params
        .iter()
        .map(|p| surface.evaluate(&f.controls, *p))
        .collect();
    let positions = evals.iter().map(|d| d.position).collect();
    let normals: Vec<_> = evals
        .iter()
        .map(|d| d.du.cross(d.dv).normalize_or_zero())
        .collect();
    // Bucket data parameters on a grid over the domain to find the nearest one quickly.
    let cells = segments.max(1);
    let mut bucket: Vec<Vec<usize>> = vec![Vec::new(); (cells + 1) * (cells + 1)];
    let key = |u: f64, v: f64| {
        let (a, b) = ((u * cells as f64) as usize, (v * cells as f64) as usize);
        a.min(cells) * (cells + 1) + b.min(cells)
    };
    for (k, p) in f.params.iter().enumerate() {
        bucket[key(p.u, p.v)].push(k);
    }
    let colors: Vec<[f32; 4]> = params
        .iter()
        .map(|p| {
            let (a, b) = ((p.u * cells as f64) as i64, (p.v * cells as f64) as i64);
            let mut best = (f64::MAX, 0.0);
            for r in 0..=cells as i64 {
                for da in -r..=r {
                    for db in -r..=r {
                        if da.abs().max(db.abs()) != r {
                            continue;
                        }
                        let (x, y) = (a + da, b + db);
                        if x < 0 || y < 0 || x > cells as i64 || y > cells as i64 {
                            continue;
                        }
                        for &k in &bucket[x as usize * (cells + 1) + y as usize] {
                            let q = f.params[k];
                            let d = (q.u - p.u).powi(2) + (q.v - p.v).powi(2);
                            if d < best.0 {
                                best = (d, f.geometric_errors[k]);
                            }
                        }
                    }
                }
                if best.0 < f64::MAX {
                    break;
                }
            }
            error_colour(best.1, tolerance)
        })
        .collect();
    // Trimmed: keep the triangles whose centroid lies inside the scanned region.
    let triangles: Vec<[u32; 3]> = lattice_triangles(segments)
        .into_iter()
        .filter(|t| {
            trim.is_none_or(|poly| {
                let c = t.iter().fold((0.0, 0.0), |acc, &i| {
                    (
                        acc.0 + params[i as usize].u / 3.0,
                        acc.1 + params[i as usize].v / 3.0,
                    )
                });
                inside(poly, c)
            })
        })
        .collect();
    let mesh = TriMesh::new(positions, triangles);
    glb_bytes(
        &mesh,
        &GlbAttributes {
            normals: Some(&normals),
            colors: Some(&colors),
            polylines: &[],
        },
    )
}

/// Even-odd point-in-polygon test.
fn inside(poly: &[(f64, f64)], p: (f64, f64)) -> bool {
    let mut c = false;
    for k in 0..poly.len() {
        let (a, b) = (poly[k], poly[(k + 1) % poly.len()]);
        if (a.1 > p.1) != (b.1 > p.1) && p.0 < a.0 + (p.1 - a.1) * (b.0 - a.0) / (b.1 - a.1) {
            c = !c;
        }
    }
    c
}

/// Temp file in the same folder, fsync, rename, fsync the folder.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    use std::io::Write;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir)
        .with_context(|| format!("temp file in {}", dir.display()))?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path)
        .with_context(|| format!("renaming into {}", path.display()))?;
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}
