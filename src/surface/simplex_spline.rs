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
//! Derivatives: the recurrence is differentiated by the product rule (the barycentric
//! coordinates are affine, the indicators piecewise constant), which off the knot lines is
//! the simplex-spline derivative formula written as a recurrence; on a knot line it gives
//! the derivative of the piece the symbolic point lies in.

use glam::DVec2;
use std::collections::HashMap;

/// Value, d/dx, d/dy, d2/dx2, d2/dxdy, d2/dy2.
pub type Jet = [f64; 6];

/// (a, b) -> (s, e) with s + e == a + b exactly (Knuth's two-sum).
#[inline]
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// Exact sign of `sum a_i b_i` for finite inputs without overflow: every product becomes
/// two floats (the fused multiply-add gives the rounding error exactly) and the sum is
/// accumulated as a non-overlapping expansion, whose sign is that of its largest part.
fn exact_sign_of_products(terms: &[(f64, f64)]) -> i8 {
    let mut expansion = [0.0f64; 32];
    let mut len = 0usize;
    let mut grow = |b: f64| {
        let mut q = b;
        let mut out = 0usize;
        for i in 0..len {
            let (s, e) = two_sum(q, expansion[i]);
            if e != 0.0 {
                expansion[out] = e;
                out += 1;
            }
            q = s;
        }
        if q != 0.0 {
            expansion[out] = q;
            out += 1;
        }
        len = out;
    };
    for &(a, b) in terms {
        let hi = a * b;
        grow(hi);
        grow(a.mul_add(b, -hi));
    }
    match len {
        0 => 0,
        _ if expansion[len - 1] > 0.0 => 1,
        _ => -1,
    }
}

/// Sign of the orientation of (p, q, r): +1 counter-clockwise, -1 clockwise, 0 collinear,
/// exact (a float filter first, the exact expansion only near zero).
pub fn orient_sign(p: DVec2, q: DVec2, r: DVec2) -> i8 {
    let left = (q.x - p.x) * (r.y - p.y);
    let right = (q.y - p.y) * (r.x - p.x);
    let det = left - right;
    let bound = 1e-15 * (left.abs() + right.abs());
    if det > bound {
        return 1;
    }
    if -det > bound {
        return -1;
    }
    exact_sign_of_products(&[
        (q.x, r.y),
        (-q.x, p.y),
        (-p.x, r.y),
        (-q.y, r.x),
        (q.y, p.x),
        (p.y, r.x),
    ])
}

/// Exact sign of `(q - p) x d`.
fn cross_sign(p: DVec2, q: DVec2, d: DVec2) -> i8 {
    let left = (q.x - p.x) * d.y;
    let right = (q.y - p.y) * d.x;
    let det = left - right;
    let bound = 1e-15 * (left.abs() + right.abs());
    if det > bound {
        return 1;
    }
    if -det > bound {
        return -1;
    }
    exact_sign_of_products(&[(q.x, d.y), (-p.x, d.y), (-q.y, d.x), (p.y, d.x)])
}

/// The side of line p -> q that the symbolic point `x + eps d + eps^2 (1,0) + eps^3 (0,1)`
/// lies on: +1 left, -1 right; never 0 for p != q.
pub fn perturbed_side(p: DVec2, q: DVec2, x: DVec2, d: DVec2) -> i8 {
    let s = orient_sign(p, q, x);
    if s != 0 {
        return s;
    }
    let s = cross_sign(p, q, d);
    if s != 0 {
        return s;
    }
    // (q - p) x (1, 0) = -(q.y - p.y); (q - p) x (0, 1) = q.x - p.x: signs of exact
    // differences are comparisons.
    match q.y.partial_cmp(&p.y) {
        Some(std::cmp::Ordering::Greater) => -1,
        Some(std::cmp::Ordering::Less) => 1,
        _ => {
            if q.x > p.x {
                1
            } else {
                -1
            }
        }
    }
}

/// Twice the signed area of (p, q, r) in floats.
#[inline]
pub fn det2(p: DVec2, q: DVec2, r: DVec2) -> f64 {
    (q - p).perp_dot(r - p)
}

/// Affine barycentric coordinates of a triangle: `lambda_j(x) = c[j][0] + c[j][1] x + c[j][2] y`.
pub fn barycentric_affine(w: [DVec2; 3]) -> [[f64; 3]; 3] {
    let d = det2(w[0], w[1], w[2]);
    let mut c = [[0.0; 3]; 3];
    for (j, cj) in c.iter_mut().enumerate() {
        let (p, q) = (w[(j + 1) % 3], w[(j + 2) % 3]);
        // orient(x, p, q) = p x q + x x (p - q), linear in x.
        *cj = [p.perp_dot(q) / d, (p.y - q.y) / d, -(p.x - q.x) / d];
    }
    c
}

#[derive(Clone, Debug)]
enum Node {
    /// A knot set with all knots collinear: a line measure, zero as a function (its
    /// parent's barycentric factor vanishes on that line).
    Zero,
    Leaf {
        /// Counter-clockwise.
        tri: [DVec2; 3],
        inv_abs_det: f64,
    },
    Inner {
        lambda: [[f64; 3]; 3],
        children: [u32; 3],
    },
}

#[derive(Clone, Debug)]
struct CompiledNode {
    node: Node,
    /// Bounding box of the subset's knots: the spline vanishes outside it.
    min: DVec2,
    max: DVec2,
}

/// A knot pool and the simplex splines of some of its subsets, ready to evaluate.
#[derive(Clone, Debug)]
pub struct SimplexFamily {
    nodes: Vec<CompiledNode>,
    /// Per root set: its node and the factor its spline is multiplied by.
    roots: Vec<(u32, f64)>,
    min: DVec2,
    max: DVec2,
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
            match orient_sign(a, b, c) {
                0 => Node::Zero,
                s => Node::Leaf {
                    tri: if s > 0 { [a, b, c] } else { [a, c, b] },
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
        for (r, &(mask, factor)) in roots.iter().enumerate() {
            let count = mask.count_ones();
            if count < 3 {
                return Err(SimplexError::TooFewKnots(r, count));
            }
            compiled_roots.push((compiler.node(mask), factor));
        }
        let (min, max) = knots.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        Ok(Self {
            nodes: compiler.nodes,
            roots: compiled_roots,
            min,
            max,
        })
    }

    /// Nodes in the shared recurrence DAG (a measure of evaluation cost).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
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
                Node::Leaf { tri, inv_abs_det } => {
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

    #[test]
    fn exact_orientation_is_consistent_where_floats_are_not() {
        let p = DVec2::new(0.1, 0.1);
        let q = DVec2::new(0.3, 0.3);
        let r = DVec2::new(0.7, 0.7);
        assert_eq!(orient_sign(p, q, r), 0);
        let above = DVec2::new(0.7, f64::from_bits(0.7f64.to_bits() + 1));
        assert_eq!(orient_sign(p, q, above), 1);
        assert_eq!(orient_sign(q, p, above), -1);
        // Points rounded onto a line: an exact sign is the same for every order of the
        // three points (up to the permutation's parity); float determinants disagree.
        let (a, b) = (DVec2::new(0.13, 0.71), DVec2::new(12.3, -4.1));
        for k in 1..200 {
            let c = a + (b - a) * (k as f64 * 0.0173);
            let s = orient_sign(a, b, c);
            assert_eq!(orient_sign(b, c, a), s);
            assert_eq!(orient_sign(c, a, b), s);
            assert_eq!(orient_sign(b, a, c), -s);
            assert_eq!(orient_sign(a, c, b), -s);
        }
        // A point on the line is put on the side the perturbation points to, antisymmetrically.
        let d = DVec2::new(-1.0, 1.0);
        assert_eq!(perturbed_side(p, q, r, d), 1);
        assert_eq!(perturbed_side(q, p, r, d), -1);
    }

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
}
