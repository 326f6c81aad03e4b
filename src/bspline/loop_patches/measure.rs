//! How far a patchwork is from its limit surface: from points of the limit surface (a
//! lattice over every patch, other than the fit's) to the patchwork, and the angle between
//! the two normals there.
//!
//! A point's distance is to its foot on its own patch or, when that foot lands on the
//! patch's edge, on the patch across that edge, whichever is nearer: the patch edges are
//! fitted curves, so a limit point close to an edge may lie just across it. Without that
//! step a flat face of a box (the limit exactly planar, every normal agreeing) measured
//! 1.9e-4 m "off" its patches, all of it along their edges. The patch's parameter is not
//! the limit surface's near an extraordinary vertex, and need not be.

use super::quartic::{triangle_foot, triangle_point};
use super::split::Node;
use super::{at, PatchDeviation, Piece};
use crate::surface::Derivatives;
use rayon::prelude::*;
use std::collections::HashMap;

/// Side of the lattice (boundary included) on which the deviation is measured: not a
/// divisor of the fit's lattices, so the check sees points the fit did not.
const CHECK_LATTICE: usize = 11;

/// A foot parameter this close to 0 (in barycentric weight) is on the patch's edge.
const ON_EDGE: f64 = 1e-12;

/// The deviation of `pieces` from the limit surface `limit` (face, parameter).
pub(super) fn deviation(
    pieces: &[Piece],
    limit: &(dyn Fn(usize, (f64, f64)) -> Derivatives + Sync),
) -> PatchDeviation {
    let mut across: HashMap<(Node, Node), Vec<usize>> = HashMap::new();
    for (i, piece) in pieces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (piece.nodes[k], piece.nodes[(k + 1) % 3]);
            across.entry((a.min(b), a.max(b))).or_default().push(i);
        }
    }
    pieces
        .par_iter()
        .enumerate()
        .map(|(i, piece)| {
            measure(i, pieces, &across, |x, y| {
                limit(piece.face, at(&piece.corners, x, y))
            })
        })
        .reduce(Stats::default, Stats::merge)
        .finish()
}

/// The patch across the edge that a foot (barycentric x, y of patch `i`) lies on, the
/// foot's place there as that patch's (x, y), and which of its corners is opposite that
/// edge; `None` inside the patch, at a corner, or at the surface's boundary.
fn across_edge(
    i: usize,
    (x, y): (f64, f64),
    pieces: &[Piece],
    across: &HashMap<(Node, Node), Vec<usize>>,
) -> Option<(usize, (f64, f64), usize)> {
    let w = [x, y, 1.0 - x - y];
    let zero: Vec<usize> = (0..3).filter(|&k| w[k] < ON_EDGE).collect();
    let [k] = zero[..] else {
        return None;
    };
    let (a, b) = ((k + 1) % 3, (k + 2) % 3);
    let nodes = pieces[i].nodes;
    let key = (nodes[a].min(nodes[b]), nodes[a].max(nodes[b]));
    let &j = across.get(&key)?.iter().find(|&&j| j != i)?;
    let there = pieces[j].nodes;
    let mut v = [0.0; 3];
    let mut opposite = 3;
    for (own, weight) in [(a, w[a]), (b, w[b])] {
        let k = there.iter().position(|n| *n == nodes[own])?;
        v[k] = weight;
        opposite -= k;
    }
    Some((j, (v[0], v[1]), opposite))
}

/// Patch `i` against the limit surface `limit` over it (its own barycentric parameters).
fn measure(
    i: usize,
    pieces: &[Piece],
    across: &HashMap<(Node, Node), Vec<usize>>,
    limit: impl Fn(f64, f64) -> Derivatives,
) -> Stats {
    let m = CHECK_LATTICE;
    let mut s = Stats::default();
    for a in 0..=m {
        for bb in 0..=m - a {
            let (x, y) = (a as f64 / m as f64, bb as f64 / m as f64);
            let exact = limit(x, y);
            let b = &pieces[i].b;
            let same = triangle_point(b, x, y)[0].distance(exact.position);
            let (foot, along) = triangle_foot(b, exact.position, (x, y));
            let mut best = if along < same {
                (along, i, foot)
            } else {
                (same, i, (x, y))
            };
            // Across the edge only when the foot there leaves the edge: a point on the
            // edge itself (a crease, where the patch across is another sheet) is its own
            // patch's.
            if let Some((j, start, opposite)) = across_edge(i, foot, pieces, across) {
                let (foot, d) = triangle_foot(&pieces[j].b, exact.position, start);
                let w = [foot.0, foot.1, 1.0 - foot.0 - foot.1];
                if d < best.0 && w[opposite] > ON_EDGE {
                    best = (d, j, foot);
                }
            }
            let (d, patch, (fx, fy)) = best;
            s.samples += 1;
            s.sum_sq += d * d;
            s.max = s.max.max(d);
            // At an extraordinary vertex the limit's parametric derivatives vanish or blow
            // up: normals are compared away from the patch's corners.
            let corner = a == m || bb == m || a + bb == 0;
            let [_, dx, dy] = triangle_point(&pieces[patch].b, fx, fy);
            let (normal, exact_normal) = (dx.cross(dy), exact.du.cross(exact.dv));
            if !corner && exact_normal.length() > 0.0 && normal.length() > 0.0 {
                let angle = exact_normal.angle_between(normal).to_degrees();
                s.normal_deg.push(angle as f32);
            }
        }
    }
    s
}

#[derive(Default)]
struct Stats {
    samples: usize,
    sum_sq: f64,
    max: f64,
    normal_deg: Vec<f32>,
}

impl Stats {
    fn merge(mut self, o: Stats) -> Stats {
        self.samples += o.samples;
        self.sum_sq += o.sum_sq;
        self.max = self.max.max(o.max);
        self.normal_deg.extend_from_slice(&o.normal_deg);
        self
    }

    fn finish(mut self) -> PatchDeviation {
        self.normal_deg.sort_by(f32::total_cmp);
        let at = |q: f64| {
            let n = self.normal_deg.len();
            if n == 0 {
                0.0
            } else {
                f64::from(self.normal_deg[((n - 1) as f64 * q).round() as usize])
            }
        };
        PatchDeviation {
            samples: self.samples,
            max: self.max,
            rms: (self.sum_sq / self.samples.max(1) as f64).sqrt(),
            normal_max_deg: at(1.0),
            normal_p99_deg: at(0.99),
        }
    }
}
