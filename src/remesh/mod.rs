//! From an arbitrary disk-like scan component to a planar map: boundary loops, hole filling
//! (virtual faces, never data), the least-fold projection (`planar`) and its bijective
//! fallback, Floater's mean-value map onto a disk (`param`), and point location in the map.

mod band;
pub mod param;
pub mod planar;
pub mod warp;

use crate::mesh::topology::{Topology, NONE};
use crate::mesh::TriMesh;
use glam::{DVec2, DVec3};

#[derive(Debug, thiserror::Error)]
pub enum RemeshError {
    #[error("not a manifold mesh: {0}")]
    NotManifold(String),
    #[error("not disk-like: {0}")]
    NotDisk(String),
    #[error("parameterization failed: {0}")]
    Parameterization(String),
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
    pub mesh: TriMesh,
    /// Vertices at index >= `real_vertices` are virtual hole centres.
    pub real_vertices: usize,
    pub outer: Vec<u32>,
    pub holes: usize,
    /// Triangles at index >= `real_triangles` are the virtual fans.
    pub real_triangles: usize,
    /// The loops the fans close, each as `boundary_loops` returns it.
    pub hole_loops: Vec<Vec<u32>>,
}

/// Picks the longest boundary loop as the outer boundary and closes every other loop with a
/// fan around a virtual centre vertex.
pub fn fill_holes(mesh: &TriMesh) -> Result<FilledPatch, RemeshError> {
    let topo = Topology::from_mesh(mesh).map_err(|e| RemeshError::NotManifold(e.to_string()))?;
    let mut loops = boundary_loops(&topo);
    if loops.is_empty() {
        return Err(RemeshError::NotDisk("closed surface (no boundary)".into()));
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
        return Err(RemeshError::NotDisk(format!(
            "Euler characteristic {chi} after filling {} holes (a disk has 1; genus {})",
            loops.len() - 1,
            (1 - chi) / 2
        )));
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
pub const DOMAIN: [DVec2; 3] = [
    DVec2::new(1.0, 0.0),
    DVec2::new(0.5, 0.866_025_403_784_438_6),
    DVec2::new(0.0, 0.0),
];
