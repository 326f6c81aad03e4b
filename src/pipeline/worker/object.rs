//! The worker's third path: whole objects (closed, higher-genus or nearly closed inputs the
//! disk map cannot take, or any input with `fit.domain = "mesh"`) fitted with the exact Loop
//! limit surface of a control mesh simplified from the data (`pipeline::object`). This
//! module decides when an input goes there, warm-starts a new version from the previous
//! control mesh, and turns an `ObjectFit` into the `PatchFit` every output reads.

use super::config::WorkerConfig;
use super::stray_guard::{stays_on_data, StrayReport};
use crate::fit::{Budget, FitOutcome, FitStatus, StepStats};
use crate::mesh::clean::CleanReport;
use crate::mesh::crease::CreaseOptions;
use crate::mesh::edge_table::EdgeTable;
use crate::mesh::point_grid::PointGrid;
use crate::mesh::simplify::SurfaceTopology;
use crate::mesh::topology::Topology;
use crate::pipeline::object::{
    extend_over_new_ground, fit_object_input, fit_on_creased_control_mesh, is_faceted,
    refit_where_changed, FacetedChoice, LayoutReport, LocalUpdate, ObjectError, ObjectFit,
    ObjectInput, ObjectOptions, ObjectTimes, PreviousFit, RefineRound, RoundReport, RoundStop,
    StrayBudget,
};
use crate::pipeline::scan::{Dropped, WarmFeet};
use crate::pipeline::{PatchFit, PipelineError, SurfaceKind, SurfaceModel};
use crate::remesh::boundary_loops;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;
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

/// What an object fit leaves for the next version of the same object.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct ObjectWarm {
    /// The control faces (the positions are `WarmStart::controls`).
    pub faces: Vec<[u32; 3]>,
    /// The data points and their final (u, v) on their control faces ...
    pub feet: WarmFeet,
    /// ... and those faces.
    pub feet_faces: Vec<u32>,
    /// The data's topology the control mesh was simplified from.
    pub euler: i64,
    /// Its boundary loops.
    pub boundary_loops: usize,
    /// The data's bounding box (min, max).
    pub bounds: [DVec3; 2],
    /// The control mesh's crease edges.
    #[serde(default)]
    pub crease_edges: Vec<[u32; 2]>,
    /// The fitted limit surface, in memory only: the next version's surfaces take over
    /// its quadtrees of child nets instead of building them again (on fertility's coarse
    /// irregular control mesh about 10 ms of an 80 ms warm refit). Not stored: a restarted
    /// daemon builds them anew.
    #[serde(skip)]
    pub surface: Option<Arc<LoopLimitSurface>>,
}

/// A new version starts from the previous control mesh only when its vertex count is
/// within this factor of the previous one ...
const WARM_MAX_SIZE_RATIO: f64 = 1.5;
/// ... and each corner of its bounding box within this fraction of the previous diagonal.
const WARM_MAX_BOX_SHIFT: f64 = 0.05;

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

/// A new version's fit from the previous control mesh: refitted where the data changed
/// when that is a small part of it, else the whole fit from there.
fn warm_fit(
    start: WarmStartPoint,
    warm: &ObjectWarm,
    opts: &ObjectOptions,
) -> Result<ObjectFit, ObjectError> {
    let creases = &warm.crease_edges;
    let WarmStartPoint {
        component,
        control_mesh,
        params,
        reference,
    } = start;
    let faceted_opts;
    let opts = if is_faceted(&control_mesh.triangles, creases) {
        faceted_opts = ObjectOptions {
            smoothing: 0.0,
            ..opts.clone()
        };
        &faceted_opts
    } else {
        opts
    };
    let reusing = warm.surface.as_deref();
    let previous = PreviousFit {
        control_mesh: &control_mesh,
        crease_edges: creases,
        rms: warm.feet.rms,
        surface: reusing,
    };
    match refit_where_changed(
        component.clone(),
        previous,
        params.clone(),
        &reference,
        opts,
    )? {
        Some(fit) => Ok(fit),
        None => {
            fit_on_creased_control_mesh(component, control_mesh, creases, params, reusing, opts)
        }
    }
}

/// A point of a new version is on new ground when the nearest previous data point is
/// farther than this many of the new data's median edge lengths.
const NEW_GROUND_EDGES: f64 = 1.0;

/// A new version extends the previous control mesh only while at most this share of its
/// points is on new ground; more is mostly a new object.
const MAX_NEW_GROUND_SHARE: f64 = 0.6;

/// ... and while the data left at most this share of the previous control faces (a merge
/// drops rim cells as views are added; a removed scan leaves far more).
const MAX_FACES_LEFT: f64 = 0.02;

/// A new version with new ground is extended only while no point lies farther than this
/// share of the bounding-box diagonal beyond the previous data over its inner faces (twice
/// the stray guard's limit, `stray_guard`). Old ground moved farther is more than a local
/// change, and the whole fit takes it; a generated tube with a 3 % bump was extended
/// acceptably without this rule, the bunny's views were not (see `from_previous`).
const MAX_INNER_CHANGE: f64 = 0.01;

/// A new version fitted from the previous fit: extended over new ground when it covers
/// more (an object session's new view), else refitted where it changed; `Err` says why
/// the previous fit does not fit the new data (the whole fit runs).
/// `component` is the one a cold fit would take (`ObjectInput`): a broken input repaired
/// the same way.
fn from_previous(
    component: TriMesh,
    warm: &ObjectWarm,
    controls: &[DVec3],
    opts: &ObjectOptions,
) -> Result<Result<ObjectFit, ObjectError>, String> {
    let faces_ok = warm
        .faces
        .iter()
        .flatten()
        .all(|&v| (v as usize) < controls.len());
    let before = warm.feet.points.len();
    if !faces_ok || warm.feet_faces.len() != before || warm.feet.params.len() != before {
        return Err("the stored control mesh is inconsistent".into());
    }
    let spacing = crate::pipeline::merge::median_edge(&component);
    let (params, reference) = nearest_params(warm, &component.positions, spacing);
    // New ground lies beyond the previous data, so its nearest previous point is on a rim
    // face; a point far from the previous data over an inner face is a change of old
    // ground (a dent), which the local refit takes, unless it is far more than a dent (see
    // below).
    let rim = Topology::build(controls.len(), &warm.faces)
        .map_err(|e| format!("the stored control mesh is not a manifold: {e}"))?
        .boundary;
    let on_rim = |p: &SurfaceParam| {
        warm.faces
            .get(p.face as usize)
            .is_some_and(|t| t.iter().any(|&v| rim[v as usize]))
    };
    // Each point's distance to the previous data and whether it lies over a rim face.
    let gaps: Vec<(f64, bool)> = component
        .positions
        .iter()
        .zip(&reference)
        .zip(&params)
        .map(|((p, r), param)| (p.distance(*r), on_rim(param)))
        .collect();
    let near = NEW_GROUND_EDGES * spacing;
    let is_new: Vec<bool> = gaps
        .iter()
        .map(|&(d, over_rim)| d > near && over_rim)
        .collect();
    let has_new = is_new.contains(&true);
    if has_new {
        // A point this far beyond the previous data over its inner faces is mostly ground
        // the previous surface passes by (the far side of an ear, seen by a new view): its
        // start is on the wrong sheet, and the refit drags the old surface across, to be
        // refused by the stray guard after the whole extension's cost (the bunny's views
        // in reverse order: bun180 took 12.3 s, 7 of them on the refused extension).
        let limit = MAX_INNER_CHANGE * component.bounds_diagonal();
        let (count, farthest) = gaps
            .iter()
            .filter(|&&(d, over_rim)| !over_rim && d > limit)
            .fold((0, 0.0f64), |(n, m), &(d, _)| (n + 1, m.max(d)));
        if count > 0 {
            return Err(format!(
                "{count} points lie up to {farthest:.3e} beyond the previous data over its \
                 inner faces (more than {limit:.3e}, {MAX_INNER_CHANGE} of the bounding-box \
                 diagonal): not a local change"
            ));
        }
    }
    let start = WarmStartPoint {
        component,
        control_mesh: TriMesh::new(controls.to_vec(), warm.faces.clone()),
        params,
        reference,
    };
    if has_new {
        return extend_fit(start, &is_new, warm, opts).map(Ok);
    }
    check_same_object(&start.component, warm)?;
    Ok(warm_fit(start, warm, opts))
}

/// The new version extended over its new ground (`object::extend_over_new_ground`); `Err`
/// says why not. Refused as well when the data left a previous control face (a removed
/// scan): that face would keep a surface no data holds.
fn extend_fit(
    start: WarmStartPoint,
    is_new: &[bool],
    warm: &ObjectWarm,
    opts: &ObjectOptions,
) -> Result<ObjectFit, String> {
    let new = is_new.iter().filter(|&&b| b).count();
    if new as f64 > MAX_NEW_GROUND_SHARE * is_new.len() as f64 {
        return Err(format!("{new} of {} points on new ground", is_new.len()));
    }
    let mut held_before = vec![false; warm.faces.len()];
    for &f in &warm.feet_faces {
        if let Some(h) = held_before.get_mut(f as usize) {
            *h = true;
        }
    }
    let mut held = vec![false; warm.faces.len()];
    for (p, _) in start.params.iter().zip(is_new).filter(|(_, &n)| !n) {
        if let Some(h) = held.get_mut(p.face as usize) {
            *h = true;
        }
    }
    let left = held_before
        .iter()
        .zip(&held)
        .filter(|(&b, &h)| b && !h)
        .count();
    if left as f64 > MAX_FACES_LEFT * held_before.len() as f64 {
        return Err(format!(
            "the data left {left} of the previous {} control faces",
            held_before.len()
        ));
    }
    let previous = PreviousFit {
        control_mesh: &start.control_mesh,
        crease_edges: &warm.crease_edges,
        rms: warm.feet.rms,
        surface: warm.surface.as_deref(),
    };
    extend_over_new_ground(
        start.component.clone(),
        previous,
        start.params.clone(),
        &start.reference,
        is_new,
        opts,
    )
    .map_err(|e| e.to_string())?
    .map_err(|why| why.to_string())
}

/// Where a new version's warm fit starts.
struct WarmStartPoint {
    /// The new version's cleaned component.
    component: TriMesh,
    /// The previous control mesh at its fitted positions.
    control_mesh: TriMesh,
    /// Each data point's start parameter: that of the nearest previous data point ...
    params: Vec<SurfaceParam>,
    /// ... which is this one.
    reference: Vec<DVec3>,
}

/// Why the previous fit does not fit a new version over the same ground, if it does not.
fn check_same_object(component: &TriMesh, warm: &ObjectWarm) -> Result<(), String> {
    let topology =
        SurfaceTopology::of(component).map_err(|e| format!("not a manifold component: {e}"))?;
    if (topology.euler, topology.boundary_loops) != (warm.euler, warm.boundary_loops) {
        return Err(format!(
            "topology changed: Euler characteristic {} -> {}, boundary loops {} -> {}",
            warm.euler, topology.euler, warm.boundary_loops, topology.boundary_loops
        ));
    }
    let (n, before) = (component.positions.len(), warm.feet.points.len());
    let ratio = n.max(1) as f64 / before.max(1) as f64;
    if !(1.0 / WARM_MAX_SIZE_RATIO..=WARM_MAX_SIZE_RATIO).contains(&ratio) {
        return Err(format!("vertex count changed from {before} to {n}"));
    }
    let bounds = bounds_of(&component.positions);
    let diagonal = (warm.bounds[1] - warm.bounds[0]).length();
    let shift = (bounds[0] - warm.bounds[0])
        .length()
        .max((bounds[1] - warm.bounds[1]).length());
    // Written so that a NaN box (no points) counts as moved.
    if shift <= WARM_MAX_BOX_SHIFT * diagonal {
        Ok(())
    } else {
        Err(format!(
            "bounding box moved by {:.3} of its diagonal",
            shift / diagonal.max(f64::MIN_POSITIVE)
        ))
    }
}

fn bounds_of(points: &[DVec3]) -> [DVec3; 2] {
    let (lo, hi) =
        crate::numeric::bounds(points).unwrap_or((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)));
    [lo, hi]
}

/// Each point's start parameter, the final parameter of the nearest previous data point,
/// and that point. Most points of a new version lie near the previous data, where a
/// bucket grid of twice the data's `spacing` answers (`PointGrid`); the rest ask an
/// R-tree, not a grid searching ring after ring: new ground lies far from every previous
/// point (a view adding 5,000 points 10-20 mm from the previous data took 1.8 s that way).
fn nearest_params(
    warm: &ObjectWarm,
    points: &[DVec3],
    spacing: f64,
) -> (Vec<SurfaceParam>, Vec<DVec3>) {
    let old: Vec<DVec3> = warm
        .feet
        .points
        .iter()
        .map(|p| glam::Vec3::from_array(*p).as_dvec3())
        .collect();
    let grid = PointGrid::new(&old, 2.0 * spacing);
    let near: Vec<Option<usize>> = points
        .par_iter()
        .map(|p| grid.as_ref().and_then(|g| g.nearest(*p)))
        .collect();
    let tree = near.contains(&None).then(|| {
        RTree::bulk_load(
            old.iter()
                .enumerate()
                .map(|(k, p)| GeomWithData::new(p.to_array(), k))
                .collect(),
        )
    });
    points
        .par_iter()
        .zip(&near)
        .map(|(p, near)| {
            let k = near
                .or_else(|| {
                    tree.as_ref()?
                        .nearest_neighbor(&p.to_array())
                        .map(|n| n.data)
                })
                .unwrap_or(0);
            let [u, v] = warm.feet.params.get(k).copied().unwrap_or([0.0, 0.0]);
            let param = SurfaceParam {
                face: warm.feet_faces.get(k).copied().unwrap_or(0),
                u: f64::from(u),
                v: f64::from(v),
            };
            (param, old.get(k).copied().unwrap_or(*p))
        })
        .unzip()
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
