//! Crease edges through the simplification, treated like boundary edges: constraint
//! planes (perpendicular to each of the edge's two faces, through the edge) keep a merged
//! vertex on the crease line, collapses run only along a crease chain, an edge joining two
//! sharp vertices off a chain is never collapsed (it would pinch the crease onto itself or
//! onto another), and crease corners (three or more crease edges, a crease meeting the
//! boundary, a chain's end, a sharp turn along a chain) stay where they are.

use super::super::topology::{Topology, NONE};
use super::quadric::Quadric;
use glam::DVec3;

pub(super) struct Creases {
    /// Crease neighbours of every vertex.
    nbrs: Vec<Vec<u32>>,
    /// Whether there are none at all: then no question reads `nbrs`, which would cost a
    /// cache miss per vertex asked about in the collapse loop.
    none: bool,
}

impl Creases {
    /// The given edges that are interior edges of the mesh (others are ignored: a boundary
    /// edge is sharp anyway, a pair that is no edge cannot be kept).
    pub(super) fn new(topo: &Topology, edges: &[[u32; 2]]) -> Self {
        let mut nbrs = vec![Vec::new(); topo.vertex_count];
        if edges.is_empty() {
            return Self { nbrs, none: true };
        }
        let wanted: std::collections::HashSet<(u32, u32)> =
            edges.iter().map(|&[a, b]| (a.min(b), a.max(b))).collect();
        for (a, b, h) in topo.edges() {
            if topo.twin[h as usize] != NONE && wanted.contains(&(a.min(b), a.max(b))) {
                nbrs[a as usize].push(b);
                nbrs[b as usize].push(a);
            }
        }
        let none = nbrs.iter().all(Vec::is_empty);
        Self { nbrs, none }
    }

    pub(super) fn count(&self, v: u32) -> usize {
        if self.none {
            return 0;
        }
        self.nbrs[v as usize].len()
    }

    /// The crease edges, each once, their ends renumbered by `to` (`halves`: an input
    /// vertex's vertex in a half).
    pub(super) fn edges_among<'s>(&'s self, to: &'s [u32]) -> impl Iterator<Item = [u32; 2]> + 's {
        let nbrs = if self.none { &[][..] } else { &self.nbrs[..] };
        nbrs.iter().enumerate().flat_map(move |(a, n)| {
            n.iter()
                .filter(move |&&b| (a as u32) < b)
                .map(move |&b| [to[a], to[b as usize]])
        })
    }

    pub(super) fn is_crease(&self, a: u32, b: u32) -> bool {
        !self.none && self.nbrs[a as usize].contains(&b)
    }

    /// Adds each crease edge's two constraint planes to its end points' quadrics.
    pub(super) fn add_planes(
        &self,
        positions: &[DVec3],
        topo: &Topology,
        weight: f64,
        quadric: &mut [Quadric],
    ) {
        // Without creases, listing the mesh's edges (every large mesh's halves glue asks
        // for its frozen vertices' planes) would be the whole cost.
        if self.none {
            return;
        }
        for (a, b, h) in topo.edges() {
            let t = topo.twin[h as usize];
            if t == NONE || !self.is_crease(a, b) {
                continue;
            }
            let (pa, pb) = (positions[a as usize], positions[b as usize]);
            for half in [h, t] {
                let p = topo.triangles[(half / 3) as usize].map(|v| positions[v as usize]);
                let unit = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                let side = (pb - pa).cross(unit).normalize_or_zero();
                let plane = Quadric::plane(side, pa, weight * (pb - pa).length_squared());
                quadric[a as usize].add(&plane);
                quadric[b as usize].add(&plane);
            }
        }
    }

    /// Vertices that stay in place: three or more crease edges, a crease on the boundary,
    /// the end of a chain, or a chain turning by more than `turn_deg`.
    pub(super) fn corners(&self, positions: &[DVec3], topo: &Topology, turn_deg: f64) -> Vec<bool> {
        let min_angle = (180.0 - turn_deg).to_radians();
        (0..self.nbrs.len())
            .map(|v| match self.nbrs[v].as_slice() {
                [] => false,
                &[a, b] if !topo.is_boundary(v as u32) => {
                    let p = positions[v];
                    let (da, db) = (positions[a as usize] - p, positions[b as usize] - p);
                    da.length() > 0.0 && db.length() > 0.0 && da.angle_between(db) < min_angle
                }
                _ => true,
            })
            .collect()
    }

    /// Whether collapsing `r` into `k` keeps the creases: along a crease edge unless the
    /// two share a third crease neighbour (a crease loop of three), across a non-crease
    /// edge only if at most one end is sharp (crease or boundary).
    pub(super) fn allows(&self, k: u32, r: u32, boundary: impl Fn(u32) -> bool) -> bool {
        if self.none {
            return true;
        }
        let (nk, nr) = (&self.nbrs[k as usize], &self.nbrs[r as usize]);
        if nk.contains(&r) {
            return !nk.iter().any(|x| *x != r && nr.contains(x));
        }
        let (ck, cr) = (!nk.is_empty(), !nr.is_empty());
        let (bk, br) = (boundary(k), boundary(r));
        !((ck && (cr || br)) || (cr && bk))
    }

    /// After `r` was collapsed into `k`: r's crease edges become k's.
    pub(super) fn merge(&mut self, k: u32, r: u32) {
        if self.none {
            return;
        }
        let moved = std::mem::take(&mut self.nbrs[r as usize]);
        for x in moved {
            self.nbrs[x as usize].retain(|&y| y != r);
            if x != k {
                if !self.nbrs[x as usize].contains(&k) {
                    self.nbrs[x as usize].push(k);
                }
                if !self.nbrs[k as usize].contains(&x) {
                    self.nbrs[k as usize].push(x);
                }
            }
        }
    }

    /// The crease edges in output numbering (`control_of`), low first, sorted.
    pub(super) fn edges(&self, control_of: &[u32]) -> Vec<[u32; 2]> {
        let mut out: Vec<[u32; 2]> = self
            .nbrs
            .iter()
            .enumerate()
            .flat_map(|(a, n)| n.iter().map(move |&b| (a as u32, b)))
            .filter(|&(a, b)| a < b)
            .map(|(a, b)| {
                let (x, y) = (control_of[a as usize], control_of[b as usize]);
                [x.min(y), x.max(y)]
            })
            .collect();
        out.sort_unstable();
        out
    }
}
