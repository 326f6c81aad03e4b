//! Why a B-patch or DMS fit of a scan failed (beside the scan preparation's own errors,
//! which keep their `PipelineError` kinds).

use crate::scattered_fit::ScatteredFitError;
use crate::surface::bpatch::BPatchError;
use crate::surface::dms::DmsError;

/// A failure of the planar-domain kinds.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ScatteredError {
    /// The map left no domain (no triangle with area).
    #[error("the planar map covers no grid cell")]
    EmptyDomain,
    /// The DMS domain would have too many triangles.
    #[error("{triangles} DMS domain triangles, at most {limit} (raise fit.scan.target_controls_pct less)")]
    TooManyTriangles {
        /// Triangles asked for.
        triangles: usize,
        /// The most accepted.
        limit: usize,
    },
    /// Data points whose plane point lies outside the domain built around them.
    #[error("{points} data points lie outside the domain")]
    OutsideDomain {
        /// How many.
        points: usize,
    },
    /// The DMS spline was refused (knot clouds, domain).
    #[error("DMS spline: {0}")]
    Dms(#[source] DmsError),
    /// The B-patch was refused (knots, domain).
    #[error("B-patch: {0}")]
    BPatch(#[source] BPatchError),
    /// The fitting engine failed.
    #[error("{0}")]
    Fit(#[source] ScatteredFitError),
    /// A subdivided input's coarse net could not be mapped to the plane (closed, not
    /// manifold, or the map failed).
    #[error("the coarse net has no parameter triangulation: {0}")]
    CoarseNet(String),
    /// The coarse net's planar map turned some faces over (a numerical failure of the
    /// mean-value map, whose convex boundary otherwise keeps it one-to-one).
    #[error("the coarse net's planar map folds {triangles} triangles")]
    CoarseNetFolded {
        /// Triangles turned over or flat.
        triangles: usize,
    },
    /// A kind of surface that is not fitted over a planar domain reached this path.
    #[error("surface kind {0} is not a planar-domain kind")]
    NotPlanarKind(&'static str),
}

impl ScatteredError {
    /// A stable snake_case name.
    pub fn kind(&self) -> &'static str {
        match self {
            ScatteredError::EmptyDomain => "empty_domain",
            ScatteredError::TooManyTriangles { .. } => "domain_too_fine",
            ScatteredError::OutsideDomain { .. } => "outside_domain",
            ScatteredError::Dms(_) => "dms_refused",
            ScatteredError::BPatch(_) => "bpatch_refused",
            ScatteredError::Fit(_) => "fit_failed",
            ScatteredError::NotPlanarKind(_) => "not_planar_kind",
            ScatteredError::CoarseNet(_) => "coarse_net_unmapped",
            ScatteredError::CoarseNetFolded { .. } => "coarse_net_folded",
        }
    }
}
