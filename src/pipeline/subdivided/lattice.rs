//! Recognising a coarse control net that is a single triangular lattice (what a Bezier
//! patch needs): three corners, and lattice coordinates propagated face by face.

use crate::mesh::topology::Topology;
use crate::surface::bezier::{lattice_index, lattice_len};

/// Why a coarse net is not one triangular lattice (a description of where the
/// propagation of lattice coordinates broke: there is no lower-level cause).
#[derive(Debug, thiserror::Error)]
#[error("the coarse control net is not one triangular lattice: {0}")]
pub struct NotALattice(pub String);

/// Lattice index of every coarse vertex, and the lattice's segment count n.
pub(crate) fn lattice_coordinates(
    vertex_count: usize,
    triangles: &[[u32; 3]],
) -> Result<(usize, Vec<usize>), NotALattice> {
    let topo = Topology::build(vertex_count, triangles).map_err(|e| NotALattice(e.to_string()))?;
    let corners: Vec<u32> = (0..vertex_count as u32)
        .filter(|&v| topo.is_corner(v))
        .collect();
    if corners.len() != 3 {
        return Err(NotALattice(format!(
            "{} corners (boundary vertices with one face), need 3",
            corners.len()
        )));
    }
    let faces = triangles.len();
    let n = (faces as f64).sqrt().round() as usize;
    if n * n != faces || lattice_len(n) != vertex_count {
        return Err(NotALattice(format!(
            "{faces} faces and {vertex_count} vertices do not make an n x n lattice"
        )));
    }
    // Corner 0 sits at (0, 0); its counter-clockwise ring (boundary first) is (1, 0), (0, 1).
    let c0 = corners[0];
    let ring = topo.ring(c0);
    let mut coord: Vec<Option<(i64, i64)>> = vec![None; vertex_count];
    coord[c0 as usize] = Some((0, 0));
    coord[ring[0] as usize] = Some((1, 0));
    coord[ring[ring.len() - 1] as usize] = Some((0, 1));
    // Walking a face counter-clockwise, the third vertex is the first plus the edge
    // direction turned by 60 degrees in lattice coordinates.
    let turn = |d: (i64, i64)| -> Option<(i64, i64)> {
        Some(match d {
            (1, 0) => (0, 1),
            (-1, 1) => (-1, 0),
            (0, -1) => (1, -1),
            (0, 1) => (-1, 1),
            (-1, 0) => (0, -1),
            (1, -1) => (1, 0),
            _ => return None,
        })
    };
    let mut changed = true;
    let mut rounds = 0;
    while changed {
        changed = false;
        rounds += 1;
        if rounds > faces + 2 {
            break;
        }
        for t in triangles {
            for k in 0..3 {
                let (p, q, r) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                if let (Some(a), Some(b), None) =
                    (coord[p as usize], coord[q as usize], coord[r as usize])
                {
                    let d = turn((b.0 - a.0, b.1 - a.1)).ok_or_else(|| {
                        NotALattice(format!("edge ({p}, {q}) is not a lattice edge"))
                    })?;
                    coord[r as usize] = Some((a.0 + d.0, a.1 + d.1));
                    changed = true;
                }
            }
        }
    }
    let mut index = vec![0usize; vertex_count];
    let mut used = vec![false; vertex_count];
    for (v, c) in coord.iter().enumerate() {
        let (i, j) = c.ok_or_else(|| NotALattice(format!("vertex {v} not reached")))?;
        if i < 0 || j < 0 || (i + j) as usize > n {
            return Err(NotALattice(format!(
                "vertex {v} lands outside the triangle at ({i}, {j})"
            )));
        }
        let idx = lattice_index(n, i as usize, j as usize);
        if used[idx] {
            return Err(NotALattice(format!(
                "two vertices land on lattice point ({i}, {j})"
            )));
        }
        used[idx] = true;
        index[v] = idx;
    }
    // Every face must be an up or down lattice triangle.
    for t in triangles {
        let c: Vec<(i64, i64)> = t
            .iter()
            .map(|&v| coord[v as usize].unwrap_or((0, 0)))
            .collect();
        let d = (c[1].0 - c[0].0, c[1].1 - c[0].1);
        let expect = turn(d).map(|e| (c[0].0 + e.0, c[0].1 + e.1));
        if expect != Some(c[2]) {
            return Err(NotALattice(format!("face {t:?} is not a lattice triangle")));
        }
    }
    Ok((n, index))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::bezier::lattice_triangles;

    #[test]
    fn recognises_a_lattice_under_renumbering() {
        let n = 5;
        let tris = lattice_triangles(n);
        let count = lattice_len(n);
        // Renumber vertices by a fixed permutation.
        let perm: Vec<u32> = (0..count as u32)
            .map(|v| (v * 5 + 3) % count as u32)
            .collect();
        let renumbered: Vec<[u32; 3]> = tris
            .iter()
            .map(|t| {
                [
                    perm[t[0] as usize],
                    perm[t[1] as usize],
                    perm[t[2] as usize],
                ]
            })
            .collect();
        let (m, index) = lattice_coordinates(count, &renumbered).expect("a lattice");
        assert_eq!(m, n);
        let mut seen = index.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..count).collect::<Vec<_>>());
    }

    #[test]
    fn rejects_a_closed_mesh() {
        let tris = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        assert!(lattice_coordinates(4, &tris).is_err());
    }
}
