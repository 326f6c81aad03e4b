//! The lattice of a control-mesh surface's tessellation with its vertices shared between
//! faces: one vertex per control vertex, per edge lattice point and per face-interior
//! lattice point, so the shown mesh is one connected surface as the fitted one is, not an
//! island per control face (which mesh tools read as thousands of components with open
//! seams), and a point on a shared edge is evaluated once.
//!
//! Crease edges keep a vertex per side, and so does a control vertex where crease edges
//! part the faces around it into sectors: the surface is only C0 across a crease, and each
//! side has its own normal. (A crease line's free end is a dart, smooth: one vertex.)

use crate::mesh::stats::UnionFind;
use crate::mesh::topology::{Topology, NONE};
use crate::surface::bezier::{lattice_points, lattice_triangles};
use crate::surface::SurfaceParam;
use rustc_hash::{FxHashMap, FxHashSet};

/// Where a lattice point comes from; points with equal keys are one vertex.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
enum Key {
    /// A control vertex, in one sector of its faces (numbered by `Sectors`).
    Corner(u32, usize),
    /// A point inside a non-crease edge: its ends (smaller first) and its step from the
    /// smaller end.
    Edge(u32, u32, usize),
    /// A point only its face has: the face and its lattice coordinates.
    Own(u32, usize, usize),
}

/// The faces around each control vertex joined across its non-crease edges: the corner
/// (vertex, face) pairs of one sector share a vertex.
struct Sectors {
    /// Corner (face, k) is pair 3 face + k.
    pairs: UnionFind,
}

impl Sectors {
    fn new(topo: &Topology, is_crease: impl Fn(u32, u32) -> bool) -> Self {
        let faces = &topo.triangles;
        let mut pairs = UnionFind::new(3 * faces.len());
        for (h, &twin) in topo.twin.iter().enumerate() {
            // Each interior edge once, from its lower half-edge.
            if twin == NONE || (twin as usize) < h {
                continue;
            }
            // Half-edge h = 3f + k runs corner k -> k + 1 of face f; its twin 3g + m runs
            // corner m -> m + 1 of face g the other way.
            let (f, k) = (h / 3, h % 3);
            let (g, m) = (twin as usize / 3, twin as usize % 3);
            if is_crease(faces[f][k], faces[f][(k + 1) % 3]) {
                continue;
            }
            pairs.union(3 * f + k, 3 * g + (m + 1) % 3);
            pairs.union(3 * f + (k + 1) % 3, 3 * g + m);
        }
        Self { pairs }
    }

    fn of(&mut self, face: usize, corner: usize) -> usize {
        self.pairs.find(3 * face + corner)
    }
}

/// The parameters and triangles of the faces of `topo` (a control mesh's half-edge
/// topology) each tessellated by the lattice of `n` segments per side (counter-clockwise
/// in the face's (u, v), as the faces), vertices shared as the module docs say. Corner 0
/// of a face is (u, v) = (1, 0), corner 1 is (0, 1), corner 2 is (0, 0); a shared vertex
/// keeps the parameter of the first face that reaches it.
pub fn welded_lattices(
    topo: &Topology,
    creases: &[[u32; 2]],
    n: usize,
) -> (Vec<SurfaceParam>, Vec<[u32; 3]>) {
    let local_triangles = lattice_triangles(n.max(1));
    let mut triangles = Vec::with_capacity(topo.triangles.len() * local_triangles.len());
    let params = weld_lattices(
        topo,
        creases,
        n,
        0..topo.triangles.len() as u32,
        |_, ids| {
            triangles.extend(local_triangles.iter().map(|t| t.map(|k| ids[k as usize])));
        },
    );
    (params, triangles)
}

/// The shared lattice points of `faces` (of `topo`; a face past its faces has no lattice)
/// at `n` segments per side, as `welded_lattices` shares them; `visit` is given each face
/// with the indices of its lattice points, in `lattice_points` order. Each point keeps
/// the parameter of the first face that reaches it.
pub fn weld_lattices(
    topo: &Topology,
    creases: &[[u32; 2]],
    n: usize,
    faces: impl IntoIterator<Item = u32>,
    mut visit: impl FnMut(u32, &[u32]),
) -> Vec<SurfaceParam> {
    let n = n.max(1);
    let edge = |a: u32, b: u32| (a.min(b), a.max(b));
    let crease: FxHashSet<(u32, u32)> = creases.iter().map(|c| edge(c[0], c[1])).collect();
    let mut sectors = Sectors::new(topo, |a, b| crease.contains(&edge(a, b)));
    let local = lattice_points(n);
    let mut ids: FxHashMap<Key, u32> = FxHashMap::default();
    let mut params = Vec::new();
    let mut vertex_of = Vec::with_capacity(local.len());
    for face in faces {
        let f = face as usize;
        let Some(t) = topo.triangles.get(f) else {
            visit(face, &[]);
            continue;
        };
        let corner_sectors: [usize; 3] = std::array::from_fn(|c| sectors.of(f, c));
        vertex_of.clear();
        for &(i, j) in &local {
            let key = point_key(face, t, (i, j), n, corner_sectors, |a, b| {
                crease.contains(&edge(a, b))
            });
            let next = params.len() as u32;
            let param = SurfaceParam {
                face,
                u: i as f64 / n as f64,
                v: j as f64 / n as f64,
            };
            // A face's own points are nobody else's: no need to look them up.
            let id = if matches!(key, Key::Own(..)) {
                params.push(param);
                next
            } else {
                *ids.entry(key).or_insert_with(|| {
                    params.push(param);
                    next
                })
            };
            vertex_of.push(id);
        }
        visit(face, &vertex_of);
    }
    params
}

/// The key of lattice point (i, j) of face `t` (number `face`, its corners in the
/// sectors `corner_sectors`) at `n` segments per side.
fn point_key(
    face: u32,
    t: &[u32; 3],
    (i, j): (usize, usize),
    n: usize,
    corner_sectors: [usize; 3],
    is_crease: impl Fn(u32, u32) -> bool,
) -> Key {
    let k = n - i - j;
    if let Some(c) = [i == n, j == n, k == n].iter().position(|&c| c) {
        return Key::Corner(t[c], corner_sectors[c]);
    }
    // Edge e runs from corner e to corner e + 1; `step` counts from corner e.
    let (e, step) = match (k, i, j) {
        (0, _, _) => (0, j),
        (_, 0, _) => (1, k),
        (_, _, 0) => (2, i),
        _ => return Key::Own(face, i, j),
    };
    let (a, b) = (t[e], t[(e + 1) % 3]);
    if is_crease(a, b) {
        return Key::Own(face, i, j);
    }
    if a < b {
        Key::Edge(a, b, step)
    } else {
        Key::Edge(b, a, n - step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// The octahedron's half-edge topology (eight faces, outward).
    fn octahedron() -> Topology {
        let (vertices, faces) = crate::testdata::octahedron();
        Topology::build(vertices.len(), &faces).expect("a manifold octahedron")
    }

    /// Uses of each directed edge.
    fn directed(triangles: &[[u32; 3]]) -> HashMap<(u32, u32), usize> {
        let mut uses = HashMap::new();
        for t in triangles {
            for k in 0..3 {
                *uses.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        uses
    }

    #[test]
    fn a_subset_of_faces_sees_each_its_whole_lattice_and_shared_points_once() {
        let (vertices, faces) = crate::testdata::octahedron();
        let topo = octahedron();
        let point = |p: SurfaceParam| {
            let t = faces[p.face as usize];
            vertices[t[0] as usize] * p.u
                + vertices[t[1] as usize] * p.v
                + vertices[t[2] as usize] * (1.0 - p.u - p.v)
        };
        // Faces 0 and 1 share an edge (vertices 2, 4); face 2 shares vertex 4 with both and
        // an edge (1, 4) with face 1; 99 is past the mesh.
        let subset = [0u32, 1, 2, 99];
        for n in [1, 2, 3, 6] {
            let mut seen = Vec::new();
            let params =
                weld_lattices(&topo, &[], n, subset, |f, ids| seen.push((f, ids.to_vec())));
            assert_eq!(seen.iter().map(|s| s.0).collect::<Vec<_>>(), subset);
            for (f, ids) in &seen[..3] {
                let own = lattice_points(n).into_iter().map(|(i, j)| SurfaceParam {
                    face: *f,
                    u: i as f64 / n as f64,
                    v: j as f64 / n as f64,
                });
                assert_eq!(ids.len(), (n + 1) * (n + 2) / 2);
                for (p, &id) in own.zip(ids) {
                    let gap = point(p).distance(point(params[id as usize]));
                    assert!(gap < 1e-12, "n {n} face {f}: {gap}");
                }
            }
            assert!(seen[3].1.is_empty());
            // Three lattices less the two edges face 1 shares (n + 1 points each; face 2's
            // corner 4 lies on the second).
            let per_face = (n + 1) * (n + 2) / 2;
            assert_eq!(params.len(), 3 * per_face - 2 * (n + 1), "n {n}");
        }
    }

    #[test]
    fn a_closed_control_mesh_gives_one_closed_oriented_surface() {
        let topo = octahedron();
        for n in [1, 2, 5, 12] {
            let (params, triangles) = welded_lattices(&topo, &[], n);
            // V + E (n - 1) + F (n - 1)(n - 2) / 2 vertices: each point once.
            let expected = 6 + 12 * (n - 1) + 8 * (n - 1) * n.saturating_sub(2) / 2;
            assert_eq!(params.len(), expected, "n = {n}");
            assert_eq!(triangles.len(), 8 * n * n);
            // Closed and consistently oriented: every directed edge once, its twin too.
            let uses = directed(&triangles);
            for (&(a, b), &count) in &uses {
                assert_eq!(count, 1, "edge {a}-{b} at n = {n}");
                assert_eq!(uses.get(&(b, a)), Some(&1), "edge {a}-{b} has no twin");
            }
            let edges = uses.len() / 2;
            let euler = params.len() as i64 - edges as i64 + triangles.len() as i64;
            assert_eq!(euler, 2, "n = {n}");
        }
    }

    #[test]
    fn crease_edges_keep_a_vertex_per_side() {
        let topo = octahedron();
        let faces = &topo.triangles;
        let n = 4;
        let (welded, _) = welded_lattices(&topo, &[], n);
        let open_edges = |creases: &[[u32; 2]]| {
            let (params, triangles) = welded_lattices(&topo, creases, n);
            let uses = directed(&triangles);
            let open: Vec<(u32, u32)> = uses
                .keys()
                .filter(|&&(a, b)| !uses.contains_key(&(b, a)))
                .copied()
                .collect();
            (params, open)
        };
        // One crease edge, its ends darts: its inner points twice, its ends once; both
        // sides open along it.
        let (params, open) = open_edges(&[[0, 2]]);
        assert_eq!(params.len(), welded.len() + n - 1);
        assert_eq!(open.len(), 2 * n);
        for (a, b) in open {
            for v in [a, b] {
                let p = params[v as usize];
                let t = faces[p.face as usize];
                let weights = [p.u, p.v, 1.0 - p.u - p.v];
                let off: f64 = (0..3)
                    .filter(|&c| t[c] != 0 && t[c] != 2)
                    .map(|c| weights[c])
                    .sum();
                assert!(off.abs() < 1e-12, "vertex {v} is off the crease");
            }
        }
        // A crease loop around the equator (0-2-1-3) parts the octahedron in two: every
        // point of the loop twice, and both halves open along all four edges.
        let equator = [[0, 2], [2, 1], [1, 3], [3, 0]];
        let (params, open) = open_edges(&equator);
        assert_eq!(params.len(), welded.len() + 4 * (n - 1) + 4);
        assert_eq!(open.len(), 2 * 4 * n);
    }
}
