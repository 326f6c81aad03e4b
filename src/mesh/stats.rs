//! Counts on a raw input mesh, before any repair (what `trispline inspect` prints).

use super::detect::Hierarchy;
use super::topology::Topology;
use super::TriMesh;
use std::collections::HashMap;

#[derive(Clone, Debug, serde::Serialize)]
/// Counts that describe a mesh's state, for `mesh stats` and reports.
pub struct MeshStats {
    /// Vertices.
    pub vertices: usize,
    /// Faces.
    pub faces: usize,
    /// Edge-connected components.
    pub components: usize,
    /// Boundary loops.
    pub boundary_loops: usize,
    /// Edges with one face.
    pub boundary_edges: usize,
    /// Edges with more than two faces.
    pub non_manifold_edges: usize,
    /// Vertices whose faces form more than one fan.
    pub non_manifold_vertices: usize,
    /// Faces repeating another's vertices.
    pub duplicate_faces: usize,
    /// Faces with a repeated vertex.
    pub degenerate_faces: usize,
    /// Vertices no face uses.
    pub unreferenced_vertices: usize,
    /// V - E + F.
    pub euler_characteristic: i64,
    /// No boundary edge.
    pub closed: bool,
    /// Genus of a single closed orientable manifold component, else `None`.
    pub genus: Option<i64>,
    /// Loop subdivision levels detected (0 = none).
    pub subdivision_depth: usize,
    /// Why detection stopped at `subdivision_depth`.
    pub subdivision_note: Option<String>,
}

/// Counts everything on the mesh as given. Components are edge-connected face sets;
/// `non_manifold_vertices` counts vertices whose faces form more than one edge-connected
/// fan (pinch vertices) on manifold edges, plus endpoints of non-manifold edges.
pub fn mesh_stats(mesh: &TriMesh, max_depth: usize) -> MeshStats {
    let nv = mesh.positions.len();
    let valid: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .copied()
        .filter(|t| t.iter().all(|&v| (v as usize) < nv))
        .collect();
    let degenerate_faces = valid
        .iter()
        .filter(|t| {
            t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || {
                let p = |i: usize| mesh.positions[t[i] as usize];
                (p(1) - p(0)).cross(p(2) - p(0)).length_squared() == 0.0
            }
        })
        .count()
        + (mesh.triangles.len() - valid.len());
    let proper: Vec<[u32; 3]> = valid
        .iter()
        .copied()
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect();
    let mut seen_faces: HashMap<[u32; 3], usize> = HashMap::new();
    for t in &proper {
        let mut k = *t;
        k.sort_unstable();
        *seen_faces.entry(k).or_insert(0) += 1;
    }
    let duplicate_faces = seen_faces.values().map(|c| c - 1).sum();
    let mut edge_faces: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (f, t) in proper.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            edge_faces
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push(f as u32);
        }
    }
    let non_manifold_edges = edge_faces.values().filter(|f| f.len() > 2).count();
    let boundary: Vec<(u32, u32)> = edge_faces
        .iter()
        .filter(|(_, f)| f.len() == 1)
        .map(|(&e, _)| e)
        .collect();
    // Components by union-find over faces sharing an edge.
    let mut uf = UnionFind::new(proper.len());
    for fs in edge_faces.values() {
        for w in fs.windows(2) {
            uf.union(w[0] as usize, w[1] as usize);
        }
    }
    let components = (0..proper.len()).filter(|&f| uf.find(f) == f).count();
    // Boundary loops: union boundary edges by shared vertices, counted per vertex cycle.
    let mut bverts: HashMap<u32, usize> = HashMap::new();
    for &(a, b) in &boundary {
        let n = bverts.len();
        bverts.entry(a).or_insert(n);
        let n = bverts.len();
        bverts.entry(b).or_insert(n);
    }
    let mut buf = UnionFind::new(bverts.len());
    for &(a, b) in &boundary {
        buf.union(bverts[&a], bverts[&b]);
    }
    let boundary_loops = (0..bverts.len()).filter(|&i| buf.find(i) == i).count();
    // Fans around each vertex: union incident faces that share a manifold edge at it.
    let mut incident: Vec<Vec<u32>> = vec![Vec::new(); nv];
    for (f, t) in proper.iter().enumerate() {
        for &v in t {
            incident[v as usize].push(f as u32);
        }
    }
    let mut nm_vertex = vec![false; nv];
    for (&(a, b), fs) in &edge_faces {
        if fs.len() > 2 {
            nm_vertex[a as usize] = true;
            nm_vertex[b as usize] = true;
        }
    }
    for v in 0..nv {
        let fs = &incident[v];
        if fs.len() < 2 || nm_vertex[v] {
            continue;
        }
        let mut local = UnionFind::new(fs.len());
        let pos: HashMap<u32, usize> = fs.iter().enumerate().map(|(i, &f)| (f, i)).collect();
        for &f in fs {
            let t = proper[f as usize];
            for &w in &t {
                if w as usize == v {
                    continue;
                }
                let key = ((v as u32).min(w), (v as u32).max(w));
                if let Some(others) = edge_faces.get(&key) {
                    if others.len() == 2 {
                        for &g in others {
                            if let Some(&j) = pos.get(&g) {
                                local.union(pos[&f], j);
                            }
                        }
                    }
                }
            }
        }
        let fans = (0..fs.len()).filter(|&i| local.find(i) == i).count();
        if fans > 1 {
            nm_vertex[v] = true;
        }
    }
    let non_manifold_vertices = nm_vertex.iter().filter(|&&b| b).count();
    let referenced = incident.iter().filter(|f| !f.is_empty()).count();
    let euler_characteristic = referenced as i64 - edge_faces.len() as i64 + proper.len() as i64;
    let closed = boundary.is_empty() && non_manifold_edges == 0 && !proper.is_empty();
    let genus =
        (closed && components == 1 && non_manifold_vertices == 0 && euler_characteristic % 2 == 0)
            .then(|| (2 - euler_characteristic) / 2);
    let (subdivision_depth, subdivision_note) = match Topology::build(nv, &mesh.triangles) {
        Ok(topo) => {
            let (h, err) = Hierarchy::detect(&topo, max_depth);
            (h.depth(), err.map(|e| e.to_string()))
        }
        Err(e) => (0, Some(format!("not a manifold mesh: {e}"))),
    };
    MeshStats {
        vertices: nv,
        faces: mesh.triangles.len(),
        components,
        boundary_loops,
        boundary_edges: boundary.len(),
        non_manifold_edges,
        non_manifold_vertices,
        duplicate_faces,
        degenerate_faces,
        unreferenced_vertices: nv - referenced,
        euler_characteristic,
        closed,
        genus,
        subdivision_depth,
        subdivision_note,
    }
}

pub(crate) struct UnionFind {
    parent: Vec<usize>,
}

impl UnionFind {
    pub fn new(n: usize) -> Self {
        Self {
            parent: (0..n).collect(),
        }
    }
    pub fn find(&mut self, mut x: usize) -> usize {
        while self.parent[x] != x {
            self.parent[x] = self.parent[self.parent[x]];
            x = self.parent[x];
        }
        x
    }
    pub(crate) fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb)] = ra.min(rb);
        }
    }
}
