//! When a scan fit's grid surface gives way to the object path's. The grid path maps a
//! disk-like input to the plane and fits a fixed lattice of cells; where the map stretches
//! a strongly curved or small input (a face, bumps on a few hundred points), the few cells
//! over it bulge away from the data between the points, up to several percent of the
//! diagonal, and the fit's own errors (data to surface) cannot see it. The object path
//! holds its surfaces to the stray bound (its repair and escalation), so a grid surface
//! past the bound (measured by `shown`) is fitted there too, and the one that lies closer
//! to the data both ways is kept (`fit_patch`). So is a grid surface that misses the data
//! everywhere (its RMS over the budget's tolerance and `GROSS_MISS_SHARE` of the
//! diagonal), when the object surface fits better without straying farther. The shown
//! surface's overhang past the rim is held to the bound by the coverage itself
//! (`Coverage::of`).

use super::config::WorkerConfig;
use super::fitted::FittedPatch;
use super::object::object_input;
use super::shown::{ShownStray, ShownSurface};
use crate::pipeline::object::ObjectInput;
use crate::pipeline::scan::ScanFit;
use crate::TriMesh;

/// A grid surface within the stray bound is fitted on the object path too only when its
/// RMS exceeds this share of the data's bounding-box diagonal (the default tolerance) as
/// well as the budget's tolerance: a gross miss whatever the budget. A tight tolerance on
/// noisy data (a user asking for 10 um of a scan with 40 um of noise) is no reason to fit
/// every scan twice; the Stanford scans' grid surfaces stay at a quarter of it.
const GROSS_MISS_SHARE: f64 = 1e-3;

/// Why a grid surface is fitted on the object path too.
enum Doubt {
    /// Its shown tessellation strays past the bound.
    Strays(ShownStray),
    /// It is within the bound, but its RMS distance from the data exceeds the budget's
    /// tolerance (a largest error) and `GROSS_MISS_SHARE` of the diagonal: it misses the
    /// data everywhere, not only at rim junk.
    MissesBudget {
        /// Its RMS.
        rms: f64,
        /// The larger of the two.
        bound: f64,
    },
}

impl Doubt {
    /// Why the object path was tried, for report.json's `object.path_reason`.
    fn reason(&self) -> String {
        match self {
            Self::Strays(stray) => stray.reason(),
            Self::MissesBudget { rms, bound } => format!(
                "the grid surface misses the data by RMS {rms:.3e}, over the tolerance and \
                 {GROSS_MISS_SHARE} of the bounding-box diagonal ({bound:.3e})"
            ),
        }
    }
}

/// Measures how far the grid surface of `grid` (a scan fit) strays from `mesh` on the
/// tessellation its GLB shows (kept in `grid` for the outputs). Past the bound, or when
/// its RMS exceeds the budget's tolerance and `GROSS_MISS_SHARE` of the diagonal, the
/// object path's fit (`fit_as_object`: the worker's, under a config, of a prepared input,
/// for a reason) is returned when it lies closer (`closer_as_object`).
pub(super) fn held_to_the_stray_bound(
    mesh: &TriMesh,
    grid: &mut FittedPatch,
    cfg: &WorkerConfig,
    fit_as_object: impl FnOnce(&WorkerConfig, ObjectInput, String) -> Option<FittedPatch>,
) -> Option<FittedPatch> {
    let scan = grid.scan.as_ref()?;
    let mut shown = ShownSurface::of_grid(mesh, scan, cfg.tessellation);
    let stray = shown.stray;
    let rms = scan.fit.geometric_rms();
    let bound = grid
        .budget
        .tolerance
        .max(GROSS_MISS_SHARE * mesh.bounds_diagonal());
    let doubt = if !stray.within() {
        Some(Doubt::Strays(stray))
    } else if rms > bound {
        Some(Doubt::MissesBudget { rms, bound })
    } else {
        None
    };
    let mut object_tried = None;
    let closer = doubt.and_then(|doubt| {
        let object = closer_as_object(mesh, cfg, scan, &stray, &doubt, fit_as_object);
        if object.is_none() {
            tracing::warn!(
                "{}; the object path's surface lies no closer to the data, so the grid \
                 surface is kept",
                doubt.reason()
            );
            object_tried = Some(doubt.reason());
        }
        object
    });
    shown.object_tried = object_tried;
    grid.shown = Some(shown);
    closer
}

/// The object path's fit of a disk-like `mesh` whose grid surface (`grid`'s, straying
/// `stray` from the data) is in `doubt`, if it lies closer to the data: its two-sided
/// (Hausdorff) distance, the larger of its farthest point from the data and the data's
/// farthest point from it, is smaller, and where the grid surface was within the stray
/// bound, no larger, with a lower RMS, and within the bound (or no farther past it than
/// the grid surface). A surface that strays less but misses the data by more is no
/// better; nor is one that fits better on average but strays past the bound the grid
/// surface kept. It is given at least as many controls as the grid surface has (a small
/// input's grid keeps a few cells over it whatever the budget), so the two are compared
/// at one cost.
fn closer_as_object(
    mesh: &TriMesh,
    cfg: &WorkerConfig,
    grid: &ScanFit,
    stray: &ShownStray,
    doubt: &Doubt,
    fit_as_object: impl FnOnce(&WorkerConfig, ObjectInput, String) -> Option<FittedPatch>,
) -> Option<FittedPatch> {
    let input = object_input(mesh, cfg)?;
    let points = input.mesh.positions.len().max(1);
    let mut cfg = cfg.clone();
    let pct = &mut cfg.fit.scan.target_controls_pct;
    *pct = pct.max((100.0 * grid.fit.controls.len() as f64 / points as f64).min(100.0));
    let fitted = fit_as_object(&cfg, input, doubt.reason())?;
    let object_stray = fitted.object.as_ref()?.stray?;
    let (object_within, object_stray) = (object_stray.within, object_stray.max);
    let object_distance = object_stray.max(fitted.fit.geometric_max());
    let grid_distance = stray.max.max(grid.fit.geometric_max());
    let closer = match doubt {
        Doubt::Strays(_) => object_distance < grid_distance,
        Doubt::MissesBudget { rms, .. } => {
            let keeps_the_bound = object_within || object_stray <= stray.max;
            keeps_the_bound && object_distance <= grid_distance && fitted.fit.geometric_rms() < *rms
        }
    };
    closer.then_some(fitted)
}
