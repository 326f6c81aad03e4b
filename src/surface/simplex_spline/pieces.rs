//! The polynomial pieces of a `SimplexFamily`, converted once per cell and kept.
//!
//! A simplex spline of degree m is one polynomial of degree m on each cell of the
//! arrangement of the lines through pairs of its knots: the recurrence's leaves are
//! indicators of knot triangles (constant off those lines) and its factors are affine. So
//! the side of every knot line a point lies on (its cell's sign key) fixes every leaf, and
//! running the recurrence on polynomials instead of numbers gives each root's polynomial on
//! that cell. A key's polynomials depend on the key alone (not on the point that first
//! reached the cell), so evaluations are reproducible whatever the order points come in.
//!
//! Why not per domain triangle (one Bezier patch each)? With knot clouds spread around the
//! vertices, knot lines cross the domain triangles: the splines are polynomial only on the
//! finer cells of the knot-line arrangement.
//!
//! Each cell's polynomials are expanded about the cell's own centre (the mean of the corners
//! of the cell, clipped from the pool's hull by the key's half-planes: a function of the key
//! alone). About a far point (the pool's centre, as first written) a cell's polynomial is
//! an extrapolation whose coefficients cancel when evaluated in the cell: at degree 3 a DMS
//! partition of unity came out 4e-9 off that way, while the recurrence at the point is
//! 1e-15 off. About a point of the cell the coefficients are the cell's own value and
//! derivatives, so the pieces are as exact as the recurrence, and degree 3 keeps pieces too.
//!
//! Signs are those of the family's own recurrence: the same float filter as
//! `orient_sign`, and the exact symbolic test (`perturbed_side`) where it cannot decide, so a
//! point on a knot line gets the piece its perturbation direction points into.
//!
//! An evaluation is then the sign key (a float test per knot line), one hash look-up and a
//! polynomial per root: several times cheaper than walking the recurrence per point, which
//! visits every node (hundreds for a degree-2 family) with exact orientation tests at the
//! leaves.

use super::node::{CompiledNode, Jet, Node};
use super::predicates::{orient_sign, perturbed_side};
use glam::{DVec2, DVec3};
use rustc_hash::FxHashMap;
use std::sync::{PoisonError, RwLock};

/// Polynomials up to this degree are representable (the monomials of degree <= 3: 10
/// coefficients).
const MAX_PIECE_DEGREE: usize = 3;

/// Families up to this degree are kept in piece form (all the degrees DMS splines use).
pub(super) const PIECE_DEGREE: usize = MAX_PIECE_DEGREE;
const MONOMIALS: usize = 10;

/// A family keeps at most this many cells; past it pieces are converted on each call
/// (a bound on memory for points sprayed over a large domain: every cell still evaluates
/// exactly).
const MAX_PIECES: usize = 1 << 13;

/// The knot lines: more than 128 would not fit a key (a 16-knot pool has 120 pairs).
const MAX_LINES: usize = 128;

/// Index of monomial X^a Y^b (by total degree, then by b).
#[inline]
const fn mono(a: usize, b: usize) -> usize {
    (a + b) * (a + b + 1) / 2 + b
}

type Poly = [f64; MONOMIALS];

/// A family's shares of one surface on the cells kept when it was frozen
/// (`SimplexFamily::freeze`): per cell its centre and, per monomial about it, the sum over
/// the roots of coefficient times control point. Kept apart from the index so that a
/// look-up stays small whatever the degree.
#[derive(Debug, Default)]
pub struct FrozenCells {
    index: FxHashMap<u128, u32>,
    centres: Vec<DVec2>,
    /// `per_root` per cell.
    coefficients: Vec<DVec3>,
}

/// One cell's polynomials, root after root (`coefficients` each), in the local coordinates
/// X = (x - centre) * inv_scale.
#[derive(Debug)]
struct Piece {
    zero: bool,
    centre: DVec2,
    coefficients: Box<[f64]>,
}

/// A family's knot lines, its local frame and the cells met so far.
pub(super) struct Pieces {
    /// Per knot line (knot i < knot j): knot i (`px`, `py`) and knot j - knot i (`dx`,
    /// `dy`), apart so that the sign loop runs without branches.
    px: Vec<f64>,
    py: Vec<f64>,
    dx: Vec<f64>,
    dy: Vec<f64>,
    ends: Vec<(DVec2, DVec2)>,
    /// The pool's convex hull, counter-clockwise: every spline vanishes outside it.
    hull: Vec<DVec2>,
    /// Per node that is a leaf: its three edges as (line, true when the ccw edge runs from
    /// the line's higher knot to its lower one).
    leaf_edges: Vec<[(u8, bool); 3]>,
    /// Where cells are expanded when the pool has no hull (collinear knots): the pool's
    /// bounding-box centre.
    centre: DVec2,
    inv_scale: f64,
    /// Monomials per root polynomial: (m + 1)(m + 2) / 2 for the highest root degree m.
    per_root: usize,
    cells: RwLock<FxHashMap<u128, Piece>>,
}

impl Clone for Pieces {
    /// A copy starts with no cells (they are a cache: refilled on use).
    fn clone(&self) -> Self {
        Self {
            px: self.px.clone(),
            py: self.py.clone(),
            dx: self.dx.clone(),
            dy: self.dy.clone(),
            ends: self.ends.clone(),
            hull: self.hull.clone(),
            leaf_edges: self.leaf_edges.clone(),
            centre: self.centre,
            inv_scale: self.inv_scale,
            per_root: self.per_root,
            cells: RwLock::new(FxHashMap::default()),
        }
    }
}

impl std::fmt::Debug for Pieces {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pieces")
            .field("lines", &self.ends.len())
            .field("cells", &self.cell_count())
            .finish()
    }
}

impl Pieces {
    /// The piece form of a compiled family whose roots have degree <= `MAX_PIECE_DEGREE`;
    /// `None` when it has more knot lines than a key holds.
    pub(super) fn new(
        knots: &[DVec2],
        nodes: &[CompiledNode],
        root_degree: usize,
        min: DVec2,
        max: DVec2,
    ) -> Option<Self> {
        if root_degree > PIECE_DEGREE {
            return None;
        }
        let mut line_of: FxHashMap<(u8, u8), u8> = FxHashMap::default();
        let mut ends: Vec<(DVec2, DVec2)> = Vec::new();
        let mut leaf_edges = Vec::new();
        for cn in nodes {
            let Node::Leaf { knots: ids, .. } = &cn.node else {
                continue;
            };
            let mut edges = [(0u8, false); 3];
            for (k, edge) in edges.iter_mut().enumerate() {
                let (u, v) = (ids[k], ids[(k + 1) % 3]);
                let key = (u.min(v), u.max(v));
                let line = match line_of.get(&key) {
                    Some(&l) => l,
                    None => {
                        if ends.len() >= MAX_LINES {
                            return None;
                        }
                        ends.push((knots[key.0 as usize], knots[key.1 as usize]));
                        let l = (ends.len() - 1) as u8;
                        line_of.insert(key, l);
                        l
                    }
                };
                *edge = (line, u > v);
            }
            leaf_edges.push(edges);
        }
        let extent = (max - min).max_element();
        // Padded with zeros to whole groups of four for `key_avx2`.
        let padded = |f: &dyn Fn(&(DVec2, DVec2)) -> f64| -> Vec<f64> {
            let mut v: Vec<f64> = ends.iter().map(f).collect();
            v.resize(ends.len().div_ceil(4) * 4, 0.0);
            v
        };
        Some(Self {
            px: padded(&|e| e.0.x),
            py: padded(&|e| e.0.y),
            dx: padded(&|e| e.1.x - e.0.x),
            dy: padded(&|e| e.1.y - e.0.y),
            ends,
            hull: convex_hull(knots),
            leaf_edges,
            centre: (min + max) * 0.5,
            inv_scale: if extent > 0.0 { 1.0 / extent } else { 1.0 },
            per_root: (root_degree + 1) * (root_degree + 2) / 2,
            cells: RwLock::new(FxHashMap::default()),
        })
    }

    /// Cells converted so far.
    pub(super) fn cell_count(&self) -> usize {
        self.cells
            .read()
            .unwrap_or_else(PoisonError::into_inner)
            .len()
    }

    /// Bit l set when x (perturbed along `dir`) lies left of knot line l.
    pub(super) fn key(&self, x: DVec2, dir: DVec2) -> u128 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked above).
            return unsafe { self.key_avx2(x, dir) };
        }
        self.key_with(x, dir)
    }

    /// `key` four lines at a time, the signs gathered by `movemask`: the sign tests were
    /// the largest single item of a 40k-point DMS fit's profile (11 % with the plain
    /// loop, which the compiler vectorised but assembled bit by bit). The same
    /// operations in the same order as `key_with`, so the same signs. The line arrays are
    /// padded to a multiple of four; the padding's bits are masked off.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn key_avx2(&self, x: DVec2, dir: DVec2) -> u128 {
        use std::arch::x86_64::*;
        let lines = self.ends.len();
        // Two 64-bit words each: a group of four lines never straddles them, and u128
        // shifts by a variable amount branch on the word.
        let (mut key, mut unsure) = ([0u64; 2], [0u64; 2]);
        let (xx, xy) = (_mm256_set1_pd(x.x), _mm256_set1_pd(x.y));
        let (scale, zero, sign) = (
            _mm256_set1_pd(1e-15),
            _mm256_setzero_pd(),
            _mm256_set1_pd(-0.0),
        );
        let mut l = 0;
        while l < lines {
            // SAFETY: the four arrays hold `lines` rounded up to a multiple of four
            // values (`new`), and l < lines is a multiple of four.
            let (px, py, dx, dy) = unsafe {
                (
                    _mm256_loadu_pd(self.px.as_ptr().add(l)),
                    _mm256_loadu_pd(self.py.as_ptr().add(l)),
                    _mm256_loadu_pd(self.dx.as_ptr().add(l)),
                    _mm256_loadu_pd(self.dy.as_ptr().add(l)),
                )
            };
            let left = _mm256_mul_pd(dx, _mm256_sub_pd(xy, py));
            let right = _mm256_mul_pd(dy, _mm256_sub_pd(xx, px));
            let det = _mm256_sub_pd(left, right);
            let bound = _mm256_mul_pd(
                scale,
                _mm256_add_pd(_mm256_andnot_pd(sign, left), _mm256_andnot_pd(sign, right)),
            );
            let positive = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_GT_OQ>(det, zero));
            let close = _mm256_movemask_pd(_mm256_cmp_pd::<_CMP_LE_OQ>(
                _mm256_andnot_pd(sign, det),
                bound,
            ));
            key[l >> 6] |= (positive as u64) << (l & 63);
            unsure[l >> 6] |= (close as u64) << (l & 63);
            l += 4;
        }
        let used = if lines >= 128 {
            u128::MAX
        } else {
            (1u128 << lines) - 1
        };
        let join = |w: [u64; 2]| (w[0] as u128 | (w[1] as u128) << 64) & used;
        self.settle_unsure(join(key), join(unsure), x, dir)
    }

    #[inline(always)]
    pub(super) fn key_with(&self, x: DVec2, dir: DVec2) -> u128 {
        let (mut key, mut unsure) = (0u128, 0u128);
        let lines = self.ends.len();
        for start in (0..lines).step_by(64) {
            let end = (start + 64).min(lines);
            let (mut k, mut u) = (0u64, 0u64);
            for (i, l) in (start..end).enumerate() {
                // `orient_sign`'s filter, term for term, so that a decided sign is its sign.
                let left = self.dx[l] * (x.y - self.py[l]);
                let right = self.dy[l] * (x.x - self.px[l]);
                let det = left - right;
                let bound = 1e-15 * (left.abs() + right.abs());
                k |= ((det > 0.0) as u64) << i;
                u |= ((det.abs() <= bound) as u64) << i;
            }
            key |= (k as u128) << start;
            unsure |= (u as u128) << start;
        }
        self.settle_unsure(key, unsure, x, dir)
    }

    /// `key` with the `unsure` lines' bits set by the exact symbolic side: where the
    /// float filter cannot tell (on or next to a line).
    #[inline(always)]
    fn settle_unsure(&self, mut key: u128, mut unsure: u128, x: DVec2, dir: DVec2) -> u128 {
        while unsure != 0 {
            let l = unsure.trailing_zeros() as usize;
            unsure &= unsure - 1;
            let (a, b) = self.ends[l];
            let left = (perturbed_side(a, b, x, dir) > 0) as u128;
            key = (key & !(1u128 << l)) | (left << l);
        }
        key
    }

    /// True when x lies strictly outside the pool's hull (exactly so: the float filter of
    /// `orient_sign` must decide it), where every spline of the family is zero.
    fn outside(&self, x: DVec2) -> bool {
        let n = self.hull.len();
        (0..n).any(|k| {
            let (p, q) = (self.hull[k], self.hull[(k + 1) % n]);
            let left = (q.x - p.x) * (x.y - p.y);
            let right = (q.y - p.y) * (x.x - p.x);
            let det = left - right;
            -det > 1e-15 * (left.abs() + right.abs())
        })
    }

    /// The centre of the cell of `key`: the mean of the corners of the hull clipped by every
    /// knot line's half-plane (Sutherland-Hodgman), skipping a line that rounding would
    /// leave no polygon of (a cell thinner than the rounding of its corners).
    fn cell_centre(&self, key: u128) -> DVec2 {
        let mut polygon = self.hull.clone();
        let mut next = Vec::with_capacity(polygon.len() + 4);
        for (l, &(a, b)) in self.ends.iter().enumerate() {
            let sign = if (key >> l) & 1 == 1 { 1.0 } else { -1.0 };
            let side = |p: DVec2| sign * (b - a).perp_dot(p - a);
            next.clear();
            for (k, &p) in polygon.iter().enumerate() {
                let q = polygon[(k + 1) % polygon.len()];
                let (sp, sq) = (side(p), side(q));
                if sp >= 0.0 {
                    next.push(p);
                }
                if (sp >= 0.0) != (sq >= 0.0) {
                    next.push(p + (q - p) * (sp / (sp - sq)));
                }
            }
            if next.len() < 3 {
                // This line leaves nothing in floats: the cell lies within rounding of
                // it, so the region clipped so far (a function of the key still) holds
                // the cell up to that rounding. Expanding there keeps the coefficients
                // local; the pool's centre, far from a thin cell, made them cancel.
                continue;
            }
            std::mem::swap(&mut polygon, &mut next);
        }
        let centre = polygon.iter().sum::<DVec2>() / polygon.len() as f64;
        if centre.is_finite() {
            centre
        } else {
            self.centre
        }
    }

    /// Every root's polynomial on the cell of `key`: the recurrence run on polynomials.
    fn convert(&self, key: u128, nodes: &[CompiledNode], roots: &[(u32, f64)]) -> Piece {
        let mut polys: Vec<Option<Poly>> = Vec::with_capacity(nodes.len());
        let mut leaf = 0usize;
        let centre = if self.hull.is_empty() {
            self.centre
        } else {
            self.cell_centre(key)
        };
        let (c, s) = (centre, 1.0 / self.inv_scale);
        for cn in nodes {
            let poly = match &cn.node {
                Node::Zero => None,
                Node::Leaf { inv_abs_det, .. } => {
                    let edges = &self.leaf_edges[leaf];
                    leaf += 1;
                    let inside = edges
                        .iter()
                        .all(|&(l, flipped)| ((key >> l) & 1 == 1) != flipped);
                    inside.then(|| {
                        let mut p = [0.0; MONOMIALS];
                        p[0] = *inv_abs_det;
                        p
                    })
                }
                Node::Inner { lambda, children } => {
                    let mut acc: Option<Poly> = None;
                    for (l, &child) in lambda.iter().zip(children) {
                        let Some(m) = &polys[child as usize] else {
                            continue;
                        };
                        // lambda(x) with x = c + s X: affine in the local X, Y.
                        let (l0, l1, l2) = (l[0] + l[1] * c.x + l[2] * c.y, l[1] * s, l[2] * s);
                        let out = acc.get_or_insert([0.0; MONOMIALS]);
                        multiply_affine(m, [l0, l1, l2], out);
                    }
                    acc
                }
            };
            polys.push(poly);
        }
        let mut coefficients = vec![0.0; roots.len() * self.per_root].into_boxed_slice();
        let mut zero = true;
        for (r, &(id, factor)) in roots.iter().enumerate() {
            if let Some(p) = &polys[id as usize] {
                zero = false;
                for (dst, src) in coefficients[r * self.per_root..(r + 1) * self.per_root]
                    .iter_mut()
                    .zip(p)
                {
                    *dst = src * factor;
                }
            }
        }
        Piece {
            zero,
            centre,
            coefficients,
        }
    }

    /// Root jets at x (perturbed along `dir`), converting and keeping its cell if new.
    pub(super) fn evaluate<const DERIV: bool>(
        &self,
        x: DVec2,
        dir: DVec2,
        nodes: &[CompiledNode],
        roots: &[(u32, f64)],
        out: &mut Vec<Jet>,
    ) {
        if self.outside(x) {
            out.clear();
            out.resize(roots.len(), [0.0; 6]);
            return;
        }
        let key = self.key(x, dir);
        self.with_piece(key, nodes, roots, |piece| {
            self.jets::<DERIV>(piece, roots.len(), x, out)
        });
    }

    /// The cell of `key`'s piece: kept, or converted (and kept while there is room).
    fn with_piece<R>(
        &self,
        key: u128,
        nodes: &[CompiledNode],
        roots: &[(u32, f64)],
        f: impl FnOnce(&Piece) -> R,
    ) -> R {
        {
            let cells = self.cells.read().unwrap_or_else(PoisonError::into_inner);
            if let Some(piece) = cells.get(&key) {
                return f(piece);
            }
        }
        let piece = self.convert(key, nodes, roots);
        let result = f(&piece);
        let mut cells = self.cells.write().unwrap_or_else(PoisonError::into_inner);
        if cells.len() < MAX_PIECES {
            cells.entry(key).or_insert(piece);
        }
        result
    }

    /// The family's share of one surface on a cell: per monomial, the sum over the roots of
    /// the root's coefficient times its control point (`controls`, in root order), into
    /// `out` (`per_root` long).
    fn share(&self, piece: &Piece, controls: &[DVec3], out: &mut [DVec3]) {
        out.fill(DVec3::ZERO);
        if piece.zero {
            return;
        }
        for (coef, c) in piece.coefficients.chunks_exact(self.per_root).zip(controls) {
            for (m, k) in out.iter_mut().zip(coef) {
                *m += *c * *k;
            }
        }
    }

    /// The family's shares of the surface of `controls` on every cell kept so far (a
    /// foot-point search evaluates one surface many times: a hit costs the sign key, a
    /// look-up and one polynomial in place of one per root).
    pub(super) fn freeze(&self, controls: &[DVec3]) -> Option<FrozenCells> {
        let cells = self.cells.read().unwrap_or_else(PoisonError::into_inner);
        let n = self.per_root;
        let mut frozen = FrozenCells {
            index: FxHashMap::default(),
            centres: Vec::with_capacity(cells.len()),
            coefficients: vec![DVec3::ZERO; cells.len() * n],
        };
        frozen.index.reserve(cells.len());
        for (i, (key, piece)) in cells.iter().enumerate() {
            frozen.index.insert(*key, i as u32);
            frozen.centres.push(piece.centre);
            self.share(
                piece,
                controls,
                &mut frozen.coefficients[i * n..(i + 1) * n],
            );
        }
        Some(frozen)
    }

    /// Value and x/y derivatives of the family's share of the surface of `controls` at x
    /// (perturbed along `dir`), from `frozen` or from the cell's piece: the same arithmetic
    /// either way, so the result does not depend on which cells were kept.
    pub(super) fn surface_jet(
        &self,
        frozen: &FrozenCells,
        x: DVec2,
        dir: DVec2,
        nodes: &[CompiledNode],
        roots: &[(u32, f64)],
        controls: &[DVec3],
    ) -> [DVec3; 6] {
        if self.outside(x) {
            return [DVec3::ZERO; 6];
        }
        let key = self.key(x, dir);
        let n = self.per_root;
        match frozen.index.get(&key) {
            Some(&i) => {
                let i = i as usize;
                let cell = &frozen.coefficients[i * n..(i + 1) * n];
                self.share_jet(frozen.centres[i], cell, x)
            }
            None => self.with_piece(key, nodes, roots, |piece| {
                let mut cell = [DVec3::ZERO; MONOMIALS];
                self.share(piece, controls, &mut cell[..n]);
                self.share_jet(piece.centre, &cell[..n], x)
            }),
        }
    }

    /// Value and x/y derivatives at x of a share (`cell`: its coefficients about `centre`).
    fn share_jet(&self, centre: DVec2, cell: &[DVec3], x: DVec2) -> [DVec3; 6] {
        let s = self.inv_scale;
        let p = (x - centre) * s;
        if cell.len() > 6 {
            let basis = monomial_jets::<true>(p, s);
            let mut jet = [DVec3::ZERO; 6];
            for (c, b) in cell.iter().zip(&basis) {
                for (j, v) in jet.iter_mut().zip(b) {
                    *j += *c * *v;
                }
            }
            return jet;
        }
        // c0 + c1 X + c2 Y + c3 X^2 + c4 X Y + c5 Y^2, X = (x - centre) * s: the quadratic
        // case by hand (the foot points of degree-2 fits spend their time here).
        let mut q = [DVec3::ZERO; 6];
        q[..cell.len()].copy_from_slice(cell);
        let [c0, c1, c2, c3, c4, c5] = q;
        [
            c0 + (c1 + c3 * p.x + c4 * p.y) * p.x + (c2 + c5 * p.y) * p.y,
            (c1 + c3 * (2.0 * p.x) + c4 * p.y) * s,
            (c2 + c4 * p.x + c5 * (2.0 * p.y)) * s,
            c3 * (2.0 * s * s),
            c4 * (s * s),
            c5 * (2.0 * s * s),
        ]
    }

    fn jets<const DERIV: bool>(&self, piece: &Piece, roots: usize, x: DVec2, out: &mut Vec<Jet>) {
        out.clear();
        if piece.zero {
            out.resize(roots, [0.0; 6]);
            return;
        }
        let basis = monomial_jets::<DERIV>((x - piece.centre) * self.inv_scale, self.inv_scale);
        let n = self.per_root;
        out.extend(piece.coefficients.chunks_exact(n).map(|coef| {
            let mut jet = [0.0; 6];
            for (c, b) in coef.iter().zip(&basis[..n]) {
                if *c == 0.0 {
                    continue;
                }
                jet[0] += c * b[0];
                if DERIV {
                    for k in 1..6 {
                        jet[k] += c * b[k];
                    }
                }
            }
            jet
        }));
    }
}

/// out += m * (l0 + l1 X + l2 Y). Only polynomials of degree <= 2 are ever multiplied
/// (a child has one knot less than its parent, and no node has degree above the roots'
/// <= 3), so m's degree-3 terms are zero and the product fits.
fn multiply_affine(m: &Poly, [l0, l1, l2]: [f64; 3], out: &mut Poly) {
    for d in 0..MAX_PIECE_DEGREE {
        for b in 0..=d {
            let a = d - b;
            let v = m[mono(a, b)];
            if v == 0.0 {
                continue;
            }
            out[mono(a, b)] += l0 * v;
            out[mono(a + 1, b)] += l1 * v;
            out[mono(a, b + 1)] += l2 * v;
        }
    }
}

/// Per monomial X^a Y^b at X: value and x/y derivatives up to second order, in the
/// caller's coordinates (X = (x - centre) * inv_scale).
fn monomial_jets<const DERIV: bool>(p: DVec2, inv_scale: f64) -> [Jet; MONOMIALS] {
    let px = [1.0, p.x, p.x * p.x, p.x * p.x * p.x];
    let py = [1.0, p.y, p.y * p.y, p.y * p.y * p.y];
    let (s1, s2) = (inv_scale, inv_scale * inv_scale);
    let mut out = [[0.0; 6]; MONOMIALS];
    for d in 0..=MAX_PIECE_DEGREE {
        for b in 0..=d {
            let a = d - b;
            let jet = &mut out[mono(a, b)];
            jet[0] = px[a] * py[b];
            if DERIV {
                let (fa, fb) = (a as f64, b as f64);
                if a > 0 {
                    jet[1] = fa * px[a - 1] * py[b] * s1;
                }
                if b > 0 {
                    jet[2] = fb * px[a] * py[b - 1] * s1;
                }
                if a > 1 {
                    jet[3] = fa * (fa - 1.0) * px[a - 2] * py[b] * s2;
                }
                if a > 0 && b > 0 {
                    jet[4] = fa * fb * px[a - 1] * py[b - 1] * s2;
                }
                if b > 1 {
                    jet[5] = fb * (fb - 1.0) * px[a] * py[b - 2] * s2;
                }
            }
        }
    }
    out
}

/// Convex hull of `points`, counter-clockwise, without collinear points (Andrew's monotone
/// chain; fewer than three distinct points give no hull, and `outside` is then never true).
fn convex_hull(points: &[DVec2]) -> Vec<DVec2> {
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    sorted.dedup();
    if sorted.len() < 3 {
        return Vec::new();
    }
    let mut hull: Vec<DVec2> = Vec::with_capacity(2 * sorted.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &DVec2>> = if pass == 0 {
            Box::new(sorted.iter())
        } else {
            Box::new(sorted.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && orient_sign(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    if hull.len() < 3 {
        return Vec::new();
    }
    hull
}
