//! Bivariate simplex splines by Micchelli's recurrence, compiled once per knot family.
//!
//! Normalisation (the one DMS splines use): a simplex spline of degree 0 on three knots is
//! `1 / |det|` on the half-open knot triangle (det = twice the signed area) and 0 elsewhere;
//! degree m on m + 3 knots V is `M(x | V) = sum_j lambda_j(x | W) M(x | V \ w_j)` for any
//! three affinely independent knots W of V, lambda the barycentric coordinates of x in W.
//! With this normalisation `|det(a, b, c)| M(x | a^(i+1), b^(j+1), c^(k+1))` is the Bernstein
//! polynomial B_ijk on [a, b, c], and DMS basis functions sum to one.
//!
//! A `SimplexFamily` holds every knot subset the recurrence reaches from a set of root knot
//! sets drawn from one small knot pool (at most 16 knots, subsets as bit masks), each subset
//! once, in an order where children precede parents. Everything that depends only on the
//! knots (the chosen W, the affine barycentric coordinates, the leaf triangles, bounding
//! boxes) is computed at compile time; an evaluation is one pass over the nodes.
//!
//! W is the best-shaped (largest |det|) knot triple of each subset: the recurrence
//! multiplies by barycentric coordinates, which are large for thin triangles.
//!
//! Points on knot lines: every degree-0 indicator is evaluated at the symbolic point
//! `x + eps d + eps^2 (1, 0) + eps^3 (0, 1)` (d a caller's direction, e.g. into the domain
//! face the parameter belongs to) with exact orientation signs, so that all indicators agree
//! on which side of every knot line x lies: the recurrence then holds at x exactly as it
//! does off the lines, and the splines (continuous from degree 1) take their values there.
//!
//! Evaluation in piece form (`pieces`): the splines are polynomials on the cells of the
//! knot-line arrangement; `evaluate_cached` converts each cell met once (the recurrence run
//! on polynomials) and then evaluates the kept polynomials. `evaluate` walks the recurrence
//! at the point: the reference the pieces are tested against.
//!
//! Derivatives: the recurrence is differentiated by the product rule (the barycentric
//! coordinates are affine, the indicators piecewise constant), which off the knot lines is
//! the simplex-spline derivative formula written as a recurrence; on a knot line it gives
//! the derivative of the piece the symbolic point lies in.

mod node;
mod pieces;
mod predicates;

pub use node::Jet;
pub use pieces::FrozenCells;
pub use predicates::{barycentric_affine, det2, orient_sign, perturbed_side};

use glam::{DVec2, DVec3};
use node::{CompiledNode, Node};
use pieces::Pieces;
use std::collections::HashMap;

/// A knot pool and the simplex splines of some of its subsets, ready to evaluate.
#[derive(Clone, Debug)]
pub struct SimplexFamily {
    nodes: Vec<CompiledNode>,
    /// Per root set: its node and the factor its spline is multiplied by.
    roots: Vec<(u32, f64)>,
    min: DVec2,
    max: DVec2,
    /// The polynomial pieces met so far (`None` above `pieces::PIECE_DEGREE` or with more
    /// knot lines than a key holds: `evaluate` serves).
    pieces: Option<Pieces>,
}

/// Knot masks address at most this many knots.
pub const MAX_KNOTS: usize = 16;

/// Why a `SimplexFamily` could not be compiled.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum SimplexError {
    /// The pool has more knots than a `u16` mask can address (`MAX_KNOTS`).
    #[error("{0} knots in one family: at most {MAX_KNOTS}")]
    TooManyKnots(usize),
    /// Root number `.0` selects only `.1` knots; a planar simplex spline needs 3 or more.
    #[error("root knot set {0} has {1} knots: a simplex spline needs at least 3")]
    TooFewKnots(usize, u32),
}

struct Compiler<'a> {
    knots: &'a [DVec2],
    nodes: Vec<CompiledNode>,
    memo: HashMap<u16, u32>,
}

impl Compiler<'_> {
    fn points(&self, mask: u16) -> Vec<(usize, DVec2)> {
        (0..self.knots.len())
            .filter(|&i| mask & (1 << i) != 0)
            .map(|i| (i, self.knots[i]))
            .collect()
    }

    /// The largest-|det| triple of the subset and its det.
    fn best_triple(pts: &[(usize, DVec2)]) -> ([usize; 3], f64) {
        let mut best = ([0, 1, 2], 0.0f64);
        for a in 0..pts.len() {
            for b in a + 1..pts.len() {
                for c in b + 1..pts.len() {
                    let d = det2(pts[a].1, pts[b].1, pts[c].1);
                    if d.abs() > best.1.abs() {
                        best = ([a, b, c], d);
                    }
                }
            }
        }
        best
    }

    fn node(&mut self, mask: u16) -> u32 {
        if let Some(&id) = self.memo.get(&mask) {
            return id;
        }
        let pts = self.points(mask);
        let (min, max) = pts.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), (_, p)| (lo.min(*p), hi.max(*p)),
        );
        let node = if pts.len() == 3 {
            let (a, b, c) = (pts[0].1, pts[1].1, pts[2].1);
            let ids = [pts[0].0, pts[1].0, pts[2].0].map(|i| i as u8);
            match orient_sign(a, b, c) {
                0 => Node::Zero,
                s => Node::Leaf {
                    tri: if s > 0 { [a, b, c] } else { [a, c, b] },
                    knots: if s > 0 { ids } else { [ids[0], ids[2], ids[1]] },
                    inv_abs_det: 1.0 / det2(a, b, c).abs(),
                },
            }
        } else {
            let (triple, det) = Self::best_triple(&pts);
            let scale = (max - min).length_squared();
            if det.abs() <= 1e-14 * scale {
                Node::Zero
            } else {
                let w = triple.map(|k| pts[k].1);
                let children = triple.map(|k| self.node(mask & !(1u16 << pts[k].0)));
                Node::Inner {
                    lambda: barycentric_affine(w),
                    children,
                }
            }
        };
        let id = self.nodes.len() as u32;
        self.nodes.push(CompiledNode { node, min, max });
        self.memo.insert(mask, id);
        id
    }
}

impl SimplexFamily {
    /// Compiles the splines `factor * M(x | knots in mask)` of every root `(mask, factor)`.
    pub fn compile(knots: &[DVec2], roots: &[(u16, f64)]) -> Result<Self, SimplexError> {
        if knots.len() > MAX_KNOTS {
            return Err(SimplexError::TooManyKnots(knots.len()));
        }
        let mut compiler = Compiler {
            knots,
            nodes: Vec::new(),
            memo: HashMap::new(),
        };
        let mut compiled_roots = Vec::with_capacity(roots.len());
        let mut root_degree = 0;
        for (r, &(mask, factor)) in roots.iter().enumerate() {
            let count = mask.count_ones();
            if count < 3 {
                return Err(SimplexError::TooFewKnots(r, count));
            }
            root_degree = root_degree.max(count as usize - 3);
            compiled_roots.push((compiler.node(mask), factor));
        }
        let (min, max) = knots.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let pieces = Pieces::new(knots, &compiler.nodes, root_degree, min, max);
        Ok(Self {
            nodes: compiler.nodes,
            roots: compiled_roots,
            min,
            max,
            pieces,
        })
    }

    /// Nodes in the shared recurrence DAG (a measure of evaluation cost).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Polynomial pieces converted and kept so far (a size figure for reports).
    pub fn piece_count(&self) -> usize {
        self.pieces.as_ref().map_or(0, Pieces::cell_count)
    }

    /// Root splines compiled, in the order of `compile`'s `roots`.
    pub fn root_count(&self) -> usize {
        self.roots.len()
    }

    /// True when x can lie in the support of some root (inside the pool's bounding box).
    #[inline]
    pub fn may_touch(&self, x: DVec2) -> bool {
        x.cmpge(self.min).all() && x.cmple(self.max).all()
    }

    /// What `evaluate` gives, from the polynomial of x's knot-line cell (converted on the
    /// first visit and kept; module docs), equal up to rounding. Families without pieces
    /// walk the recurrence (`scratch` serves only then).
    pub fn evaluate_cached<const DERIV: bool>(
        &self,
        x: DVec2,
        dir: DVec2,
        scratch: &mut Vec<Jet>,
        out: &mut Vec<Jet>,
    ) {
        match &self.pieces {
            Some(pieces) => pieces.evaluate::<DERIV>(x, dir, &self.nodes, &self.roots, out),
            None => self.evaluate::<DERIV>(x, dir, scratch, out),
        }
    }

    /// The family's shares of the surface of `controls` (one per root, in root order) on
    /// the cells kept so far, for `surface_jet`; `None` when the family walks the
    /// recurrence or `controls` does not match its roots.
    pub fn freeze(&self, controls: &[DVec3]) -> Option<FrozenCells> {
        if controls.len() != self.roots.len() {
            return None;
        }
        self.pieces.as_ref()?.freeze(controls)
    }

    /// Value and x/y derivatives of `sum_r controls[r] * root_r` at x (knot lines resolved
    /// towards `dir`), `frozen` from `freeze` with the same controls; equal up to rounding
    /// to combining `evaluate`'s jets, and the same whichever cells `frozen` holds.
    pub fn surface_jet(
        &self,
        frozen: &FrozenCells,
        x: DVec2,
        dir: DVec2,
        controls: &[DVec3],
    ) -> [DVec3; 6] {
        match &self.pieces {
            Some(pieces) => pieces.surface_jet(frozen, x, dir, &self.nodes, &self.roots, controls),
            None => {
                let (mut scratch, mut out) = (Vec::new(), Vec::new());
                self.evaluate::<true>(x, dir, &mut scratch, &mut out);
                let mut sum = [DVec3::ZERO; 6];
                for (jet, c) in out.iter().zip(controls) {
                    for (s, w) in sum.iter_mut().zip(jet) {
                        *s += *c * *w;
                    }
                }
                sum
            }
        }
    }

    /// Root values (and, with `DERIV`, x/y derivatives up to second order) at x, the
    /// symbolic perturbation of knot-line points along `dir` first; `scratch` is reused.
    pub fn evaluate<const DERIV: bool>(
        &self,
        x: DVec2,
        dir: DVec2,
        scratch: &mut Vec<Jet>,
        out: &mut Vec<Jet>,
    ) {
        scratch.clear();
        scratch.resize(self.nodes.len(), [0.0; 6]);
        for (id, cn) in self.nodes.iter().enumerate() {
            if !(x.cmpge(cn.min).all() && x.cmple(cn.max).all()) {
                continue;
            }
            let jet = match &cn.node {
                Node::Zero => [0.0; 6],
                Node::Leaf {
                    tri, inv_abs_det, ..
                } => {
                    let inside =
                        (0..3).all(|k| perturbed_side(tri[k], tri[(k + 1) % 3], x, dir) > 0);
                    if inside {
                        [*inv_abs_det, 0.0, 0.0, 0.0, 0.0, 0.0]
                    } else {
                        [0.0; 6]
                    }
                }
                Node::Inner { lambda, children } => {
                    let mut acc = [0.0; 6];
                    for (c, k) in lambda.iter().zip(children) {
                        let m = scratch[*k as usize];
                        if m == [0.0; 6] {
                            continue;
                        }
                        let l = c[0] + c[1] * x.x + c[2] * x.y;
                        acc[0] += l * m[0];
                        if DERIV {
                            let (gx, gy) = (c[1], c[2]);
                            acc[1] += l * m[1] + gx * m[0];
                            acc[2] += l * m[2] + gy * m[0];
                            acc[3] += l * m[3] + 2.0 * gx * m[1];
                            acc[4] += l * m[4] + gx * m[2] + gy * m[1];
                            acc[5] += l * m[5] + 2.0 * gy * m[2];
                        }
                    }
                    acc
                }
            };
            scratch[id] = jet;
        }
        out.clear();
        out.extend(
            self.roots
                .iter()
                .map(|&(id, f)| scratch[id as usize].map(|v| v * f)),
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testdata::uniform;

    #[test]
    fn coincident_knots_give_bernstein_polynomials() {
        let (a, b, c) = (
            DVec2::new(0.0, 0.0),
            DVec2::new(2.0, 0.2),
            DVec2::new(0.5, 1.5),
        );
        // Degree 2 with knots a^2 b^2 c (i = 1, j = 1, k = 0): B_110 = 2 u v.
        let knots = [a, a, b, b, c];
        let det = det2(a, b, c);
        let fam = SimplexFamily::compile(&knots, &[(0b11111, det.abs())]).expect("compiles");
        let x = a * 0.3 + b * 0.5 + c * 0.2;
        let (mut s, mut out) = (Vec::new(), Vec::new());
        fam.evaluate::<false>(x, DVec2::ZERO, &mut s, &mut out);
        // The coincident knots make every proper 3-subset a thin (zero) triangle except
        // [a, b, c], so the recurrence reduces to de Casteljau on the Bernstein weights.
        assert!((out[0][0] - 2.0 * 0.3 * 0.5).abs() < 1e-12, "{}", out[0][0]);
    }

    #[test]
    fn pieces_equal_the_recurrence_off_and_on_knot_lines_whatever_the_order() {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        for degree in 0..=pieces::PIECE_DEGREE {
            for _ in 0..12 {
                let size = degree + 3;
                let pool: Vec<DVec2> = (0..size + 2)
                    .map(|_| DVec2::new(uniform(&mut seed), uniform(&mut seed)))
                    .collect();
                let all = (1u16 << (size + 2)) - 1;
                let roots = [
                    ((1u16 << size) - 1, 1.0),
                    (all & !0b11, 2.0),
                    (all & !0b101, 0.5),
                ];
                let family = SimplexFamily::compile(&pool, &roots).expect("compiles");
                let mut points: Vec<(DVec2, DVec2)> = (0..300)
                    .map(|_| {
                        let x = DVec2::new(uniform(&mut seed), uniform(&mut seed)) * 1.2 - 0.1;
                        (
                            x,
                            DVec2::new(uniform(&mut seed) - 0.5, uniform(&mut seed) - 0.5),
                        )
                    })
                    .collect();
                // Points on knot lines, resolved by their direction.
                for a in 0..pool.len() {
                    for b in a + 1..pool.len() {
                        let t = uniform(&mut seed);
                        let dir = DVec2::new(uniform(&mut seed) - 0.5, uniform(&mut seed) - 0.5);
                        points.push((pool[a] + (pool[b] - pool[a]) * t, dir));
                    }
                }
                // The vector sign key (where the CPU has one) is the plain loop's.
                let pieces = family.pieces.as_ref().expect("kept in pieces");
                for &(x, dir) in &points {
                    assert_eq!(pieces.key(x, dir), pieces.key_with(x, dir), "x {x}");
                }
                let (mut scratch, mut want, mut got) = (Vec::new(), Vec::new(), Vec::new());
                let mut reference = Vec::new();
                let mut scale = [0.0f64; 6];
                for &(x, dir) in &points {
                    family.evaluate::<true>(x, dir, &mut scratch, &mut want);
                    for jet in &want {
                        for (s, v) in scale.iter_mut().zip(jet) {
                            *s = s.max(v.abs());
                        }
                    }
                    reference.push(want.clone());
                }
                let mut cached = Vec::new();
                for (&(x, dir), want) in points.iter().zip(&reference) {
                    family.evaluate_cached::<true>(x, dir, &mut scratch, &mut got);
                    for (w, g) in want.iter().zip(&got) {
                        for k in 0..6 {
                            assert!(
                                (w[k] - g[k]).abs() <= 1e-8 * (1.0 + scale[k]),
                                "degree {degree}, x {x}, component {k}: {} vs {}",
                                w[k],
                                g[k]
                            );
                        }
                    }
                    cached.push(got.clone());
                }
                assert!(family.piece_count() > 0, "cells were kept");
                // A fresh copy visiting the points backwards converts its cells from other
                // points first: the pieces depend on the cell alone.
                let fresh = family.clone();
                assert_eq!(fresh.piece_count(), 0);
                for (&(x, dir), first) in points.iter().zip(&cached).rev() {
                    fresh.evaluate_cached::<true>(x, dir, &mut scratch, &mut got);
                    assert_eq!(&got, first, "degree {degree}, x {x}");
                }
            }
        }
    }
}
