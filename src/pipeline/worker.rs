//! The worker as one pure function: (mesh, previous control net, config) -> outputs as
//! bytes and JSON values. The CLI and the daemon write them; nothing here touches files.

use super::geometric::error_colour;
use super::scan::{fit_scan, ScanOptions};
use super::{fit_subdivided, FitOptions, PatchFit, PipelineError, SurfaceKind};
use crate::fit::{Budget, FitStatus, Method, StepStats};
use crate::io::glb::{glb_bytes, GlbAttributes};
use crate::mesh::inverse::InverseMethod;
use crate::surface::bezier::{lattice_points, lattice_triangles};
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use serde_json::json;
use std::time::Instant;

/// Everything the worker needs to know; the CLI flags and the daemon config both map here.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkerConfig {
    pub surface: SurfaceKind,
    pub levels: usize,
    pub method: Method,
    pub inverse: InverseMethod,
    pub max_iterations: usize,
    /// Absolute tolerance; when absent, `tolerance_rel` times the bounding-box diagonal.
    pub tolerance: Option<f64>,
    pub tolerance_rel: f64,
    pub max_error: Option<f64>,
    pub mean_error: Option<f64>,
    pub within_tolerance_pct: Option<f64>,
    pub max_time_ms: Option<u64>,
    /// Scans: control-net segments per side.
    pub lattice: usize,
    /// Scans: fairness weight relative to the data.
    pub smoothing: f64,
    /// Tessellation segments per side in the GLB.
    pub tessellation: usize,
}

impl Default for WorkerConfig {
    fn default() -> Self {
        Self {
            surface: SurfaceKind::Bezier,
            levels: 2,
            method: Method::Cg,
            inverse: InverseMethod::Exact,
            max_iterations: 100,
            tolerance: None,
            tolerance_rel: 1e-3,
            max_error: None,
            mean_error: None,
            within_tolerance_pct: None,
            max_time_ms: None,
            lattice: 16,
            smoothing: 1e-5,
            tessellation: 128,
        }
    }
}

pub struct PatchOutputs {
    pub surface: serde_json::Value,
    pub report: serde_json::Value,
    pub glb: Vec<u8>,
    /// What the next version of the patch starts from; callers store it opaquely.
    pub warm: WarmStart,
    pub status: FitStatus,
}

/// What a fit leaves for the next version of the same patch. Stored whole by the daemon's
/// state store (serde), so new fields must carry `#[serde(default)]`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct WarmStart {
    pub surface: SurfaceKind,
    /// Bezier degree or Loop domain segments: with `surface`, the control-net structure.
    pub degree: usize,
    pub controls: Vec<DVec3>,
}

/// The error budget with the tolerance resolved against the mesh's size; with no target set
/// the fit aims at max error <= tolerance.
pub fn resolve_budget(cfg: &WorkerConfig, mesh: &TriMesh) -> Budget {
    let tolerance = cfg
        .tolerance
        .unwrap_or(cfg.tolerance_rel * mesh.bounds_diagonal());
    let mut budget = Budget {
        tolerance,
        max_error: cfg.max_error,
        mean_error: cfg.mean_error,
        within_tolerance_pct: cfg.within_tolerance_pct,
        max_iterations: cfg.max_iterations,
        max_time_ms: cfg.max_time_ms,
        ..Budget::default()
    };
    if !budget.has_targets() {
        budget.max_error = Some(tolerance);
    }
    budget
}

pub fn run_patch(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
) -> Result<PatchOutputs, PipelineError> {
    let wall = Instant::now();
    let budget = resolve_budget(cfg, mesh);
    let opts = FitOptions {
        surface: cfg.surface,
        levels: cfg.levels,
        method: cfg.method,
        inverse: cfg.inverse,
        budget: budget.clone(),
    };
    let mut scan_info = None;
    let previous = previous.filter(|w| w.surface == cfg.surface);
    let prev_controls = previous.map(|w| w.controls.as_slice());
    let fitted = match fit_subdivided(mesh, &opts, prev_controls) {
        Ok(f) => f,
        Err(PipelineError::NoSubdivision(why) | PipelineError::Unsupported(why)) => {
            // No subdivision connectivity: remesh the scan onto a lattice.
            let scan = ScanOptions {
                lattice: cfg.lattice,
                smoothing: cfg.smoothing,
            };
            let s = fit_scan(mesh, &opts, &scan, prev_controls).map_err(|e| {
                PipelineError::Unsupported(format!("{e} (and no subdivision connectivity: {why})"))
            })?;
            let f = s.fit.clone();
            scan_info = Some(s);
            f
        }
        Err(e) => return Err(e),
    };
    let trim = scan_info.as_ref().map(|s| s.prepared.trim.as_slice());
    let glb = tessellated_glb(&fitted, cfg.tessellation.max(1), budget.tolerance, trim);
    let mut report = report_json(cfg, &fitted, &budget, wall.elapsed().as_secs_f64() * 1e3);
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
    let mut surface = surface_json(&fitted, &report);
    if let Some(s) = &scan_info {
        surface["trim"] = json!({
            "space": "barycentric (u, v) of the domain triangle",
            "outer": s.prepared.trim.iter().map(|&(u, v)| [u, v]).collect::<Vec<_>>(),
        });
    }
    Ok(PatchOutputs {
        surface,
        report,
        glb,
        warm: WarmStart {
            surface: fitted.surface,
            degree: fitted.degree,
            controls: fitted.controls.clone(),
        },
        status: fitted.outcome.status,
    })
}

fn surface_json(f: &PatchFit, report: &serde_json::Value) -> serde_json::Value {
    let controls = f
        .controls
        .iter()
        .map(|p| [p.x, p.y, p.z])
        .collect::<Vec<_>>();
    let mut v = match f.surface {
        SurfaceKind::Bezier => json!({
            "kind": "bezier",
            "degree": f.degree,
            "lattice_ordering": "control point P_{i,j,k} (i + j + k = degree) has weight degree!/(i! j! k!) u^i v^j w^k and sits at index j*(degree+1) - j*(j-1)/2 + i",
        }),
        SurfaceKind::Loop => json!({
            "kind": "loop",
            "domain_segments": f.degree,
            "control_lattice_segments": f.degree + 3,
            "lattice_ordering": "the domain triangle is divided into a lattice of n = domain_segments; control point (i, j), i, j >= -1, i + j <= n + 1, sits at index b*(m+1) - b*(b-1)/2 + a with a = i + 1, b = j + 1, m = n + 3",
            "basis": "Loop limit surface of the regular control lattice: on every domain triangle the quartic three-direction box spline of its 12 surrounding control points",
        }),
    };
    v["schema"] = json!("trispline.surface/1");
    v["domain"] = json!("reference triangle: barycentric (u, v, w = 1 - u - v)");
    v["control_points"] = json!(controls);
    v["fit"] = report["final"].clone();
    v["status"] = report["status"].clone();
    v
}

fn step_json(s: &StepStats) -> serde_json::Value {
    json!({
        "k": s.k, "max_error": s.max_error, "mean_error": s.mean_error, "rms_error": s.rms_error,
        "within_tolerance_pct": s.within_tolerance_pct, "elapsed_ms": s.elapsed_ms,
    })
}

fn report_json(
    cfg: &WorkerConfig,
    f: &PatchFit,
    budget: &Budget,
    wall_ms: f64,
) -> serde_json::Value {
    let last = f.outcome.steps.last().map(step_json).unwrap_or(json!({}));
    let mut fin = last;
    fin["geometric_max_error"] = json!(f.geometric_max());
    fin["geometric_rms_error"] = json!(f.geometric_rms());
    json!({
                "surface": f.surface,
        "method": cfg.method,
        "levels": cfg.levels,
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
    let surface = super::scan::surface_for(f.surface, f.degree);
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
