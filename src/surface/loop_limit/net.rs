//! The local control net of one quadtree node: the node's face and every face touching one
//! of its corners (the face's 1-ring), each vertex expressed as dense weights over the
//! support of the root face (the original control points of its 1-ring).
//!
//! Loop's rules at a vertex read only its 1-ring, and at an edge only its two faces, so
//! the 1-ring of a child face is computable from the 1-ring of the parent: the child's
//! vertices are even points of the parent corners and odd points of edges at those corners.

use crate::mesh::loop_subdiv::loop_beta;

/// Coefficient of one vertex of the net in a linear combination.
pub(super) type Term = (u32, f64);

/// Vertex weights are kept as the weights of vertex 0 (`base`) plus each vertex's
/// difference from them (`rows`): deep in the quadtree all vertices of a node have nearly
/// the same weights, and derivatives, which only see differences, would otherwise come out
/// of the cancellation of O(1) numbers scaled by 2^depth.
#[derive(Clone, Debug, Default)]
pub(super) struct Net {
    /// Weights of vertex 0 over the root support.
    pub base: Vec<f64>,
    /// Row-major `vertex count x nsup`: each vertex's weights minus `base`.
    pub rows: Vec<f64>,
    pub nsup: usize,
    /// Triangle 0 is the node face, its corners are vertices 0, 1, 2 in parameter order.
    pub tris: Vec<[u32; 3]>,
    /// Edge k of a triangle (corner k to corner k + 1) lies on the mesh boundary.
    pub bnd: Vec<[bool; 3]>,
    /// Edge k of a triangle is a crease edge (both triangles of the edge say so).
    pub crease: Vec<[bool; 3]>,
    /// Faces around each vertex in the whole mesh at this level where the net holds them
    /// all; more than the net holds (`PARTIAL_STAR` at the root) where it does not.
    pub faces_total: Vec<u32>,
}

/// What kind of vertex a (complete) net vertex is.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum VertexKind {
    /// Closed counter-clockwise ring.
    Interior(Vec<u32>),
    /// Counter-clockwise ring from one boundary neighbour to the other (faces + 1 entries).
    Boundary(Vec<u32>),
}

/// Which of the subdivision rules (Hoppe et al. 1994) moves a vertex, by the number of
/// sharp (boundary or crease) edges at it.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum VertexRule {
    /// No sharp edge, or one crease edge ending here (a dart): Loop's rule over the closed
    /// counter-clockwise ring.
    Smooth {
        /// The ring.
        ring: Vec<u32>,
        /// Whether one crease edge ends here.
        dart: bool,
    },
    /// Exactly two sharp edges, to these neighbours: the cubic B-spline rules along them.
    Crease(u32, u32),
    /// Three or more sharp edges, or a boundary vertex with one face: fixed.
    Corner,
}

impl VertexRule {
    /// Loop's limit-position mask. A dart's differs from the smooth mask (the odd point of
    /// its crease edge takes the crease rule), so it is the fixed point of the 1-ring's
    /// subdivision matrix, found by iterating it.
    pub(crate) fn limit_mask(&self, v: u32, net: &Net) -> Vec<Term> {
        match self {
            VertexRule::Smooth { ring, dart: false } => {
                let n = ring.len();
                let beta = loop_beta(n);
                let chi = 1.0 / (3.0 / (8.0 * beta) + n as f64);
                std::iter::once((v, 1.0 - n as f64 * chi))
                    .chain(ring.iter().map(|&j| (j, chi)))
                    .collect()
            }
            VertexRule::Smooth { ring, dart: true } => {
                let sharp: Vec<bool> = ring.iter().map(|&r| net.edge_is_crease(v, r)).collect();
                let w = dart_limit_weights(&sharp);
                std::iter::once(v)
                    .chain(ring.iter().copied())
                    .zip(w)
                    .collect()
            }
            VertexRule::Crease(a, b) => vec![(v, 2.0 / 3.0), (*a, 1.0 / 6.0), (*b, 1.0 / 6.0)],
            VertexRule::Corner => vec![(v, 1.0)],
        }
    }
}

/// The limit-position weights (centre first, then the ring) of a closed 1-ring whose
/// edges `sharp` take the crease rule: the row of the centre in S^k as k grows, S being
/// the 1-ring's subdivision matrix (Loop's even rule at the centre, odd rules on the
/// spokes). The subdominant eigenvalue of a dart is at most about 0.7, so 200 steps leave
/// nothing of it in f64.
pub(crate) fn dart_limit_weights(sharp: &[bool]) -> Vec<f64> {
    let n = sharp.len();
    let beta = loop_beta(n);
    let mut row = vec![0.0; n + 1];
    row[0] = 1.0;
    let mut next = vec![0.0; n + 1];
    for _ in 0..200 {
        // next = row * S: the centre's new weight spreads over the coarse vertices by the
        // even rule, each spoke's by its odd rule.
        next.iter_mut().for_each(|x| *x = 0.0);
        next[0] += row[0] * (1.0 - n as f64 * beta);
        for x in next[1..].iter_mut() {
            *x += row[0] * beta;
        }
        for (j, &s) in sharp.iter().enumerate() {
            let r = row[1 + j];
            if s {
                next[0] += 0.5 * r;
                next[1 + j] += 0.5 * r;
            } else {
                next[0] += 0.375 * r;
                next[1 + j] += 0.375 * r;
                next[1 + (j + 1) % n] += 0.125 * r;
                next[1 + (j + n - 1) % n] += 0.125 * r;
            }
        }
        std::mem::swap(&mut row, &mut next);
    }
    row
}

/// A vertex of the subdivided net: an even copy of a vertex, or the odd point of an edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fine {
    Even(u32),
    Odd(u32, u32),
}

fn odd(a: u32, b: u32) -> Fine {
    Fine::Odd(a.min(b), a.max(b))
}

impl Net {
    /// A vertex's weights minus those of vertex 0.
    pub(crate) fn diff(&self, v: u32) -> &[f64] {
        let s = v as usize * self.nsup;
        &self.rows[s..s + self.nsup]
    }

    /// Adds `w` times the differences (from vertex 0) of the combination `terms` to `acc`:
    /// the whole combination when its coefficients sum to 0, else all but the base part.
    pub(crate) fn add_diff(&self, terms: &[Term], w: f64, acc: &mut [f64]) {
        for &(v, c) in terms {
            if v == 0 {
                continue;
            }
            for (a, r) in acc.iter_mut().zip(self.diff(v)) {
                *a += w * c * r;
            }
        }
    }

    /// Ring and boundary status of a vertex whose faces are all in the net, or `None` if
    /// some are missing.
    pub(crate) fn vertex_kind(&self, v: u32) -> Option<VertexKind> {
        // Around v, a face (v, next, prev) goes counter-clockwise from next to prev.
        let mut links: Vec<(u32, u32)> = Vec::with_capacity(8);
        for t in &self.tris {
            if let Some(k) = t.iter().position(|&x| x == v) {
                links.push((t[(k + 1) % 3], t[(k + 2) % 3]));
            }
        }
        if links.is_empty() || links.len() != self.faces_total[v as usize] as usize {
            return None;
        }
        let start = links
            .iter()
            .position(|&(n, _)| !links.iter().any(|&(_, p)| p == n));
        let interior = start.is_none();
        let mut cur = links[start.unwrap_or(0)];
        let mut ring = Vec::with_capacity(links.len() + 1);
        ring.push(cur.0);
        for _ in 1..links.len() {
            ring.push(cur.1);
            cur = *links.iter().find(|&&(n, _)| n == cur.1)?;
        }
        if interior {
            if cur.1 != ring[0] {
                return None;
            }
            Some(VertexKind::Interior(ring))
        } else {
            ring.push(cur.1);
            Some(VertexKind::Boundary(ring))
        }
    }

    /// Triangles holding edge (a, b), with the vertex opposite it in each.
    fn edge_faces(&self, a: u32, b: u32) -> ([(usize, u32); 2], usize) {
        let mut out = [(0usize, 0u32); 2];
        let mut n = 0;
        for (t, tri) in self.tris.iter().enumerate() {
            if tri.contains(&a) && tri.contains(&b) && n < 2 {
                let o = tri.iter().copied().find(|&x| x != a && x != b).unwrap_or(a);
                out[n] = (t, o);
                n += 1;
            }
        }
        (out, n)
    }

    fn edge_is_boundary(&self, a: u32, b: u32) -> bool {
        self.tris.iter().zip(&self.bnd).any(|(t, f)| {
            (0..3).any(|k| {
                let (x, y) = (t[k], t[(k + 1) % 3]);
                f[k] && ((x == a && y == b) || (x == b && y == a))
            })
        })
    }

    /// Whether edge (a, b) is a crease edge.
    pub(crate) fn edge_is_crease(&self, a: u32, b: u32) -> bool {
        self.tris.iter().zip(&self.crease).any(|(t, f)| {
            (0..3).any(|k| {
                let (x, y) = (t[k], t[(k + 1) % 3]);
                f[k] && ((x == a && y == b) || (x == b && y == a))
            })
        })
    }

    /// The rule of a vertex whose faces are all in the net (`None` otherwise).
    pub(crate) fn vertex_rule(&self, v: u32) -> Option<VertexRule> {
        Some(match self.vertex_kind(v)? {
            VertexKind::Interior(ring) => {
                let creases = ring.iter().filter(|&&r| self.edge_is_crease(v, r)).count();
                match creases {
                    0 | 1 => VertexRule::Smooth {
                        dart: creases == 1,
                        ring,
                    },
                    2 => {
                        let mut ends = ring.iter().filter(|&&r| self.edge_is_crease(v, r));
                        let (a, b) = (*ends.next()?, *ends.next()?);
                        VertexRule::Crease(a, b)
                    }
                    _ => VertexRule::Corner,
                }
            }
            VertexKind::Boundary(ring) => {
                let inner = &ring[1..ring.len() - 1];
                if ring.len() == 2 || inner.iter().any(|&r| self.edge_is_crease(v, r)) {
                    VertexRule::Corner
                } else {
                    VertexRule::Crease(ring[0], ring[ring.len() - 1])
                }
            }
        })
    }

    /// The ring of corner `v` of the node face within its sector: counter-clockwise from
    /// one sharp edge to the next, through the node face (the whole ring of a boundary
    /// vertex without creases). `None` unless `v` has two sharp edges.
    fn sector(&self, v: u32) -> Option<Vec<u32>> {
        let t = self.tris[0];
        let k = t.iter().position(|&x| x == v)?;
        let (next, prev) = (t[(k + 1) % 3], t[(k + 2) % 3]);
        let ring = match self.vertex_kind(v)? {
            VertexKind::Interior(r) | VertexKind::Boundary(r) => r,
        };
        let n = ring.len();
        let sharp = |r: u32| self.edge_is_crease(v, r) || self.edge_is_boundary(v, r);
        let i = ring.iter().position(|&r| r == next)?;
        if ring[(i + 1) % n] != prev {
            return None;
        }
        let mut from = i;
        let mut steps = 0;
        while !sharp(ring[from]) {
            from = (from + n - 1) % n;
            steps += 1;
            if steps > n {
                return None;
            }
        }
        let mut out = vec![ring[from]];
        let mut at = from;
        loop {
            at = (at + 1) % n;
            out.push(ring[at]);
            if sharp(ring[at]) || out.len() > n {
                break;
            }
        }
        Some(out)
    }

    /// Whether corner `v` of the node face is regular for it: smooth of valence 6 with no
    /// crease, or a crease vertex with 3 faces on the node face's side (where the box
    /// spline with ghost points is exact, as at a regular boundary).
    pub(crate) fn corner_is_regular(&self, v: u32) -> bool {
        match self.vertex_rule(v) {
            Some(VertexRule::Smooth { ring, dart }) => !dart && ring.len() == 6,
            Some(VertexRule::Crease(..)) => self.sector(v).is_some_and(|s| s.len() == 4),
            _ => false,
        }
    }

    /// The subdivision rule producing a fine vertex, as terms over this net.
    fn rule(&self, f: Fine) -> Vec<Term> {
        match f {
            Fine::Even(v) => match self
                .vertex_rule(v)
                .expect("even points are only needed at node corners, whose rings are complete")
            {
                VertexRule::Smooth { ring, .. } => {
                    let beta = loop_beta(ring.len());
                    std::iter::once((v, 1.0 - ring.len() as f64 * beta))
                        .chain(ring.iter().map(|&j| (j, beta)))
                        .collect()
                }
                VertexRule::Crease(a, b) => vec![(v, 0.75), (a, 0.125), (b, 0.125)],
                VertexRule::Corner => vec![(v, 1.0)],
            },
            Fine::Odd(a, b) => {
                let (faces, n) = self.edge_faces(a, b);
                if n == 2 && !self.edge_is_crease(a, b) {
                    vec![
                        (a, 0.375),
                        (b, 0.375),
                        (faces[0].1, 0.125),
                        (faces[1].1, 0.125),
                    ]
                } else {
                    debug_assert!(
                        n == 2 || self.edge_is_boundary(a, b),
                        "odd points are only needed on edges at node corners, whose faces are all present"
                    );
                    vec![(a, 0.5), (b, 0.5)]
                }
            }
        }
    }

    /// The net of child `c` of the node face (0..3 at corners 0, 1, 2; 3 in the middle,
    /// corners (m01, m12, m20)).
    pub fn child(&self, c: usize) -> Net {
        // A child's edge lies on a parent edge (and is sharp like it) or inside the face.
        let halves = |b: &[bool; 3]| -> [[bool; 3]; 4] {
            [
                [b[0], false, b[2]],
                [b[1], false, b[0]],
                [b[2], false, b[1]],
                [false; 3],
            ]
        };
        let children = |t: &[u32; 3]| -> [[Fine; 3]; 4] {
            let (m0, m1, m2) = (odd(t[0], t[1]), odd(t[1], t[2]), odd(t[2], t[0]));
            let e = Fine::Even;
            [
                [e(t[0]), m0, m2],
                [e(t[1]), m1, m0],
                [e(t[2]), m2, m1],
                [m0, m1, m2],
            ]
        };
        let target = children(&self.tris[0])[c];
        let mut verts: Vec<Fine> = target.to_vec();
        let mut tris = vec![[0u32, 1, 2]];
        let mut bnd = vec![halves(&self.bnd[0])[c]];
        let mut crease = vec![halves(&self.crease[0])[c]];
        let id = |f: Fine, verts: &mut Vec<Fine>| -> u32 {
            match verts.iter().position(|&x| x == f) {
                Some(i) => i as u32,
                None => {
                    verts.push(f);
                    (verts.len() - 1) as u32
                }
            }
        };
        for ((t, b), cr) in self.tris.iter().zip(&self.bnd).zip(&self.crease) {
            for ((ft, fb), fc) in children(t).into_iter().zip(halves(b)).zip(halves(cr)) {
                if ft == target || !ft.iter().any(|x| target.contains(x)) {
                    continue;
                }
                let tri = [
                    id(ft[0], &mut verts),
                    id(ft[1], &mut verts),
                    id(ft[2], &mut verts),
                ];
                tris.push(tri);
                bnd.push(fb);
                crease.push(fc);
            }
        }
        let nsup = self.nsup;
        let rules: Vec<Vec<Term>> = verts.iter().map(|&f| self.rule(f)).collect();
        // The new base is fine vertex 0; every rule sums to 1, so a fine vertex's difference
        // from it is its rule minus vertex 0's rule applied to the old differences.
        let mut base = self.base.clone();
        self.add_diff(&rules[0], 1.0, &mut base);
        let mut rows = vec![0.0; verts.len() * nsup];
        let mut faces_total = Vec::with_capacity(verts.len());
        for (i, &f) in verts.iter().enumerate() {
            if i > 0 {
                let row = &mut rows[i * nsup..(i + 1) * nsup];
                self.add_diff(&rules[i], 1.0, row);
                self.add_diff(&rules[0], -1.0, row);
            }
            faces_total.push(match f {
                Fine::Even(v) => self.faces_total[v as usize],
                Fine::Odd(a, b) if self.edge_faces(a, b).1 == 2 => 6,
                // A boundary edge's odd point lies in three of its face's children.
                Fine::Odd(..) => 3,
            });
        }
        Net {
            base,
            rows,
            nsup,
            tris,
            bnd,
            crease,
            faces_total,
        }
    }

    /// The 12 box-spline stencil points of the node face, if the face is regular: every
    /// corner regular for it (`corner_is_regular`), and two crease or boundary corners
    /// joined by a sharp edge. Points beyond a sharp edge are ghosts `v + a - b`
    /// continuing the lattice (a crease or boundary vertex's missing ring slots are the
    /// reflections of its inner neighbours); a dyadic test checks this is exact. Across a
    /// crease this is the boundary patch of the mesh cut open along it, which subdivides
    /// by the same rules on the node face's side.
    pub(crate) fn regular_stencil(&self) -> Option<Vec<Vec<Term>>> {
        let mut rings: Vec<Vec<Vec<Term>>> = Vec::with_capacity(3);
        let mut sided = [false; 3];
        for v in 0..3u32 {
            if !self.corner_is_regular(v) {
                return None;
            }
            let full: Vec<Vec<Term>> = match self.vertex_rule(v)? {
                VertexRule::Smooth { ring, .. } => ring.iter().map(|&x| vec![(x, 1.0)]).collect(),
                _ => {
                    let r = self.sector(v)?;
                    sided[v as usize] = true;
                    let mut s: Vec<Vec<Term>> = r.iter().map(|&x| vec![(x, 1.0)]).collect();
                    s.push(vec![(v, 1.0), (r[3], 1.0), (r[2], -1.0)]);
                    s.push(vec![(v, 1.0), (r[0], 1.0), (r[1], -1.0)]);
                    s
                }
            };
            rings.push(full);
        }
        for k in 0..3 {
            let sharp = self.bnd[0][k] || self.crease[0][k];
            if sided[k] && sided[(k + 1) % 3] && !sharp {
                return None;
            }
        }
        // Six ring slots of each corner, counter-clockwise from a given neighbour.
        let ring6 = |v: u32, start: u32| -> Option<Vec<Vec<Term>>> {
            let full = &rings[v as usize];
            let at = full.iter().position(|s| s.as_slice() == [(start, 1.0)])?;
            Some((0..6).map(|i| full[(at + i) % 6].clone()).collect())
        };
        // Lattice: corner 2 at (0, 0), corner 0 at (1, 0), corner 1 at (0, 1).
        let r2 = ring6(2, 0)?;
        let r0 = ring6(0, 1)?;
        let r1 = ring6(1, 2)?;
        let one = |v: u32| vec![(v, 1.0)];
        Some(vec![
            one(2),
            one(0),
            one(1),
            r2[2].clone(), // (-1, 1)
            r2[3].clone(), // (-1, 0)
            r2[4].clone(), // (0, -1)
            r2[5].clone(), // (1, -1)
            r0[4].clone(), // (2, 0)
            r0[5].clone(), // (1, 1)
            r0[3].clone(), // (2, -1)
            r1[3].clone(), // (0, 2)
            r1[4].clone(), // (-1, 2)
        ])
    }
}
