//! The topology of a surface mesh in numbers: what simplification must keep.

use crate::mesh::topology::{Topology, TopologyError, NONE};
use crate::mesh::TriMesh;

/// Euler characteristic, boundary loops, connected components and the genus they imply
/// (orientable surfaces: `2 c - chi - b = 2 g`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct SurfaceTopology {
    /// Euler characteristic `V - E + F`, counting only vertices used by a face.
    pub euler: i64,
    /// Closed chains of boundary edges (holes).
    pub boundary_loops: usize,
    /// Edge-connected pieces.
    pub components: usize,
    /// Total genus of all components, from the formula above (exact for orientable meshes).
    pub genus: i64,
}

impl SurfaceTopology {
    /// Counts the topology of `mesh`; fails where no half-edge topology can be built.
    pub fn of(mesh: &TriMesh) -> Result<SurfaceTopology, TopologyError> {
        Ok(Self::of_built(mesh, &Topology::from_mesh(mesh)?))
    }

    /// [`SurfaceTopology::of`] from the mesh's half-edge topology, built already.
    pub fn of_built(mesh: &TriMesh, topo: &Topology) -> SurfaceTopology {
        let used: Vec<u32> = (0..mesh.positions.len() as u32)
            .filter(|&v| topo.face_valence[v as usize] > 0)
            .collect();
        let euler = used.len() as i64 - topo.edge_count() as i64 + mesh.triangles.len() as i64;
        // Boundary half-edges chain head to tail: one outgoing per boundary vertex.
        let mut outgoing = vec![NONE; mesh.positions.len()];
        let boundary_halfedges: Vec<u32> = (0..topo.twin.len() as u32)
            .filter(|&h| topo.twin[h as usize] == NONE)
            .collect();
        let source = |h: u32| mesh.triangles[(h / 3) as usize][(h % 3) as usize];
        let target = |h: u32| mesh.triangles[(h / 3) as usize][((h % 3 + 1) % 3) as usize];
        for &h in &boundary_halfedges {
            outgoing[source(h) as usize] = h;
        }
        let mut visited = vec![false; mesh.positions.len()];
        let mut boundary_loops = 0;
        for &h in &boundary_halfedges {
            if visited[source(h) as usize] {
                continue;
            }
            boundary_loops += 1;
            let mut e = h;
            while e != NONE && !visited[source(e) as usize] {
                visited[source(e) as usize] = true;
                e = outgoing[target(e) as usize];
            }
        }
        let mut component = vec![NONE; mesh.positions.len()];
        let mut components = 0;
        for &start in &used {
            if component[start as usize] != NONE {
                continue;
            }
            let mut stack = vec![start];
            component[start as usize] = components;
            while let Some(v) = stack.pop() {
                for &x in topo.ring(v) {
                    if component[x as usize] == NONE {
                        component[x as usize] = components;
                        stack.push(x);
                    }
                }
            }
            components += 1;
        }
        let components = components as usize;
        SurfaceTopology {
            euler,
            boundary_loops,
            components,
            genus: (2 * components as i64 - euler - boundary_loops as i64) / 2,
        }
    }
}
