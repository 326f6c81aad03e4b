//! The worker as one pure function: (mesh, previous control net, config) -> outputs as
//! bytes and JSON values. The CLI and the daemon write them; nothing here touches files.

use super::components::{cleaned_components, split_components, ComponentFilter, ComponentMode};
use super::output::{surface_json, tessellate, tessellated_glb, Coverage};
use super::scan::{
    fit_scan, BezierLayout, Correction, Domain, ScanFit, ScanOptions, ScanWarm, SurfaceModel,
    WarmFeet,
};
use super::{fit_subdivided, FitOptions, PatchFit, PipelineError, SurfaceKind};
use crate::fit::{Budget, FitStatus, Method, StepHook, StepStats};
use crate::mesh::clean::{clean, CleanOptions};
use crate::mesh::inverse::InverseMethod;
use crate::remesh::planar::PlaneFrame;
use crate::remesh::warp::PlaneWarp;
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
    /// Inputs with subdivision connectivity: when the budget is not met, refit with one
    /// level of inverse subdivision less (4x control points), down to this floor.
    #[serde(default = "default_min_levels")]
    pub min_levels: usize,
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
    /// Scans, `bezier` with the `single` layout: the degree (control-net segments per side).
    pub lattice: usize,
    /// Scans with `bezier`: one quartic patch per grid cell, or one patch of degree
    /// `lattice`.
    #[serde(default)]
    pub bezier_layout: BezierLayout,
    /// Scans, `loop`: grid cells across the patch's longer side; when absent the spacing
    /// follows `target_controls_pct`.
    #[serde(default)]
    pub grid_segments: Option<usize>,
    /// Scans, `loop`: control points as a percentage of the data points.
    #[serde(default = "default_target_controls_pct")]
    pub target_controls_pct: f64,
    /// Scans: rounds of parameter correction (foot points) after the first fit.
    #[serde(default = "default_correction_rounds")]
    pub correction_rounds: usize,
    /// Scans: what a correction round refits.
    #[serde(default = "default_correction")]
    pub correction: Correction,
    /// Scans: correction rounds stop once one lowers the geometric RMS by less than this
    /// fraction.
    #[serde(default = "default_correction_min_gain")]
    pub correction_min_gain: f64,
    /// Scans, distance rounds: share of the point-to-point term beside point-to-plane,
    /// inside the data...
    #[serde(default = "default_correction_tangential")]
    pub correction_tangential: f64,
    /// ... and within half a control spacing of the data's edges.
    #[serde(default = "default_correction_tangential_edge")]
    pub correction_tangential_edge: f64,
    /// Scans: fairness weight relative to the data.
    pub smoothing: f64,
    /// Tessellation segments per side in the GLB.
    pub tessellation: usize,
    /// Scans: fit the largest component, or every kept component as its own surface.
    #[serde(default)]
    pub components: ComponentMode,
    /// Scans: components with fewer vertices are not fitted (the largest too: the input is
    /// then refused).
    #[serde(default = "default_min_component_vertices")]
    pub min_component_vertices: usize,
    /// Scans, `components = "all"`: components with fewer vertices than this fraction of the
    /// largest are not fitted.
    #[serde(default = "default_min_component_fraction")]
    pub min_component_fraction: f64,
    /// Scans: holes whose bridging radius (largest distance from the hole's flat fill to
    /// its rim) exceeds this many median edge lengths of the data are trimmed out of the
    /// surface, narrower ones bridged; data triangles wider than that are trimmed too.
    #[serde(default = "default_hole_bridge_edges")]
    pub hole_bridge_edges: f64,
}

fn default_hole_bridge_edges() -> f64 {
    1.5
}

fn default_min_component_vertices() -> usize {
    100
}

fn default_min_component_fraction() -> f64 {
    0.05
}

fn default_min_levels() -> usize {
    1
}

pub fn default_target_controls_pct() -> f64 {
    5.0
}

pub fn default_correction_min_gain() -> f64 {
    0.04
}

pub fn default_correction_tangential() -> f64 {
    0.005
}

pub fn default_correction_tangential_edge() -> f64 {
    0.02
}

pub fn default_correction_rounds() -> usize {
    8
}

fn default_correction() -> Correction {
    Correction::Distance
}

impl Default for WorkerConfig {
    fn default() -> Self {
        Self {
            surface: SurfaceKind::Bezier,
            levels: 2,
            min_levels: default_min_levels(),
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
            bezier_layout: BezierLayout::default(),
            grid_segments: None,
            target_controls_pct: default_target_controls_pct(),
            correction_rounds: default_correction_rounds(),
            correction_min_gain: default_correction_min_gain(),
            correction_tangential: default_correction_tangential(),
            correction_tangential_edge: default_correction_tangential_edge(),
            correction: default_correction(),
            smoothing: 1e-5,
            tessellation: 128,
            components: ComponentMode::default(),
            min_component_vertices: default_min_component_vertices(),
            min_component_fraction: default_min_component_fraction(),
            hole_bridge_edges: default_hole_bridge_edges(),
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
    /// Matched to the new net by count (a triangular lattice's count fixes its degree) or,
    /// for a Loop grid, by `coords`.
    pub controls: Vec<DVec3>,
    /// Remeshed scans: the plane and domain the previous version was mapped to, so that the
    /// new version's parameters line up with the previous controls.
    #[serde(default)]
    pub frame: Option<PlaneFrame>,
    /// ... and the warp of that plane (warped projections).
    #[serde(default)]
    pub warp: Option<PlaneWarp>,
    #[serde(default)]
    pub domain: Option<Domain>,
    /// Loop grid: grid coordinates of `controls`.
    #[serde(default)]
    pub coords: Vec<(i64, i64)>,
    /// Remeshed scans on a grid: the data points and their final parameters.
    #[serde(default)]
    pub feet: Option<WarmFeet>,
    /// `components = "all"`: one warm start per fitted component (the fields above are then
    /// empty).
    #[serde(default)]
    pub parts: Vec<PartWarm>,
}

/// A component's warm start and where the component was, so that the pieces of the next
/// version find theirs even when their sizes (and so their order) change.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PartWarm {
    pub suffix: String,
    pub centroid: DVec3,
    pub diagonal: f64,
    pub vertices: usize,
    pub warm: WarmStart,
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

/// A fit before it is turned into outputs.
pub struct FittedPatch {
    pub fit: PatchFit,
    /// Remeshed scans: the preparation and domain.
    pub scan: Option<ScanFit>,
    pub budget: Budget,
    /// Levels of inverse subdivision of the fit returned (subdivided inputs may refine).
    pub levels: usize,
    /// Subdivided inputs: the fits that missed the budget before it, coarsest first.
    pub refinement: Vec<serde_json::Value>,
}

/// The fit alone: subdivision connectivity when the input has it, else the scan path.
pub fn fit_patch(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
) -> Result<FittedPatch, PipelineError> {
    fit_patch_with(mesh, previous, cfg, None)
}

/// `fit_patch` reporting every step to `on_step` (a progress display).
pub fn fit_patch_with(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
) -> Result<FittedPatch, PipelineError> {
    let budget = resolve_budget(cfg, mesh);
    let opts = FitOptions {
        surface: cfg.surface,
        levels: cfg.levels,
        method: cfg.method,
        inverse: cfg.inverse,
        budget: budget.clone(),
        on_step,
    };
    let previous = previous.filter(|w| w.surface == cfg.surface);
    let mut scan_info = None;
    let mut levels = cfg.levels;
    let mut refinement = Vec::new();
    let subdivided = loop {
        let at_level = FitOptions {
            levels,
            ..opts.clone()
        };
        match fit_subdivided(mesh, &at_level, previous.map(|w| w.controls.as_slice())) {
            Ok(f) if f.outcome.status != FitStatus::Met && levels > cfg.min_levels => {
                refinement.push(json!({
                    "levels": levels,
                    "control_points": f.controls.len(),
                    "status": f.outcome.status,
                    "final": f.outcome.steps.last().map(step_json),
                }));
                levels -= 1;
            }
            other => break other,
        }
    };
    let fitted = match subdivided {
        Ok(f) => f,
        Err(PipelineError::NoSubdivision(why) | PipelineError::Unsupported(why)) => {
            // No subdivision connectivity: remesh the scan onto a lattice.
            let scan = ScanOptions {
                lattice: cfg.lattice,
                bezier_layout: cfg.bezier_layout,
                grid_segments: cfg.grid_segments,
                target_controls_pct: cfg.target_controls_pct,
                smoothing: cfg.smoothing,
                correction_rounds: cfg.correction_rounds,
                correction: cfg.correction,
                correction_min_gain: cfg.correction_min_gain,
                correction_tangential: cfg.correction_tangential,
                correction_tangential_edge: cfg.correction_tangential_edge,
                min_component_vertices: cfg.min_component_vertices,
                hole_bridge_edges: cfg.hole_bridge_edges,
            };
            let warm = previous.map(|w| ScanWarm {
                frame: w.frame,
                warp: w.warp.as_ref(),
                domain: w.domain.as_ref(),
                controls: &w.controls,
                coords: &w.coords,
                feet: w.feet.as_ref(),
            });
            let s = fit_scan(mesh, &opts, &scan, warm.as_ref()).map_err(|e| {
                PipelineError::Unsupported(format!("{e} (and no subdivision connectivity: {why})"))
            })?;
            let f = s.fit.clone();
            scan_info = Some(s);
            f
        }
        Err(e) => return Err(e),
    };
    Ok(FittedPatch {
        levels: if scan_info.is_some() {
            cfg.levels
        } else {
            levels
        },
        fit: fitted,
        scan: scan_info,
        budget,
        refinement,
    })
}

pub fn run_patch(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
) -> Result<PatchOutputs, PipelineError> {
    run_patch_with(mesh, previous, cfg, None)
}

/// `run_patch` reporting every fitting step to `on_step`.
pub fn run_patch_with(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
) -> Result<PatchOutputs, PipelineError> {
    let wall = Instant::now();
    let FittedPatch {
        fit: fitted,
        scan: scan_info,
        budget,
        levels,
        refinement,
    } = fit_patch_with(mesh, previous, cfg, on_step)?;
    let coverage = scan_info.as_ref().map(|s| {
        Coverage::new(
            &s.hole_plan.covered,
            &fitted.params,
            &s.mapped_params,
            &s.near_fold,
        )
    });
    // The shown surface and the written descriptions need nothing of each other.
    let (glb, (mut report, surface, warm)) = rayon::join(
        || {
            let tess = tessellate(&fitted, cfg.tessellation.max(1), coverage.as_ref());
            tessellated_glb(&fitted, &tess, budget.tolerance)
        },
        || {
            describe(
                cfg,
                &fitted,
                scan_info.as_ref(),
                &budget,
                levels,
                &refinement,
                wall,
            )
        },
    );
    report["wall_ms"] = json!(wall.elapsed().as_secs_f64() * 1e3);
    Ok(PatchOutputs {
        surface,
        report,
        glb,
        warm,
        status: fitted.outcome.status,
    })
}

/// The report, surface.json and warm-start state of a fitted patch.
fn describe(
    cfg: &WorkerConfig,
    fitted: &PatchFit,
    scan_info: Option<&ScanFit>,
    budget: &Budget,
    levels: usize,
    refinement: &[serde_json::Value],
    wall: Instant,
) -> (serde_json::Value, serde_json::Value, WarmStart) {
    let mut report = report_json(cfg, fitted, budget, wall.elapsed().as_secs_f64() * 1e3);
    report["levels"] = json!(levels);
    if !refinement.is_empty() {
        report["refinement"] = json!(refinement);
    }
    if let Some(s) = scan_info {
        report["remeshed"] = json!(true);
        report["components"] = json!(s.components);
        report["kept_vertices"] = json!(s.kept_vertices);
        report["holes_filled"] = json!(s.holes);
        report["holes"] = json!({
            "count": s.holes,
            "bridged": s.hole_plan.bridged.iter().filter(|b| **b).count(),
            "trimmed": s.hole_plan.trimmed(),
            "wide_triangles_trimmed": s.hole_plan.wide_triangles.len(),
            "max_bridge": s.hole_plan.max_bridge,
            "largest_radius": s.hole_plan.radius.iter().cloned().fold(0.0, f64::max),
        });
        report["parameterization"] = json!({
            "method": s.map_method,
            "folded_triangles": s.folds_projected,
            "warp_blend": s.warp.as_ref().map(|w| w.blend),
            "warp_folded_triangles": s.folds_warped,
        });
        report["initial_net"] = json!({
            "resampled_points": s.initial.resample_points,
            "inverse": s.initial.inverse,
        });
        report["domain"] = json!(s.domain);
        report["cells"] = json!(fitted.model.as_surface().domain_face_count());
        report["reused_controls"] = json!(s.reused_controls);
        report["parameter_correction_rms"] = json!(s.correction_rms);
        report["parameterization_ms"] = json!(s.parameterization_ms);
        report["resample_ms"] = json!(s.resample_ms);
    }
    let surface = surface_json(fitted, scan_info, &report);
    let warm = WarmStart {
        surface: fitted.surface,
        controls: fitted.controls.clone(),
        frame: scan_info.map(|s| s.frame),
        warp: scan_info.and_then(|s| s.warp.clone()),
        domain: scan_info.map(|s| s.domain.clone()),
        coords: match &fitted.model {
            SurfaceModel::Grid(g) => g.control_coords().to_vec(),
            SurfaceModel::Bezier(_) | SurfaceModel::Mesh(_) => Vec::new(),
        },
        feet: scan_info.and_then(WarmFeet::of),
        parts: Vec::new(),
    };
    (report, surface, warm)
}

/// One fitted surface of an input: the whole patch (`suffix` empty) or one component
/// (`suffix` = `.c<k>`, appended to the patch id).
pub struct PartOutputs {
    pub suffix: String,
    pub outputs: PatchOutputs,
}

/// Everything one input yields under the component policy.
pub struct InputOutputs {
    pub parts: Vec<PartOutputs>,
    /// Components that were kept but could not be fitted: (suffix, reason).
    pub failed: Vec<(String, String)>,
    /// What the next version of the input starts from.
    pub warm: WarmStart,
}

impl InputOutputs {
    /// The worst status over the fitted parts.
    pub fn status(&self) -> FitStatus {
        let rank = |s: FitStatus| match s {
            FitStatus::Met => 0,
            FitStatus::Stalled => 1,
            FitStatus::Capped => 2,
        };
        self.parts
            .iter()
            .map(|p| p.outputs.status)
            .max_by_key(|s| rank(*s))
            .unwrap_or(FitStatus::Met)
    }
}

/// The worker under the component policy: `largest` is `run_patch` on the input; `all`
/// cleans and splits the input and fits every component big enough, each warm-started from
/// the previous version's component that sat in the same place.
pub fn run_input(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
) -> Result<InputOutputs, PipelineError> {
    run_input_with(mesh, previous, cfg, None)
}

/// `run_input` reporting every fitting step (of every component) to `on_step`.
pub fn run_input_with(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
) -> Result<InputOutputs, PipelineError> {
    if cfg.components == ComponentMode::Largest {
        let outputs = run_patch_with(mesh, previous.filter(|w| w.parts.is_empty()), cfg, on_step)?;
        return Ok(InputOutputs {
            warm: outputs.warm.clone(),
            parts: vec![PartOutputs {
                suffix: String::new(),
                outputs,
            }],
            failed: Vec::new(),
        });
    }
    let cleaned = clean(mesh, &CleanOptions::default());
    let filter = ComponentFilter {
        min_vertices: cfg.min_component_vertices,
        min_fraction: cfg.min_component_fraction,
    };
    let split = split_components(cleaned_components(&cleaned), &filter);
    if split.kept.is_empty() {
        return Err(PipelineError::Unsupported(format!(
            "no component has min_component_vertices = {} vertices (the largest has {})",
            cfg.min_component_vertices,
            split.dropped_vertices.first().copied().unwrap_or(0)
        )));
    }
    let previous_parts = previous.map_or(&[][..], |w| w.parts.as_slice());
    let mut taken = vec![false; previous_parts.len()];
    let mut parts = Vec::new();
    let mut failed = Vec::new();
    let mut warm_parts = Vec::new();
    for (k, c) in split.kept.iter().enumerate() {
        let suffix = format!(".c{k}");
        let vertices = c.mesh.positions.len();
        let matched = matching_part(previous_parts, &taken, c.centroid, c.diagonal, vertices);
        if let Some(i) = matched {
            taken[i] = true;
        }
        match run_patch_with(
            &c.mesh,
            matched.map(|i| &previous_parts[i].warm),
            cfg,
            on_step,
        ) {
            Ok(mut outputs) => {
                outputs.report["component"] = json!({
                    "index": k,
                    "vertices": vertices,
                    "kept": split.kept.len(),
                    "total": split.total,
                    "dropped_vertices": split.dropped_vertices,
                });
                warm_parts.push(PartWarm {
                    suffix: suffix.clone(),
                    centroid: c.centroid,
                    diagonal: c.diagonal,
                    vertices,
                    warm: outputs.warm.clone(),
                });
                parts.push(PartOutputs { suffix, outputs });
            }
            Err(e) => failed.push((suffix, e.to_string())),
        }
    }
    if parts.is_empty() {
        let reasons: Vec<String> = failed.iter().map(|(s, r)| format!("{s}: {r}")).collect();
        return Err(PipelineError::Unsupported(format!(
            "no component could be fitted ({})",
            reasons.join("; ")
        )));
    }
    Ok(InputOutputs {
        parts,
        failed,
        warm: WarmStart {
            surface: cfg.surface,
            controls: Vec::new(),
            frame: None,
            warp: None,
            domain: None,
            coords: Vec::new(),
            feet: None,
            parts: warm_parts,
        },
    })
}

/// The untaken previous component nearest to a new one, if it is plausibly the same piece:
/// centroids within a quarter of the larger diagonal and vertex counts within 2x.
fn matching_part(
    previous: &[PartWarm],
    taken: &[bool],
    centroid: DVec3,
    diagonal: f64,
    vertices: usize,
) -> Option<usize> {
    previous
        .iter()
        .enumerate()
        .filter(|(i, p)| {
            let ratio = p.vertices.max(1) as f64 / vertices.max(1) as f64;
            !taken[*i]
                && (0.5..=2.0).contains(&ratio)
                && p.centroid.distance(centroid) <= 0.25 * p.diagonal.max(diagonal)
        })
        .min_by(|(_, a), (_, b)| {
            a.centroid
                .distance(centroid)
                .total_cmp(&b.centroid.distance(centroid))
        })
        .map(|(i, _)| i)
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
