//! The report of a fitted patch and what it leaves for the next version. The report stays a
//! JSON value: the CLI and the daemon add their own keys (input, patch, version) to it.

use super::config::WorkerConfig;
use crate::fit::{Budget, FitStatus, StepStats};
use crate::pipeline::output::{error_ramp, surface_json};
use crate::pipeline::scan::{warm_feet, ScanFit};
use crate::pipeline::{PatchFit, SurfaceKind, SurfaceModel};
use crate::remesh::planar::PlaneFrame;
use crate::remesh::warp::PlaneWarp;
use glam::DVec3;
use serde_json::json;
use std::time::Instant;

/// A fit of a subdivided input that missed the budget before a finer one was tried.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Refinement {
    /// Levels of inverse subdivision of that fit.
    pub levels: usize,
    /// Its control points.
    pub control_points: usize,
    /// How it ended.
    pub status: FitStatus,
    /// Its last step.
    #[serde(rename = "final")]
    pub last: Option<StepStats>,
}

/// What a fit leaves for the next version of the same patch. Stored whole by the daemon's
/// state store (serde), so new fields must carry `#[serde(default)]`.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct WarmStart {
    /// The kind of surface fitted (a warm start of another kind is ignored).
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
    /// ... and the domain over it.
    #[serde(default)]
    pub domain: Option<crate::pipeline::scan::Domain>,
    /// Loop grid: grid coordinates of `controls`.
    #[serde(default)]
    pub coords: Vec<(i64, i64)>,
    /// Remeshed scans on a grid: the data points and their final parameters.
    #[serde(default)]
    pub feet: Option<crate::pipeline::scan::WarmFeet>,
    /// `components = "all"`: one warm start per fitted component (the fields above are then
    /// empty).
    #[serde(default)]
    pub parts: Vec<PartWarm>,
    /// Whole objects: the control mesh's faces and the data's final parameters on it (the
    /// control positions are `controls`).
    #[serde(default)]
    pub object: Option<super::object_version::ObjectWarm>,
    /// B-patch and DMS fits: the domain, knots and controls (the plane frame, warp and data
    /// feet are in the fields above).
    #[serde(default)]
    pub scattered: Option<crate::pipeline::scattered::ScatteredWarm>,
}

impl WarmStart {
    /// Whether this warm start, or a part's, keeps a fitted surface in memory
    /// (`ObjectWarm::surface`).
    pub fn holds_surface(&self) -> bool {
        self.object.as_ref().is_some_and(|o| o.surface.is_some())
            || self.parts.iter().any(|p| p.warm.holds_surface())
    }

    /// Drops the fitted surfaces kept in memory for the next version, here and in the
    /// parts (the next version then builds its quadtrees anew): a holder of many warm
    /// starts, or of one for long, bounds its memory this way.
    pub fn drop_surfaces(&mut self) {
        if let Some(object) = &mut self.object {
            object.surface = None;
        }
        for part in &mut self.parts {
            part.warm.drop_surfaces();
        }
    }
}

/// A component's warm start and where the component was, so that the pieces of the next
/// version find theirs even when their sizes (and so their order) change.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct PartWarm {
    /// The component's suffix (`.c<k>`).
    pub suffix: String,
    /// Its vertices' centroid.
    pub centroid: DVec3,
    /// Its bounding-box diagonal.
    pub diagonal: f64,
    /// Its vertex count.
    pub vertices: usize,
    /// Its own warm start.
    pub warm: WarmStart,
}

/// The report, surface.json and warm-start state of a fitted patch.
pub(super) fn describe(
    cfg: &WorkerConfig,
    fitted: &PatchFit,
    scan_info: Option<&ScanFit>,
    budget: &Budget,
    levels: usize,
    refinement: &[Refinement],
    wall: Instant,
) -> (serde_json::Value, serde_json::Value, WarmStart) {
    let mut report = report_json(cfg, fitted, budget, wall.elapsed().as_secs_f64() * 1e3);
    report["levels"] = json!(levels);
    if !refinement.is_empty() {
        report["refinement"] = json!(refinement);
    }
    if let Some(s) = scan_info {
        add_scan_report(&mut report, fitted, s);
    }
    let surface = surface_json(fitted, scan_info, &report);
    let warm = WarmStart {
        surface: fitted.surface,
        controls: fitted.controls.clone(),
        frame: scan_info.map(|s| s.mapping.frame),
        warp: scan_info.and_then(|s| s.mapping.warp.clone()),
        domain: scan_info.map(|s| s.domain.clone()),
        coords: match &fitted.model {
            SurfaceModel::Grid(g) => g.control_coords().to_vec(),
            _ => Vec::new(),
        },
        feet: scan_info.and_then(warm_feet),
        parts: Vec::new(),
        object: None,
        scattered: None,
    };
    (report, surface, warm)
}

/// The report's keys about a scan's preparation, map, domain and rounds.
fn add_scan_report(report: &mut serde_json::Value, fitted: &PatchFit, s: &ScanFit) {
    let plan = &s.trims.plan;
    report["remeshed"] = json!(true);
    report["components"] = json!(s.preparation.components);
    report["kept_vertices"] = json!(s.preparation.kept_vertices);
    // Pieces left out are said, never dropped silently: how many, their vertices and share.
    report["dropped"] = json!(s.preparation.dropped);
    report["cold_start"] = json!(s.cold_start.as_ref().map(|c| c.to_string()));
    report["holes_filled"] = json!(s.preparation.holes);
    report["holes"] = json!({
        "count": s.preparation.holes,
        "bridged": plan.bridged.iter().filter(|b| **b).count(),
        "trimmed": plan.trimmed(),
        "wide_triangles_trimmed": plan.wide_triangles.len(),
        "max_bridge": plan.max_bridge,
        "largest_radius": plan.radius.iter().cloned().fold(0.0, f64::max),
    });
    report["parameterization"] = json!({
        "method": s.mapping.method,
        "folded_triangles": s.mapping.folds_projected,
        "warp_blend": s.mapping.warp.as_ref().map(|w| w.blend),
        "warp_folded_triangles": s.mapping.folds_warped,
    });
    report["initial_net"] = json!({
        "resampled_points": s.initial.resample_points,
        "inverse": s.initial.inverse,
    });
    report["domain"] = json!(s.domain);
    report["cells"] = json!(fitted.model.as_surface().domain_face_count());
    report["reused_controls"] = json!(s.reused_controls);
    report["parameter_correction_rms"] = json!(s.correction_rms);
    report["parameterization_ms"] = json!(s.timings.parameterization_ms);
    report["resample_ms"] = json!(s.timings.resample_ms);
}

fn report_json(
    cfg: &WorkerConfig,
    f: &PatchFit,
    budget: &Budget,
    wall_ms: f64,
) -> serde_json::Value {
    let mut fin = f.outcome.steps.last().map_or(json!({}), |s| json!(s));
    fin["geometric_max_error"] = json!(f.geometric_max());
    fin["geometric_rms_error"] = json!(f.geometric_rms());
    json!({
        "surface": f.surface,
        "method": cfg.fit.method,
        "levels": cfg.fit.levels,
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
        "iterations": f.outcome.steps,
        "final": fin,
        // What surface.glb's colours mean (legend.svg draws the same).
        "error_ramp": error_ramp(budget.tolerance)["error_ramp"],
    })
}
