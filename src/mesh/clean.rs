//! Repairs: weld, drop degenerate and duplicate faces and zero-thickness sheets, split
//! non-manifold edges and pinch vertices into manifold fans, orient each component
//! consistently, drop unused vertices.

use super::edge_table::EdgeTable;
use super::repeats::repeated_faces;
use super::stats::UnionFind;
use super::TriMesh;
use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashMap;

#[derive(Clone, Debug, Default)]
/// How `clean` repairs a mesh.
pub struct CleanOptions {
    /// Merge vertices closer than this; `None` merges only bit-identical positions.
    pub weld_tolerance: Option<f64>,
}

#[derive(Clone, Debug, Default, serde::Serialize)]
/// What `clean` changed, by kind of repair.
pub struct CleanReport {
    /// Vertices merged into another.
    pub welded_vertices: usize,
    /// Faces with an out-of-range index, a repeated vertex (after welding) or zero area, removed.
    pub degenerate_faces_removed: usize,
    /// Faces repeating another's vertices in the same orientation removed (and the other
    /// side of a lone double-sided sheet, one side of which stays).
    pub duplicate_faces_removed: usize,
    /// Faces removed as both sides of a sheet of zero thickness hanging off the surface
    /// (a face and its reverse: `mesh::repeats`).
    pub sheet_faces_removed: usize,
    /// Edges with more than two faces, split apart.
    pub non_manifold_edges_split: usize,
    /// Vertices whose faces formed several fans, split into one per fan.
    pub pinch_vertices_split: usize,
    /// Faces reversed to agree with their neighbours.
    pub faces_flipped: usize,
    /// Components that cannot be oriented consistently (Moebius-like).
    pub non_orientable_components: usize,
    /// Vertices no face used, dropped.
    pub unreferenced_vertices_removed: usize,
}

#[derive(Clone, Debug)]
/// A cleaned mesh and how it relates to its input.
pub struct Cleaned {
    /// The manifold, consistently oriented mesh.
    pub mesh: TriMesh,
    /// Cleaned vertex -> input vertex (a split vertex maps to the vertex it came from).
    pub original_vertex: Vec<u32>,
    /// Per face of `mesh`, the first face (lowest index) of its edge-connected component:
    /// the components found while orienting, so that splitting the mesh into them needs no
    /// second edge table.
    pub face_component: Vec<u32>,
    /// What was changed.
    pub report: CleanReport,
}

/// Repairs a scan mesh into a manifold, consistently oriented one (see the module docs).
pub fn clean(input: &TriMesh, opts: &CleanOptions) -> Cleaned {
    let mut report = CleanReport::default();
    let nv = input.positions.len();
    let rep = weld_map(&input.positions, opts.weld_tolerance);
    report.welded_vertices = (0..nv).filter(|&v| rep[v] as usize != v).count();
    // Splitting non-manifold edges and pinch vertices appends copies: room for some, as
    // pages never written cost nothing and a full vector would be copied whole to grow.
    let room = nv + nv / 16 + 16;
    let mut positions = Vec::with_capacity(room);
    positions.extend_from_slice(&input.positions);
    let mut origin: Vec<u32> = Vec::with_capacity(room);
    origin.extend(0..nv as u32);
    // Degenerate faces.
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
        faces.push(t);
    }
    // Faces repeating another's vertices: duplicates, and sheets of zero thickness.
    let repeats = repeated_faces(&faces, nv);
    let mut k = 0;
    faces.retain(|_| {
        k += 1;
        !repeats.dropped[k - 1]
    });
    report.duplicate_faces_removed = repeats.duplicates;
    report.sheet_faces_removed = repeats.sheet_faces;
    // Non-manifold edges. Where the faces around one of the edge's ends form fans (joined
    // through manifold edges) that hold at most two of the edge's faces each, the pinch
    // split below parts them: two closed sheets touching along the edge stay closed.
    // Otherwise the first two faces keep the edge and every further face gets its own
    // copies of the edge's endpoints (and a hole there). Edges come sorted by their
    // endpoints, the faces of each in face order.
    let incidence = EdgeTable::new(&faces, positions.len());
    let mut around: Option<Incidence> = None;
    for e in 0..incidence.len() {
        let hs = incidence.halves(e);
        if hs.len() <= 2 {
            continue;
        }
        report.non_manifold_edges_split += 1;
        let around = around.get_or_insert_with(|| Incidence::new(&faces, positions.len()));
        let on_edge: Vec<u32> = hs.iter().map(|&h| h / 3).collect();
        let [a, b] = incidence.ends(e);
        if fans_part(a, b, &on_edge, around, &faces) || fans_part(b, a, &on_edge, around, &faces) {
            continue;
        }
        for &f in &on_edge[2..] {
            for end in incidence.ends(e) {
                let copy = positions.len() as u32;
                positions.push(positions[end as usize]);
                origin.push(origin[end as usize]);
                for v in faces[f as usize].iter_mut() {
                    if *v == end {
                        *v = copy;
                    }
                }
            }
        }
    }
    // Splitting changed the faces; otherwise the table still describes them.
    let incidence = if report.non_manifold_edges_split > 0 {
        EdgeTable::new(&faces, positions.len())
    } else {
        incidence
    };
    let mut face_component = Vec::new();
    report.faces_flipped = orient(
        &mut faces,
        &incidence,
        &mut report.non_orientable_components,
        &mut face_component,
    );
    report.pinch_vertices_split = split_pinches(&mut faces, &mut positions, &mut origin);
    // Compact: drop vertices no face uses.
    let mut new_index = vec![u32::MAX; positions.len()];
    let mut out_pos = Vec::with_capacity(positions.len());
    let mut out_origin = Vec::with_capacity(positions.len());
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
    // Keep the input's vertex order among survivors (readers promise file order): a
    // counting sort by input vertex, stable in first-use order, so split copies of one
    // input vertex keep the order in which they were first used.
    let mut bucket = vec![0u32; nv + 1];
    for &o in &out_origin {
        bucket[o as usize + 1] += 1;
    }
    let kept_inputs = bucket.iter().filter(|&&c| c > 0).count();
    for v in 0..nv {
        bucket[v + 1] += bucket[v];
    }
    let mut rank = vec![0u32; out_pos.len()];
    let mut positions = vec![DVec3::ZERO; out_pos.len()];
    let mut original_vertex = vec![0u32; out_pos.len()];
    for (i, &o) in out_origin.iter().enumerate() {
        let r = bucket[o as usize];
        bucket[o as usize] += 1;
        rank[i] = r;
        positions[r as usize] = out_pos[i];
        original_vertex[r as usize] = o;
    }
    for t in faces.iter_mut() {
        for v in t.iter_mut() {
            *v = rank[*v as usize];
        }
    }
    report.unreferenced_vertices_removed =
        (nv - report.welded_vertices).saturating_sub(kept_inputs);
    Cleaned {
        mesh: TriMesh::new(positions, faces),
        original_vertex,
        face_component,
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
/// Also labels every face with its component's seed face (`component`): after non-manifold
/// edges are split every edge has at most two faces, so the manifold neighbours the search
/// walks join exactly the edge-connected faces, and seeds are taken in face order.
fn orient(
    faces: &mut [[u32; 3]],
    incidence: &EdgeTable,
    non_orientable: &mut usize,
    component: &mut Vec<u32>,
) -> usize {
    let nbr = incidence.manifold_neighbours();
    let has_directed =
        |t: &[u32; 3], a: u32, b: u32| (0..3).any(|k| t[k] == a && t[(k + 1) % 3] == b);
    // 0 unvisited, 1 visited as built, 2 visited and flipped: a flip swaps corners 1 and 2,
    // so the face's edge k is then the table's edge 2 - k.
    let mut state = vec![0u8; faces.len()];
    component.clear();
    component.resize(faces.len(), u32::MAX);
    let mut flipped = 0;
    let mut queue = std::collections::VecDeque::new();
    for seed in 0..faces.len() {
        if state[seed] != 0 {
            continue;
        }
        state[seed] = 1;
        component[seed] = seed as u32;
        queue.push_back(seed);
        let mut conflict = false;
        while let Some(f) = queue.pop_front() {
            let t = faces[f];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let slot = if state[f] == 2 { 2 - k } else { k };
                let g = nbr[3 * f + slot];
                if g == u32::MAX {
                    continue;
                }
                let g = g as usize;
                let consistent = has_directed(&faces[g], b, a);
                if state[g] == 0 {
                    state[g] = 1;
                    component[g] = seed as u32;
                    if !consistent {
                        faces[g].swap(1, 2);
                        flipped += 1;
                        state[g] = 2;
                    }
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

/// The faces around each vertex, as one flat array with offsets.
struct Incidence {
    start: Vec<u32>,
    faces: Vec<u32>,
}

impl Incidence {
    fn new(faces: &[[u32; 3]], vertex_count: usize) -> Self {
        let mut start = vec![0u32; vertex_count + 1];
        for t in faces {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut incident = vec![0u32; start[vertex_count] as usize];
        for (f, t) in faces.iter().enumerate() {
            for &v in t {
                incident[fill[v as usize] as usize] = f as u32;
                fill[v as usize] += 1;
            }
        }
        Self {
            start,
            faces: incident,
        }
    }

    fn around(&self, v: u32) -> &[u32] {
        &self.faces[self.start[v as usize] as usize..self.start[v as usize + 1] as usize]
    }
}

/// The fans of the faces `fs` around `v`: `parent` ends holding, per face of `fs`, its
/// fan's root (a local index). Two faces around `v` are joined when they share a
/// neighbour `w` that no other face around `v` has: the edge (v, w) is then manifold.
fn fan_roots(
    v: u32,
    fs: &[u32],
    faces: &[[u32; 3]],
    others: &mut Vec<(u32, u32)>,
    parent: &mut Vec<u32>,
) {
    let find = |parent: &mut [u32], mut x: u32| {
        while parent[x as usize] != x {
            parent[x as usize] = parent[parent[x as usize] as usize];
            x = parent[x as usize];
        }
        x
    };
    others.clear();
    for (i, &f) in fs.iter().enumerate() {
        for &w in &faces[f as usize] {
            if w != v {
                others.push((w, i as u32));
            }
        }
    }
    others.sort_unstable();
    parent.clear();
    parent.extend(0..fs.len() as u32);
    for same in others.chunk_by(|a, b| a.0 == b.0) {
        if let [x, y] = same {
            let (a, b) = (find(parent, x.1), find(parent, y.1));
            parent[a.max(b) as usize] = a.min(b);
        }
    }
    for i in 0..fs.len() as u32 {
        let root = find(parent, i);
        parent[i as usize] = root;
    }
}

/// Whether the fans around `end`, an end of the non-manifold edge to `other`, hold at most
/// two of the edge's faces `on_edge` each, the two ways round, so that giving each fan its
/// own copy of `end` parts them into manifold edges.
fn fans_part(
    end: u32,
    other: u32,
    on_edge: &[u32],
    around: &Incidence,
    faces: &[[u32; 3]],
) -> bool {
    // Faces an earlier edge's copies moved off `end` are no longer around it.
    let fs: Vec<u32> = around
        .around(end)
        .iter()
        .copied()
        .filter(|&f| faces[f as usize].contains(&end))
        .collect();
    let (mut others, mut parent) = (Vec::new(), Vec::new());
    fan_roots(end, &fs, faces, &mut others, &mut parent);
    // Per face on the edge: its fan, and whether it runs from `end` to `other`.
    let mut fans: Vec<(u32, bool)> = on_edge
        .iter()
        .filter_map(|&f| {
            let t = faces[f as usize];
            let k = t.iter().position(|&v| v == end)?;
            let i = fs.iter().position(|&g| g == f)?;
            Some((parent[i], t[(k + 1) % 3] == other))
        })
        .collect();
    fans.sort_unstable();
    // A fan keeping two of the faces must hold them the two ways round (consistently
    // oriented), or the split leaves an edge no orientation can mend.
    fans.len() == on_edge.len()
        && fans.chunk_by(|x, y| x.0 == y.0).all(|fan| match fan {
            [_] => true,
            [x, y] => x.1 != y.1,
            _ => false,
        })
}

/// Gives every fan of faces around a vertex after the first its own copy of the vertex
/// (`fan_roots`). Every face on an edge (v, w) is a face around `v`, and only the
/// processing of `v` itself moves faces off `v`, so counting among the faces around `v`
/// sees the same edge counts as a global table would, without one.
fn split_pinches(
    faces: &mut [[u32; 3]],
    positions: &mut Vec<DVec3>,
    origin: &mut Vec<u32>,
) -> usize {
    let nv = positions.len();
    let incidence = Incidence::new(faces, nv);
    // Which faces around each vertex leave its first fan: worked out for all vertices at
    // once on the faces as they are. Splitting a vertex w cannot change another vertex v's
    // fans: two faces around v joined through w share the edge (v, w), so they are joined
    // at w too (through v) and keep the same copy of w.
    let faces_now: &[[u32; 3]] = faces;
    // Per pinch vertex: (local face index, fan root) of each face outside the first fan.
    let pinches: Vec<(u32, Vec<(u32, u32)>)> = (0..nv as u32)
        .into_par_iter()
        .with_min_len(4096)
        .map_init(
            || (Vec::<(u32, u32)>::new(), Vec::<u32>::new()),
            |(others, parent), v| {
                let fs = incidence.around(v);
                if fs.len() < 2 {
                    return None;
                }
                fan_roots(v, fs, faces_now, others, parent);
                let first_root = parent[0];
                let moved: Vec<(u32, u32)> = (0..fs.len() as u32)
                    .filter_map(|i| {
                        let root = parent[i as usize];
                        (root != first_root).then_some((i, root))
                    })
                    .collect();
                (!moved.is_empty()).then_some((v, moved))
            },
        )
        .flatten()
        .collect();
    let mut copies: Vec<(u32, u32)> = Vec::new();
    for (v, moved) in &pinches {
        let v = *v;
        let fs = incidence.around(v);
        copies.clear();
        for &(i, root) in moved {
            let copy = match copies.iter().find(|c| c.0 == root) {
                Some(&(_, c)) => c,
                None => {
                    let c = positions.len() as u32;
                    positions.push(positions[v as usize]);
                    origin.push(origin[v as usize]);
                    copies.push((root, c));
                    c
                }
            };
            for w in faces[fs[i as usize] as usize].iter_mut() {
                if *w == v {
                    *w = copy;
                }
            }
        }
    }
    pinches.len()
}
