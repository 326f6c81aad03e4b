//! Which data points lie near an edge of the data: within a distance (in the plane of the
//! map) of the outer rim or of a hole's rim, measured along the mesh.
//!
//! Distance rounds let the surface slide along itself at a cost set by their tangential
//! share. Inside the data a small share converges fastest (sliding there only moves
//! control points to where the shape needs them); where the data end, sliding pulls the
//! surface past the last points, and the maximum errors there grow. So the band along the
//! edges keeps the larger share.

use crate::TriMesh;
use glam::DVec2;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Per vertex of `mesh`: whether its distance along the mesh's edges (edge lengths taken
/// from `plane`) to the nearest of `rims` is at most `radius`. Vertices of `rims` past
/// the mesh's vertex count (virtual fill centres) are ignored.
pub(crate) fn near_edges(
    mesh: &TriMesh,
    plane: &[DVec2],
    rims: &[&[u32]],
    radius: f64,
) -> Vec<bool> {
    let n = mesh.positions.len().min(plane.len());
    let neighbours = neighbour_lists(mesh, n);
    let mut dist = vec![f64::INFINITY; n];
    // Dijkstra from all rim vertices at once, stopped at `radius`: only the band is visited.
    let mut heap = BinaryHeap::new();
    for &v in rims.iter().flat_map(|r| r.iter()) {
        let v = v as usize;
        if v < n && dist[v] > 0.0 {
            dist[v] = 0.0;
            heap.push(Reverse((Ordered(0.0), v)));
        }
    }
    while let Some(Reverse((Ordered(d), v))) = heap.pop() {
        if d > dist[v] {
            continue;
        }
        for &w in &neighbours.1[neighbours.0[v]..neighbours.0[v + 1]] {
            let w = w as usize;
            let dw = d + plane[v].distance(plane[w]);
            if dw <= radius && dw < dist[w] {
                dist[w] = dw;
                heap.push(Reverse((Ordered(dw), w)));
            }
        }
    }
    dist.iter().map(|d| *d <= radius).collect()
}

/// The vertices' neighbours as (offsets, flat list); an edge shared by two triangles
/// appears twice, which Dijkstra does not mind.
fn neighbour_lists(mesh: &TriMesh, n: usize) -> (Vec<usize>, Vec<u32>) {
    let valid = |t: &[u32; 3]| t.iter().all(|&v| (v as usize) < n);
    let mut offsets = vec![0usize; n + 1];
    for t in mesh.triangles.iter().filter(|t| valid(t)) {
        for &v in t {
            offsets[v as usize + 1] += 2;
        }
    }
    for v in 0..n {
        offsets[v + 1] += offsets[v];
    }
    let mut fill = offsets.clone();
    let mut list = vec![0u32; offsets[n]];
    for t in mesh.triangles.iter().filter(|t| valid(t)) {
        for k in 0..3 {
            let v = t[k] as usize;
            list[fill[v]] = t[(k + 1) % 3];
            list[fill[v] + 1] = t[(k + 2) % 3];
            fill[v] += 2;
        }
    }
    (offsets, list)
}

/// A distance with the total order the heap needs (distances here are finite).
#[derive(Clone, Copy, PartialEq)]
struct Ordered(f64);

impl Eq for Ordered {}

impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::topology::grid_triangles;
    use glam::DVec3;

    /// `grid_triangles(k)` with its vertices in the plane and in space (z = 0).
    fn grid(k: usize) -> (TriMesh, Vec<DVec2>) {
        let plane: Vec<DVec2> = (0..=k)
            .flat_map(|j| (0..=k).map(move |i| DVec2::new(i as f64, j as f64)))
            .collect();
        let positions = plane.iter().map(|p| DVec3::new(p.x, p.y, 0.0)).collect();
        (TriMesh::new(positions, grid_triangles(k)), plane)
    }

    #[test]
    fn the_band_follows_the_rim_at_the_given_distance() {
        let k = 10;
        let (mesh, plane) = grid(k);
        let rim: Vec<u32> = (0..=k as u32).collect(); // the bottom row, j = 0
        let near = near_edges(&mesh, &plane, &[&rim], 2.5);
        for (v, p) in plane.iter().enumerate() {
            // Along grid edges the distance to the bottom row is the row number.
            assert_eq!(near[v], p.y <= 2.5, "vertex at {p}");
        }
    }

    #[test]
    fn holes_count_as_edges_and_virtual_vertices_are_ignored() {
        let k = 10;
        let (mesh, plane) = grid(k);
        let centre = (5 * (k + 1) + 5) as u32;
        let virtual_centre = plane.len() as u32 + 3;
        let near = near_edges(&mesh, &plane, &[&[centre, virtual_centre]], 1.0);
        let count = near.iter().filter(|b| **b).count();
        // The centre and its four axis neighbours (the diagonals are sqrt 2 away).
        assert_eq!(count, 5);
        assert!(near[centre as usize]);
        let nothing = near_edges(&mesh, &plane, &[], 5.0);
        assert!(nothing.iter().all(|b| !*b));
    }
}
