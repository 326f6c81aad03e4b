//! Why a control mesh cannot carry a Loop limit surface.

use crate::mesh::topology::TopologyError;

/// Why a control mesh cannot carry a Loop limit surface.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LoopLimitError {
    /// No faces, so no surface.
    #[error("the control mesh has no faces")]
    NoFaces,
    /// More control points than 32-bit indices address.
    #[error("{count} control points do not fit 32-bit indices")]
    TooManyControls {
        /// Control points given.
        count: usize,
    },
    /// A face refers to a control point that does not exist.
    #[error("face {face} uses control index {index}, but there are only {count} control points")]
    IndexOutOfRange {
        /// The face.
        face: usize,
        /// The index it uses.
        index: u32,
        /// Control points there are.
        count: usize,
    },
    /// A face with a repeated corner.
    #[error("face {face} repeats a control point")]
    DegenerateFace {
        /// The face.
        face: usize,
    },
    /// A control point no face uses.
    #[error("control point {vertex} belongs to no face, so it has no place on the limit surface")]
    IsolatedVertex {
        /// The control point.
        vertex: usize,
    },
    /// The faces do not form a manifold mesh.
    #[error("the control mesh is not a manifold: {0}")]
    NonManifold(#[source] TopologyError),
    /// A crease edge that is no edge of the control mesh.
    #[error("crease edge ({a}, {b}) is not an edge of the control mesh")]
    UnknownCreaseEdge {
        /// One end.
        a: u32,
        /// The other end.
        b: u32,
    },
}

impl LoopLimitError {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::NoFaces => "no_faces",
            Self::TooManyControls { .. } => "too_many_controls",
            Self::IndexOutOfRange { .. } => "index_out_of_range",
            Self::DegenerateFace { .. } => "degenerate_face",
            Self::IsolatedVertex { .. } => "isolated_vertex",
            Self::NonManifold(_) => "non_manifold",
            Self::UnknownCreaseEdge { .. } => "unknown_crease_edge",
        }
    }
}
