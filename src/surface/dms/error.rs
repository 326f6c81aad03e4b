//! Why a DMS spline or its record is refused: its own module so that the knot rules and
//! the spline can both name it without importing each other.

use crate::surface::simplex_spline::SimplexError;

/// Why a DMS spline or its record was refused.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DmsError {
    /// The degree is outside 1..=3.
    #[error("degree {0}: DMS splines here have degree 1..=3")]
    Degree(usize),
    /// The domain triangulation has no triangles.
    #[error("the domain has no triangles")]
    Empty,
    /// A triangle refers to a vertex index past the end of the vertex list.
    #[error("triangle {triangle} names vertex {vertex}, which does not exist")]
    VertexIndex {
        /// Index of the offending triangle.
        triangle: u32,
        /// The out-of-range vertex index it names.
        vertex: u32,
    },
    /// The domain triangle with this index has zero, negative or non-finite area.
    #[error("domain triangle {0} is degenerate or clockwise")]
    NotCounterClockwise(u32),
    /// The directed edge (from, to) occurs in more than one triangle.
    #[error("domain edge ({0}, {1}) is used more than once in one direction")]
    NonManifoldEdge(u32, u32),
    /// The vertex's boundary edges do not form a single in/out pair.
    #[error("domain vertex {0} has more than one boundary fan")]
    NonManifoldVertex(u32),
    /// Given knot clouds do not match the domain vertices one to one.
    #[error("{found} knot clouds for {expected} domain vertices")]
    CloudCount {
        /// Clouds given.
        found: usize,
        /// Domain vertices.
        expected: usize,
    },
    /// A knot cloud does not have degree + 1 points.
    #[error("knot cloud of vertex {vertex} has {found} points, expected {expected}")]
    CloudLength {
        /// The domain vertex whose cloud is wrong.
        vertex: u32,
        /// Points in the cloud.
        found: usize,
        /// degree + 1.
        expected: usize,
    },
    /// The vertex's cloud does not start at the vertex itself, or holds a non-finite knot.
    #[error("knot cloud of vertex {0} does not start at the vertex (or is not finite)")]
    CloudNotAtVertex(u32),
    /// A knot of this boundary vertex is on the inner side of one of its boundary edges.
    #[error("a knot of boundary vertex {0} lies inside the domain (the basis would not sum to one there)")]
    BoundaryKnotInside(u32),
    /// A knot triangle breaks the DMS condition (degenerate or clockwise).
    #[error("DMS condition: knot triangle {knots:?} of domain triangle {triangle} is degenerate or clockwise")]
    KnotTriangle {
        /// The domain triangle (a, b, c).
        triangle: u32,
        /// Knot indices `[i, j, k]` in the clouds of a, b and c.
        knots: [usize; 3],
    },
    /// The `KnotRule` spread is not finite and positive.
    #[error("knot spread {0} must be finite and positive")]
    Spread(f64),
    /// Every halving of the spread still broke a condition.
    #[error("no knot placement kept the conditions after {halvings} halvings of the spread")]
    KnotsRejected {
        /// Halvings tried.
        halvings: usize,
        /// The condition the last (smallest) placement broke.
        #[source]
        last: Box<DmsError>,
    },
    /// Compiling a triangle's simplex-spline basis failed.
    #[error("basis compilation")]
    Simplex(#[from] SimplexError),
    /// A record's control point count does not match its spline.
    #[error("{found} control points, the surface has {expected}")]
    ControlCount {
        /// Control points in the record.
        found: usize,
        /// Control points the spline has (triangles times `(n + 1)(n + 2) / 2`).
        expected: usize,
    },
}
