//! What a planar-domain fit leaves beside the fit itself (for the outputs, the report and
//! the next version), and the planar view of its model.

use crate::pipeline::output::Coverage;
use crate::pipeline::scan::Preparation;
use crate::pipeline::SurfaceModel;
use crate::remesh::planar::{MapMethod, PlaneFrame};
use crate::remesh::warp::PlaneWarp;
use crate::surface::dms::PlanarSurface;
use glam::DVec2;

/// What a planar-domain fit leaves for its outputs, report and next version beside the fit.
pub struct ScatteredInfo {
    /// What cleaning and hole filling found.
    pub preparation: Preparation,
    /// The plane of the map.
    pub frame: PlaneFrame,
    /// Its warp, if the map is a warped projection.
    pub warp: Option<PlaneWarp>,
    /// How the map was made.
    pub method: MapMethod,
    /// The scanned region in domain coordinates (data at their final domain points).
    pub coverage: Coverage,
    /// The outer rim of the data in domain coordinates...
    pub outer: Vec<DVec2>,
    /// ... and the rims of trimmed holes and wide data triangles.
    pub holes: Vec<Vec<DVec2>>,
    /// Geometric RMS after each round.
    pub correction_rms: Vec<f64>,
    /// DMS: the grid spacing of the domain.
    pub spacing: Option<f64>,
    /// Controls taken from the previous version.
    pub reused_controls: usize,
    /// Given a previous version, why it (or its domain) was not used.
    pub cold_start: Option<String>,
}

/// The model of a fit as a planar surface (B-patch and DMS models only).
pub(crate) fn planar_surface(model: &SurfaceModel) -> Option<&dyn PlanarSurface> {
    match model {
        SurfaceModel::BPatch(b) => Some(b.as_ref() as &dyn PlanarSurface),
        SurfaceModel::Dms(d) => Some(d.as_ref() as &dyn PlanarSurface),
        _ => None,
    }
}
