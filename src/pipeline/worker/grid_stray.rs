//! How far a scan fit's grid surface strays from its data. The grid path maps a disk-like
//! input to the plane and fits a fixed lattice of cells; where the map stretches a strongly
//! curved or small input (a face, bumps on a few hundred points), the few cells over it
//! bulge away from the data between the points, up to several percent of the diagonal, and
//! the fit's own errors (data to surface) cannot see it. The object path holds its surfaces
//! to the stray bound (its repair and escalation), so a grid surface past the bound is
//! fitted there too, and the one that lies closer to the data both ways is kept
//! (`fit_patch`). The shown surface's overhang past the rim is held to the bound by the
//! coverage itself (`Coverage::of`).

use super::config::WorkerConfig;
use super::fitted::FittedPatch;
use super::object::object_input;
use super::stray_guard::MAX_STRAY_SHARE;
use crate::mesh::distance::MeshDistance;
use crate::pipeline::object::ObjectInput;
use crate::pipeline::output::{tessellate, Coverage, Tessellation};
use crate::pipeline::scan::ScanFit;
use crate::TriMesh;
use rayon::prelude::*;

/// The grid surface's farthest point from the data, measured on the tessellation the GLB
/// shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct GridStray {
    /// The largest distance from a vertex of the shown tessellation to the data mesh
    /// (infinite when a vertex has no nearest point).
    pub max: f64,
    /// `max` as a share of the data's bounding-box diagonal.
    pub share_of_diagonal: f64,
}

impl GridStray {
    /// The stray of `scan`'s surface from `data` (the input it was fitted to), on the
    /// tessellation of `segments` the outputs show, and that tessellation (the GLB's).
    pub(super) fn of(data: &TriMesh, scan: &ScanFit, segments: usize) -> (GridStray, Tessellation) {
        let coverage = Coverage::of(&scan.fit, scan);
        let shown = tessellate(&scan.fit, segments.max(1), Some(&coverage));
        let nearest = MeshDistance::new(data);
        // The coverage drops triangles, not vertices: only the kept triangles' corners
        // are shown.
        let mut corner = vec![false; shown.positions.len()];
        for &v in shown.triangles.iter().flatten() {
            if let Some(c) = corner.get_mut(v as usize) {
                *c = true;
            }
        }
        let max = shown
            .positions
            .par_iter()
            .zip(&corner)
            .with_min_len(256)
            .filter(|(_, &shown)| shown)
            .map(|(&p, _)| nearest.distance(p).unwrap_or(f64::INFINITY))
            .reduce(|| 0.0, f64::max);
        let diagonal = data.bounds_diagonal();
        let share_of_diagonal = if diagonal > 0.0 { max / diagonal } else { 0.0 };
        let stray = GridStray {
            max,
            share_of_diagonal,
        };
        (stray, shown)
    }

    /// Whether it is within the bound every whole fit is held to (an infinite or NaN
    /// share is not).
    pub(super) fn within(&self) -> bool {
        self.share_of_diagonal <= MAX_STRAY_SHARE
    }

    /// Why the object path was tried, for report.json's `object.path_reason`.
    pub(super) fn reason(&self) -> String {
        format!(
            "the grid surface strays {:.2} % of the bounding-box diagonal from the data \
             (over {:.2} %)",
            100.0 * self.share_of_diagonal,
            100.0 * MAX_STRAY_SHARE
        )
    }
}

/// Measures how far the grid surface of `grid` (a scan fit) strays from `mesh` on the
/// tessellation its GLB shows (kept in `grid` for the outputs), and past the bound, the
/// object path's fit (`fit_as_object`: the worker's, under a config, of a prepared input,
/// for a reason) when that lies closer (`closer_as_object`).
pub(super) fn held_to_the_stray_bound(
    mesh: &TriMesh,
    grid: &mut FittedPatch,
    cfg: &WorkerConfig,
    fit_as_object: impl FnOnce(&WorkerConfig, ObjectInput, String) -> Option<FittedPatch>,
) -> Option<FittedPatch> {
    let scan = grid.scan.as_ref()?;
    let (stray, shown) = GridStray::of(mesh, scan, cfg.tessellation);
    let closer = if stray.within() {
        None
    } else {
        let object = closer_as_object(mesh, cfg, scan, &stray, fit_as_object);
        if object.is_none() {
            tracing::warn!(
                "{}; the object path's surface lies no closer to the data, so the grid \
                 surface is kept",
                stray.reason()
            );
        }
        object
    };
    grid.grid_shown = Some(shown);
    closer
}

/// The object path's fit of a disk-like `mesh` whose grid surface (`grid`'s) strayed past
/// the bound (`stray`), if it lies closer to the data: its two-sided (Hausdorff) distance,
/// the larger of its farthest point from the data and the data's farthest point from it,
/// is smaller. A surface that strays less but misses the data by more is no better. It
/// is given at least as many controls as the grid surface has (a small input's grid keeps
/// a few cells over it whatever the budget), so the two are compared at one cost.
fn closer_as_object(
    mesh: &TriMesh,
    cfg: &WorkerConfig,
    grid: &ScanFit,
    stray: &GridStray,
    fit_as_object: impl FnOnce(&WorkerConfig, ObjectInput, String) -> Option<FittedPatch>,
) -> Option<FittedPatch> {
    let input = object_input(mesh, cfg)?;
    let points = input.mesh.positions.len().max(1);
    let mut cfg = cfg.clone();
    let pct = &mut cfg.fit.scan.target_controls_pct;
    *pct = pct.max((100.0 * grid.fit.controls.len() as f64 / points as f64).min(100.0));
    let fitted = fit_as_object(&cfg, input, stray.reason())?;
    let object_stray = fitted.object.as_ref()?.stray?.max;
    let object_distance = object_stray.max(fitted.fit.geometric_max());
    let grid_distance = stray.max.max(grid.fit.geometric_max());
    (object_distance < grid_distance).then_some(fitted)
}
