//! A fit as the worker's paths return it, before it is turned into outputs.

use super::object::ObjectInfo;
use super::report::Refinement;
use super::shown::ShownSurface;
use crate::fit::Budget;
use crate::pipeline::output::Coverage;
use crate::pipeline::scan::ScanFit;
use crate::pipeline::scattered::ScatteredInfo;
use crate::pipeline::PatchFit;

/// A fit before it is turned into outputs.
pub struct FittedPatch {
    /// The fit.
    pub fit: PatchFit,
    /// Remeshed scans: the preparation and domain.
    pub scan: Option<ScanFit>,
    /// The budget, its tolerance resolved.
    pub budget: Budget,
    /// Levels of inverse subdivision of the fit returned (subdivided inputs may refine).
    pub levels: usize,
    /// Subdivided inputs: the fits that missed the budget before it, coarsest first.
    pub refinement: Vec<Refinement>,
    /// Whole objects: the object fit and why that path was taken.
    pub object: Option<ObjectInfo>,
    /// B-patch and DMS fits: the planar map, coverage and trims.
    pub scattered: Option<ScatteredInfo>,
    /// B-patch and DMS fits of subdivided inputs: the region shown, in domain points.
    pub planar_shown: Option<Coverage>,
    /// Remeshed scans and exact-subdivision fits: the tessellation the GLB shows and its
    /// stray from the data (a grid surface's measured by the stray check).
    pub shown: Option<ShownSurface>,
}

impl FittedPatch {
    /// Which path fitted the input, as report.json's `path` says it: `subdivided` (exact
    /// subdivision connectivity: the input's own coarse net), `scan` (a disk-like scan on
    /// its grid), `planar` (B-patch or DMS over a planar map of the input) or `object` (a
    /// whole object over a simplified control mesh).
    pub fn path(&self) -> &'static str {
        if self.object.is_some() {
            "object"
        } else if self.scan.is_some() {
            "scan"
        } else if self.scattered.is_some() {
            "planar"
        } else {
            "subdivided"
        }
    }

    /// `fit` at `budget` with nothing beside it (no levels, refinement or path details):
    /// what each path fills in.
    pub(crate) fn bare(fit: PatchFit, budget: Budget) -> Self {
        Self {
            fit,
            scan: None,
            budget,
            levels: 0,
            refinement: Vec::new(),
            object: None,
            scattered: None,
            planar_shown: None,
            shown: None,
        }
    }
}
