//! Holes the meshing leaves inside the data, closed. Surface nets drop a vertex where its
//! samples hold no quadric, and cleaning splits their few non-manifold configurations
//! apart: each leaves a hole of a few edges that the data does not have (the bunny's five
//! views merged gave 89 loops on the largest part, most of 4 to 20 edges). Left open, each
//! becomes a hole of the object's control mesh, the fitted surface pulls back from it, and
//! the hole count changes with every update, so no update could keep the control mesh.
//!
//! A hole is closed when its centre lies inside the data: the implicit function is defined
//! there and the point stands within the convex hull of the samples around it (the rule
//! that keeps a vertex, `Implicit::overhang`). A hole wider than the averaging diameter has
//! no sample near its centre and stays open: that is where no scan saw the object. The fill
//! adds no vertex (every merged vertex is the vertex of one grid cell): the loop is cut
//! into triangles by ear clipping in the tangent plane at its centre.

use super::implicit::Implicit;
use crate::TriMesh;
use glam::{DVec2, DVec3};
use rustc_hash::{FxHashMap, FxHashSet};

/// Longest loop considered. No loop around a hole narrower than the averaging diameter
/// (5 cells by default) is this long: a circle of that diameter is 16 cells round, and a
/// loop of surface-nets edges on it about 1.4 times that.
const MAX_LOOP_EDGES: usize = 32;

/// Closes the holes of `mesh` that lie inside the data (see the module docs); returns how
/// many were closed.
pub(super) fn close_holes_inside_data(mesh: &mut TriMesh, implicit: &Implicit) -> usize {
    let mut edges: FxHashSet<(u32, u32)> = directed_edges(&mesh.triangles).collect();
    let mut closed = 0;
    for ring in boundary_loops(&mesh.triangles, &edges) {
        let Some(triangles) = fill(&ring, &mesh.positions, &edges, implicit) else {
            continue;
        };
        edges.extend(directed_edges(&triangles));
        mesh.triangles.extend(triangles);
        closed += 1;
    }
    closed
}

/// The edges of `triangles` in the direction each face runs them.
fn directed_edges(triangles: &[[u32; 3]]) -> impl Iterator<Item = (u32, u32)> + '_ {
    triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
}

/// The loops of boundary edges (edges whose reverse no face runs) of at most
/// `MAX_LOOP_EDGES`, each in the direction its faces run it, in the order of their
/// smallest vertex; loops through a vertex with several boundary edges out are skipped.
/// Not `remesh::boundary_loops`: that walks a half-edge `Topology`, which the merged mesh,
/// with surface nets' few non-manifold spots, may not have.
fn boundary_loops(triangles: &[[u32; 3]], edges: &FxHashSet<(u32, u32)>) -> Vec<Vec<u32>> {
    let mut next: FxHashMap<u32, Option<u32>> = FxHashMap::default();
    for (a, b) in directed_edges(triangles) {
        if !edges.contains(&(b, a)) {
            // A second boundary edge out of `a` makes the walk ambiguous.
            next.entry(a).and_modify(|n| *n = None).or_insert(Some(b));
        }
    }
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut seen: FxHashSet<u32> = FxHashSet::default();
    let mut loops = Vec::new();
    for start in starts {
        if seen.contains(&start) {
            continue;
        }
        let mut ring = vec![start];
        seen.insert(start);
        let mut v = start;
        let closed = loop {
            let Some(&Some(w)) = next.get(&v) else {
                break false;
            };
            if w == start {
                break true;
            }
            if !seen.insert(w) || ring.len() >= MAX_LOOP_EDGES {
                break false;
            }
            ring.push(w);
            v = w;
        };
        if closed && ring.len() >= 3 {
            loops.push(ring);
        }
    }
    loops
}

/// The triangles closing `ring` (a boundary loop in its faces' direction), or `None` when
/// its centre lies outside the data or the loop is no simple polygon in its tangent plane.
fn fill(
    ring: &[u32],
    positions: &[DVec3],
    edges: &FxHashSet<(u32, u32)>,
    implicit: &Implicit,
) -> Option<Vec<[u32; 3]>> {
    let centre = ring.iter().map(|&v| positions[v as usize]).sum::<DVec3>() / ring.len() as f64;
    let normal = implicit.at(centre)?.normal;
    if implicit.overhang(centre, normal)? != DVec3::ZERO {
        return None;
    }
    // Faces run the loop clockwise about their normal (the hole on the right), so the
    // reversed loop is counter-clockwise, as the fill's faces must run it.
    let polygon: Vec<u32> = ring.iter().rev().copied().collect();
    let e1 = normal.any_orthonormal_vector();
    let e2 = normal.cross(e1);
    let plane: Vec<DVec2> = polygon
        .iter()
        .map(|&v| {
            let d = positions[v as usize] - centre;
            DVec2::new(d.dot(e1), d.dot(e2))
        })
        .collect();
    ear_clip(&polygon, &plane, positions, edges)
}

/// Ear clipping of a counter-clockwise polygon (`plane` its 2D corners), the shortest
/// diagonal first; `None` if it is not counter-clockwise, or no ear can be cut without
/// repeating an edge of the mesh.
fn ear_clip(
    polygon: &[u32],
    plane: &[DVec2],
    positions: &[DVec3],
    edges: &FxHashSet<(u32, u32)>,
) -> Option<Vec<[u32; 3]>> {
    let n = polygon.len();
    let twice_area: f64 = (0..n).map(|k| plane[k].perp_dot(plane[(k + 1) % n])).sum();
    if twice_area <= 0.0 {
        return None;
    }
    let mut left: Vec<usize> = (0..n).collect();
    let mut triangles = Vec::with_capacity(n - 2);
    while left.len() > 3 {
        let m = left.len();
        let ear = (0..m)
            .filter(|&k| {
                let (a, b, c) = (left[(k + m - 1) % m], left[k], left[(k + 1) % m]);
                is_ear(a, b, c, &left, plane)
                    && !edges.contains(&(polygon[a], polygon[c]))
                    && !edges.contains(&(polygon[c], polygon[a]))
            })
            .min_by(|&i, &j| {
                let diagonal = |k: usize| {
                    let (a, c) = (left[(k + m - 1) % m], left[(k + 1) % m]);
                    positions[polygon[a] as usize].distance(positions[polygon[c] as usize])
                };
                diagonal(i).total_cmp(&diagonal(j))
            })?;
        let (a, b, c) = (left[(ear + m - 1) % m], left[ear], left[(ear + 1) % m]);
        triangles.push([polygon[a], polygon[b], polygon[c]]);
        left.remove(ear);
    }
    triangles.push([polygon[left[0]], polygon[left[1]], polygon[left[2]]]);
    Some(triangles)
}

/// Whether corner `b` between `a` and `c` is convex and no other corner left lies in the
/// triangle (a, b, c).
fn is_ear(a: usize, b: usize, c: usize, left: &[usize], plane: &[DVec2]) -> bool {
    let (pa, pb, pc) = (plane[a], plane[b], plane[c]);
    if (pb - pa).perp_dot(pc - pa) <= 0.0 {
        return false;
    }
    left.iter()
        .filter(|&&k| k != a && k != b && k != c)
        .all(|&k| {
            let p = plane[k];
            let inside = (pb - pa).perp_dot(p - pa) >= 0.0
                && (pc - pb).perp_dot(p - pb) >= 0.0
                && (pa - pc).perp_dot(p - pc) >= 0.0;
            !inside
        })
}

#[cfg(test)]
mod tests {
    use super::{boundary_loops, directed_edges, ear_clip};
    use glam::{DVec2, DVec3};
    use rustc_hash::FxHashSet;

    #[test]
    fn a_grid_with_a_missing_square_has_one_loop_that_the_fill_closes() {
        // A 4 x 4 vertex grid, its middle square (vertices 5, 6, 10, 9) left out.
        let mut triangles = Vec::new();
        for j in 0..3u32 {
            for i in 0..3u32 {
                if (i, j) == (1, 1) {
                    continue;
                }
                let v = j * 4 + i;
                triangles.push([v, v + 1, v + 5]);
                triangles.push([v, v + 5, v + 4]);
            }
        }
        let positions: Vec<DVec3> = (0..16)
            .map(|v| DVec3::new((v % 4) as f64, (v / 4) as f64, 0.0))
            .collect();
        let edges: FxHashSet<(u32, u32)> = directed_edges(&triangles).collect();
        // A loop reversed (as the fill runs it) and its corners in the grid's plane.
        let reversed = |ring: &[u32]| -> (Vec<u32>, Vec<DVec2>) {
            let polygon: Vec<u32> = ring.iter().rev().copied().collect();
            let plane = polygon
                .iter()
                .map(|&v| positions[v as usize].truncate())
                .collect();
            (polygon, plane)
        };
        let loops = boundary_loops(&triangles, &edges);
        // The outer rim (12 edges) and the hole (4 edges).
        let mut lengths: Vec<usize> = loops.iter().map(|l| l.len()).collect();
        lengths.sort_unstable();
        assert_eq!(lengths, vec![4, 12]);
        let hole = loops.iter().find(|l| l.len() == 4).expect("hole");
        let (polygon, plane) = reversed(hole);
        let fill = ear_clip(&polygon, &plane, &positions, &edges).expect("fill");
        assert_eq!(fill.len(), 2);
        // The fill runs every hole edge the other way round: the mesh is closed there.
        let mut all = edges.clone();
        for t in &fill {
            for k in 0..3 {
                assert!(all.insert((t[k], t[(k + 1) % 3])), "edge repeated");
            }
        }
        for w in 0..4 {
            let (a, b) = (hole[w], hole[(w + 1) % 4]);
            assert!(all.contains(&(b, a)));
        }
        // The outer rim, run the wrong way round, is no counter-clockwise polygon.
        let rim = loops.iter().find(|l| l.len() == 12).expect("rim");
        let (polygon, plane) = reversed(rim);
        assert!(ear_clip(&polygon, &plane, &positions, &edges).is_none());
    }
}
