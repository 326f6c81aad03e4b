//! Detection of Loop subdivision connectivity (after Taubin 2002): tag vertices even/odd
//! from a seed, check consistency, recover the coarse faces. Linear time per level.

use super::topology::{next, Topology, TopologyError, NONE};

/// Why a mesh is not read as a Loop subdivision (levels count from the finest, 0).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DetectError {
    /// The mesh at this level is not a manifold triangle mesh.
    #[error("level {level}: {source}")]
    Topology {
        /// Subdivision level being read.
        level: usize,
        /// What is wrong with the connectivity.
        #[source]
        source: TopologyError,
    },
    /// The connectivity is not a 1-to-4 split of any coarser mesh.
    #[error("level {level}: no subdivision connectivity around vertex {vertex}: {reason}")]
    NotSubdivided {
        /// Subdivision level being read.
        level: usize,
        /// A fine vertex where the pattern breaks.
        vertex: u32,
        /// How it breaks.
        reason: String,
    },
}

impl DetectError {
    /// A stable snake_case name of the variant, for machine-readable reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Topology { .. } => "topology",
            Self::NotSubdivided { .. } => "not_subdivided",
        }
    }
}

/// One level of recovered structure: a fine mesh seen as the 1-to-4 split of `coarse`.
#[derive(Debug, Clone)]
pub struct Level {
    /// Coarse faces, indices into the coarse vertex list.
    pub coarse_triangles: Vec<[u32; 3]>,
    /// Coarse vertex -> fine (even) vertex, in increasing fine index.
    pub coarse_to_fine: Vec<u32>,
    /// Fine vertex -> coarse vertex for even vertices, `NONE` for odd ones.
    pub fine_to_coarse: Vec<u32>,
    /// Fine vertex -> the two coarse endpoints of its edge (odd vertices only).
    pub odd_endpoints: Vec<[u32; 2]>,
    /// Fine face -> (coarse face, barycentric weights of its three corners in that face).
    pub face_parent: Vec<(u32, [[f64; 3]; 3])>,
}

const UNKNOWN: u8 = 0;
const EVEN: u8 = 1;
const ODD: u8 = 2;

fn fail(level: usize, vertex: u32, reason: impl Into<String>) -> DetectError {
    DetectError::NotSubdivided {
        level,
        vertex,
        reason: reason.into(),
    }
}

/// Tries to read the fine mesh `topo` as one Loop subdivision step; `level` only labels errors.
pub fn detect_level(topo: &Topology, level: usize) -> Result<Level, DetectError> {
    let label = even_odd_labels(topo, level)?;
    let (fine_to_coarse, coarse_to_fine) = coarse_numbering(&label);
    let odd_endpoints = odd_edge_endpoints(topo, &label, &fine_to_coarse, level)?;
    let numbering = Numbering {
        fine_to_coarse: &fine_to_coarse,
        odd_endpoints: &odd_endpoints,
    };
    let (coarse_triangles, face_parent) = coarse_faces(topo, &coarse_to_fine, numbering, level)?;
    Ok(Level {
        coarse_triangles,
        coarse_to_fine,
        fine_to_coarse,
        odd_endpoints,
        face_parent,
    })
}

/// EVEN or ODD for every vertex. Vertices are grouped into components by the propagation
/// itself: each unlabelled vertex starts a new component whose seed candidates are tried
/// in turn.
fn even_odd_labels(topo: &Topology, level: usize) -> Result<Vec<u8>, DetectError> {
    let nv = topo.vertex_count;
    let mut label = vec![UNKNOWN; nv];
    let mut component_done = vec![false; nv];
    for start in 0..nv as u32 {
        if component_done[start as usize] || topo.ring(start).is_empty() {
            continue;
        }
        let comp = component_of(topo, start, &mut component_done);
        let candidates = seed_candidates(topo, &comp);
        let mut last_err = None;
        let mut ok = false;
        for seed in candidates {
            match propagate(topo, &comp, seed, level, &mut label) {
                Ok(()) => {
                    ok = true;
                    break;
                }
                Err(e) => {
                    for &v in &comp {
                        label[v as usize] = UNKNOWN;
                    }
                    last_err = Some(e);
                }
            }
        }
        if !ok {
            return Err(
                last_err.unwrap_or_else(|| fail(level, start, "no seed vertex to start from"))
            );
        }
    }
    // Isolated vertices carry no structure: treat them as even so that they survive.
    for l in label.iter_mut() {
        if *l == UNKNOWN {
            *l = EVEN;
        }
    }
    Ok(label)
}

/// Even vertices numbered as coarse vertices in increasing fine index:
/// (fine -> coarse or NONE, coarse -> fine).
fn coarse_numbering(label: &[u8]) -> (Vec<u32>, Vec<u32>) {
    let mut fine_to_coarse = vec![NONE; label.len()];
    let mut coarse_to_fine = Vec::new();
    for (v, &l) in label.iter().enumerate() {
        if l == EVEN {
            fine_to_coarse[v] = coarse_to_fine.len() as u32;
            coarse_to_fine.push(v as u32);
        }
    }
    (fine_to_coarse, coarse_to_fine)
}

/// For every odd vertex, the coarse endpoints of the edge it splits (its two even
/// neighbours); `[NONE, NONE]` for even vertices.
fn odd_edge_endpoints(
    topo: &Topology,
    label: &[u8],
    fine_to_coarse: &[u32],
    level: usize,
) -> Result<Vec<[u32; 2]>, DetectError> {
    let mut odd_endpoints = vec![[NONE, NONE]; label.len()];
    for (v, ends) in odd_endpoints.iter_mut().enumerate() {
        if label[v] != ODD {
            continue;
        }
        let mut evens = [NONE; 2];
        let mut count = 0;
        for &w in topo.ring(v as u32) {
            if label[w as usize] == EVEN {
                if count < 2 {
                    evens[count] = w;
                }
                count += 1;
            }
        }
        if count != 2 {
            return Err(fail(
                level,
                v as u32,
                format!("odd vertex has {count} even neighbours, not 2"),
            ));
        }
        *ends = [
            fine_to_coarse[evens[0] as usize],
            fine_to_coarse[evens[1] as usize],
        ];
    }
    Ok(odd_endpoints)
}

/// The fine-to-coarse maps the face recovery reads.
#[derive(Clone, Copy)]
struct Numbering<'a> {
    fine_to_coarse: &'a [u32],
    odd_endpoints: &'a [[u32; 2]],
}

impl Numbering<'_> {
    /// The coarse vertex at the other end of odd vertex `m`'s edge, seen from even `a`.
    fn far(&self, a: u32, m: u32) -> u32 {
        let [p, q] = self.odd_endpoints[m as usize];
        if p == self.fine_to_coarse[a as usize] {
            q
        } else {
            p
        }
    }

    /// Barycentric coordinates of fine vertex `v` in coarse face `face`: a corner, or the
    /// midpoint of an edge. None when `v` is not on the face.
    fn barycentric(&self, v: u32, face: [u32; 3]) -> Option<[f64; 3]> {
        let c = self.fine_to_coarse[v as usize];
        if c != NONE {
            return face.iter().position(|&x| x == c).map(|i| {
                let mut b = [0.0; 3];
                b[i] = 1.0;
                b
            });
        }
        let [p, q] = self.odd_endpoints[v as usize];
        let i = face.iter().position(|&x| x == p)?;
        let j = face.iter().position(|&x| x == q)?;
        let mut b = [0.0; 3];
        b[i] = 0.5;
        b[j] = 0.5;
        Some(b)
    }
}

/// Coarse faces, each found once from its lowest-numbered corner, with every fine face's
/// parent and corner weights; fails unless the fine faces are exactly four per coarse face.
#[allow(clippy::type_complexity)]
fn coarse_faces(
    topo: &Topology,
    coarse_to_fine: &[u32],
    numbering: Numbering,
    level: usize,
) -> Result<(Vec<[u32; 3]>, Vec<(u32, [[f64; 3]; 3])>), DetectError> {
    let fine_to_coarse = numbering.fine_to_coarse;
    let mut coarse_triangles = Vec::new();
    let mut face_parent = vec![(NONE, [[0.0; 3]; 3]); topo.triangles.len()];
    for &a in coarse_to_fine {
        let ring = topo.ring(a);
        let hs = topo.ring_halfedges(a);
        for k in 0..hs.len() {
            let h = hs[k];
            if h == NONE {
                continue;
            }
            let m1 = ring[k];
            let m2 = ring[(k + 1) % ring.len()];
            let ca = fine_to_coarse[a as usize];
            let (cb, cc) = (numbering.far(a, m1), numbering.far(a, m2));
            if ca > cb || ca > cc {
                continue;
            }
            let d = coarse_triangles.len() as u32;
            coarse_triangles.push([ca, cb, cc]);
            for f in four_children(topo, h, a, m1, level)? {
                let tri = topo.triangles[f as usize];
                let mut corners = [[0.0; 3]; 3];
                for (slot, &v) in corners.iter_mut().zip(tri.iter()) {
                    *slot = numbering
                        .barycentric(v, [ca, cb, cc])
                        .ok_or_else(|| fail(level, v, "fine face leaves its coarse face"))?;
                }
                if face_parent[f as usize].0 != NONE {
                    return Err(fail(level, tri[0], "fine face belongs to two coarse faces"));
                }
                face_parent[f as usize] = (d, corners);
            }
        }
    }
    if coarse_triangles.len() * 4 != topo.triangles.len() {
        let v = face_parent
            .iter()
            .position(|p| p.0 == NONE)
            .map_or(0, |f| topo.triangles[f][0]);
        return Err(fail(
            level,
            v,
            format!(
                "{} fine faces do not make {} coarse faces",
                topo.triangles.len(),
                coarse_triangles.len()
            ),
        ));
    }
    Ok((coarse_triangles, face_parent))
}

/// The four fine faces of the coarse face at even vertex `a` whose corner face holds
/// half-edge `h` (from `a` to odd `m1`): the corner face at a, the central face across
/// (m1, m2), and the corner faces across the central face's other two edges.
fn four_children(
    topo: &Topology,
    h: u32,
    a: u32,
    m1: u32,
    level: usize,
) -> Result<[u32; 4], DetectError> {
    let corner_a = h / 3;
    let h_mid = next(h); // m1 -> m2 in the corner face
    let t = topo.twin[h_mid as usize];
    if t == NONE {
        return Err(fail(
            level,
            m1,
            "central face of a split triangle is missing",
        ));
    }
    let central = t / 3;
    let mut children = [corner_a, central, NONE, NONE];
    let mut count = 2;
    for e in 0..3u32 {
        let tw = topo.twin[(central * 3 + e) as usize];
        if tw != NONE && tw / 3 != corner_a && count < 4 {
            children[count] = tw / 3;
            count += 1;
        }
    }
    if count != 4 {
        return Err(fail(
            level,
            a,
            "a coarse face does not split into four fine faces",
        ));
    }
    Ok(children)
}

/// Vertices of the component of `start`, marking them in `seen`.
fn component_of(topo: &Topology, start: u32, seen: &mut [bool]) -> Vec<u32> {
    let mut stack = vec![start];
    seen[start as usize] = true;
    let mut out = Vec::new();
    while let Some(v) = stack.pop() {
        out.push(v);
        for &w in topo.ring(v) {
            if !seen[w as usize] {
                seen[w as usize] = true;
                stack.push(w);
            }
        }
    }
    out
}

/// Odd vertices always have 6 neighbours (4 on the boundary), so any other valence marks
/// an even vertex. In a fully regular component, one of the three corners of any face is
/// even unless that face is a central one: trying a vertex and its whole ring suffices.
fn seed_candidates(topo: &Topology, comp: &[u32]) -> Vec<u32> {
    if let Some(&v) = comp.iter().find(|&&v| {
        let n = topo.valence(v);
        if topo.is_boundary(v) {
            n != 4
        } else {
            n != 6
        }
    }) {
        return vec![v];
    }
    let v = comp[0];
    std::iter::once(v)
        .chain(topo.ring(v).iter().copied())
        .collect()
}

fn propagate(
    topo: &Topology,
    comp: &[u32],
    seed: u32,
    level: usize,
    label: &mut [u8],
) -> Result<(), DetectError> {
    let mut queue = std::collections::VecDeque::new();
    label[seed as usize] = EVEN;
    queue.push_back(seed);
    while let Some(e) = queue.pop_front() {
        for &m in topo.ring(e) {
            match label[m as usize] {
                EVEN => return Err(fail(level, m, "two even vertices are adjacent")),
                UNKNOWN => label[m as usize] = ODD,
                _ => {}
            }
            let ring = topo.ring(m);
            let opposite = if topo.is_boundary(m) {
                if ring.len() != 4 {
                    return Err(fail(
                        level,
                        m,
                        format!("boundary odd vertex has {} neighbours, not 4", ring.len()),
                    ));
                }
                if ring[0] == e {
                    ring[3]
                } else if ring[3] == e {
                    ring[0]
                } else {
                    return Err(fail(
                        level,
                        m,
                        "even neighbour of a boundary odd vertex is not on the boundary",
                    ));
                }
            } else {
                if ring.len() != 6 {
                    return Err(fail(
                        level,
                        m,
                        format!("interior odd vertex has valence {}, not 6", ring.len()),
                    ));
                }
                let k = ring.iter().position(|&x| x == e).unwrap_or(0);
                ring[(k + 3) % 6]
            };
            match label[opposite as usize] {
                ODD => return Err(fail(level, opposite, "vertex must be both even and odd")),
                UNKNOWN => {
                    label[opposite as usize] = EVEN;
                    queue.push_back(opposite);
                }
                _ => {}
            }
        }
    }
    if let Some(&v) = comp.iter().find(|&&v| label[v as usize] == UNKNOWN) {
        return Err(fail(level, v, "vertex not reached by the even/odd tagging"));
    }
    Ok(())
}

/// A hierarchy of `levels.len()` detected levels, finest first.
#[derive(Debug, Clone)]
pub struct Hierarchy {
    /// The levels, finest first.
    pub levels: Vec<Level>,
}

impl Hierarchy {
    /// Detects up to `max_levels` levels, stopping at the first failure; the error of that
    /// failure is returned beside the hierarchy found so far.
    pub fn detect(fine: &Topology, max_levels: usize) -> (Hierarchy, Option<DetectError>) {
        let mut levels = Vec::new();
        let mut current = fine.clone();
        for level in 1..=max_levels {
            let lvl = match detect_level(&current, level) {
                Ok(l) => l,
                Err(e) => return (Hierarchy { levels }, Some(e)),
            };
            let next_topo = match Topology::build(lvl.coarse_to_fine.len(), &lvl.coarse_triangles) {
                Ok(t) => t,
                Err(source) => {
                    return (
                        Hierarchy { levels },
                        Some(DetectError::Topology { level, source }),
                    )
                }
            };
            levels.push(lvl);
            current = next_topo;
        }
        (Hierarchy { levels }, None)
    }

    /// Number of levels found.
    pub fn depth(&self) -> usize {
        self.levels.len()
    }

    /// Location of every finest vertex on the coarsest mesh: (coarse face, u, v) with
    /// barycentric weights (u, v, 1 - u - v) for the face's corners 0, 1, 2. With no level
    /// the coarsest mesh is the fine one, and each vertex sits at a corner of one of its
    /// own faces.
    pub fn fine_vertex_params(&self, fine: &Topology) -> Vec<(u32, f64, f64)> {
        const OWN_CORNERS: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let mut out = vec![(NONE, 0.0, 0.0); fine.vertex_count];
        for (f, tri) in fine.triangles.iter().enumerate() {
            // Corner weights of this face in the coarsest face, composing the parents.
            let (mut face, mut corners) = (f as u32, OWN_CORNERS);
            for lvl in &self.levels {
                let (pf, pc) = lvl.face_parent[face as usize];
                let mut composed = [[0.0; 3]; 3];
                for (c, row) in corners.iter().enumerate() {
                    for (k, w) in row.iter().enumerate() {
                        for j in 0..3 {
                            composed[c][j] += w * pc[k][j];
                        }
                    }
                }
                face = pf;
                corners = composed;
            }
            for (c, &v) in tri.iter().enumerate() {
                if out[v as usize].0 == NONE {
                    out[v as usize] = (face, corners[c][0], corners[c][1]);
                }
            }
        }
        out
    }

    /// Fine index of every coarsest vertex.
    pub fn coarsest_to_fine(&self) -> Vec<u32> {
        let mut map: Vec<u32> = match self.levels.last() {
            Some(l) => l.coarse_to_fine.clone(),
            None => return Vec::new(),
        };
        for lvl in self.levels.iter().rev().skip(1) {
            for m in map.iter_mut() {
                *m = lvl.coarse_to_fine[*m as usize];
            }
        }
        map
    }
}
