//! Stage 2 of a scan fit: the domain over the map (one triangle for a single Bezier patch,
//! a grid otherwise) and its initial net, resampled and inverse-subdivided, or taken from the
//! previous version. The hole plan, which decides only what is trimmed afterwards, is made
//! beside it.

use super::cold_start::ColdStart;
use super::domain::{
    barycentric, bezier_initial_net, covered_cells, enclosing_triangle, grid_for_target,
    grid_initial_net, plane_extent, GridFrame, InitialNet,
};
use super::holes::{plan_holes, HolePlan};
use super::prepare::Prepared;
use super::types::{BezierLayout, Domain, ScanOptions, ScanWarm};
use super::warm::net_from_warm;
use super::warm_guard::WARM_BUDGET_SLACK;
use crate::pipeline::{FitOptions, PipelineError, SurfaceKind, SurfaceModel};
use crate::remesh::planar::PlanarMap;
use crate::surface::bezier::{lattice_triangles, BezierTriangle};
use crate::surface::grid_spline::GridSpline;
use crate::surface::TriSurface;
use glam::DVec2;

/// The surface model over its domain and the net a fit starts from.
pub(super) struct Resampled {
    pub(super) model: SurfaceModel,
    pub(super) domain: Domain,
    pub(super) initial: InitialNet,
    /// The control net's triangles: what the fairness term smooths over.
    pub(super) fairness_triangles: Vec<[u32; 3]>,
    /// Set when the previous version's grid spacing was refused for the budget.
    pub(super) cold_start: Option<ColdStart>,
}

pub(super) fn resample(
    prepared: &Prepared,
    opts: &FitOptions,
    scan: &ScanOptions,
    warm: Option<&ScanWarm>,
) -> Result<(HolePlan, Resampled), PipelineError> {
    let Prepared {
        part,
        patch,
        map,
        edge_length,
        ..
    } = prepared;
    let single_bezier =
        opts.surface == SurfaceKind::Bezier && scan.config.bezier_layout == BezierLayout::Single;
    let plan_hole_trims = || {
        plan_holes(
            &map.mesh,
            patch.real_vertices,
            &patch.hole_loops,
            &part.triangles,
            scan.config.hole_bridge_edges * edge_length,
        )
    };
    let (hole_plan, resampled) = rayon::join(plan_hole_trims, || match single_bezier {
        true => single_patch(map, opts, scan, warm),
        false => grid(map, patch.real_vertices, opts, scan, warm),
    });
    Ok((hole_plan, resampled?))
}

/// Beyond this the single patch is neither a sensible model of a scan nor cheap to evaluate.
const MAX_BEZIER_DEGREE: usize = 96;

/// Points of the resampled lattice beyond which a single patch is refused before anything is
/// allocated (a huge degree or many levels would otherwise exhaust memory).
const MAX_BEZIER_RESAMPLE_POINTS: f64 = 1e8;

/// Margin of the enclosing triangle around the map, as a fraction of its size: the outermost
/// data then sit strictly inside the reference triangle rather than on its edges.
const ENCLOSING_MARGIN: f64 = 0.01;

/// One Bezier patch of degree `lattice` over a triangle enclosing the map (the previous
/// version's triangle when it still encloses it).
fn single_patch(
    map: &PlanarMap,
    opts: &FitOptions,
    scan: &ScanOptions,
    warm: Option<&ScanWarm>,
) -> Result<Resampled, PipelineError> {
    let plane = &map.plane;
    let n0 = scan.config.lattice.max(1);
    let segments = (n0 as f64) * 2f64.powi(opts.levels.min(60) as i32);
    if n0 > MAX_BEZIER_DEGREE
        || (segments + 1.0) * (segments + 2.0) / 2.0 > MAX_BEZIER_RESAMPLE_POINTS
    {
        return Err(PipelineError::BezierTooLarge {
            degree: n0,
            levels: opts.levels,
            segments,
            max_degree: MAX_BEZIER_DEGREE,
        });
    }
    let corners = match warm.and_then(|w| w.domain) {
        Some(Domain::Triangle { corners })
            if plane.iter().all(|p| {
                let (u, v) = barycentric(corners, *p);
                u >= 0.0 && v >= 0.0 && u + v <= 1.0
            }) =>
        {
            *corners
        }
        _ => enclosing_triangle(plane, ENCLOSING_MARGIN),
    };
    let initial = bezier_initial_net(&map.mesh, plane, &corners, n0, opts.levels, opts.inverse);
    Ok(Resampled {
        model: SurfaceModel::Bezier(BezierTriangle::new(n0)),
        domain: Domain::Triangle { corners },
        initial,
        fairness_triangles: lattice_triangles(n0),
        cold_start: None,
    })
}

/// A grid over the map: `grid_segments` cells across, the previous version's spacing, or
/// the spacing that gives `target_controls_pct` of the `real` data points as controls.
fn grid(
    map: &PlanarMap,
    real: usize,
    opts: &FitOptions,
    scan: &ScanOptions,
    warm: Option<&ScanWarm>,
) -> Result<Resampled, PipelineError> {
    let plane = &map.plane;
    let target = (scan.config.target_controls_pct / 100.0 * real as f64).round() as usize;
    let for_target = || grid_for_target(plane, &map.mesh.triangles, target);
    let (spacing, cells) = match (warm.and_then(|w| w.domain), scan.config.grid_segments) {
        (_, Some(n)) => (
            plane_extent(plane).max_element().max(1e-300) / n.max(1) as f64,
            None,
        ),
        (Some(Domain::Grid { spacing }), None) => (*spacing, None),
        _ => {
            let (h, cells) = for_target();
            (h, Some(cells))
        }
    };
    let warm_spacing = cells.is_none() && scan.config.grid_segments.is_none();
    let gf = GridFrame { spacing };
    check_grid_size(plane, spacing, opts.levels)?;
    let cells = cells.unwrap_or_else(|| covered_cells(&gf, plane, &map.mesh.triangles));
    let mut grid = GridSpline::new(cells);
    let mut spacing = spacing;
    let mut cold_start = None;
    // The previous spacing over data that changed shape can cost any number of controls:
    // past the budget's slack the grid is laid out for the target instead.
    let limit = (WARM_BUDGET_SLACK * target as f64).ceil() as usize;
    if warm_spacing && target > 0 && grid.control_count() > limit {
        cold_start = Some(ColdStart::Budget {
            controls: grid.control_count(),
            limit,
        });
        let (h, cells) = for_target();
        check_grid_size(plane, h, opts.levels)?;
        spacing = h;
        grid = GridSpline::new(cells);
    }
    let gf = GridFrame { spacing };
    let same_domain = warm.filter(|w| w.domain == Some(&Domain::Grid { spacing }));
    let initial = match same_domain.and_then(|w| net_from_warm(&grid, w)) {
        Some(net) => net,
        None => grid_initial_net(&map.mesh, plane, &gf, &grid, opts.levels, opts.inverse),
    };
    let fairness_triangles = grid.net_triangles();
    Ok(Resampled {
        model: SurfaceModel::Grid(grid),
        domain: Domain::Grid { spacing },
        initial,
        fairness_triangles,
        cold_start,
    })
}

/// Cells of the grid's bounding box times the 4^levels resampling triangles of each: a
/// bound on the memory the grid path takes, checked before anything is allocated (a tiny
/// spacing from a degenerate patch or a huge `--lattice` would otherwise exhaust memory).
const MAX_RESAMPLED_TRIANGLES: f64 = 2e8;

fn check_grid_size(plane: &[DVec2], spacing: f64, levels: usize) -> Result<(), PipelineError> {
    let extent = plane_extent(plane);
    let cells = 2.0 * (extent.x / spacing + 3.0) * (extent.y / (0.866 * spacing) + 3.0);
    let triangles = cells * 4f64.powi(levels.min(30) as i32);
    if !(spacing > 0.0 && triangles.is_finite() && triangles <= MAX_RESAMPLED_TRIANGLES) {
        return Err(PipelineError::GridTooFine {
            spacing,
            width: extent.x,
            height: extent.y,
            levels,
            triangles,
            limit: MAX_RESAMPLED_TRIANGLES,
        });
    }
    Ok(())
}
