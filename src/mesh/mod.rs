//! Triangle meshes: the in-memory form every reader produces and every stage consumes.
#![warn(missing_docs)]

use glam::DVec3;

pub mod bucket_grid;
pub mod clean;
pub mod crease;
pub mod detect;
pub mod distance;
pub(crate) mod edge_table;
pub mod inverse;
pub mod loop_subdiv;
pub mod point_grid;
mod repeats;
pub mod rigid;
pub mod simplify;
pub mod spatial_order;
pub mod stats;
pub mod topology;

/// An indexed triangle mesh in f64. Faces index `positions`; orientation is the
/// counter-clockwise order of the three corners.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub positions: Vec<DVec3>,
    /// Counter-clockwise triangles of vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    /// A mesh of these vertices and triangles (not checked: see `clean` and `Topology`).
    pub fn new(positions: Vec<DVec3>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            positions,
            triangles,
        }
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn face_count(&self) -> usize {
        self.triangles.len()
    }

    /// The volume a closed mesh encloses, positive when its triangles face outwards (the
    /// divergence theorem: a sum of tetrahedra from the origin).
    pub fn signed_volume(&self) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| self.positions[v as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Length of the bounding-box diagonal (0 for an empty mesh).
    pub fn bounds_diagonal(&self) -> f64 {
        crate::numeric::bounds_diagonal(&self.positions)
    }

    /// Per vertex, the sum of its faces' area normals (`triangle_area_normal`: weighted by
    /// twice their areas; zero where it has no face with area). Faces with an index out of
    /// range are skipped.
    pub fn area_normal_sums(&self) -> Vec<DVec3> {
        let n = self.positions.len();
        let mut sums = vec![DVec3::ZERO; n];
        for t in self
            .triangles
            .iter()
            .filter(|t| t.iter().all(|&v| (v as usize) < n))
        {
            let area_normal = triangle_area_normal(t.map(|v| self.positions[v as usize]));
            for &v in t {
                sums[v as usize] += area_normal;
            }
        }
        sums
    }

    /// Area-weighted unit vertex normals (zero where `area_normal_sums` is).
    pub fn vertex_normals(&self) -> Vec<DVec3> {
        self.area_normal_sums()
            .iter()
            .map(|n| n.normalize_or_zero())
            .collect()
    }
}

/// Triangle `p`'s normal scaled by twice its area (right-handed in corner order).
pub fn triangle_area_normal(p: [DVec3; 3]) -> DVec3 {
    (p[1] - p[0]).cross(p[2] - p[0])
}

/// `4 sqrt(3) area / sum of squared edges`: 1 for an equilateral triangle, 0 for a
/// degenerate one.
pub fn triangle_quality(p: [DVec3; 3]) -> f64 {
    let edges = (p[1] - p[0]).length_squared()
        + (p[2] - p[1]).length_squared()
        + (p[0] - p[2]).length_squared();
    if edges <= 0.0 {
        return 0.0;
    }
    2.0 * 3f64.sqrt() * triangle_area_normal(p).length() / edges
}
