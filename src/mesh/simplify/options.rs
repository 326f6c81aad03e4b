//! What `simplify` is asked (target and guards) and what it returns.

use crate::mesh::topology::TopologyError;
use crate::mesh::TriMesh;
use glam::DVec3;

/// Marks an input vertex that was collapsed away (`Simplified::control_of`).
pub const REMOVED: u32 = u32::MAX;

/// Target size and the guards a collapse must pass (see the module docs).
#[derive(Clone, Debug)]
pub struct SimplifyOptions {
    /// Vertices left at the end (at least 4; fewer if no further collapse is allowed).
    pub target_vertices: usize,
    /// Most faces around an interior vertex; a boundary vertex has one less.
    pub max_faces_per_vertex: usize,
    /// Triangle quality `4 sqrt(3) area / sum of squared edges` (1 for equilateral) that a
    /// collapse may not go below unless the faces it replaces were already worse.
    pub min_quality: f64,
    /// A collapse may turn no remaining face's normal by more than this.
    pub max_normal_turn_deg: f64,
    /// Weight of a boundary edge's constraint plane relative to face planes of the same
    /// squared size.
    pub boundary_weight: f64,
    /// Boundary vertices where the boundary turns by more than this stay where they are.
    pub corner_turn_deg: f64,
    /// Weight of the edge length to the fourth power (the quadric error's units) added to
    /// each collapse's cost. 0 is plain quadric decimation, the best piecewise-linear
    /// approximation for the count; a positive weight collapses short edges first, giving
    /// the more even, isotropic triangles a control mesh needs (a Loop limit surface over
    /// long thin faces and widely spread valences fits far worse than over an even mesh).
    pub isotropy: f64,
    /// Edges a boundary loop keeps at least (a loop that starts shorter keeps all of
    /// its edges); at least 3. A hole's rim is the cubic B-spline of its loop on a Loop
    /// surface: a loop of very few controls cannot follow a round rim.
    pub min_boundary_loop: usize,
}

impl Default for SimplifyOptions {
    fn default() -> Self {
        Self {
            target_vertices: 1000,
            max_faces_per_vertex: 12,
            min_quality: 0.15,
            max_normal_turn_deg: 60.0,
            boundary_weight: 20.0,
            corner_turn_deg: 75.0,
            isotropy: 0.0,
            min_boundary_loop: 3,
        }
    }
}

/// Where an input vertex lies on the simplified mesh: a face and the barycentric weights of
/// its corners 0 and 1 (corner 2 has `1 - u - v`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Landing {
    /// Index into the simplified mesh's `triangles`.
    pub face: u32,
    /// Barycentric weight of the face's corner 0.
    pub u: f64,
    /// Barycentric weight of the face's corner 1.
    pub v: f64,
}

impl Landing {
    /// The point it stands for on `mesh` (`None` when `mesh` has no such face).
    pub fn position_on(&self, mesh: &TriMesh) -> Option<DVec3> {
        let t = mesh.triangles.get(self.face as usize)?;
        let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
        Some(a * self.u + b * self.v + c * (1.0 - self.u - self.v))
    }
}

/// The result of [`simplify`]: the control mesh and how the input vertices map onto it.
#[derive(Clone, Debug)]
pub struct Simplified {
    /// The simplified mesh, vertices renumbered densely (input order kept).
    pub mesh: TriMesh,
    /// Per input vertex: the vertex of `mesh` it became, or `REMOVED`.
    pub control_of: Vec<u32>,
    /// Per input vertex: where it lies on `mesh`.
    pub landing: Vec<Landing>,
    /// Edge collapses performed (input vertices minus output vertices).
    pub collapses: usize,
    /// Boundary vertices and crease corners locked in place.
    pub locked_corners: usize,
    /// The crease edges kept, in `mesh`'s numbering (low index first, sorted).
    pub crease_edges: Vec<[u32; 2]>,
}

/// Why [`simplify`] refused a mesh.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SimplifyError {
    /// The mesh has no triangles.
    #[error("the mesh has no faces")]
    NoFaces,
    /// A vertex is used by no triangle, so it could never land on the simplified mesh.
    #[error("vertex {vertex} belongs to no face")]
    IsolatedVertex {
        /// Index of the unused vertex in the input mesh.
        vertex: usize,
    },
    /// No half-edge topology could be built: a bad face or a non-manifold edge.
    #[error("the mesh is not a manifold")]
    NonManifold(#[source] TopologyError),
}
