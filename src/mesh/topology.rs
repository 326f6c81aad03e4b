//! Half-edge connectivity with ordered 1-rings, built in linear time by bucketing
//! half-edges by their source vertex (no global sort or hash of edges).

use super::TriMesh;

pub const NONE: u32 = u32::MAX;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TopologyError {
    #[error("face {face} has an index out of range or a repeated vertex")]
    BadFace { face: usize },
    #[error("edge ({a}, {b}) is not manifold: {count} faces use it in the same direction or it has more than two faces")]
    NonManifoldEdge { a: u32, b: u32, count: usize },
    #[error("vertex {vertex} is a pinch vertex: its faces form {fans} separate fans")]
    PinchVertex { vertex: u32, fans: usize },
}

/// Half-edge `h = 3 f + k` runs from corner k of face f to corner k+1.
#[derive(Debug, Clone)]
pub struct Topology {
    pub vertex_count: usize,
    pub triangles: Vec<[u32; 3]>,
    /// Opposite half-edge, or `NONE` on the boundary.
    pub twin: Vec<u32>,
    /// CSR of the ordered 1-ring of each vertex: counter-clockwise, starting at the boundary
    /// neighbour for boundary vertices (whose ring then has one more vertex than faces).
    pub ring_start: Vec<u32>,
    pub ring: Vec<u32>,
    /// Outgoing half-edge to each ring entry (`NONE` for the last neighbour of a boundary
    /// vertex, which is reached only through an incoming half-edge).
    pub ring_halfedge: Vec<u32>,
    pub boundary: Vec<bool>,
    /// Number of incident faces per vertex.
    pub face_valence: Vec<u32>,
}

#[inline]
pub fn next(h: u32) -> u32 {
    if h % 3 == 2 {
        h - 2
    } else {
        h + 1
    }
}
#[inline]
pub fn prev(h: u32) -> u32 {
    if h.is_multiple_of(3) {
        h + 2
    } else {
        h - 1
    }
}

impl Topology {
    pub fn from_mesh(mesh: &TriMesh) -> Result<Topology, TopologyError> {
        Self::build(mesh.positions.len(), &mesh.triangles)
    }

    pub fn build(vertex_count: usize, triangles: &[[u32; 3]]) -> Result<Topology, TopologyError> {
        let nh = triangles.len() * 3;
        for (f, t) in triangles.iter().enumerate() {
            if t.iter().any(|&v| v as usize >= vertex_count)
                || t[0] == t[1]
                || t[1] == t[2]
                || t[0] == t[2]
            {
                return Err(TopologyError::BadFace { face: f });
            }
        }
        let src = |h: usize| triangles[h / 3][h % 3];
        let dst = |h: usize| triangles[h / 3][(h + 1) % 3];
        // Bucket outgoing half-edges by source vertex, with their destinations alongside so
        // that the twin search scans one contiguous run per vertex.
        let mut out_start = vec![0u32; vertex_count + 1];
        for t in triangles {
            for &v in t {
                out_start[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            out_start[v + 1] += out_start[v];
        }
        let mut fill = out_start.clone();
        let mut out = vec![0u32; nh];
        let mut out_dst = vec![0u32; nh];
        for (f, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let s = t[k] as usize;
                out[fill[s] as usize] = (3 * f + k) as u32;
                out_dst[fill[s] as usize] = t[(k + 1) % 3];
                fill[s] += 1;
            }
        }
        drop(fill);
        let run = |v: u32| out_start[v as usize] as usize..out_start[v as usize + 1] as usize;
        let outgoing = |v: u32| &out[run(v)];
        let mut twin = vec![NONE; nh];
        for (f, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let same = out_dst[run(a)].iter().filter(|&&d| d == b).count();
                let r = run(b);
                let mut opposite = out_dst[r.clone()]
                    .iter()
                    .enumerate()
                    .filter(|(_, &d)| d == a);
                let first = opposite.next().map(|(i, _)| out[r.start + i]);
                let more = opposite.next().is_some();
                if same > 1 || more {
                    return Err(TopologyError::NonManifoldEdge {
                        a: a.min(b),
                        b: a.max(b),
                        count: same + usize::from(first.is_some()) + usize::from(more),
                    });
                }
                if let Some(g) = first {
                    twin[3 * f + k] = g;
                }
            }
        }
        // Ordered rings: rotate counter-clockwise with h -> twin(prev(h)).
        let mut ring_start = Vec::with_capacity(vertex_count + 1);
        let mut ring = Vec::with_capacity(nh + vertex_count);
        let mut ring_halfedge = Vec::with_capacity(nh + vertex_count);
        let mut boundary = vec![false; vertex_count];
        let mut face_valence = vec![0u32; vertex_count];
        ring_start.push(0u32);
        for v in 0..vertex_count as u32 {
            let outs = outgoing(v);
            face_valence[v as usize] = outs.len() as u32;
            if outs.is_empty() {
                ring_start.push(ring.len() as u32);
                continue;
            }
            // A boundary vertex starts at the outgoing edge with no face on its right.
            let mut starts = outs.iter().copied().filter(|&h| twin[h as usize] == NONE);
            let first_start = starts.next();
            let is_boundary = first_start.is_some();
            let more_starts = starts.count();
            if more_starts > 0 {
                return Err(TopologyError::PinchVertex {
                    vertex: v,
                    fans: 1 + more_starts,
                });
            }
            let start = first_start.unwrap_or(outs[0]);
            let mut h = start;
            let mut visited = 0usize;
            loop {
                ring.push(dst(h as usize));
                ring_halfedge.push(h);
                visited += 1;
                let p = prev(h);
                let t = twin[p as usize];
                if t == NONE {
                    ring.push(src(p as usize));
                    ring_halfedge.push(NONE);
                    break;
                }
                if t == start {
                    break;
                }
                h = t;
                if visited > outs.len() {
                    break;
                }
            }
            if visited != outs.len() {
                return Err(TopologyError::PinchVertex { vertex: v, fans: 2 });
            }
            boundary[v as usize] = is_boundary;
            ring_start.push(ring.len() as u32);
        }
        Ok(Topology {
            vertex_count,
            triangles: triangles.to_vec(),
            twin,
            ring_start,
            ring,
            ring_halfedge,
            boundary,
            face_valence,
        })
    }

    #[inline]
    pub fn ring(&self, v: u32) -> &[u32] {
        &self.ring[self.ring_start[v as usize] as usize..self.ring_start[v as usize + 1] as usize]
    }

    /// Number of neighbours (edges) of `v`.
    #[inline]
    pub fn ring_halfedges(&self, v: u32) -> &[u32] {
        &self.ring_halfedge
            [self.ring_start[v as usize] as usize..self.ring_start[v as usize + 1] as usize]
    }

    #[inline]
    pub fn valence(&self, v: u32) -> usize {
        self.ring(v).len()
    }

    #[inline]
    pub fn is_boundary(&self, v: u32) -> bool {
        self.boundary[v as usize]
    }

    /// A corner in the sense of Loop's boundary rules: a boundary vertex with one face.
    #[inline]
    pub fn is_corner(&self, v: u32) -> bool {
        self.boundary[v as usize] && self.face_valence[v as usize] == 1
    }

    pub fn edge_count(&self) -> usize {
        let boundary = self.twin.iter().filter(|&&t| t == NONE).count();
        boundary + (self.twin.len() - boundary) / 2
    }

    /// Undirected edges, each once: (a, b, half-edge) with the half-edge a -> b chosen so
    /// that every interior edge appears through its lower-numbered half-edge.
    pub fn edges(&self) -> Vec<(u32, u32, u32)> {
        let mut e = Vec::with_capacity(self.twin.len() / 2 + 16);
        for h in 0..self.twin.len() as u32 {
            let t = self.twin[h as usize];
            if t == NONE || h < t {
                let f = (h / 3) as usize;
                let k = (h % 3) as usize;
                e.push((self.triangles[f][k], self.triangles[f][(k + 1) % 3], h));
            }
        }
        e
    }

    /// Vertex opposite half-edge h in its face.
    #[inline]
    pub fn opposite(&self, h: u32) -> u32 {
        let f = (h / 3) as usize;
        self.triangles[f][((h % 3 + 2) % 3) as usize]
    }
}
