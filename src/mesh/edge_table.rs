//! The undirected edges of a triangle list that may not be manifold, for the repairs.

/// The undirected edges of a triangle list and the faces on each, built without hashing:
/// half-edges are bucketed by their lower endpoint and each (small) bucket sorted. Edge
/// ids follow the (lower, higher) endpoint order; each edge's faces come in face order.
/// Cleaning runs on every input and must stay a small share of a fit.
pub(crate) struct EdgeTable {
    /// Half-edge count (3 per face; half-edge `3 f + k` runs from corner k of face f).
    halfedges: usize,
    /// Half-edges of edge e: `half[start[e]..start[e + 1]]` (face `h / 3`).
    start: Vec<u32>,
    half: Vec<u32>,
    ends: Vec<[u32; 2]>,
}

impl EdgeTable {
    /// Every index in `faces` must be below `vertex_count`.
    pub(crate) fn new(faces: &[[u32; 3]], vertex_count: usize) -> Self {
        let nh = faces.len() * 3;
        let mut bucket = vec![0u32; vertex_count + 1];
        for t in faces {
            for k in 0..3 {
                bucket[t[k].min(t[(k + 1) % 3]) as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            bucket[v + 1] += bucket[v];
        }
        // (higher endpoint, half-edge), grouped by lower endpoint.
        let mut entries = vec![(0u32, 0u32); nh];
        let mut fill = bucket.clone();
        for (f, t) in faces.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let lo = a.min(b) as usize;
                entries[fill[lo] as usize] = (a.max(b), (3 * f + k) as u32);
                fill[lo] += 1;
            }
        }
        drop(fill);
        // Edges number between nh / 2 and nh (boundary edges have one half-edge): sized for
        // the most, as pages never written cost nothing, where growing would copy.
        let mut start = Vec::with_capacity(nh + 1);
        let mut half = Vec::with_capacity(nh);
        let mut ends = Vec::with_capacity(nh);
        for v in 0..vertex_count {
            let group = &mut entries[bucket[v] as usize..bucket[v + 1] as usize];
            // Half-edges were filled in order, so this keeps face order within an edge.
            group.sort_unstable();
            for (k, &(hi, h)) in group.iter().enumerate() {
                if k == 0 || group[k - 1].0 != hi {
                    start.push(half.len() as u32);
                    ends.push([v as u32, hi]);
                }
                half.push(h);
            }
        }
        start.push(half.len() as u32);
        Self {
            halfedges: nh,
            start,
            half,
            ends,
        }
    }

    pub(crate) fn len(&self) -> usize {
        self.ends.len()
    }

    /// The half-edges on edge e, in face order (half-edge h belongs to face h / 3).
    pub(crate) fn halves(&self, e: usize) -> &[u32] {
        &self.half[self.start[e] as usize..self.start[e + 1] as usize]
    }

    /// For every half-edge, the other face of its edge when the edge has exactly two
    /// faces, else `u32::MAX`.
    pub(crate) fn manifold_neighbours(&self) -> Vec<u32> {
        let mut nbr = vec![u32::MAX; self.halfedges];
        for e in 0..self.len() {
            if let &[h, g] = self.halves(e) {
                nbr[h as usize] = g / 3;
                nbr[g as usize] = h / 3;
            }
        }
        nbr
    }

    /// Lower endpoint first.
    pub(crate) fn ends(&self, e: usize) -> [u32; 2] {
        self.ends[e]
    }
}
