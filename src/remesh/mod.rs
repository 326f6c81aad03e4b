//! From an arbitrary disk-like scan component to a planar map: boundary loops, hole filling
//! (virtual faces, never data), the least-fold projection (`planar`) and its bijective
//! fallback, Floater's mean-value map onto a disk (`param`), point location in the map, and
//! the triangulation of point clouds (`points`).
#![warn(missing_docs)]

mod band;
pub mod oriented;
pub mod param;
pub mod planar;
mod plane2d;
pub mod points;
pub(crate) mod warp;

use crate::mesh::topology::{Topology, TopologyError, NONE};
use crate::mesh::TriMesh;
use glam::{DVec2, DVec3};

/// Why a scan component gets no planar map.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RemeshError {
    /// The component's triangles do not form a manifold mesh.
    #[error("not a manifold mesh: {0}")]
    NotManifold(#[source] TopologyError),
    /// A closed surface has no boundary to map onto a disk.
    #[error("not disk-like: closed surface (no boundary)")]
    Closed,
    /// Filling the holes left something other than a disk (a handle or several sheets).
    #[error("not disk-like: Euler characteristic {chi} after filling {holes} holes (a disk has 1; genus {genus})")]
    NotDisk {
        /// V - E + F of the filled patch.
        chi: i64,
        /// Holes filled (boundary loops but the outer one).
        holes: usize,
        /// The genus that characteristic means for one sheet.
        genus: i64,
    },
    /// The map onto the plane could not be computed or folds.
    #[error("parameterization failed: {0}")]
    Parameterization(#[source] MapFailure),
    /// No height field, and the disk map squeezes much of the surface (see
    /// `PlanarMap::undersampled_share`): a lattice over it would leave that part with a
    /// fraction of its share of the controls.
    #[error("not disk-like enough: the disk map gives {:.0} % of the surface less than 1/{factor} of its share of the domain", 100.0 * share)]
    Distorted {
        /// The share of the surface's area so squeezed ...
        share: f64,
        /// ... below this many times less than its share of the domain.
        factor: f64,
    },
}

impl RemeshError {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::NotManifold(_) => "not_manifold",
            Self::Closed => "closed",
            Self::NotDisk { .. } => "not_disk",
            Self::Parameterization(_) => "parameterization",
            Self::Distorted { .. } => "distorted",
        }
    }
}

/// How the mean-value map failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MapFailure {
    /// A free vertex whose neighbour weights sum to zero or are not finite.
    #[error("vertex {vertex} has no usable neighbours")]
    NoUsableNeighbours {
        /// The vertex.
        vertex: usize,
    },
    /// The sparse solver refused the system (its message).
    #[error("mean-value system: {detail}")]
    Solver {
        /// What the solver reported.
        detail: String,
    },
    /// The solution is not finite.
    #[error("the mean-value system is singular (a part without a path to the boundary?)")]
    Singular,
    /// The disk map still folds triangles.
    #[error(
        "{count} folded triangles remain after the mean-value map (degenerate input triangles?)"
    )]
    FoldsRemain {
        /// Folded triangles.
        count: usize,
    },
}

/// Boundary loops as ordered vertex lists, walking boundary half-edges (face on the left).
pub fn boundary_loops(topo: &Topology) -> Vec<Vec<u32>> {
    let tri = &topo.triangles;
    let mut next_on_boundary = vec![NONE; topo.vertex_count];
    for (h, &t) in topo.twin.iter().enumerate() {
        if t == NONE {
            let (a, b) = (tri[h / 3][h % 3], tri[h / 3][(h + 1) % 3]);
            next_on_boundary[a as usize] = b;
        }
    }
    let mut seen = vec![false; topo.vertex_count];
    let mut loops = Vec::new();
    for start in 0..topo.vertex_count {
        if next_on_boundary[start] == NONE || seen[start] {
            continue;
        }
        let mut l = Vec::new();
        let mut v = start as u32;
        while !seen[v as usize] && v != NONE {
            seen[v as usize] = true;
            l.push(v);
            v = next_on_boundary[v as usize];
        }
        loops.push(l);
    }
    loops
}

fn loop_length(positions: &[DVec3], l: &[u32]) -> f64 {
    (0..l.len())
        .map(|k| (positions[l[k] as usize] - positions[l[(k + 1) % l.len()] as usize]).length())
        .sum()
}

/// A disk-like patch ready for parameterization: the input plus virtual hole fans.
#[derive(Clone, Debug)]
pub struct FilledPatch {
    /// The patch with the virtual fans appended.
    pub mesh: TriMesh,
    /// Vertices at index >= `real_vertices` are virtual hole centres.
    pub real_vertices: usize,
    /// The outer boundary loop (the longest), which goes onto the disk's rim.
    pub outer: Vec<u32>,
    /// Number of holes filled.
    pub holes: usize,
    /// Triangles at index >= `real_triangles` are the virtual fans.
    pub real_triangles: usize,
    /// The loops the fans close, each as `boundary_loops` returns it.
    pub hole_loops: Vec<Vec<u32>>,
}

/// Picks the longest boundary loop as the outer boundary and closes every other loop with a
/// fan around a virtual centre vertex.
pub fn fill_holes(mesh: &TriMesh) -> Result<FilledPatch, RemeshError> {
    let topo = Topology::from_mesh(mesh).map_err(RemeshError::NotManifold)?;
    let mut loops = boundary_loops(&topo);
    if loops.is_empty() {
        return Err(RemeshError::Closed);
    }
    // Longest first; equal lengths keep their order (a stable sort on cached lengths).
    let lengths: Vec<f64> = loops
        .iter()
        .map(|l| loop_length(&mesh.positions, l))
        .collect();
    let mut order: Vec<usize> = (0..loops.len()).collect();
    order.sort_by(|&a, &b| lengths[b].total_cmp(&lengths[a]));
    let mut taken: Vec<Option<Vec<u32>>> = loops.into_iter().map(Some).collect();
    loops = order.iter().filter_map(|&k| taken[k].take()).collect();
    let outer = loops[0].clone();
    // Built at its final size: a clone grown by the fans would be copied once more.
    let fan_faces: usize = loops[1..].iter().map(Vec::len).sum();
    let mut filled = TriMesh {
        positions: Vec::with_capacity(mesh.positions.len() + loops.len() - 1),
        triangles: Vec::with_capacity(mesh.triangles.len() + fan_faces),
    };
    filled.positions.extend_from_slice(&mesh.positions);
    filled.triangles.extend_from_slice(&mesh.triangles);
    for hole in &loops[1..] {
        let c = hole
            .iter()
            .map(|&v| mesh.positions[v as usize])
            .sum::<DVec3>()
            / hole.len() as f64;
        let centre = filled.positions.len() as u32;
        filled.positions.push(c);
        // The boundary runs with the face on its left; the fan closes it the other way.
        for k in 0..hole.len() {
            let (a, b) = (hole[k], hole[(k + 1) % hole.len()]);
            filled.triangles.push([b, a, centre]);
        }
    }
    // Counted rather than rebuilt: every boundary vertex of a manifold mesh without pinch
    // vertices (which `Topology` refuses) lies on exactly one loop, once, so the fans add
    // one vertex per hole, one spoke edge and one face per loop vertex, and turn each loop
    // edge from boundary to interior without adding it again: the filled mesh is manifold
    // and V - E + F grows by exactly the number of holes.
    let v = filled.positions.len() as i64;
    let e = (topo.edge_count() + fan_faces) as i64;
    let chi = v - e + filled.triangles.len() as i64;
    if chi != 1 {
        return Err(RemeshError::NotDisk {
            chi,
            holes: loops.len() - 1,
            genus: (1 - chi) / 2,
        });
    }
    Ok(FilledPatch {
        mesh: filled,
        real_vertices: mesh.positions.len(),
        outer,
        holes: loops.len() - 1,
        real_triangles: mesh.triangles.len(),
        hole_loops: loops[1..].to_vec(),
    })
}

/// An equilateral triangle of side 1; the mean-value disk map puts the boundary on (a
/// slightly shrunk copy of) its inscribed circle.
pub(crate) const DOMAIN: [DVec2; 3] = [
    DVec2::new(1.0, 0.0),
    DVec2::new(0.5, 0.866_025_403_784_438_6),
    DVec2::new(0.0, 0.0),
];
