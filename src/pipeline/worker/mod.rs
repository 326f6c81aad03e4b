//! The worker as one pure function: (mesh, previous version's warm start, config) ->
//! outputs as bytes and JSON values. The CLI and the daemon write them; nothing here touches
//! files. It chooses the path (subdivision connectivity when the input has it, else the
//! scan path for disk-like scans and the object path for the rest, see `Domain`) and
//! applies the component policy.

mod cloud;
mod config;
mod fitted;
mod grid_stray;
mod object;
mod object_version;
mod report;
mod shown;
mod stray_guard;

pub use config::{
    BudgetConfig, ComponentsConfig, Domain, FitConfig, WorkerConfig, DEFAULT_CREASE_ANGLE_DEG,
    DEFAULT_CREASE_RELATIVE_RATIO, DEFAULT_TESSELLATION,
};
pub use fitted::FittedPatch;
pub use object::{ObjectInfo, WarmDecision};
pub use object_version::ObjectWarm;
pub use report::{PartWarm, Refinement, WarmStart};
pub use shown::TessellationCheck;
pub use stray_guard::StrayReport;
pub(crate) use stray_guard::{stray_refusal, MAX_STRAY_GROWTH, MAX_STRAY_SHARE};

use super::measure::{distance_stats, surface_mesh};
use super::output::{error_legend, tessellate, tessellate_mesh_faces, tessellated_glb, Coverage};
use super::scan::components::{
    cleaned_components, split_components, ComponentFilter, ComponentMode,
};
use super::scan::{fit_scan, ScanOptions, ScanWarm};
use super::scattered::{add_outputs, fit_planar, fit_planar_subdivided, tessellate_planar};
use super::subdivided::fit_subdivided;
use super::{FitOptions, PatchFit, PipelineError, SurfaceKind};
use crate::fit::{Budget, FitStatus, StepHook};
use crate::mesh::clean::{clean, CleanOptions};
use crate::remesh::RemeshError;
use crate::TriMesh;
use glam::DVec3;
use grid_stray::held_to_the_stray_bound;
use serde_json::json;
use shown::ShownSurface;
use std::time::Instant;

/// What one fitted surface yields.
pub struct PatchOutputs {
    /// surface.json.
    pub surface: serde_json::Value,
    /// report.json (callers add where the input came from).
    pub report: serde_json::Value,
    /// surface.glb.
    pub glb: Vec<u8>,
    /// legend.svg: what surface.glb's colours mean.
    pub legend: String,
    /// surface.stp, when asked for and the surface has a CAD form (the daemon adds it:
    /// `daemon::cad`).
    pub step: Option<Vec<u8>>,
    /// What the next version of the patch starts from; callers store it opaquely.
    pub warm: WarmStart,
    /// How the fit ended.
    pub status: FitStatus,
}

/// The fit alone: with `domain = "mesh"` the object path; else subdivision connectivity
/// when the input has it, else (`auto`) the object path for inputs the disk map cannot take
/// and the scan path for the rest (`grid`: always the scan path).
pub fn fit_patch(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
) -> Result<FittedPatch, PipelineError> {
    fit_patch_with(mesh, previous, cfg, None)
}

/// `fit_patch` reporting every step to `on_step` (a progress display).
pub(crate) fn fit_patch_with(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
) -> Result<FittedPatch, PipelineError> {
    let input = cloud::with_faces(mesh, cfg)?;
    let (mesh, cfg) = (input.mesh.as_ref(), input.cfg.as_ref());
    let fit_cfg = &cfg.fit;
    let budget = fit_cfg.budget.resolve(mesh);
    let opts = FitOptions {
        surface: fit_cfg.surface,
        levels: fit_cfg.levels,
        method: fit_cfg.method,
        inverse: fit_cfg.inverse,
        budget: budget.clone(),
        on_step,
    };
    if matches!(fit_cfg.surface, SurfaceKind::Bpatch | SurfaceKind::Dms) {
        return fit_planar_kind(mesh, previous, cfg, budget);
    }
    if fit_cfg.domain == Domain::Mesh {
        return object_patch(
            mesh,
            None,
            previous,
            cfg,
            budget,
            "fit.domain = \"mesh\"".into(),
        );
    }
    let any_previous = previous;
    let previous = previous.filter(|w| w.surface == fit_cfg.surface);
    let mut levels = fit_cfg.levels;
    let mut refinement = Vec::new();
    let subdivided = loop {
        let at_level = FitOptions {
            levels,
            ..opts.clone()
        };
        match fit_subdivided(mesh, &at_level, previous.map(|w| w.controls.as_slice())) {
            Ok(f) if f.outcome.status != FitStatus::Met && levels > fit_cfg.min_levels => {
                refinement.push(Refinement {
                    levels,
                    control_points: f.controls.len(),
                    status: f.outcome.status,
                    last: f.outcome.steps.last().cloned(),
                });
                levels -= 1;
            }
            other => break other,
        }
    };
    let not_subdivided = match subdivided {
        Ok(fit) => {
            let shown = exact_surface_shown(mesh, &fit, cfg);
            return Ok(FittedPatch {
                levels,
                refinement,
                shown: Some(shown),
                ..FittedPatch::bare(fit, budget)
            });
        }
        Err(e @ (PipelineError::NoSubdivision(_) | PipelineError::NoLimitSurface { .. })) => e,
        Err(e) => return Err(e),
    };
    let auto = fit_cfg.domain == Domain::Auto;
    if auto && object::may_be_nearly_closed(mesh) {
        let input = object::object_input(mesh, cfg);
        if let Some(reason) = input.as_ref().and_then(object::object_reason) {
            return object_patch(mesh, input, any_previous, cfg, budget, reason);
        }
    }
    // No subdivision connectivity: remesh the scan onto a lattice.
    let scan = ScanOptions {
        config: fit_cfg.scan,
        correction: fit_cfg.correction,
        min_component_vertices: fit_cfg.components.min_vertices,
        refuse_distorted: auto,
    };
    let warm = previous.map(|w| ScanWarm {
        frame: w.frame,
        warp: w.warp.as_ref(),
        domain: w.domain.as_ref(),
        controls: &w.controls,
        coords: &w.coords,
        feet: w.feet.as_ref(),
    });
    let s = match fit_scan(mesh, &opts, &scan, warm.as_ref()) {
        Ok(s) => s,
        // Closed after cleaning, handles, or a component cleaning left non-orientable: the
        // disk map cannot take it; the object path's component repair and control mesh can.
        Err(PipelineError::NotDiskLike {
            source:
                source @ (RemeshError::Closed
                | RemeshError::NotDisk { .. }
                | RemeshError::NotManifold(_)
                | RemeshError::Distorted { .. }),
        }) if auto => {
            return object_patch(mesh, None, any_previous, cfg, budget, source.to_string());
        }
        Err(e) => {
            return Err(PipelineError::ScanFailed {
                source: Box::new(e),
                not_subdivided: Box::new(not_subdivided),
            })
        }
    };
    let mut fitted = FittedPatch {
        levels: fit_cfg.levels,
        refinement,
        ..FittedPatch::bare(s.fit.clone(), budget)
    };
    fitted.scan = Some(s);
    // The object path fits Loop surfaces only; another kind asked for is kept.
    if auto && fit_cfg.surface == SurfaceKind::Loop {
        let budget = fitted.budget.clone();
        let fit_as_object = |cfg: &WorkerConfig, input, reason| {
            object_patch(mesh, Some(input), any_previous, cfg, budget, reason).ok()
        };
        if let Some(object) = held_to_the_stray_bound(mesh, &mut fitted, cfg, fit_as_object) {
            return Ok(object);
        }
    } else if let Some(scan) = &fitted.scan {
        // Measured and reported all the same: the path was asked for.
        fitted.shown = Some(ShownSurface::of_grid(mesh, scan, cfg.tessellation));
    }
    Ok(fitted)
}

/// The tessellation the GLB of an exact-subdivision fit of `mesh` shows, and how far it
/// strays from `mesh`. The exact path keeps its surface (the inverse subdivision of the
/// input's own connectivity), so a stray past the bound is reported and logged, not
/// mended: on CGAL's 162-vertex spheres the data's own facets sag 0.49 % of the diagonal
/// below the sphere the surface follows.
fn exact_surface_shown(mesh: &TriMesh, fit: &PatchFit, cfg: &WorkerConfig) -> ShownSurface {
    let shown = ShownSurface::of_whole(mesh, fit, cfg.tessellation);
    if !shown.stray.within() {
        tracing::warn!(
            "the exact subdivision surface strays {:.2} % of the bounding-box diagonal from \
             the data (over the bound of {:.2} %)",
            100.0 * shown.stray.share_of_diagonal,
            100.0 * MAX_STRAY_SHARE
        );
    }
    shown
}

/// B-patch and DMS fits: over the coarse net of an input with subdivision connectivity,
/// else over a planar map of the input.
fn fit_planar_kind(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    budget: Budget,
) -> Result<FittedPatch, PipelineError> {
    let fit_cfg = &cfg.fit;
    // Subdivision connectivity: over the coarse net, as the other kinds.
    if let Some((fit, shown)) = fit_planar_subdivided(mesh, previous, cfg, &budget)? {
        return Ok(FittedPatch {
            levels: fit_cfg.levels,
            planar_shown: Some(shown),
            ..FittedPatch::bare(fit, budget)
        });
    }
    let (fit, info) = fit_planar(mesh, previous, cfg, &budget)?;
    Ok(FittedPatch {
        scattered: Some(info),
        ..FittedPatch::bare(fit, budget)
    })
}

/// The object path of `fit_patch`: warm from the previous version's object fit if any.
fn object_patch(
    mesh: &TriMesh,
    input: Option<crate::pipeline::object::ObjectInput>,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    budget: Budget,
    reason: String,
) -> Result<FittedPatch, PipelineError> {
    if cfg.fit.surface != SurfaceKind::Loop {
        // Written as it is (report.json `surface`), and said where the fits are logged.
        tracing::warn!(
            asked = cfg.fit.surface.name(),
            "a whole object is fitted as a Loop surface: the object path fits no other kind"
        );
    }
    let warm = previous.and_then(|w| w.object.as_ref().map(|o| (o, w.controls.as_slice())));
    let (fit, info) = object::fit_as_object(
        mesh,
        input,
        warm.map(|w| w.0),
        warm.map_or(&[][..], |w| w.1),
        cfg,
        &budget,
        reason,
    )?;
    Ok(FittedPatch {
        object: Some(info),
        ..FittedPatch::bare(fit, budget)
    })
}

/// The fit and its outputs.
pub fn run_patch(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
) -> Result<PatchOutputs, PipelineError> {
    run_patch_with(mesh, previous, cfg, None)
}

/// `run_patch` reporting every fitting step to `on_step`.
pub(crate) fn run_patch_with(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
) -> Result<PatchOutputs, PipelineError> {
    run_patch_measuring(mesh, previous, cfg, on_step, None)
}

/// `run_patch_with`, measuring `measured` (a reconstructed cloud's points, when the cloud
/// was reconstructed by the caller) or the points of a cloud it reconstructs itself
/// against the fitted surface: report.json's `point_cloud.points_to_surface`.
fn run_patch_measuring(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
    measured: Option<&[DVec3]>,
) -> Result<PatchOutputs, PipelineError> {
    let wall = Instant::now();
    let input = cloud::with_faces(mesh, cfg)?;
    let (mesh, cfg) = (input.mesh.as_ref(), input.cfg.as_ref());
    let fitted = fit_patch_with(mesh, previous, cfg, on_step)?;
    let to_surface = input
        .measured_points
        .or(measured)
        .map(|points| distance_stats(points, &surface_mesh(&fitted.fit)));
    let mut outputs = outputs_of(fitted, cfg, wall);
    if let Some(cloud) = input.report() {
        set_cloud_report(&mut outputs.report, cloud);
    }
    if let Some(stats) = to_surface {
        outputs.report["point_cloud"]["points_to_surface"] = json!(stats);
    }
    Ok(outputs)
}

/// What the worker makes of a point cloud (a mesh without triangles) under `cfg`, as
/// report.json's `point_cloud` gives it (the triangulation or the reconstruction it would
/// fit, and their figures), or why it refuses the cloud (`refused`, `kind`); `None` for a
/// mesh. What `inspect` prints.
pub fn point_cloud_route(cloud: &TriMesh, cfg: &WorkerConfig) -> Option<serde_json::Value> {
    if !cloud.triangles.is_empty() {
        return None;
    }
    Some(match cloud::with_faces(cloud, cfg) {
        Ok(input) => input.report().unwrap_or_default(),
        Err(e) => json!({"refused": e.to_string(), "kind": e.kind()}),
    })
}

/// Sets report.json's `point_cloud`, keeping a `points_to_surface` measured before.
fn set_cloud_report(report: &mut serde_json::Value, cloud: serde_json::Value) {
    let measured = report["point_cloud"]["points_to_surface"].take();
    report["point_cloud"] = cloud;
    if !measured.is_null() {
        report["point_cloud"]["points_to_surface"] = measured;
    }
}

/// The outputs of a fit (`fit_patch`'s result): surface.json, report.json, the GLB and the
/// warm start; `wall` is when the work on the input began (report.json's `wall_ms`).
pub fn outputs_of(fitted: FittedPatch, cfg: &WorkerConfig, wall: Instant) -> PatchOutputs {
    let path = fitted.path();
    let FittedPatch {
        fit: fitted,
        scan: scan_info,
        budget,
        levels,
        refinement,
        object: object_info,
        scattered: planar_info,
        planar_shown,
        shown,
    } = fitted;
    let shown_stray = shown.as_ref().map(|shown| shown.stray.report());
    let object_tried = shown.as_ref().and_then(|s| s.object_tried.clone());
    let shown = shown.map(|shown| shown.tessellation);
    // The shown surface and the written descriptions need nothing of each other.
    let (glb_and_check, (mut report, surface, mut warm)) = rayon::join(
        || {
            if object_info.is_some() {
                let t = Instant::now();
                let check = shown::object_tessellation(&fitted, object_start(&fitted, cfg));
                let tess = tessellate_mesh_faces(&fitted, check.per_face);
                let glb = tessellated_glb(&fitted, &tess, budget.tolerance);
                let shown_ms = t.elapsed().as_secs_f64() * 1e3;
                return (glb, Some((check, shown_ms)));
            }
            let planar = planar_info.as_ref().map(|i| &i.coverage);
            let tess = match (planar.or(planar_shown.as_ref()), shown) {
                (Some(shown), _) => tessellate_planar(&fitted, shown, cfg.tessellation.max(1)),
                (None, Some(shown)) => shown,
                (None, None) => {
                    let coverage = scan_info.as_ref().map(|s| Coverage::of(&fitted, s));
                    tessellate(&fitted, cfg.tessellation.max(1), coverage.as_ref())
                }
            };
            (tessellated_glb(&fitted, &tess, budget.tolerance), None)
        },
        || {
            report::describe(
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
    let (glb, check) = glb_and_check;
    let mut surface = surface;
    if let Some(info) = &planar_info {
        add_outputs(&fitted, info, &mut report, &mut surface, &mut warm);
    }
    if let Some(info) = &object_info {
        let object_report = object::object_report(&fitted, info);
        report["topology"] = object_report["topology"].clone();
        report["object"] = object_report;
        // Under the same key as the scan path's, which `trispline fit`'s line reads.
        report["dropped"] = json!(info.dropped);
        if let Some((check, shown_ms)) = check {
            report["tessellation"] = json!(check);
            // The tessellation and its GLB (beside the report, in parallel with it).
            report["object"]["stages"]["shown_ms"] = json!(shown_ms);
        }
        warm.object = object::object_warm(&fitted, info);
    }
    // Every path that measures how far its surface strays from the data says so in one
    // place: the scan and exact paths' shown tessellation, the object path's lattice
    // (`object.stray`).
    let object_stray = report["object"]["stray"].clone();
    let stray = shown_stray.or_else(|| {
        (!object_stray.is_null()).then(|| {
            let mut stray = object_stray;
            stray["measured_on"] =
                json!("a lattice over each control face, its farthest samples climbed to their local maxima");
            stray
        })
    });
    if let Some(stray) = stray {
        report["stray"] = stray;
    }
    if let Some(reason) = object_tried {
        report["object_path_tried"] = json!({ "reason": reason, "kept": false });
    }
    report["path"] = json!(path);
    report["wall_ms"] = json!(wall.elapsed().as_secs_f64() * 1e3);
    PatchOutputs {
        surface,
        report,
        glb,
        legend: error_legend(budget.tolerance),
        step: None,
        warm,
        status: fitted.outcome.status,
    }
}

/// One fitted surface of an input: the whole patch (`suffix` empty) or one component
/// (`suffix` = `.c<k>`, appended to the patch id).
pub struct PartOutputs {
    /// Empty, or `.c<k>`.
    pub suffix: String,
    /// The surface's outputs.
    pub outputs: PatchOutputs,
}

/// Everything one input yields under the component policy.
pub struct InputOutputs {
    /// The fitted surfaces.
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
pub(crate) fn run_input_with(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
) -> Result<InputOutputs, PipelineError> {
    let input = cloud::with_faces(mesh, cfg)?;
    let mut fitted = run_components(
        &input.mesh,
        previous,
        &input.cfg,
        on_step,
        input.measured_points,
    )?;
    if let Some(cloud) = input.report() {
        for part in &mut fitted.parts {
            set_cloud_report(&mut part.outputs.report, cloud.clone());
        }
    }
    Ok(fitted)
}

/// `run_input_with` on a mesh with triangles; `measured`, a reconstructed cloud's points,
/// are measured against the surface of the largest component only (with the `all`
/// components policy most points would belong to other parts).
fn run_components(
    mesh: &TriMesh,
    previous: Option<&WarmStart>,
    cfg: &WorkerConfig,
    on_step: Option<StepHook>,
    measured: Option<&[DVec3]>,
) -> Result<InputOutputs, PipelineError> {
    let components = &cfg.fit.components;
    if components.mode == ComponentMode::Largest {
        let warm = previous.filter(|w| w.parts.is_empty());
        let outputs = run_patch_measuring(mesh, warm, cfg, on_step, measured)?;
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
        min_vertices: components.min_vertices,
        min_fraction: components.min_fraction,
    };
    let split = split_components(cleaned_components(&cleaned), &filter);
    if split.kept.is_empty() {
        return Err(PipelineError::NoComponent {
            min: components.min_vertices,
            largest: split.dropped_vertices.first().copied().unwrap_or(0),
        });
    }
    let previous_parts = previous.map_or(&[][..], |w| w.parts.as_slice());
    let mut taken = vec![false; previous_parts.len()];
    let mut parts = Vec::new();
    let mut failures = Vec::new();
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
            Err(e) => failures.push((suffix, e)),
        }
    }
    if parts.is_empty() {
        return Err(PipelineError::NoComponentFitted { failures });
    }
    Ok(InputOutputs {
        parts,
        failed: failures
            .into_iter()
            .map(|(suffix, e)| (suffix, e.to_string()))
            .collect(),
        warm: WarmStart {
            surface: cfg.fit.surface,
            controls: Vec::new(),
            frame: None,
            warp: None,
            domain: None,
            coords: Vec::new(),
            feet: None,
            parts: warm_parts,
            object: None,
            scattered: None,
        },
    })
}

/// Largest ratio of vertex counts between a component and the previous version's piece it
/// may continue: a piece that doubled or halved is taken for another piece, which starts
/// cold rather than from a net fitted to different data.
const MATCH_MAX_SIZE_RATIO: f64 = 2.0;

/// How far (as a fraction of the larger diagonal) a component's centroid may sit from the
/// previous piece it continues.
const MATCH_MAX_CENTROID_SHIFT: f64 = 0.25;

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
                && (1.0 / MATCH_MAX_SIZE_RATIO..=MATCH_MAX_SIZE_RATIO).contains(&ratio)
                && p.centroid.distance(centroid)
                    <= MATCH_MAX_CENTROID_SHIFT * p.diagonal.max(diagonal)
        })
        .min_by(|(_, a), (_, b)| {
            a.centroid
                .distance(centroid)
                .total_cmp(&b.centroid.distance(centroid))
        })
        .map(|(i, _)| i)
}

/// Segments per control-face side the configured tessellation gives an object fit (as for
/// subdivided inputs: the total spread over the faces), before the chord check refines it.
fn object_start(fitted: &PatchFit, cfg: &WorkerConfig) -> usize {
    let faces = match &fitted.model {
        super::SurfaceModel::Mesh(m) => m.faces().len().max(1),
        _ => 1,
    };
    (cfg.tessellation as f64 / (faces as f64).sqrt())
        .ceil()
        .max(2.0) as usize
}
