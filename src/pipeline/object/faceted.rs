//! The faceted candidate of a sharp-edged object: a Loop surface whose every control edge
//! is a crease.
//!
//! With every edge a crease, every vertex has three or more crease edges and is a corner:
//! Loop's crease rules then place each new edge vertex at its edge's midpoint and leave
//! every old vertex in place, so the limit surface is the control mesh itself, a
//! triangle mesh. That mesh is one of the surfaces the fit can reach, and on a machined
//! part it is often the one that fits: the smooth surface rounds every edge the crease
//! detection does not keep, and on parts whose sharp edges form a dense net rather than
//! feature lines (`MAX_FIXED_SHARE` in the module above drops such nets, since on scans
//! they are noise) it keeps none. Measured at the smooth fit's control count on CGAL's
//! meshes, never tuned on: boeing's smooth fit stood 3.5 times as far from its data as a
//! quadric decimation (RMS), couplingdown's 1.5 times, pinion_small's 1.2 times, and
//! blade's, a faceted blade whose decimation is exact, 10^4 times.
//!
//! The other data it fits are coarse or rough meshes: where the vertices do not sample
//! a smooth shape finely, the smooth surface bulges off the facets between them and
//! strays past the bound even at the largest budget (CGAL's elk, coarse double tori,
//! bones), while a decimation keeps to them.
//!
//! So on data with sharp edges (`SHARP_SHARE` of the vertices at least, where a
//! faceting can win at all), and on any data whose smooth fit strays past the bound, a
//! second fit runs at the same control count: an unguarded
//! quadric decimation (exact facets need long thin triangles), every edge a crease, the
//! controls fitted to the data without the fairness term (which would pull the corners
//! together) for `ROUNDS` foot-point rounds. The fit nearer the data (RMS) is kept where
//! its stray allows it (`stray_allows`); `FacetedChoice` says which and why.

use super::data_side::DataSide;
use super::fit_parts::FitStart;
use super::model::{
    landing_params, ms_since, FacetedChoice, ObjectError, ObjectFit, ObjectOptions, StrayBudget,
    STRAY_LATTICE_SEGMENTS,
};
use super::stray::{decimation_strays, farthest_of};
use crate::mesh::edge_table::EdgeTable;
use crate::mesh::simplify::{simplify_with_topology, Simplified, SimplifyOptions};
use crate::mesh::topology::Topology;
use crate::TriMesh;
use std::time::Instant;

/// The share of the data's vertices on sharp edges from which the faceted candidate is
/// tried. The meshes whose smooth fit lost to a decimation had 7.6-96 % of their vertices
/// on sharp edges (blade the fewest); organic models and scans have 0-4 % (camelhead 0.1,
/// the lion 1.5, mannequin-devil 4.2), so they pay nothing for it unless their smooth
/// fit strays past the bound.
const SHARP_SHARE: f64 = 0.05;

/// Foot-point rounds of the faceted fit. Two brought the largest distance down by 20-40 %
/// on blade, pinion_small and couplingdown (blade 8.3e-6 -> 5.2e-6); six more gave
/// couplingdown another 16 % of its max (5 % of its RMS) and the others under 2 %, at
/// 2-3 times the candidate's time.
const ROUNDS: usize = 2;

/// Share of `vertices` on one of the `sharp` edges.
fn sharp_share(vertices: usize, sharp: &[[u32; 2]]) -> f64 {
    let mut on = vec![false; vertices];
    for &v in sharp.iter().flatten() {
        if let Some(on) = on.get_mut(v as usize) {
            *on = true;
        }
    }
    on.iter().filter(|&&s| s).count() as f64 / vertices.max(1) as f64
}

/// `smooth`, or the faceted fit at its control count where that fits the data better
/// (module docs; tried on sharp data and where `smooth` strays past the bound);
/// `data_topo` is the data's topology, when it is a manifold, `sharp` its sharp edges
/// (`detect_creases`), and `fit_from` fits a control mesh to `side`'s data.
pub(super) fn keep_nearer(
    smooth: ObjectFit,
    side: &DataSide,
    data_topo: Option<&Topology>,
    sharp: &[[u32; 2]],
    opts: &ObjectOptions,
    fit_from: impl Fn(FitStart, &ObjectOptions) -> Result<ObjectFit, ObjectError>,
) -> ObjectFit {
    let Some(topo) = data_topo else {
        return smooth;
    };
    let vertices = side.mesh.positions.len();
    let limit = opts.stray_limit(side.mesh).unwrap_or(f64::INFINITY);
    let smooth_strays = smooth.stray.is_some_and(|s| s > limit);
    let wanted = faceting_allowed(opts);
    if !wanted || (sharp_share(vertices, sharp) < SHARP_SHARE && !smooth_strays) {
        return smooth;
    }
    let t = Instant::now();
    let fitted = faceted_fit(side, topo, smooth.controls.len(), opts, fit_from);
    let Ok(mut faceted) = fitted else {
        return smooth;
    };
    let faceted_stray = farthest_of(&faceted, side.nearest(), STRAY_LATTICE_SEGMENTS);
    let smooth_stray = smooth.stray;
    let kept_faceted = faceted.rms < smooth.rms
        && stray_allows(
            (faceted.rms, faceted_stray),
            (smooth.rms, smooth_stray),
            limit,
        );
    let choice = FacetedChoice {
        controls: faceted.controls.len(),
        smooth_rms: smooth.rms,
        smooth_max: smooth.max,
        smooth_stray,
        faceted_rms: faceted.rms,
        faceted_max: faceted.max,
        faceted_stray,
        kept_faceted,
        ms: ms_since(t),
    };
    let mut times = smooth.times.clone();
    times.faceted_ms = choice.ms;
    if !kept_faceted {
        return ObjectFit {
            faceted: Some(choice),
            times,
            ..smooth
        };
    }
    faceted.stray = Some(faceted_stray);
    faceted.faceted = Some(choice);
    faceted.stray_budgets = smooth.stray_budgets;
    faceted.cleaning = smooth.cleaning;
    faceted.times = times;
    faceted
}

/// Whether a faceted fit nearer the data than the smooth one (RMS `faceted_rms` against
/// `smooth_rms`) may replace it, by their strays: when it stays within the bound
/// `limit`; when it strays no farther than the smooth one; and when both stray past the
/// bound, when it gains at least as much in RMS as it loses in stray, ratio for ratio.
/// Neither then holds the bound, so the two measures are traded at equal relative
/// weight, with no constant to tune: on CGAL's coarse double torus the faceting halves
/// the RMS and strays 1.45 times as far (kept), on its pig it gains 5 % and strays 1.76
/// times as far (not).
fn stray_allows(
    (faceted_rms, faceted_stray): (f64, f64),
    (smooth_rms, smooth_stray): (f64, Option<f64>),
    limit: f64,
) -> bool {
    let smooth_stray = smooth_stray.unwrap_or(f64::INFINITY);
    faceted_stray <= limit
        || faceted_stray <= smooth_stray
        || (smooth_stray > limit && faceted_stray * faceted_rms <= smooth_stray * smooth_rms)
}

/// The stray escalation's last resort: where the kept fit (smooth or faceted) still
/// strays past the bound after the budget grew (`ObjectOptions::stray_budget_steps`, none
/// of it when that is 0) and a decimation to its control count strays as well (the count
/// cannot hold the shape; where a decimation holds it, the surface strays by its own
/// making and a faceting would only trade a smooth scan for facets), faceted fits at
/// twice the controls, step after step up to the data's own vertex count, and the first
/// within the bound is kept. A smooth surface cannot get there on such data: between
/// the vertices of a coarse mesh it leaves the flat facets by their sag whatever its
/// count (a jolted 384-vertex torus: 3.5 times the bound with a control at every
/// vertex), while a faceting converges to the data mesh itself, whose stray is nought.
/// So the bound the user was promised holds on every input, at the cost of controls and
/// of smoothness, which the report says (`stray_budgets` entries marked `faceted`, and
/// `faceted`). Where none gets within the bound, the fit is kept as it was with the tries
/// listed.
pub(super) fn hold_bound(
    fit: ObjectFit,
    side: &DataSide,
    data_topo: Option<&Topology>,
    opts: &ObjectOptions,
    fit_from: impl Fn(FitStart, &ObjectOptions) -> Result<ObjectFit, ObjectError>,
) -> ObjectFit {
    let (Some(limit), Some(topo)) = (opts.stray_limit(side.mesh), data_topo) else {
        return fit;
    };
    let stray = fit.stray.unwrap_or(f64::INFINITY);
    let wanted = faceting_allowed(opts) && opts.stray_budget_steps > 0;
    let vertices = side.mesh.positions.len();
    if !wanted || stray <= limit || fit.controls.len() >= vertices {
        return fit;
    }
    let t = Instant::now();
    let segments = STRAY_LATTICE_SEGMENTS;
    if !decimation_strays(
        side.nearest(),
        side.mesh,
        data_topo,
        fit.controls.len(),
        limit,
        segments,
    ) {
        return fit;
    }
    let mut tried = Vec::new();
    let mut count = fit.controls.len();
    while count < vertices && !opts.stop.out_of_time() {
        count = (2 * count).min(vertices);
        let Ok(decimated) = decimation(side, topo, count) else {
            continue;
        };
        // The fitted faceting first (nearer the data where it holds), the decimation as
        // it is where the fit strays.
        for how in [Faceting::Fitted, Faceting::AsDecimated] {
            let Ok(mut faceted) = faceting(&decimated, opts, &fit_from, how) else {
                continue;
            };
            let stray = farthest_of(&faceted, side.nearest(), segments);
            faceted.stray = Some(stray);
            let mut budget = StrayBudget::of(count, &faceted);
            budget.faceted = true;
            tried.push(budget);
            if stray <= limit {
                return kept_last_resort(fit, faceted, tried, ms_since(t));
            }
        }
    }
    let mut fit = fit;
    fit.times.stray_budget_ms += ms_since(t);
    fit.stray_budgets.extend(tried);
    fit
}

/// Whether `opts` let a faceted surface be fitted at all: the candidate asked for, and
/// creases on (turned off, they rule out the surface whose every edge is one).
fn faceting_allowed(opts: &ObjectOptions) -> bool {
    opts.faceted_candidate && opts.crease.on()
}

/// `faceted`, the last resort `hold_bound` keeps in place of `fit`, with the escalation's
/// account: `fit`'s tries and then the faceted ones (`tried`, the last the one kept), and
/// the choice against the surface it replaces.
fn kept_last_resort(
    fit: ObjectFit,
    mut faceted: ObjectFit,
    mut tried: Vec<StrayBudget>,
    ms: f64,
) -> ObjectFit {
    let first = StrayBudget::of(fit.controls.len(), &fit);
    let mut budgets = fit.stray_budgets;
    if budgets.is_empty() {
        budgets.push(first);
    }
    for b in &mut budgets {
        b.kept = false;
    }
    if let Some(last) = tried.last_mut() {
        last.kept = true;
    }
    budgets.extend(tried);
    // Against the smooth surface where the fit kept before was faceted already.
    let (smooth_rms, smooth_max, smooth_stray) = match fit.faceted {
        Some(c) if c.kept_faceted => (c.smooth_rms, c.smooth_max, c.smooth_stray),
        _ => (fit.rms, fit.max, fit.stray),
    };
    faceted.faceted = Some(FacetedChoice {
        controls: faceted.controls.len(),
        smooth_rms,
        smooth_max,
        smooth_stray,
        faceted_rms: faceted.rms,
        faceted_max: faceted.max,
        faceted_stray: faceted.stray.unwrap_or(f64::INFINITY),
        kept_faceted: true,
        ms,
    });
    faceted.stray_budgets = budgets;
    faceted.cleaning = fit.cleaning;
    faceted.times = fit.times;
    faceted.times.stray_budget_ms += ms;
    faceted
}

/// The faceted fit of `side`'s data at `controls` control points (module docs), by
/// `fit_from`.
fn faceted_fit(
    side: &DataSide,
    topo: &Topology,
    controls: usize,
    opts: &ObjectOptions,
    fit_from: impl Fn(FitStart, &ObjectOptions) -> Result<ObjectFit, ObjectError>,
) -> Result<ObjectFit, ObjectError> {
    let decimated = decimation(side, topo, controls)?;
    faceting(&decimated, opts, fit_from, Faceting::Fitted)
}

/// What a faceting does with the decimation.
#[derive(Clone, Copy, PartialEq)]
enum Faceting {
    /// Its controls fitted to the data (`ROUNDS` rounds, no fairness).
    Fitted,
    /// Its controls where the simplification left them, the data's feet found on it: the
    /// mesh a quadric decimation gives, whose stray `stray::decimation_strays` judges.
    /// The fit's rounds lower the RMS by moving controls, which can take the facets
    /// farther from the data than the decimation left them: CGAL's oblong at 128
    /// controls strays 0.60 % of the diagonal fitted and 0.48 % as decimated, so the
    /// last resort stops there instead of a doubling later.
    AsDecimated,
}

/// The plain quadric decimation of `side`'s data to `controls` vertices a faceting is
/// made of. Plain Garland-Heckbert: the smooth fit's isotropy term and triangle-quality
/// guard trade the facets' planes for even faces, which only a smooth surface needs.
fn decimation(
    side: &DataSide,
    topo: &Topology,
    controls: usize,
) -> Result<Simplified, ObjectError> {
    let simplify_opts = SimplifyOptions {
        target_vertices: controls,
        min_quality: 0.0,
        isotropy: 0.0,
        ..SimplifyOptions::default()
    };
    simplify_with_topology(side.mesh, topo, &simplify_opts, &[]).map_err(ObjectError::Simplify)
}

/// The faceted surface of `decimated` (every edge a crease), as `how` says.
fn faceting(
    decimated: &Simplified,
    opts: &ObjectOptions,
    fit_from: impl Fn(FitStart, &ObjectOptions) -> Result<ObjectFit, ObjectError>,
    how: Faceting,
) -> Result<ObjectFit, ObjectError> {
    let creases = every_edge(&decimated.mesh);
    let params = landing_params(&decimated.landing);
    let as_is = how == Faceting::AsDecimated;
    let fit_opts = ObjectOptions {
        smoothing: 0.0,
        rounds: if as_is { 0 } else { ROUNDS },
        // The first fit at the landings themselves: they are where the simplification
        // carried each point on the decimated faces, which this surface is, so projecting
        // them again only lets points jump to a nearer face across a thin part or a hole.
        // On CGAL's elephant with 106 holes the fit from projected starts diverged in its
        // rounds (RMS 8.0e-4 -> 8.6e-3 at 1876 controls); from the landings it converges
        // (8.2e-4 -> 7.1e-4); blade, couplingdown, pinion_small and anchor fit the same.
        limit_start: false,
        ..opts.clone()
    };
    let warm = as_is.then(|| decimated.mesh.positions.clone());
    let start = FitStart {
        warm,
        ..FitStart::new(decimated.mesh.clone(), &creases, params)
    };
    fit_from(start, &fit_opts)
}

/// Whether every interior edge of the control mesh `faces` is one of `creases` (each low
/// index first, sorted, as `LoopLimitSurface::crease_edges` keeps them: interior edges
/// only): the faceted surface, whose refits take no fairness term either.
pub fn is_faceted(faces: &[[u32; 3]], creases: &[[u32; 2]]) -> bool {
    let vertices = faces.iter().flatten().max().map_or(0, |&v| v as usize + 1);
    let edges = EdgeTable::new(faces, vertices);
    !faces.is_empty()
        && (0..edges.len())
            .filter(|&e| edges.halves(e).len() == 2)
            .all(|e| creases.binary_search(&edges.ends(e)).is_ok())
}

/// Every edge of `mesh`, low index first, sorted.
fn every_edge(mesh: &TriMesh) -> Vec<[u32; 2]> {
    let edges = EdgeTable::new(&mesh.triangles, mesh.positions.len());
    (0..edges.len()).map(|e| edges.ends(e)).collect()
}

#[cfg(test)]
mod tests {
    use super::stray_allows;

    #[test]
    fn a_faceting_that_strays_farther_is_kept_only_for_as_much_nearness() {
        let limit = 1.0;
        // Within the bound, or no farther than the smooth surface: kept.
        assert!(stray_allows((1.0, 0.9), (2.0, Some(0.5)), limit));
        assert!(stray_allows((1.0, 1.5), (2.0, Some(1.6)), limit));
        // The smooth surface within the bound and the faceting past it: never.
        assert!(!stray_allows((0.1, 1.1), (2.0, Some(0.9)), limit));
        // Both past: half the RMS buys up to twice the stray, not more.
        assert!(stray_allows((1.0, 3.9), (2.0, Some(2.0)), limit));
        assert!(!stray_allows((1.0, 4.1), (2.0, Some(2.0)), limit));
        // A smooth fit whose stray was not measured counts as past any bound.
        assert!(stray_allows((1.0, 40.0), (2.0, None), limit));
    }
}
