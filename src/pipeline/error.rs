//! Why the pipeline refuses an input or fails on it. Every error names its cause (the
//! lower layer's error as `source`, not its text) and a stable machine-readable `kind` that
//! the daemon puts beside the human reason in its rejection events.
//!
//! The messages include their cause's text because the CLI and the daemon show one line per
//! refusal; `source()` still gives the cause itself to callers that walk the chain.

use super::subdivided::lattice::NotALattice;
use crate::fit::FitError;
use crate::mesh::detect::DetectError;
use crate::mesh::inverse::InverseError;
use crate::mesh::topology::TopologyError;
use crate::pipeline::merge::CloudError;
use crate::pipeline::object::ObjectError;
use crate::pipeline::scattered::ScatteredError;
use crate::remesh::points::PointCloudError;
use crate::remesh::RemeshError;
use crate::surface::loop_limit::LoopLimitError;

/// A refusal or failure of the worker on one input.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PipelineError {
    /// The input has no Loop subdivision connectivity at the asked depth (the worker then
    /// takes the scan path; this reaches callers of `fit_subdivided` only).
    #[error(transparent)]
    NoSubdivision(#[from] NoSubdivision),
    /// `bezier` on a subdivided input whose coarse net is not one triangular lattice.
    #[error("{0} (fit it with --surface loop / fit.surface = \"loop\")")]
    NotALattice(#[from] NotALattice),
    /// The coarse net of a subdivided input has no Loop limit surface.
    #[error("the coarse net after {levels} levels has no Loop limit surface: {source}")]
    NoLimitSurface {
        /// Levels of inverse subdivision that made the coarse net.
        levels: usize,
        /// Why the limit surface was refused.
        source: LoopLimitError,
    },
    /// Cleaning the scan left no triangle.
    #[error("no faces left after cleaning")]
    EmptyAfterCleaning,
    /// The largest component is smaller than the configured minimum.
    #[error("the largest component has {vertices} vertices, fewer than the minimum {min} (fit.components.min_vertices, --min-component-vertices)")]
    TooFewVertices {
        /// Vertices of the largest component.
        vertices: usize,
        /// The configured minimum.
        min: usize,
    },
    /// With `components = "all"`: no component reaches the minimum size.
    #[error("no component has the minimum {min} vertices (fit.components.min_vertices, --min-component-vertices); the largest has {largest}")]
    NoComponent {
        /// The configured minimum.
        min: usize,
        /// Vertices of the largest component (0 when there is none).
        largest: usize,
    },
    /// With `components = "all"`: every kept component failed.
    #[error("no component could be fitted ({})", describe_failures(failures))]
    NoComponentFitted {
        /// Suffix of each component and why it failed.
        failures: Vec<(String, PipelineError)>,
    },
    /// The scan is not a disk with holes (closed, non-manifold, ...): it has no map to the
    /// plane.
    #[error("{source}")]
    NotDiskLike {
        /// What the hole filling found.
        source: RemeshError,
    },
    /// The scan's map to the plane failed.
    #[error("{source}")]
    MapFailed {
        /// What the planar map reported.
        source: RemeshError,
    },
    /// The scan has no mean normal (its triangles cancel out): no plane to map it to.
    #[error("degenerate patch: no mean normal")]
    DegeneratePatch,
    /// The single Bezier patch asked for is too large to resample or evaluate.
    #[error("Bezier degree {degree} with {levels} levels: the degree must be at most {max_degree} and the resampled lattice ({segments} segments) at most 1e8 points (lower --lattice / fit.scan.lattice or the levels)")]
    BezierTooLarge {
        /// The asked degree.
        degree: usize,
        /// Levels of inverse subdivision.
        levels: usize,
        /// Segments per side of the resampled lattice.
        segments: f64,
        /// The largest degree accepted.
        max_degree: usize,
    },
    /// The grid asked for would take too much memory to resample.
    #[error("grid too fine for this patch: spacing {spacing:e} over a {width:e} x {height:e} map with {levels} levels (about {triangles:.1e} resampling triangles, limit {limit:e}; lower the levels or --lattice / fit.scan.grid_segments)")]
    GridTooFine {
        /// Grid spacing in the plane of the map.
        spacing: f64,
        /// Width of the map.
        width: f64,
        /// Height of the map.
        height: f64,
        /// Levels of inverse subdivision.
        levels: usize,
        /// Resampling triangles the grid would take.
        triangles: f64,
        /// The largest count accepted.
        limit: f64,
    },
    /// The input has no subdivision connectivity and the scan path failed too.
    #[error("{source} (and no subdivision connectivity: {not_subdivided})")]
    ScanFailed {
        /// Why the scan path failed.
        source: Box<PipelineError>,
        /// Why the exact-connectivity path did not apply.
        not_subdivided: Box<PipelineError>,
    },
    /// The whole-object path (a control mesh simplified from the data) failed.
    #[error("whole-object fit: {source}")]
    Object {
        /// What the object fit reported.
        #[source]
        source: ObjectError,
    },
    /// A point cloud that cannot be triangulated over a plane (or was sent to a path that
    /// needs a mesh).
    #[error("point cloud: {0}")]
    PointCloud(#[from] PointCloudError),
    /// A point cloud that could not be reconstructed into a mesh (whole-object clouds and
    /// clouds under `fit.domain = "mesh"`).
    #[error("point cloud: {0}")]
    CloudReconstruction(#[from] CloudError),
    /// The solver failed.
    #[error(transparent)]
    Fit(#[from] FitError),
    /// A B-patch or DMS fit (`pipeline::scattered`) failed.
    #[error(transparent)]
    Scattered(#[from] ScatteredError),
}

fn describe_failures(failures: &[(String, PipelineError)]) -> String {
    let parts: Vec<String> = failures.iter().map(|(s, e)| format!("{s}: {e}")).collect();
    parts.join("; ")
}

impl PipelineError {
    /// A stable snake_case name of the refusal, for machines (daemon events, metrics).
    /// A failed scan after a failed subdivision check reports the scan's kind.
    pub fn kind(&self) -> &'static str {
        match self {
            PipelineError::NoSubdivision(_) => "no_subdivision",
            PipelineError::NotALattice(_) => "not_a_lattice",
            PipelineError::NoLimitSurface { .. } => "no_limit_surface",
            PipelineError::EmptyAfterCleaning => "empty_after_cleaning",
            PipelineError::TooFewVertices { .. } => "too_few_vertices",
            PipelineError::NoComponent { .. } => "no_component",
            PipelineError::NoComponentFitted { .. } => "no_component_fitted",
            PipelineError::NotDiskLike { .. } => "not_disk_like",
            PipelineError::MapFailed { .. } => "map_failed",
            PipelineError::DegeneratePatch => "degenerate_patch",
            PipelineError::BezierTooLarge { .. } => "bezier_too_large",
            PipelineError::GridTooFine { .. } => "grid_too_fine",
            PipelineError::ScanFailed { source, .. } => source.kind(),
            PipelineError::Object { source } => match source {
                ObjectError::Empty => "empty_after_cleaning",
                ObjectError::NotManifold(_) => "not_manifold",
                ObjectError::Simplify(_) => "simplify_failed",
                ObjectError::Surface(_) => "no_limit_surface",
                ObjectError::Solve { .. } => "fit_failed",
                _ => "object_failed",
            },
            PipelineError::PointCloud(e) => e.kind(),
            PipelineError::CloudReconstruction(_) => "degenerate_point_cloud",
            PipelineError::Fit(_) => "fit_failed",
            PipelineError::Scattered(e) => e.kind(),
        }
    }

    /// True when the input (or the configuration) cannot be fitted, as opposed to a solver
    /// failure: the CLI exits with 2 on these.
    pub(crate) fn is_refusal(&self) -> bool {
        !matches!(
            self,
            PipelineError::Fit(_)
                | PipelineError::Scattered(ScatteredError::Fit(_))
                | PipelineError::Object {
                    source: ObjectError::Solve { .. }
                }
        )
    }
}

/// Why an input has no Loop subdivision connectivity at the asked depth.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NoSubdivision {
    /// The face count is not a multiple of 4^levels.
    #[error("{faces} faces are not a multiple of 4^{levels} (what {levels} levels of Loop subdivision make)")]
    FaceCount {
        /// Faces of the input.
        faces: usize,
        /// The asked depth.
        levels: usize,
    },
    /// A face no subdivided mesh has (scans fail this early).
    #[error("face {face} has fewer than two corners with 3 or 6 faces, as every face of a Loop-subdivided mesh has (the vertices subdivision adds on edges)")]
    IrregularFace {
        /// Index of the face.
        face: usize,
    },
    /// The input is not a manifold mesh.
    #[error("not a manifold mesh: {0}")]
    NotManifold(#[source] TopologyError),
    /// The hierarchy found is shallower than asked.
    #[error("no Loop subdivision connectivity at depth {wanted} (found {found}): {}", cause.as_ref().map_or_else(String::new, ToString::to_string))]
    TooShallow {
        /// The asked depth.
        wanted: usize,
        /// The depth found.
        found: usize,
        /// What stopped the detection one level deeper.
        #[source]
        cause: Option<DetectError>,
    },
    /// Inverse subdivision refused the mesh.
    #[error("{0}")]
    Inverse(#[source] InverseError),
    /// The exact inverse operator could not be composed.
    #[error("{0}")]
    InverseOperator(#[source] TopologyError),
}
