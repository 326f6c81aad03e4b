//! Repairs: weld, drop degenerate and duplicate faces, split non-manifold edges and pinch
//! vertices into manifold fans, orient each component consistently, drop unused vertices.

use super::stats::UnionFind;
use super::TriMesh;
use glam::DVec3;
use rustc_hash::{FxHashMap, FxHashSet};

#[derive(Clone, Debug, Default)]
pub struct CleanOptions {
    /// Merge vertices closer than this; `None` merges only bit-identical positions.
    pub weld_tolerance: Option<f64>,
}

#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct CleanReport {
    pub welded_vertices: usize,
    pub degenerate_faces_removed: usize,
    pub duplicate_faces_removed: usize,
    pub non_manifold_edges_split: usize,
    pub pinch_vertices_split: usize,
    pub faces_flipped: usize,
    pub non_orientable_components: usize,
    pub unreferenced_vertices_removed: usize,
}

#[derive(Clone, Debug)]
pub struct Cleaned {
    pub mesh: TriMesh,
    /// Cleaned vertex -> input vertex (a split vertex maps to the vertex it came from).
    pub original_vertex: Vec<u32>,
    pub report: CleanReport,
}

pub fn clean(input: &TriMesh, opts: &CleanOptions) -> Cleaned {
    let mut report = CleanReport::default();
    let nv = input.positions.len();
    let rep = weld_map(&input.positions, opts.weld_tolerance);
    report.welded_vertices = (0..nv).filter(|&v| rep[v] as usize != v).count();
    let mut positions = input.positions.clone();
    let mut origin: Vec<u32> = (0..nv as u32).collect();
    // Degenerate and duplicate faces.
    let mut seen = FxHashSet::default();
    seen.reserve(input.triangles.len());
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(input.triangles.len());
    for t in &input.triangles {
        if t.iter().any(|&v| v as usize >= nv) {
            report.degenerate_faces_removed += 1;
            continue;
        }
        let t = [rep[t[0] as usize], rep[t[1] as usize], rep[t[2] as usize]];
        let area2 = (positions[t[1] as usize] - positions[t[0] as usize])
            .cross(positions[t[2] as usize] - positions[t[0] as usize])
            .length_squared();
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || area2 == 0.0 {
            report.degenerate_faces_removed += 1;
            continue;
        }
        let mut key = t;
        key.sort_unstable();
        if !seen.insert(key) {
            report.duplicate_faces_removed += 1;
            continue;
        }
        faces.push(t);
    }
    // Non-manifold edges: the first two faces keep the edge; every further face gets its
    // own copies of the edge's endpoints (the pinch split below then tidies the fans).
    let incidence = EdgeIncidence::new(&faces);
    let split_edges = incidence.non_manifold();
    report.non_manifold_edges_split = split_edges.len();
    for ((a, b), fs) in split_edges {
        for &f in &fs[2..] {
            let f = f as usize;
            for end in [a, b] {
                let copy = positions.len() as u32;
                positions.push(positions[end as usize]);
                origin.push(origin[end as usize]);
                for v in faces[f].iter_mut() {
                    if *v == end {
                        *v = copy;
                    }
                }
            }
        }
    }
    report.faces_flipped = orient(&mut faces, &mut report.non_orientable_components);
    report.pinch_vertices_split = split_pinches(&mut faces, &mut positions, &mut origin);
    // Compact: drop vertices no face uses.
    let mut new_index = vec![u32::MAX; positions.len()];
    let mut out_pos = Vec::new();
    let mut out_origin = Vec::new();
    for t in faces.iter_mut() {
        for v in t.iter_mut() {
            if new_index[*v as usize] == u32::MAX {
                new_index[*v as usize] = out_pos.len() as u32;
                out_pos.push(positions[*v as usize]);
                out_origin.push(origin[*v as usize]);
            }
            *v = new_index[*v as usize];
        }
    }
    // Keep the input's vertex order among survivors (readers promise file order).
    let mut order: Vec<u32> = (0..out_pos.len() as u32).collect();
    order.sort_by_key(|&i| (out_origin[i as usize], i));
    let mut rank = vec![0u32; order.len()];
    for (r, &i) in order.iter().enumerate() {
        rank[i as usize] = r as u32;
    }
    let positions: Vec<DVec3> = order.iter().map(|&i| out_pos[i as usize]).collect();
    let original_vertex: Vec<u32> = order.iter().map(|&i| out_origin[i as usize]).collect();
    for t in faces.iter_mut() {
        for v in t.iter_mut() {
            *v = rank[*v as usize];
        }
    }
    let kept_inputs: FxHashSet<u32> = original_vertex.iter().copied().collect();
    report.unreferenced_vertices_removed =
        (nv - report.welded_vertices).saturating_sub(kept_inputs.len());
    Cleaned {
        mesh: TriMesh::new(positions, faces),
        original_vertex,
        report,
    }
}

/// Representative of each vertex after welding (the lowest index of its cluster).
fn weld_map(positions: &[DVec3], tolerance: Option<f64>) -> Vec<u32> {
    let n = positions.len();
    match tolerance.filter(|t| *t > 0.0) {
        None => {
            let mut first: FxHashMap<[u64; 3], u32> = FxHashMap::default();
            first.reserve(n);
            positions
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    *first
                        .entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
                        .or_insert(i as u32)
                })
                .collect()
        }
        Some(tol) => {
            let cell = |p: DVec3| {
                let q = (p / tol).floor();
                [q.x as i64, q.y as i64, q.z as i64]
            };
            let mut grid: FxHashMap<[i64; 3], Vec<u32>> = FxHashMap::default();
            for (i, p) in positions.iter().enumerate() {
                grid.entry(cell(*p)).or_default().push(i as u32);
            }
            let mut uf = UnionFind::new(n);
            for (i, p) in positions.iter().enumerate() {
                let c = cell(*p);
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            if let Some(ids) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                                for &j in ids {
                                    if (positions[j as usize] - *p).length() <= tol {
                                        uf.union(i, j as usize);
                                    }
                                }
                            }
                        }
                    }
                }
            }
            (0..n).map(|i| uf.find(i) as u32).collect()
        }
    }
}

/// Breadth-first flips so that neighbours use each shared edge in opposite directions.
/// Returns the number of faces flipped; counts components where that is impossible.
fn orient(faces: &mut [[u32; 3]], non_orientable: &mut usize) -> usize {
    let incidence = EdgeIncidence::new(faces);
    let has_directed =
        |t: &[u32; 3], a: u32, b: u32| (0..3).any(|k| t[k] == a && t[(k + 1) % 3] == b);
    let mut state = vec![0u8; faces.len()]; // 0 unvisited, 1 visited
    let mut flipped = 0;
    for seed in 0..faces.len() {
        if state[seed] != 0 {
            continue;
        }
        state[seed] = 1;
        let mut queue = std::collections::VecDeque::from([seed]);
        let mut conflict = false;
        while let Some(f) = queue.pop_front() {
            let t = faces[f];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let Some(nbrs) = incidence.manifold(a, b) else {
                    continue;
                };
                let g = if nbrs[0] as usize == f {
                    nbrs[1]
                } else {
                    nbrs[0]
                } as usize;
                let consistent = has_directed(&faces[g], b, a);
                if state[g] == 0 {
                    if !consistent {
                        faces[g].swap(1, 2);
                        flipped += 1;
                    }
                    state[g] = 1;
                    queue.push_back(g);
                } else if !consistent {
                    conflict = true;
                }
            }
        }
        if conflict {
            *non_orientable += 1;
        }
    }
    flipped
}

/// Gives every fan of faces around a vertex after the first its own copy of the vertex.
fn split_pinches(
    faces: &mut [[u32; 3]],
    positions: &mut Vec<DVec3>,
    origin: &mut Vec<u32>,
) -> usize {
    let nv = positions.len();
    // Faces around each vertex, as one flat array with offsets.
    let mut start = vec![0usize; nv + 1];
    for t in faces.iter() {
        for &v in t {
            start[v as usize + 1] += 1;
        }
    }
    for v in 0..nv {
        start[v + 1] += start[v];
    }
    let mut fill = start.clone();
    let mut incident = vec![0usize; start[nv]];
    for (f, t) in faces.iter().enumerate() {
        for &v in t {
            incident[fill[v as usize]] = f;
            fill[v as usize] += 1;
        }
    }
    let mut edge_count: FxHashMap<u64, u32> = FxHashMap::default();
    edge_count.reserve(faces.len() * 3 / 2 + 16);
    for t in faces.iter() {
        for k in 0..3 {
            *edge_count
                .entry(edge_key(t[k], t[(k + 1) % 3]))
                .or_insert(0) += 1;
        }
    }
    let mut split = 0;
    for v in 0..nv as u32 {
        let fs = &incident[start[v as usize]..start[v as usize + 1]];
        if fs.len() < 2 {
            continue;
        }
        let mut uf = UnionFind::new(fs.len());
        for i in 0..fs.len() {
            for j in i + 1..fs.len() {
                let shared = faces[fs[i]]
                    .iter()
                    .filter(|&&w| w != v && faces[fs[j]].contains(&w))
                    .any(|&w| edge_count.get(&edge_key(v, w)) == Some(&2));
                if shared {
                    uf.union(i, j);
                }
            }
        }
        let mut fan_copy: FxHashMap<usize, u32> = FxHashMap::default();
        let first_root = uf.find(0);
        for i in 0..fs.len() {
            let root = uf.find(i);
            if root == first_root {
                continue;
            }
            let copy = *fan_copy.entry(root).or_insert_with(|| {
                positions.push(positions[v as usize]);
                origin.push(origin[v as usize]);
                (positions.len() - 1) as u32
            });
            let t = faces[fs[i]];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if a == v || b == v {
                    let other = if a == v { b } else { a };
                    if let Some(c) = edge_count.get_mut(&edge_key(v, other)) {
                        *c -= 1;
                    }
                    *edge_count.entry(edge_key(copy, other)).or_insert(0) += 1;
                }
            }
            for w in faces[fs[i]].iter_mut() {
                if *w == v {
                    *w = copy;
                }
            }
        }
        if !fan_copy.is_empty() {
            split += 1;
        }
    }
    split
}

/// An undirected edge as one hashable word.
pub fn edge_key(a: u32, b: u32) -> u64 {
    ((a.min(b) as u64) << 32) | a.max(b) as u64
}

/// Faces on each undirected edge: the first two in face order inline (most edges have at
/// most two), further ones in a side list. Built with one hash entry per edge and no
/// allocation per edge: cleaning runs on every input and must stay a small share of a fit.
struct EdgeIncidence {
    /// (first face, second face or u32::MAX, total count).
    edges: FxHashMap<u64, (u32, u32, u32)>,
    /// (edge, face) beyond the second, in face order.
    more: Vec<(u64, u32)>,
}

impl EdgeIncidence {
    fn new(faces: &[[u32; 3]]) -> Self {
        let mut edges: FxHashMap<u64, (u32, u32, u32)> = FxHashMap::default();
        edges.reserve(faces.len() * 3 / 2 + 16);
        let mut more = Vec::new();
        for (f, t) in faces.iter().enumerate() {
            for k in 0..3 {
                let key = edge_key(t[k], t[(k + 1) % 3]);
                let e = edges.entry(key).or_insert((f as u32, u32::MAX, 0));
                match e.2 {
                    0 => {}
                    1 => e.1 = f as u32,
                    _ => more.push((key, f as u32)),
                }
                e.2 += 1;
            }
        }
        Self { edges, more }
    }

    /// The two faces of an edge that has exactly two.
    fn manifold(&self, a: u32, b: u32) -> Option<[u32; 2]> {
        match self.edges.get(&edge_key(a, b)) {
            Some(&(f, g, 2)) => Some([f, g]),
            _ => None,
        }
    }

    /// Edges with more than two faces and all their faces in face order, sorted by edge.
    fn non_manifold(&self) -> Vec<((u32, u32), Vec<u32>)> {
        // Grouped by edge (faces stay in face order: the sort is by (edge, face)).
        let mut more = self.more.clone();
        more.sort_unstable();
        let mut out: Vec<((u32, u32), Vec<u32>)> = self
            .edges
            .iter()
            .filter(|(_, e)| e.2 > 2)
            .map(|(&key, e)| {
                let mut fs = vec![e.0, e.1];
                let from = more.partition_point(|m| m.0 < key);
                let to = more.partition_point(|m| m.0 <= key);
                fs.extend(more[from..to].iter().map(|m| m.1));
                (((key >> 32) as u32, key as u32), fs)
            })
            .collect();
        out.sort_unstable();
        out
    }
}
