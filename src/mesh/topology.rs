//! Half-edge connectivity with ordered 1-rings, built in linear time by bucketing
//! half-edges by their source vertex (no global sort or hash of edges).

use super::TriMesh;
use rayon::prelude::*;

/// Half-edges (twins) and vertices (rings) per parallel task.
const PARALLEL_MIN: usize = 1 << 12;

/// "No such half-edge / vertex" in the index arrays.
pub const NONE: u32 = u32::MAX;

/// Why a triangle list is not a manifold mesh this crate can walk.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TopologyError {
    /// A face with an index out of range or a repeated vertex.
    #[error("face {face} has an index out of range or a repeated vertex")]
    BadFace {
        /// The face's index.
        face: usize,
    },
    /// An edge used twice in one direction, or by more than two faces.
    #[error("edge ({a}, {b}) is not manifold: {count} faces use it in the same direction or it has more than two faces")]
    NonManifoldEdge {
        /// Lower vertex of the edge.
        a: u32,
        /// Higher vertex of the edge.
        b: u32,
        /// Faces using it.
        count: usize,
    },
    /// A vertex whose faces form more than one fan (two surface sheets touch there).
    #[error("vertex {vertex} is a pinch vertex: its faces form {fans} separate fans")]
    PinchVertex {
        /// The vertex.
        vertex: u32,
        /// Number of separate fans (at least 2).
        fans: usize,
    },
}

impl TopologyError {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::BadFace { .. } => "bad_face",
            Self::NonManifoldEdge { .. } => "non_manifold_edge",
            Self::PinchVertex { .. } => "pinch_vertex",
        }
    }
}

/// Half-edge `h = 3 f + k` runs from corner k of face f to corner k+1.
#[derive(Debug, Clone)]
pub struct Topology {
    /// Number of vertices (isolated ones included).
    pub vertex_count: usize,
    /// The triangles.
    pub triangles: Vec<[u32; 3]>,
    /// Opposite half-edge, or `NONE` on the boundary.
    pub twin: Vec<u32>,
    /// CSR of the ordered 1-ring of each vertex: counter-clockwise, starting at the boundary
    /// neighbour for boundary vertices (whose ring then has one more vertex than faces).
    pub ring_start: Vec<u32>,
    /// Ring entries (neighbour vertices), see `ring_start`.
    pub ring: Vec<u32>,
    /// Outgoing half-edge to each ring entry (`NONE` for the last neighbour of a boundary
    /// vertex, which is reached only through an incoming half-edge).
    pub ring_halfedge: Vec<u32>,
    /// Whether each vertex is on the boundary.
    pub boundary: Vec<bool>,
    /// Number of incident faces per vertex.
    pub face_valence: Vec<u32>,
}

#[inline]
/// The next half-edge in the same face.
pub fn next(h: u32) -> u32 {
    if h % 3 == 2 {
        h - 2
    } else {
        h + 1
    }
}
#[inline]
/// The previous half-edge in the same face.
pub fn prev(h: u32) -> u32 {
    if h.is_multiple_of(3) {
        h + 2
    } else {
        h - 1
    }
}

impl Topology {
    /// `build` on a mesh's vertex count and triangles.
    pub fn from_mesh(mesh: &TriMesh) -> Result<Topology, TopologyError> {
        Self::build(mesh.positions.len(), &mesh.triangles)
    }

    /// Checks the faces and builds twins and ordered rings; fails on a bad face index, a
    /// non-manifold edge or a pinch vertex.
    pub fn build(vertex_count: usize, triangles: &[[u32; 3]]) -> Result<Topology, TopologyError> {
        check_faces(vertex_count, triangles)?;
        let buckets = Outgoing::new(vertex_count, triangles);
        let twin = twins(triangles, &buckets)?;
        let rings = ordered_rings(vertex_count, triangles, &buckets, &twin)?;
        let face_valence = (0..vertex_count as u32)
            .map(|v| buckets.outgoing(v).len() as u32)
            .collect();
        Ok(Topology {
            vertex_count,
            triangles: triangles.to_vec(),
            twin,
            ring_start: rings.ring_start,
            ring: rings.ring,
            ring_halfedge: rings.ring_halfedge,
            boundary: rings.boundary,
            face_valence,
        })
    }

    #[inline]
    /// The ordered 1-ring of `v`.
    pub fn ring(&self, v: u32) -> &[u32] {
        &self.ring[self.ring_start[v as usize] as usize..self.ring_start[v as usize + 1] as usize]
    }

    /// Number of neighbours (edges) of `v`.
    #[inline]
    pub(crate) fn ring_halfedges(&self, v: u32) -> &[u32] {
        &self.ring_halfedge
            [self.ring_start[v as usize] as usize..self.ring_start[v as usize + 1] as usize]
    }

    #[inline]
    /// Number of neighbours of `v`.
    pub fn valence(&self, v: u32) -> usize {
        self.ring(v).len()
    }

    #[inline]
    /// Whether `v` is on the boundary.
    pub fn is_boundary(&self, v: u32) -> bool {
        self.boundary[v as usize]
    }

    /// A corner in the sense of Loop's boundary rules: a boundary vertex with one face.
    #[inline]
    pub fn is_corner(&self, v: u32) -> bool {
        self.boundary[v as usize] && self.face_valence[v as usize] == 1
    }

    pub(crate) fn edge_count(&self) -> usize {
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

/// A k x k grid of unit squares, each split along one diagonal: vertex (i, j) at index
/// j * (k + 1) + i (a test mesh for the modules that walk meshes).
fn check_faces(vertex_count: usize, triangles: &[[u32; 3]]) -> Result<(), TopologyError> {
    for (f, t) in triangles.iter().enumerate() {
        if t.iter().any(|&v| v as usize >= vertex_count)
            || t[0] == t[1]
            || t[1] == t[2]
            || t[0] == t[2]
        {
            return Err(TopologyError::BadFace { face: f });
        }
    }
    Ok(())
}

fn src(triangles: &[[u32; 3]], h: usize) -> u32 {
    triangles[h / 3][h % 3]
}

fn dst(triangles: &[[u32; 3]], h: usize) -> u32 {
    triangles[h / 3][(h + 1) % 3]
}

/// Outgoing half-edges bucketed by source vertex, with their destinations alongside so
/// that the twin search scans one contiguous run per vertex.
struct Outgoing {
    start: Vec<u32>,
    halfedge: Vec<u32>,
    dst: Vec<u32>,
}

impl Outgoing {
    fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> Self {
        let nh = triangles.len() * 3;
        let mut start = vec![0u32; vertex_count + 1];
        for t in triangles {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            start[v + 1] += start[v];
        }
        let mut fill = start.clone();
        let mut halfedge = vec![0u32; nh];
        let mut dst = vec![0u32; nh];
        for (f, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let s = t[k] as usize;
                halfedge[fill[s] as usize] = (3 * f + k) as u32;
                dst[fill[s] as usize] = t[(k + 1) % 3];
                fill[s] += 1;
            }
        }
        Self {
            start,
            halfedge,
            dst,
        }
    }

    fn run(&self, v: u32) -> std::ops::Range<usize> {
        self.start[v as usize] as usize..self.start[v as usize + 1] as usize
    }

    fn outgoing(&self, v: u32) -> &[u32] {
        &self.halfedge[self.run(v)]
    }
}

/// Per half-edge a -> b: the opposite half-edge, if any, how many faces use the edge, and
/// whether it is used twice in one direction or has more than two faces.
fn twin_of(triangles: &[[u32; 3]], buckets: &Outgoing, h: usize) -> (u32, usize, bool) {
    let (a, b) = (src(triangles, h), dst(triangles, h));
    let same = buckets.dst[buckets.run(a)]
        .iter()
        .filter(|&&d| d == b)
        .count();
    let r = buckets.run(b);
    let mut opposite = buckets.dst[r.clone()]
        .iter()
        .enumerate()
        .filter(|(_, &d)| d == a);
    let first = opposite.next().map(|(i, _)| buckets.halfedge[r.start + i]);
    let more = opposite.next().is_some();
    let count = same + usize::from(first.is_some()) + usize::from(more);
    (first.unwrap_or(NONE), count, same > 1 || more)
}

/// The twin of every half-edge (`NONE` on the boundary), or the first non-manifold edge.
fn twins(triangles: &[[u32; 3]], buckets: &Outgoing) -> Result<Vec<u32>, TopologyError> {
    // Half-edge ids stay below NONE - 1 (a mesh that large cannot be read).
    const NON_MANIFOLD: u32 = NONE - 1;
    let nh = triangles.len() * 3;
    let twin: Vec<u32> = (0..nh)
        .into_par_iter()
        .with_min_len(PARALLEL_MIN)
        .map(|h| match twin_of(triangles, buckets, h) {
            (_, _, true) => NON_MANIFOLD,
            (t, _, false) => t,
        })
        .collect();
    if let Some(h) = twin.iter().position(|&t| t == NON_MANIFOLD) {
        let (a, b) = (src(triangles, h), dst(triangles, h));
        return Err(TopologyError::NonManifoldEdge {
            a: a.min(b),
            b: a.max(b),
            count: twin_of(triangles, buckets, h).1,
        });
    }
    Ok(twin)
}

/// The ring CSR and boundary flags of `Topology`.
struct Rings {
    ring_start: Vec<u32>,
    ring: Vec<u32>,
    ring_halfedge: Vec<u32>,
    boundary: Vec<bool>,
}

/// Appends the ordered ring of `v` (rotating counter-clockwise with h -> twin(prev(h)))
/// and returns whether `v` is on the boundary.
fn ring_of(
    triangles: &[[u32; 3]],
    buckets: &Outgoing,
    twin: &[u32],
    v: u32,
    ring: &mut Vec<u32>,
    ring_halfedge: &mut Vec<u32>,
) -> Result<bool, TopologyError> {
    let outs = buckets.outgoing(v);
    if outs.is_empty() {
        return Ok(false);
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
        ring.push(dst(triangles, h as usize));
        ring_halfedge.push(h);
        visited += 1;
        let p = prev(h);
        let t = twin[p as usize];
        if t == NONE {
            ring.push(src(triangles, p as usize));
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
    Ok(is_boundary)
}

/// Every vertex's ordered ring. Vertex ranges are walked in parallel and joined in order;
/// the first error in vertex order wins.
fn ordered_rings(
    vertex_count: usize,
    triangles: &[[u32; 3]],
    buckets: &Outgoing,
    twin: &[u32],
) -> Result<Rings, TopologyError> {
    type Chunk = (Vec<u32>, Vec<u32>, Vec<u32>, Vec<bool>);
    let nh = triangles.len() * 3;
    let chunks: Vec<Result<Chunk, TopologyError>> = (0..vertex_count.div_ceil(PARALLEL_MIN))
        .into_par_iter()
        .map(|c| {
            let vs = c * PARALLEL_MIN..((c + 1) * PARALLEL_MIN).min(vertex_count);
            // A ring holds a vertex's outgoing half-edges and at most one more.
            let most = (buckets.start[vs.end] - buckets.start[vs.start]) as usize + vs.len();
            let (mut ring, mut ring_halfedge) =
                (Vec::with_capacity(most), Vec::with_capacity(most));
            let mut ends = Vec::with_capacity(vs.len());
            let mut boundary = Vec::with_capacity(vs.len());
            for v in vs {
                boundary.push(ring_of(
                    triangles,
                    buckets,
                    twin,
                    v as u32,
                    &mut ring,
                    &mut ring_halfedge,
                )?);
                ends.push(ring.len() as u32);
            }
            Ok((ring, ring_halfedge, ends, boundary))
        })
        .collect();
    let mut rings = Rings {
        ring_start: Vec::with_capacity(vertex_count + 1),
        ring: Vec::with_capacity(nh + vertex_count),
        ring_halfedge: Vec::with_capacity(nh + vertex_count),
        boundary: Vec::with_capacity(vertex_count),
    };
    rings.ring_start.push(0u32);
    for chunk in chunks {
        let (r, rh, ends, b) = chunk?;
        let base = rings.ring.len() as u32;
        rings.ring_start.extend(ends.iter().map(|e| base + e));
        rings.ring.extend(r);
        rings.ring_halfedge.extend(rh);
        rings.boundary.extend(b);
    }
    Ok(rings)
}

#[cfg(test)]
pub(crate) fn grid_triangles(k: usize) -> Vec<[u32; 3]> {
    let at = |i: usize, j: usize| (j * (k + 1) + i) as u32;
    let mut t = Vec::new();
    for j in 0..k {
        for i in 0..k {
            t.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            t.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Large enough for several parallel ranges of half-edges and vertices.
    #[test]
    fn rings_of_a_large_grid_match_its_half_edges_and_boundary() {
        let k = 90;
        let n = (k + 1) * (k + 1);
        assert!(n > 2 * PARALLEL_MIN);
        let topo = Topology::build(n, &grid_triangles(k)).expect("manifold");
        for v in 0..n as u32 {
            let (i, j) = (v as usize % (k + 1), v as usize / (k + 1));
            let on_rim = i == 0 || j == 0 || i == k || j == k;
            assert_eq!(topo.is_boundary(v), on_rim, "vertex ({i}, {j})");
            if !on_rim {
                assert_eq!(topo.valence(v), 6);
            }
            // Every ring entry is reached by its half-edge (but a boundary ring's last).
            for (&w, &h) in topo.ring(v).iter().zip(topo.ring_halfedges(v)) {
                if h != NONE {
                    let t = topo.triangles[h as usize / 3];
                    assert_eq!((t[h as usize % 3], t[(h as usize + 1) % 3]), (v, w));
                }
            }
        }
        assert_eq!(topo.edge_count(), 3 * k * k + 2 * k);
    }

    #[test]
    fn non_manifold_edges_and_pinch_vertices_are_named() {
        // Three faces on the edge (0, 1).
        let fin = [[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        assert_eq!(
            Topology::build(5, &fin).err(),
            Some(TopologyError::NonManifoldEdge {
                a: 0,
                b: 1,
                count: 3
            })
        );
        // Two triangles touching at vertex 0 only.
        let bowtie = [[0, 1, 2], [0, 3, 4]];
        assert!(matches!(
            Topology::build(5, &bowtie),
            Err(TopologyError::PinchVertex { vertex: 0, .. })
        ));
    }
}
