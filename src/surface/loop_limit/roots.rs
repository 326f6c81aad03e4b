//! The root net of each control face: its 1-ring as weights over itself, listed in a
//! canonical order, and the face's patch from it (a box spline where the face is regular,
//! else what its quadtree is built from).

use super::net::{Net, VertexRule};
use super::patch::RegularPatch;
use super::reuse::Trees;
use super::{FacePatch, IrregularPatch, LoopLimitSurface};
use crate::mesh::topology::{Topology, NONE};
use rayon::prelude::*;

/// The face count of a root-net vertex with faces outside the net: more than any net
/// holds, which is all that its count is read for.
const PARTIAL_STAR: u32 = u32::MAX;

impl LoopLimitSurface {
    /// The patch of every face; irregular faces of one 1-ring shape share a quadtree, the
    /// previous surface's where it had that shape.
    pub(super) fn patches(
        topo: &Topology,
        crease_half: &[bool],
        previous: Option<&LoopLimitSurface>,
    ) -> Vec<FacePatch> {
        let built: Vec<Built> = (0..topo.triangles.len())
            .into_par_iter()
            .with_min_len(64)
            .map(|f| Self::face_patch(topo, crease_half, f))
            .collect();
        let mut trees = previous.map(Trees::of).unwrap_or_default();
        built
            .into_iter()
            .map(|b| match b {
                Built::Regular(p) => FacePatch::Regular(p),
                Built::Irregular { support, net, cap } => FacePatch::Irregular(IrregularPatch {
                    support,
                    tree: trees.tree(net),
                    cap,
                }),
            })
            .collect()
    }

    fn face_patch(topo: &Topology, crease_half: &[bool], f: usize) -> Built {
        let (support, net) = Self::face_net(topo, crease_half, f);
        Self::patch_of(support, net)
    }

    /// The root net of face `f` (its 1-ring, vertices as weights over themselves) and the
    /// original control index of each support column.
    fn face_net(topo: &Topology, crease_half: &[bool], f: usize) -> (Vec<u32>, Net) {
        let corners = topo.triangles[f];
        let mut support: Vec<u32> = corners.to_vec();
        // The order is canonical, a function of the 1-ring's shape alone (each corner's
        // faces taken from face f on, each face from its corner that came first), so that
        // faces of the same shape get the same root net and share its quadtree.
        let mut faces = vec![f];
        for &c in &corners {
            let ring = topo.ring_halfedges(c);
            let at = ring
                .iter()
                .position(|&h| h != NONE && (h / 3) as usize == f)
                .unwrap_or(0);
            for &h in ring[at..].iter().chain(&ring[..at]) {
                if h != NONE && !faces.contains(&((h / 3) as usize)) {
                    faces.push((h / 3) as usize);
                }
            }
        }
        let mut tris = Vec::with_capacity(faces.len());
        let mut bnd = Vec::with_capacity(faces.len());
        let mut crease = Vec::with_capacity(faces.len());
        for &g in &faces {
            let corners_of_g = topo.triangles[g];
            let first = (0..3)
                .min_by_key(|&k| {
                    support
                        .iter()
                        .position(|&s| s == corners_of_g[k])
                        .unwrap_or(usize::MAX)
                })
                .unwrap_or(0);
            let order = [first, (first + 1) % 3, (first + 2) % 3];
            let mut t = [0u32; 3];
            for (slot, &k) in t.iter_mut().zip(&order) {
                let v = corners_of_g[k];
                *slot = match support.iter().position(|&s| s == v) {
                    Some(i) => i as u32,
                    None => {
                        support.push(v);
                        (support.len() - 1) as u32
                    }
                };
            }
            tris.push(t);
            bnd.push(order.map(|k| topo.twin[3 * g + k] == NONE));
            crease.push(order.map(|k| crease_half[3 * g + k]));
        }
        let n = support.len();
        let mut base = vec![0.0; n];
        base[0] = 1.0;
        let mut rows = vec![0.0; n * n];
        for i in 1..n {
            rows[i * n + i] = 1.0;
            rows[i * n] = -1.0;
        }
        // A vertex's face count only tells whether its faces are all in the net (its
        // rules need them all, `Net::vertex_kind`); an outer vertex's exact count would
        // make shapes differ that subdivide alike.
        let mut in_net = vec![0u32; n];
        for t in &tris {
            for &v in t {
                in_net[v as usize] += 1;
            }
        }
        let faces_total = support
            .iter()
            .zip(&in_net)
            .map(|(&v, &held)| {
                let total = topo.face_valence[v as usize];
                if total == held {
                    total
                } else {
                    PARTIAL_STAR
                }
            })
            .collect();
        let net = Net {
            base,
            rows,
            nsup: n,
            tris,
            bnd,
            crease,
            faces_total,
        };
        (support, net)
    }

    /// The patch of a face from its root net (see `face_net`).
    fn patch_of(support: Vec<u32>, net: Net) -> Built {
        if let Some(st) = net.regular_stencil() {
            return Built::Regular(RegularPatch::new(&net, &st, true, |s| support[s as usize]));
        }
        // Deep enough that the node's image is below f64 resolution: near an interior
        // vertex of valence n the limit surface shrinks by the subdominant eigenvalue
        // 3/8 + cos(2 pi / n) / 4 per level (at most 5/8; 80 levels of 5/8 is 5e-17).
        // Near a boundary vertex the boundary curve shrinks by 1/2 per level; the
        // cross-boundary rate is not derived here, so those take the full 80 as margin
        // (the cap costs nothing unless a parameter is within 2^-cap of the vertex).
        let cap = (0..3u32)
            .filter_map(|v| net.vertex_rule(v))
            .map(|k| match k {
                VertexRule::Smooth { ring, dart: false } => {
                    let lambda =
                        0.375 + 0.25 * (2.0 * std::f64::consts::PI / ring.len() as f64).cos();
                    (-38.0 / lambda.ln()).ceil() as usize
                }
                _ => 80,
            })
            .max()
            .unwrap_or(80)
            .clamp(60, 80);
        Built::Irregular { support, net, cap }
    }
}

/// A face's patch before irregular faces of the same shape are given one quadtree.
enum Built {
    Regular(RegularPatch),
    Irregular {
        support: Vec<u32>,
        net: Net,
        /// See `IrregularPatch::cap`.
        cap: usize,
    },
}
