//! A new version of a whole object fitted from the previous one: extended over its new
//! ground when it covers more (an object session's new view), refitted where it changed
//! when it covers the same ground, and refused (`Err(why)`: the whole fit runs) when the
//! previous fit does not fit it.

use crate::mesh::point_grid::PointGrid;
use crate::mesh::simplify::SurfaceTopology;
use crate::mesh::topology::Topology;
use crate::pipeline::object::{
    extend_over_new_ground, fit_on_creased_control_mesh, is_faceted, refit_where_changed,
    ObjectError, ObjectFit, ObjectOptions, PreviousFit,
};
use crate::pipeline::scan::WarmFeet;
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::SurfaceParam;
use crate::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use rstar::primitives::GeomWithData;
use rstar::RTree;
use std::sync::Arc;

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
pub(super) fn from_previous(
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

pub(super) fn bounds_of(points: &[DVec3]) -> [DVec3; 2] {
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
