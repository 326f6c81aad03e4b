//! The exact Loop limit surface of an arbitrary manifold triangle control mesh (spec 01:
//! Loop's original beta, boundary odd point 1/2 (a + b), boundary even point
//! 3/4 v + 1/8 (a + b), corners fixed).
//!
//! The domain faces are the control faces; a parameter is (face, u, v) with u, v the
//! barycentric weights of the face's corners 0 and 1.
//!
//! Evaluation: a face whose three corners are regular (interior of valence 6, or boundary
//! with 3 faces) is a quartic box-spline patch of 12 stencil points, with ghost points
//! `v + a - b` beyond a boundary (the ghost extension commutes with Loop's boundary rules
//! on a straight regular boundary; the dyadic tests confirm it). Any other face is
//! subdivided locally: the 1-ring of the face gives the 1-ring of each child, and the
//! descent follows the child containing the parameter until the child is regular. Every
//! local vertex is kept as weights over the face's original 1-ring, so the final row is in
//! original control indices. The child nets are memoised per quadtree node
//! (`OnceLock`, so the surface is `Sync` and rows can be built from many threads), and
//! a quadtree is a function of its root net, which lists the 1-ring in a canonical order:
//! faces whose 1-rings have one shape share one quadtree (`reuse`), their leaves mapped
//! to each face's own controls.
//!
//! Only original vertices can be irregular (subdivision adds interior vertices of valence 6
//! and boundary vertices with 3 faces), so a descent goes deep only towards one of them:
//! a parameter exactly at an irregular vertex takes its limit-position mask directly
//! (derivatives there: see `IrregularPatch::vertex_rows`), and a descent that is still
//! irregular at the depth cap interpolates the exact limit positions of the node corners.
//!
//! Crease edges (Hoppe et al. 1994) are sharp like boundary edges: their odd points take
//! 1/2 (a + b), a vertex with two sharp edges 3/4 v + 1/8 (a + b) along them, one with
//! three or more is fixed, and a dart (one crease edge) keeps the smooth rule. Face by
//! face this is the boundary surface of the mesh cut open along its creases, so a face
//! whose corners are regular on its side of a crease is again a ghost-point box spline;
//! the local subdivision carries crease flags like boundary flags. A dart's limit mask is
//! not Loop's (its crease spoke takes the crease rule): it is found by iterating its
//! 1-ring's subdivision matrix.
//!
//! Derivatives follow the chain rule through each child's affine map (the middle child is
//! flipped). Node weights are kept as a base row plus differences, so derivatives near an
//! irregular vertex keep their relative precision although the map scales by 2^depth.

mod cached;
mod error;
mod net;
mod patch;
mod reuse;
mod roots;
mod sums;

pub use error::LoopLimitError;

use super::{BasisDerivRows, Derivatives, SurfaceParam, TriSurface};
use crate::mesh::topology::{Topology, NONE};
use glam::DVec3;
use net::{Net, Term, VertexRule};
use patch::{add_column, add_patch_rows, cap_rows, pick_child, Jac, RegularPatch};
use std::sync::OnceLock;
use sums::{restore_sum, restore_sums};

/// Child nets are memoised down to this depth; deeper ones (reached only within 2^-6 of
/// an irregular vertex) are computed on the fly so memory stays bounded. Every
/// memoised node lives as long as the surface, and the deep ones are nearly all visited
/// once (by a lattice sample or a foot point close to a vertex): at 40, CGAL's cheese.off
/// (8.6k vertices, genus 133, nearly every control irregular) peaked at 1.26 GB, at 6 at
/// 274 MB in the same time; bun_zipper and the 135k scan fit alike either way.
const MEMO_DEPTH: usize = 6;

/// Parameter offset (towards the face centre) at which derivatives are taken for a
/// parameter exactly at an irregular boundary vertex or corner. Small, because with many
/// faces the normal settles slowly (at 7 faces, 7e-3 rad between the two ends of the fan
/// at 1e-10); the descent keeps full relative precision at this depth (see `Net`).
const VERTEX_NUDGE: f64 = 1.0 / (1u64 << 40) as f64;

/// Parameters this close (in barycentric weight) to a boundary, crease or corner vertex
/// or a dart take the vertex's own rows, whose derivatives are those 2^-40 inside the
/// face anyway (`VERTEX_NUDGE`): otherwise each takes a descent of 36 levels or more, all
/// but 6 computed on the fly. Rim points on a control vertex and foot points sliding into
/// one land there every round (on a range scan's ragged rim, 2.3k such descents per fit).
/// The value moves by under 2^-36 of an edge.
const CORNER_SNAP: f64 = 1.0 / (1u64 << 36) as f64;

struct Node {
    net: Net,
    regular: Option<RegularPatch>,
    children: [OnceLock<Box<Node>>; 4],
}

impl Node {
    fn new(net: Net) -> Node {
        let regular = net
            .regular_stencil()
            .map(|st| RegularPatch::new(&net, &st, false, |s| s));
        Node {
            // A regular node is a leaf: only its patch is read again.
            net: if regular.is_some() {
                Net::default()
            } else {
                net
            },
            regular,
            children: Default::default(),
        }
    }

    fn child(&self, c: usize) -> &Node {
        self.children[c].get_or_init(|| Box::new(Node::new(self.net.child(c))))
    }
}

struct IrregularPatch {
    /// Original control index of each support column (the face's 1-ring).
    support: Vec<u32>,
    /// The quadtree of child nets, shared by every face of the same 1-ring shape (see
    /// `reuse`): it is a function of the root net alone, which is the identity over the
    /// support in the canonical order of `face_net`.
    tree: std::sync::Arc<Tree>,
    /// Depth at which the descent stops (see `cap_rows`).
    cap: usize,
}

/// A face's quadtree and what else is a function of its root net alone.
struct Tree {
    root: Node,
    /// Per corner, the rows at a boundary, crease or corner vertex or a dart
    /// (`vertex_rows`), found once: their derivatives take a descent to depth 40, 34
    /// levels of it below the memoised nodes, and the boundary curve's samples and the rim
    /// points clamped to an edge's end ask for the same corners in every round of every
    /// fit (kept with the tree, they outlive a refined surface, as the tree does).
    corner_rows: [OnceLock<Box<[[f64; 6]]>>; 3],
}

impl Tree {
    fn new(net: Net) -> Tree {
        Tree {
            root: Node::new(net),
            corner_rows: Default::default(),
        }
    }
}

enum FacePatch {
    Regular(RegularPatch),
    Irregular(IrregularPatch),
}

/// The Loop limit surface over the faces of a control mesh.
pub struct LoopLimitSurface {
    control_count: usize,
    topo: Topology,
    /// Crease edges as (low, high) control indices, sorted, each once.
    creases: Vec<[u32; 2]>,
    patches: Vec<FacePatch>,
}

impl std::fmt::Debug for LoopLimitSurface {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoopLimitSurface")
            .field("control_count", &self.control_count)
            .field("faces", &self.patches.len())
            .field("irregular_faces", &self.irregular_face_count())
            .field("crease_edges", &self.creases.len())
            .finish()
    }
}

impl LoopLimitSurface {
    /// Builds the surface of a manifold control mesh of `control_count` points.
    pub fn new(control_count: usize, faces: &[[u32; 3]]) -> Result<Self, LoopLimitError> {
        Self::with_creases(control_count, faces, &[])
    }

    /// Builds the surface with sharp edges: each crease edge (a pair of control indices, in
    /// either order; repeats and boundary edges, sharp anyway, are harmless) is subdivided
    /// with the boundary rules on both sides (Hoppe et al. 1994). A vertex with two sharp
    /// (crease or boundary) edges follows the cubic B-spline along them, one with more (or
    /// a boundary vertex with a crease) is a fixed corner, and one crease edge ending at a
    /// vertex (a dart) leaves it smooth.
    pub fn with_creases(
        control_count: usize,
        faces: &[[u32; 3]],
        crease_edges: &[[u32; 2]],
    ) -> Result<Self, LoopLimitError> {
        Self::build(control_count, faces, crease_edges, None)
    }

    /// [`Self::with_creases`], taking over the quadtrees of `previous` (with what its
    /// evaluations memoised) for faces whose 1-ring has the shape of one of its faces':
    /// a quadtree depends on nothing else, so the surface is the same as built afresh. A
    /// locally refined control mesh keeps most of its faces' 1-rings.
    pub fn with_creases_reusing(
        control_count: usize,
        faces: &[[u32; 3]],
        crease_edges: &[[u32; 2]],
        previous: &LoopLimitSurface,
    ) -> Result<Self, LoopLimitError> {
        Self::build(control_count, faces, crease_edges, Some(previous))
    }

    fn build(
        control_count: usize,
        faces: &[[u32; 3]],
        crease_edges: &[[u32; 2]],
        previous: Option<&LoopLimitSurface>,
    ) -> Result<Self, LoopLimitError> {
        if faces.is_empty() {
            return Err(LoopLimitError::NoFaces);
        }
        if u32::try_from(control_count).is_err() {
            return Err(LoopLimitError::TooManyControls {
                count: control_count,
            });
        }
        for (f, t) in faces.iter().enumerate() {
            if let Some(&index) = t.iter().find(|&&i| i as usize >= control_count) {
                return Err(LoopLimitError::IndexOutOfRange {
                    face: f,
                    index,
                    count: control_count,
                });
            }
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                return Err(LoopLimitError::DegenerateFace { face: f });
            }
        }
        let topo = Topology::build(control_count, faces).map_err(LoopLimitError::NonManifold)?;
        if let Some(vertex) = topo.face_valence.iter().position(|&n| n == 0) {
            return Err(LoopLimitError::IsolatedVertex { vertex });
        }
        let (creases, crease_half) = Self::crease_halfedges(&topo, crease_edges)?;
        let patches = Self::patches(&topo, &crease_half, previous);
        Ok(Self {
            control_count,
            topo,
            creases,
            patches,
        })
    }

    /// The interior crease edges (sorted, low index first) and a flag per half-edge.
    fn crease_halfedges(
        topo: &Topology,
        crease_edges: &[[u32; 2]],
    ) -> Result<(Vec<[u32; 2]>, Vec<bool>), LoopLimitError> {
        let mut half = vec![false; topo.twin.len()];
        let mut kept = Vec::with_capacity(crease_edges.len());
        for &[a, b] in crease_edges {
            let unknown = LoopLimitError::UnknownCreaseEdge { a, b };
            if a as usize >= topo.vertex_count || b as usize >= topo.vertex_count {
                return Err(unknown);
            }
            let h = topo
                .ring_halfedges(a)
                .iter()
                .copied()
                .find(|&h| {
                    h != NONE && topo.triangles[(h / 3) as usize][((h + 1) % 3) as usize] == b
                })
                .or_else(|| {
                    topo.ring_halfedges(b).iter().copied().find(|&h| {
                        h != NONE && topo.triangles[(h / 3) as usize][((h + 1) % 3) as usize] == a
                    })
                })
                .ok_or(unknown)?;
            let t = topo.twin[h as usize];
            if t == NONE {
                continue;
            }
            half[h as usize] = true;
            half[t as usize] = true;
            kept.push([a.min(b), a.max(b)]);
        }
        kept.sort_unstable();
        kept.dedup();
        Ok((kept, half))
    }

    /// The crease edges of the surface: interior edges, low control index first, sorted.
    pub fn crease_edges(&self) -> &[[u32; 2]] {
        &self.creases
    }

    /// The control faces (the domain faces), as given.
    pub fn faces(&self) -> &[[u32; 3]] {
        &self.topo.triangles
    }

    /// The control mesh's half-edge topology.
    pub fn topology(&self) -> &Topology {
        &self.topo
    }

    /// Whether a face is a single box-spline patch (all corners regular), evaluated
    /// without subdivision.
    pub fn is_regular_face(&self, face: usize) -> bool {
        matches!(self.patches.get(face), Some(FacePatch::Regular(_)))
    }

    /// Faces that are not a single box-spline patch.
    pub fn irregular_face_count(&self) -> usize {
        self.patches
            .iter()
            .filter(|p| matches!(p, FacePatch::Irregular(_)))
            .count()
    }
}

impl IrregularPatch {
    /// Rows over the support at the face parameter (u, v).
    fn rows(&self, u: f64, v: f64, acc: &mut [[f64; 6]]) {
        let corner = match (u, v) {
            (1.0, 0.0) => Some(0u32),
            (0.0, 1.0) => Some(1),
            (0.0, 0.0) => Some(2),
            _ => None,
        };
        let net = &self.tree.root.net;
        let at_vertex = |c: u32| {
            (!net.corner_is_regular(c))
                .then(|| net.vertex_rule(c).map(|k| (c, k)))
                .flatten()
        };
        let irregular = match corner {
            Some(c) => at_vertex(c),
            None => {
                let w = [u, v, 1.0 - u - v];
                (0..3u32)
                    .find(|&c| w[c as usize] > 1.0 - CORNER_SNAP)
                    .and_then(at_vertex)
                    .filter(|(_, k)| !matches!(k, VertexRule::Smooth { dart: false, .. }))
            }
        };
        match irregular {
            Some((c, k)) => {
                let (u, v) = [(1.0, 0.0), (0.0, 1.0), (0.0, 0.0)][c as usize];
                self.vertex_rows(c, &k, u, v, acc)
            }
            None => self.descend(u, v, acc),
        }
    }

    /// At an irregular vertex: the value is Loop's limit-position mask. For an interior
    /// vertex of valence n the parametric derivatives tend to 0 (n < 6) or grow without
    /// bound (n > 6); what is returned instead is the derivative along each face edge as
    /// Loop's tangent mask `2/n sum_m cos(2 pi (m - j) / n) r_m` (exact tangent plane, the
    /// box spline's values at n = 6), and zero second derivatives. At a boundary, crease or
    /// corner vertex, or a dart, the derivatives are those at a parameter 2^-40 towards the
    /// face centre.
    fn vertex_rows(&self, c: u32, kind: &VertexRule, u: f64, v: f64, acc: &mut [[f64; 6]]) {
        match kind {
            VertexRule::Smooth { ring, dart: false } => {
                let n = ring.len();
                // Derivative along the edge from c to its ring neighbour x.
                let along = |x: u32| -> Vec<Term> {
                    let j = ring.iter().position(|&r| r == x).unwrap_or(0);
                    ring.iter()
                        .enumerate()
                        .map(|(m, &r)| {
                            let ang = 2.0 * std::f64::consts::PI * (m as f64 - j as f64) / n as f64;
                            (r, 2.0 / n as f64 * ang.cos())
                        })
                        .collect()
                };
                // d/du moves along corner2 -> corner0, d/dv along corner2 -> corner1.
                let (du, dv): (Vec<Term>, Vec<Term>) = match c {
                    2 => (along(0), along(1)),
                    0 => {
                        let t2 = along(2);
                        let neg2: Vec<Term> = t2.iter().map(|&(r, w)| (r, -w)).collect();
                        (neg2.clone(), along(1).into_iter().chain(neg2).collect())
                    }
                    _ => {
                        let t2 = along(2);
                        let neg2: Vec<Term> = t2.iter().map(|&(r, w)| (r, -w)).collect();
                        (along(0).into_iter().chain(neg2.clone()).collect(), neg2)
                    }
                };
                for (col, terms) in [(1usize, &du), (2, &dv)] {
                    add_column(&self.tree.root.net, terms, col, acc);
                }
            }
            _ => {
                let rows = self.tree.corner_rows[c as usize].get_or_init(|| {
                    let mut rows = vec![[0.0; 6]; self.support.len()];
                    let d = VERTEX_NUDGE;
                    self.descend((1.0 - d) * u + d / 3.0, (1.0 - d) * v + d / 3.0, &mut rows);
                    for r in rows.iter_mut() {
                        *r = [0.0, r[1], r[2], 0.0, 0.0, 0.0];
                    }
                    rows.into_boxed_slice()
                });
                for (a, r) in acc.iter_mut().zip(rows.iter()) {
                    *a = *r;
                }
            }
        }
        add_column(
            &self.tree.root.net,
            &kind.limit_mask(c, &self.tree.root.net),
            0,
            acc,
        );
    }

    /// The memoised regular quadtree node holding face parameter (u, v), with the local
    /// parameter and the Jacobian of its map; `None` where `rows` takes another route (an
    /// irregular corner exactly, the depth cap, or below the memoised depth).
    fn leaf(&self, u: f64, v: f64) -> Option<(&RegularPatch, f64, f64, Jac)> {
        let at_corner = matches!((u, v), (1.0, 0.0) | (0.0, 1.0) | (0.0, 0.0));
        let (mut a, mut b) = (u, v);
        let mut jac = Jac::ID;
        let mut node: &Node = &self.tree.root;
        let mut depth = 0;
        loop {
            if let Some(rp) = &node.regular {
                return Some((rp, a, b, jac));
            }
            // Only the root can be regular at an irregular corner: it is not.
            if at_corner || depth == self.cap || depth == MEMO_DEPTH {
                return None;
            }
            let (c, na, nb, j) = pick_child(a, b);
            (a, b, jac) = (na, nb, jac.then(j));
            depth += 1;
            node = node.child(c);
        }
    }

    fn descend(&self, u: f64, v: f64, acc: &mut [[f64; 6]]) {
        let (mut a, mut b) = (u, v);
        let mut jac = Jac::ID;
        let mut node: &Node = &self.tree.root;
        let mut depth = 0;
        loop {
            if let Some(rp) = &node.regular {
                return add_patch_rows(rp, a, b, &jac, acc);
            }
            if depth == self.cap {
                return cap_rows(&node.net, a, b, &jac, acc);
            }
            let (c, na, nb, j) = pick_child(a, b);
            (a, b, jac) = (na, nb, jac.then(j));
            depth += 1;
            if depth > MEMO_DEPTH {
                return self.descend_unmemoised(node.net.child(c), a, b, jac, depth, acc);
            }
            node = node.child(c);
        }
    }

    fn descend_unmemoised(
        &self,
        mut net: Net,
        mut a: f64,
        mut b: f64,
        mut jac: Jac,
        mut depth: usize,
        acc: &mut [[f64; 6]],
    ) {
        loop {
            if let Some(st) = net.regular_stencil() {
                let rp = RegularPatch::new(&net, &st, false, |s| s);
                return add_patch_rows(&rp, a, b, &jac, acc);
            }
            if depth >= self.cap {
                return cap_rows(&net, a, b, &jac, acc);
            }
            let (c, na, nb, j) = pick_child(a, b);
            (a, b, jac) = (na, nb, jac.then(j));
            net = net.child(c);
            depth += 1;
        }
    }
}

impl LoopLimitSurface {
    /// The value column of the full rows (the route `basis_row` takes where no leaf
    /// patch answers).
    fn value_column(&self, p: SurfaceParam, out: &mut Vec<(u32, f64)>) {
        let mut rows = BasisDerivRows::default();
        self.basis_rows_with_derivatives(p, &mut rows);
        out.clear();
        out.extend(
            rows.indices
                .iter()
                .zip(&rows.weights)
                .map(|(&i, w)| (i, w[0])),
        );
    }
}

/// Clamps a parameter into the face.
fn clamp_param(u: f64, v: f64) -> (f64, f64) {
    let u = if u.is_finite() {
        u.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let v = if v.is_finite() {
        v.clamp(0.0, 1.0 - u)
    } else {
        0.0
    };
    (u, v)
}

impl TriSurface for LoopLimitSurface {
    fn control_count(&self) -> usize {
        self.control_count
    }

    fn domain_face_count(&self) -> usize {
        self.patches.len()
    }

    /// The value column alone: a regular patch's stencil values, without derivatives.
    fn basis_row(&self, p: SurfaceParam, out: &mut Vec<(u32, f64)>) {
        out.clear();
        let f = (p.face as usize).min(self.patches.len() - 1);
        let (u, v) = clamp_param(p.u, p.v);
        let mut acc = [0.0; 64];
        match &self.patches[f] {
            FacePatch::Regular(rp) if rp.cols.len() <= acc.len() => {
                let n = rp.cols.len();
                rp.add_values(u, v, &mut acc[..n]);
                out.extend(rp.cols.iter().copied().zip(acc[..n].iter().copied()));
            }
            FacePatch::Irregular(ip) => match ip.leaf(u, v) {
                Some((rp, a, b, _)) if rp.cols.len() <= acc.len() => {
                    let n = rp.cols.len();
                    rp.add_values(a, b, &mut acc[..n]);
                    restore_sum(&mut acc[..n], 1.0);
                    out.extend(
                        rp.cols
                            .iter()
                            .zip(&acc[..n])
                            .filter(|(_, &w)| w != 0.0)
                            .map(|(&c, &w)| (ip.support[c as usize], w)),
                    );
                }
                _ => self.value_column(p, out),
            },
            FacePatch::Regular(_) => self.value_column(p, out),
        }
    }

    /// Regular faces as Bezier ordinates of their controls, computed once; irregular faces
    /// by the memoised descent, the leaf's ordinates formed from the controls per call
    /// (rows only where `leaf` has no answer). Equal to `evaluate` to rounding.
    fn evaluator<'a>(
        &'a self,
        controls: &'a [DVec3],
    ) -> Box<dyn Fn(SurfaceParam) -> Derivatives + Sync + 'a> {
        let cached = cached::CachedEvaluator::new(self, controls);
        Box::new(move |p| cached.evaluate(p))
    }

    /// Out-of-range faces are clamped to the last face, parameters into the face.
    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows) {
        out.indices.clear();
        out.weights.clear();
        let f = (p.face as usize).min(self.patches.len() - 1);
        let (u, v) = clamp_param(p.u, p.v);
        match &self.patches[f] {
            FacePatch::Regular(rp) => {
                let mut acc = [[0.0; 6]; 64];
                let n = rp.cols.len().min(acc.len());
                rp.add_rows(u, v, &Jac::ID, &mut acc[..n]);
                out.indices.extend_from_slice(&rp.cols[..n]);
                out.weights.extend_from_slice(&acc[..n]);
            }
            FacePatch::Irregular(ip) => {
                let mut acc = vec![[0.0; 6]; ip.support.len()];
                ip.rows(u, v, &mut acc);
                restore_sums(&mut acc);
                for (s, w) in ip.support.iter().zip(&acc) {
                    if w.iter().any(|&x| x != 0.0) {
                        out.indices.push(*s);
                        out.weights.push(*w);
                    }
                }
            }
        }
    }

    /// Moves in the parameter plane by (du, dv), crossing into neighbouring faces through
    /// shared edges. The neighbour is unfolded onto the current face as in the regular
    /// lattice (its far corner at `a + b - c`), so the remaining barycentric deltas map
    /// linearly. At a boundary edge the motion across it is dropped and the rest slides
    /// along the edge.
    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam {
        let mut f = (p.face as usize).min(self.patches.len() - 1);
        let (u, v) = clamp_param(p.u, p.v);
        let mut bary = [u, v, 1.0 - u - v];
        let (du, dv) = (
            if du.is_finite() { du } else { 0.0 },
            if dv.is_finite() { dv } else { 0.0 },
        );
        let mut d = [du, dv, -du - dv];
        // Zero-length slides along boundary edges of one face in a row: at a corner between
        // two boundary edges with the step pointing out of both, each slide halves the
        // step and hands it to the other edge, so the point never moves again.
        let mut pinned = 0;
        // Each crossing enters a new face or removes a component at the boundary; the bound
        // only guards against a cycle through rounding at a vertex.
        for _ in 0..(4 * self.patches.len()).clamp(64, 100_000) {
            let mut t_exit = 1.0;
            let mut exit = None;
            for i in 0..3 {
                if d[i] < 0.0 {
                    let t = (bary[i] / -d[i]).max(0.0);
                    if t < t_exit {
                        t_exit = t;
                        exit = Some(i);
                    }
                }
            }
            let Some(i) = exit else {
                for k in 0..3 {
                    bary[k] += d[k];
                }
                break;
            };
            for k in 0..3 {
                bary[k] += t_exit * d[k];
                d[k] *= 1.0 - t_exit;
            }
            bary[i] = 0.0;
            let (j, k) = ((i + 1) % 3, (i + 2) % 3);
            let twin = self.topo.twin[3 * f + j];
            if twin == NONE {
                // After the second zero-length slide in a row the step points out of the
                // first edge again (half of a component pointing out): the point is pinned
                // and would only repeat this until the step underflows, about a thousand
                // rounds per foot-point trial at a rim corner (7 % of the merged bunny's
                // whole fit), ending where it is now.
                pinned = if t_exit == 0.0 { pinned + 1 } else { 0 };
                if pinned == 2 {
                    break;
                }
                d[j] += 0.5 * d[i];
                d[k] += 0.5 * d[i];
                d[i] = 0.0;
                continue;
            }
            pinned = 0;
            // Half-edge 3f + j runs corner j -> corner k; its twin runs k -> j in face g.
            let g = (twin / 3) as usize;
            let gk = (twin % 3) as usize;
            let (gj, go) = ((gk + 1) % 3, (gk + 2) % 3);
            let mut nb = [0.0; 3];
            let mut nd = [0.0; 3];
            nb[gj] = bary[j];
            nb[gk] = bary[k];
            nd[gj] = d[j] + d[i];
            nd[gk] = d[k] + d[i];
            nd[go] = -d[i];
            (f, bary, d) = (g, nb, nd);
        }
        let (u, v) = clamp_param(bary[0], bary[1]);
        SurfaceParam {
            face: f as u32,
            u,
            v,
        }
    }
}
