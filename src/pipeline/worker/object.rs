//! The worker's third path: whole objects (closed, higher-genus or nearly closed inputs the
//! disk map cannot take, or any input with `fit.domain = "mesh"`) fitted with the exact Loop
//! limit surface of a control mesh simplified from the data (`pipeline::object`). This
//! module decides when an input goes there, hands a new version to `object_version` (its
//! start from the previous control mesh), and turns an `ObjectFit` into the `PatchFit`
//! every output reads.

use super::config::WorkerConfig;
use super::object_version::{bounds_of, from_previous, ObjectWarm};
use super::stray_guard::{stays_on_data, StrayReport};
use crate::fit::{Budget, FitOutcome, FitStatus, StepStats};
use crate::mesh::clean::CleanReport;
use crate::mesh::crease::CreaseOptions;
use crate::mesh::edge_table::EdgeTable;
use crate::mesh::simplify::SurfaceTopology;
use crate::pipeline::object::{
    fit_object_input, FacetedChoice, LayoutReport, LocalUpdate, ObjectError, ObjectFit,
    ObjectInput, ObjectOptions, ObjectTimes, RefineRound, RoundReport, RoundStop, StrayBudget,
};
use crate::pipeline::scan::{Dropped, WarmFeet};
use crate::pipeline::{PatchFit, PipelineError, SurfaceKind, SurfaceModel};
use crate::remesh::boundary_loops;
use crate::TriMesh;
use glam::DVec3;
use std::sync::Arc;
use std::time::Instant;

/// A surface whose longest boundary loop is shorter than this many square roots of its
/// area is nearly closed (a disk has 3.5, a range scan's ragged rim more; bun_zipper's
/// largest hole 0.3): squeezed onto a disk it would be ruined, so it is fitted whole.
const NEARLY_CLOSED_RIM: f64 = 1.0;

/// Whether the raw input may be closed or nearly closed, judged without cleaning it: no
/// boundary edge, or no boundary loop as long as twice `NEARLY_CLOSED_RIM` square roots of
/// the area (cleaning can split a loop at a pinch vertex: the margin covers it). Every
/// disk-like scan fails this in a few milliseconds, so only candidates pay for the
/// cleaned check (`object_reason`); handles are found by the scan path's own refusal.
pub(super) fn may_be_nearly_closed(mesh: &TriMesh) -> bool {
    let n = mesh.positions.len();
    if mesh.triangles.iter().flatten().any(|&v| v as usize >= n) {
        return true;
    }
    let edges = EdgeTable::new(&mesh.triangles, n);
    let mut next = vec![u32::MAX; n];
    for e in 0..edges.len() {
        if let [h] = edges.halves(e) {
            let t = mesh.triangles[(*h / 3) as usize];
            let k = (*h % 3) as usize;
            next[t[k] as usize] = t[(k + 1) % 3];
        }
    }
    let mut seen = vec![false; n];
    let mut longest = 0.0f64;
    for start in 0..n {
        let mut length = 0.0;
        let mut v = start;
        while next[v] != u32::MAX && !seen[v] {
            seen[v] = true;
            let w = next[v] as usize;
            length += mesh.positions[v].distance(mesh.positions[w]);
            v = w;
        }
        longest = longest.max(length);
    }
    let area: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();
    // Written so that a NaN (no area) counts as a candidate.
    let long_rim = longest >= 2.0 * NEARLY_CLOSED_RIM * area.sqrt();
    !long_rim
}

/// `mesh` prepared for the object path as `fit_as_object` fits it (the worker's cleaning
/// options); `None` when cleaning leaves nothing.
pub(super) fn object_input(mesh: &TriMesh, cfg: &WorkerConfig) -> Option<ObjectInput> {
    ObjectInput::of(mesh, &options(cfg).clean)
}

/// Why an input without subdivision connectivity goes the object path under
/// `domain = "auto"`, or `None` when it is a disk-like scan (or so broken that the scan
/// path's own refusal says more). Judged on the component the object path would fit.
pub(super) fn object_reason(input: &ObjectInput) -> Option<String> {
    let part = &input.mesh;
    let topo = input.topology.as_ref()?;
    let loops = boundary_loops(topo);
    if loops.is_empty() {
        return Some("closed surface".into());
    }
    let chi = part.positions.len() as i64 - topo.edge_count() as i64 + part.triangles.len() as i64;
    // A disk with holes has chi = 2 - loops; less means handles.
    let genus = (2 - loops.len() as i64 - chi) / 2;
    if genus != 0 {
        return Some(format!(
            "genus {genus} with {} boundary loops (Euler characteristic {chi})",
            loops.len()
        ));
    }
    let length = |l: &Vec<u32>| -> f64 {
        (0..l.len())
            .map(|k| {
                part.positions[l[k] as usize]
                    .distance(part.positions[l[(k + 1) % l.len()] as usize])
            })
            .sum()
    };
    let rim = loops.iter().map(length).fold(0.0, f64::max);
    let area: f64 = part
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| part.positions[v as usize]);
            0.5 * (b - a).cross(c - a).length()
        })
        .sum();
    let ratio = rim / area.sqrt().max(f64::MIN_POSITIVE);
    (ratio < NEARLY_CLOSED_RIM).then(|| {
        format!(
            "nearly closed: {} boundary loops, the longest {ratio:.2} times the square root of the area",
            loops.len()
        )
    })
}

/// The report's account of an object fit (the surface, controls, data and parameters are
/// in the `PatchFit`).
pub struct ObjectInfo {
    /// Why the object path was taken.
    pub reason: String,
    /// Whether the previous version's control mesh was the start, and if not why.
    pub warm: WarmDecision,
    /// The data's topology.
    pub data_topology: SurfaceTopology,
    /// The control mesh's topology.
    pub control_topology: SurfaceTopology,
    /// RMS and max after the first fit and after each round.
    pub rounds: Vec<RoundReport>,
    /// Stage times.
    pub times: ObjectTimes,
    /// What the layout stage changed in the simplified control mesh.
    pub layout: LayoutReport,
    /// The fit before refinement and after each refinement round.
    pub refinement: Vec<RefineRound>,
    /// What a local refit of a new version touched (`None`: a whole fit).
    pub local: Option<LocalUpdate>,
    /// How far the surface strays from the data (`None`: not measured, as on an object
    /// session's local refit, whose guard measures the faces it moved).
    pub stray: Option<StrayReport>,
    /// What cleaning changed in the input (`None` on a warm refit, which cleans the new
    /// version only to match it to the previous one).
    pub cleaning: Option<CleanReport>,
    /// The whole fits at growing budgets when the first strayed (empty otherwise).
    pub stray_budgets: Vec<StrayBudget>,
    /// The smooth and the faceted fit of a sharp-edged object, and which was kept.
    pub faceted: Option<FacetedChoice>,
    /// The input's components left out (the `components` policy's `largest`).
    pub dropped: Dropped,
}

/// Whether a warm start was used.
pub enum WarmDecision {
    /// There was no previous object fit.
    None,
    /// Started from the previous control mesh and foot points.
    Used,
    /// Started cold: why the previous fit did not fit, and the milliseconds the refused
    /// attempt took before the fit from scratch (an extension is judged after its feet on
    /// the previous surface are found; a refit after it ran).
    Refused {
        /// Why.
        why: String,
        /// What finding it out cost.
        tried_ms: f64,
    },
}

fn options(cfg: &WorkerConfig) -> ObjectOptions {
    ObjectOptions {
        target_controls_pct: cfg.fit.scan.target_controls_pct,
        crease: CreaseOptions {
            angle_deg: cfg.fit.crease_angle_deg,
            relative_ratio: cfg.fit.crease_relative_ratio,
            ..CreaseOptions::default()
        },
        smoothing: cfg.fit.scan.smoothing,
        stray_budget_steps: cfg.fit.scan.stray_budget_steps,
        faceted_candidate: cfg.fit.faceted,
        rounds: cfg.fit.correction.rounds,
        curvature_floor: cfg.fit.correction.curvature_floor(),
        ..ObjectOptions::default()
    }
}

/// Fits `mesh` as a whole object, from `previous` when it still fits; `input` is `mesh`
/// prepared already (`object_input`), if it was.
pub(super) fn fit_as_object(
    mesh: &TriMesh,
    input: Option<ObjectInput>,
    previous: Option<&ObjectWarm>,
    previous_controls: &[DVec3],
    cfg: &WorkerConfig,
    budget: &Budget,
    reason: String,
) -> Result<(PatchFit, ObjectInfo), PipelineError> {
    let mut opts = options(cfg);
    opts.refine.tolerance = Some(budget.tolerance);
    // The rounds stop where the budget holds or its time is up, as a scan's do.
    opts.stop = RoundStop::of_budget(budget, Instant::now());
    let object = |source| PipelineError::Object { source };
    let input = match input {
        Some(input) => input,
        None => ObjectInput::of(mesh, &opts.clean)
            .ok_or(ObjectError::Empty)
            .map_err(object)?,
    };
    let dropped = Dropped::of(&input.left_out, input.cleaned_vertices);
    dropped.warn(input.left_out.len() + 1, input.cleaned_vertices);
    let tried = Instant::now();
    let (fit, warm) = match previous {
        Some(w) => match from_previous(input.mesh.clone(), w, previous_controls, &opts)
            .and_then(|fit| stays_on_data(fit, &w.faces, &w.crease_edges, previous_controls))
        {
            Ok(fit) => (fit.map_err(object)?, WarmDecision::Used),
            Err(why) => {
                let tried_ms = tried.elapsed().as_secs_f64() * 1e3;
                (
                    fit_object_input(input, &opts).map_err(object)?,
                    WarmDecision::Refused { why, tried_ms },
                )
            }
        },
        None => (
            fit_object_input(input, &opts).map_err(object)?,
            WarmDecision::None,
        ),
    };
    // The scan path's minimum holds here too: a closed 8-vertex cube came out as a
    // 4-control blob straying 17 % of its diagonal from its corners.
    let min = cfg.fit.components.min_vertices;
    if fit.data.len() < min {
        return Err(PipelineError::TooFewVertices {
            vertices: fit.data.len(),
            min,
        });
    }
    let info = ObjectInfo {
        reason,
        warm,
        data_topology: fit.data_topology,
        control_topology: fit.control_topology,
        rounds: fit.rounds.clone(),
        times: fit.times.clone(),
        layout: fit.layout,
        refinement: fit.refinement.clone(),
        local: fit.local.clone(),
        stray: Some(StrayReport::of(&fit)),
        cleaning: fit.cleaning.clone(),
        stray_budgets: fit.stray_budgets.clone(),
        faceted: fit.faceted,
        dropped,
    };
    if let Some(stray) = info.stray.filter(|s| !s.within) {
        tracing::warn!(
            "the surface strays {:.3e} from the data, {:.2} % of the bounding-box diagonal \
             (over {:.2} %): more control points bring it closer",
            stray.max,
            100.0 * stray.share_of_diagonal,
            100.0 * stray.limit_share
        );
    }
    let out_of_time = opts.stop.out_of_time();
    let patch = patch_fit(
        fit,
        budget,
        matches!(info.warm, WarmDecision::Used),
        out_of_time,
    );
    Ok((patch, info))
}

/// The object fit in the form every output reads: a Loop surface on its control mesh.
fn patch_fit(fit: ObjectFit, budget: &Budget, warm_start: bool, out_of_time: bool) -> PatchFit {
    let last = StepStats::from_distances(
        fit.rounds.len().saturating_sub(1),
        &fit.distances,
        budget.tolerance,
        fit.times.total_ms,
    );
    let status = if budget.met(&last) {
        FitStatus::Met
    } else if out_of_time {
        FitStatus::Capped
    } else {
        FitStatus::Stalled
    };
    PatchFit {
        surface: SurfaceKind::Loop,
        degree: 0,
        model: SurfaceModel::Mesh(Arc::new(fit.surface)),
        outcome: FitOutcome {
            controls: fit.controls.clone(),
            iterations: last.k,
            steps: vec![last],
            status,
        },
        controls: fit.controls,
        data: fit.data,
        params: fit.params,
        geometric_errors: fit.distances,
        warm_start,
        prepare_ms: fit.times.clean_ms
            + fit.times.simplify_ms
            + fit.times.layout_ms
            + fit.times.surface_ms,
        fit_ms: fit.times.first_fit_ms + fit.times.rounds_ms + fit.times.refine_ms,
    }
}

/// What the next version starts from (`None` for a fit of another model).
pub(super) fn object_warm(fit: &PatchFit, info: &ObjectInfo) -> Option<ObjectWarm> {
    let SurfaceModel::Mesh(surface) = &fit.model else {
        return None;
    };
    Some(ObjectWarm {
        faces: surface.faces().to_vec(),
        feet: WarmFeet {
            points: fit.data.iter().map(|p| p.as_vec3().to_array()).collect(),
            params: fit
                .params
                .iter()
                .map(|p| [p.u as f32, p.v as f32])
                .collect(),
            rms: fit.geometric_rms(),
        },
        feet_faces: fit.params.iter().map(|p| p.face).collect(),
        euler: info.data_topology.euler,
        boundary_loops: info.data_topology.boundary_loops,
        bounds: bounds_of(&fit.data),
        crease_edges: surface.crease_edges().to_vec(),
        surface: Some(surface.clone()),
    })
}

/// The report's keys about an object fit.
pub(super) fn object_report(fit: &PatchFit, info: &ObjectInfo) -> serde_json::Value {
    let topology = |t: &SurfaceTopology| {
        serde_json::json!({
            "genus": t.genus,
            "boundary_loops": t.boundary_loops,
            "euler_characteristic": t.euler,
            "components": t.components,
        })
    };
    let (faces, creases) = match &fit.model {
        SurfaceModel::Mesh(m) => (m.faces().len(), m.crease_edges().len()),
        _ => (0, 0),
    };
    let warm = match &info.warm {
        WarmDecision::None => serde_json::json!({"used": false}),
        WarmDecision::Used => serde_json::json!({"used": true}),
        WarmDecision::Refused { why, tried_ms } => {
            serde_json::json!({"used": false, "cold_because": why, "tried_ms": tried_ms})
        }
    };
    serde_json::json!({
        "path_reason": info.reason,
        "data_points": fit.data.len(),
        "control_points": fit.controls.len(),
        "control_faces": faces,
        "crease_edges": creases,
        "initial_positions": initial_positions(info),
        "layout": info.layout,
        "refinement": info.refinement,
        "topology": {"data": topology(&info.data_topology), "control": topology(&info.control_topology)},
        "rounds": info.rounds,
        "stages": info.times,
        "warm": warm,
        "local": info.local,
        "stray": info.stray,
        "stray_budgets": info.stray_budgets,
        "faceted": info.faceted,
        "cleaning": info.cleaning,
    })
}

/// How the control mesh the fit started from was made.
fn initial_positions(info: &ObjectInfo) -> &'static str {
    match (&info.warm, info.layout.flips + info.layout.relax_steps) {
        (WarmDecision::Used, _) => "previous version",
        (_, 0) => "simplification",
        _ => "simplification, valence flips, tangential relaxation",
    }
}
