//! B-patches (Seidel 1991): a degree-n polynomial over one domain triangle [A, B, C],
//! represented through three knot sequences r_0..r_{n-1}, s_0..s_{n-1}, t_0..t_{n-1}
//! (r_0 = A, s_0 = B, t_0 = C).
//!
//! Control point P_b (|b| = n, stored at `lattice_index(n, b0, b1)` like the Bezier kind) is
//! the blossom of the polynomial at (r_0..r_{b0-1}, s_0..s_{b1-1}, t_0..t_{b2-1}). The value
//! at a domain point x is the de Boor-like recursion: for l = 1..n and |b| = n - l,
//! `P_b^l = sum_j lambda_j(x | D_b) P_{b+e_j}^{l-1}`, D_b the knot triangle
//! [r_{b0}, s_{b1}, t_{b2}]. Knots on the corners give the Bezier patch (every D_b = [A, B, C]).
//!
//! Basis rows come from running the recursion top-down on weights (a node's weight times
//! lambda_j flows to child b + e_j); the lambdas are affine in the parameter, so first and
//! second derivatives follow by the product rule in the same pass. The affine coefficients
//! of every knot triangle are knot-only data, computed once.
//!
//! Parameters: face 0, (u, v) barycentric w.r.t. A and B (C gets w = 1 - u - v).
//!
//! Knot rule (`BPatch::outward`): knots on the medians, pushed out of the triangle,
//! `r_i = A + spread (i / n) (A - G)` with G the centroid (likewise s from B, t from C).
//! Every knot triangle then contains the domain triangle, so all lambdas are in [0, 1] on
//! the domain: the basis is non-negative there and the recursion a convex combination.

use super::bezier::{lattice_index, lattice_len, lattice_points, lattice_triangles};
use super::dms::record::{pts2, pts3, vec2, vec3};
use super::dms::PlanarSurface;
use super::simplex_spline::{barycentric_affine, det2};
use super::{BasisDerivRows, SurfaceParam, TriSurface};
use glam::{DVec2, DVec3};

/// Why a B-patch or its record was refused.
#[derive(Debug, thiserror::Error, PartialEq)]
#[non_exhaustive]
pub enum BPatchError {
    /// The degree is outside 1..=32.
    #[error("degree {0}: a B-patch needs degree 1..=32")]
    Degree(usize),
    /// A knot sequence does not have exactly `degree` points.
    #[error("knot sequence {name} has {found} points, degree {degree} needs {degree}")]
    KnotCount {
        /// Which sequence: `'r'`, `'s'` or `'t'`.
        name: char,
        /// Points it has.
        found: usize,
        /// The patch degree, which is also the points it needs.
        degree: usize,
    },
    /// The named sequence's first knot is not its domain corner (r at A, s at B, t at C).
    #[error("knot sequence {0} does not start at its domain corner")]
    KnotNotAtCorner(char),
    /// The domain triangle has zero or negative (clockwise) area, or is not finite.
    #[error("the domain triangle is degenerate or clockwise")]
    Domain,
    /// Knot triangle `[r_i, s_j, t_k]` (the indices) is near-degenerate or flipped
    /// relative to the domain, so its barycentric coordinates are undefined or unstable.
    #[error("knot triangle [r{0}, s{1}, t{2}] is degenerate or not oriented like the domain")]
    KnotTriangle(usize, usize, usize),
    /// The `outward` spread is negative or not finite.
    #[error("knot spread {0} must be finite and non-negative")]
    Spread(f64),
    /// A record's control point count is not `(n + 1)(n + 2) / 2` for its degree n.
    #[error("{found} control points, the surface has {expected}")]
    ControlCount {
        /// Control points in the record.
        found: usize,
        /// Control points the degree needs.
        expected: usize,
    },
}

/// One knot triangle's affine barycentric coordinates in terms of the surface parameter:
/// `lambda_j(u, v) = c[j][0] + c[j][1] u + c[j][2] v`.
type ParamAffine = [[f64; 3]; 3];

/// A checked B-patch: degree, domain triangle, knots and the precomputed knot-triangle
/// coordinates its evaluation needs (control points are kept apart).
#[derive(Clone, Debug)]
pub struct BPatch {
    degree: usize,
    domain: [DVec2; 3],
    knots: [Vec<DVec2>; 3],
    /// Per b with |b| <= n - 1, in lattice order level by level.
    affine: Vec<Vec<ParamAffine>>,
}

impl BPatch {
    /// A B-patch with given knot sequences `[r, s, t]`, n points each, starting at the
    /// domain corners (A, B, C counter-clockwise).
    pub fn new(
        degree: usize,
        domain: [DVec2; 3],
        knots: [Vec<DVec2>; 3],
    ) -> Result<Self, BPatchError> {
        if !(1..=32).contains(&degree) {
            return Err(BPatchError::Degree(degree));
        }
        let domain_det = det2(domain[0], domain[1], domain[2]);
        if domain_det.is_nan() || domain_det <= 0.0 {
            return Err(BPatchError::Domain);
        }
        for (k, (seq, name)) in knots.iter().zip(['r', 's', 't']).enumerate() {
            if seq.len() != degree {
                return Err(BPatchError::KnotCount {
                    name,
                    found: seq.len(),
                    degree,
                });
            }
            if seq[0] != domain[k] {
                return Err(BPatchError::KnotNotAtCorner(name));
            }
        }
        // Parameter (u, v) -> x = C + u (A - C) + v (B - C).
        let (eu, ev, c) = (domain[0] - domain[2], domain[1] - domain[2], domain[2]);
        let mut affine = Vec::with_capacity(degree);
        for level in 0..degree {
            let mut row = Vec::with_capacity(lattice_len(level));
            for (i, j) in lattice_points(level) {
                let k = level - i - j;
                let w = [knots[0][i], knots[1][j], knots[2][k]];
                let d = det2(w[0], w[1], w[2]);
                if d.is_nan() || d <= 1e-12 * domain_det {
                    return Err(BPatchError::KnotTriangle(i, j, k));
                }
                let xy = barycentric_affine(w);
                row.push(xy.map(|a| {
                    [
                        a[0] + a[1] * c.x + a[2] * c.y,
                        a[1] * eu.x + a[2] * eu.y,
                        a[1] * ev.x + a[2] * ev.y,
                    ]
                }));
            }
            affine.push(row);
        }
        Ok(Self {
            degree,
            domain,
            knots,
            affine,
        })
    }

    /// The documented knot rule: knots on the medians pushed outwards by `spread` (0 gives
    /// the Bezier patch; the default used by the examples is 0.5).
    pub fn outward(degree: usize, domain: [DVec2; 3], spread: f64) -> Result<Self, BPatchError> {
        if !(spread.is_finite() && spread >= 0.0) {
            return Err(BPatchError::Spread(spread));
        }
        let g = (domain[0] + domain[1] + domain[2]) / 3.0;
        let n = degree.max(1) as f64;
        let knots = domain.map(|corner| {
            (0..degree)
                .map(|i| {
                    if i == 0 {
                        corner
                    } else {
                        corner + (corner - g) * (spread * i as f64 / n)
                    }
                })
                .collect()
        });
        Self::new(degree, domain, knots)
    }

    /// The polynomial degree n.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// The domain triangle `[A, B, C]`, counter-clockwise.
    pub fn domain(&self) -> [DVec2; 3] {
        self.domain
    }

    /// `[r, s, t]`.
    pub fn knots(&self) -> &[Vec<DVec2>; 3] {
        &self.knots
    }

    /// Control points of the B-patch equal to the degree-n Bezier patch with `bezier`
    /// control points over the same domain triangle (lattice order): each is the Bezier
    /// polynomial's blossom at the control's knots.
    pub fn controls_from_bezier(&self, bezier: &[DVec3]) -> Vec<DVec3> {
        let n = self.degree;
        lattice_points(n)
            .into_iter()
            .map(|(i, j)| {
                let k = n - i - j;
                let args: Vec<DVec2> = self.knots[0][..i]
                    .iter()
                    .chain(&self.knots[1][..j])
                    .chain(&self.knots[2][..k])
                    .copied()
                    .collect();
                bezier_blossom(n, self.domain, bezier, &args)
            })
            .collect()
    }

    /// The parameter of domain point x (barycentric, not clamped).
    pub fn param_of(&self, x: DVec2) -> SurfaceParam {
        let [a, b, c] = self.domain;
        let d = det2(a, b, c);
        SurfaceParam {
            face: 0,
            u: det2(x, b, c) / d,
            v: det2(a, x, c) / d,
        }
    }
}

/// The blossom of the degree-n Bezier polynomial with `controls` (lattice order) over the
/// domain triangle at the n points `args`: de Casteljau with one argument per level.
pub fn bezier_blossom(n: usize, domain: [DVec2; 3], controls: &[DVec3], args: &[DVec2]) -> DVec3 {
    let [a, b, c] = domain;
    let d = det2(a, b, c);
    let mut pts = controls.to_vec();
    for (r, x) in (1..=n).rev().zip(args) {
        let (lu, lv) = (det2(*x, b, c) / d, det2(a, *x, c) / d);
        let lw = 1.0 - lu - lv;
        let mut next = vec![DVec3::ZERO; lattice_len(r - 1)];
        for j in 0..r {
            for i in 0..r - j {
                next[lattice_index(r - 1, i, j)] = pts[lattice_index(r, i + 1, j)] * lu
                    + pts[lattice_index(r, i, j + 1)] * lv
                    + pts[lattice_index(r, i, j)] * lw;
            }
        }
        pts = next;
    }
    pts[0]
}

/// Independent reference: Seidel's recursion on the control points themselves (for tests
/// and output checks).
pub fn de_boor(patch: &BPatch, controls: &[DVec3], u: f64, v: f64) -> DVec3 {
    let n = patch.degree;
    let mut pts = controls.to_vec();
    for level in (0..n).rev() {
        let mut next = vec![DVec3::ZERO; lattice_len(level)];
        for (idx, (i, j)) in lattice_points(level).into_iter().enumerate() {
            let l = patch.affine[level][idx].map(|c| c[0] + c[1] * u + c[2] * v);
            next[idx] = pts[lattice_index(level + 1, i + 1, j)] * l[0]
                + pts[lattice_index(level + 1, i, j + 1)] * l[1]
                + pts[lattice_index(level + 1, i, j)] * l[2];
        }
        pts = next;
    }
    pts[0]
}

impl TriSurface for BPatch {
    fn control_count(&self) -> usize {
        lattice_len(self.degree)
    }

    fn domain_face_count(&self) -> usize {
        1
    }

    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows) {
        let mut cur: Vec<[f64; 6]> = vec![[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]];
        for level in 0..self.degree {
            let mut next = vec![[0.0f64; 6]; lattice_len(level + 1)];
            for (idx, (i, j)) in lattice_points(level).into_iter().enumerate() {
                let w = cur[idx];
                let children = [
                    lattice_index(level + 1, i + 1, j),
                    lattice_index(level + 1, i, j + 1),
                    lattice_index(level + 1, i, j),
                ];
                for (c, child) in self.affine[level][idx].iter().zip(children) {
                    let l = c[0] + c[1] * p.u + c[2] * p.v;
                    let (gu, gv) = (c[1], c[2]);
                    let t = &mut next[child];
                    t[0] += w[0] * l;
                    t[1] += w[1] * l + w[0] * gu;
                    t[2] += w[2] * l + w[0] * gv;
                    t[3] += w[3] * l + 2.0 * w[1] * gu;
                    t[4] += w[4] * l + w[1] * gv + w[2] * gu;
                    t[5] += w[5] * l + 2.0 * w[2] * gv;
                }
            }
            cur = next;
        }
        out.indices.clear();
        out.weights.clear();
        out.indices.extend(0..cur.len() as u32);
        out.weights.extend(cur);
    }

    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam {
        let mut u = (p.u + du).max(0.0);
        let mut v = (p.v + dv).max(0.0);
        let s = u + v;
        if s > 1.0 {
            u /= s;
            v /= s;
        }
        SurfaceParam { face: 0, u, v }
    }
}

impl PlanarSurface for BPatch {
    fn domain_point(&self, p: SurfaceParam) -> DVec2 {
        let [a, b, c] = self.domain;
        c + (a - c) * p.u + (b - c) * p.v
    }

    fn locate(&self, x: DVec2) -> Option<SurfaceParam> {
        let p = self.param_of(x);
        let tol = -1e-12;
        (p.u >= tol && p.v >= tol && 1.0 - p.u - p.v >= tol).then_some(p)
    }

    fn greville_sites(&self) -> Vec<DVec2> {
        let n = self.degree;
        lattice_points(n)
            .into_iter()
            .map(|(i, j)| {
                let k = n - i - j;
                let sum: DVec2 = self.knots[0][..i]
                    .iter()
                    .chain(&self.knots[1][..j])
                    .chain(&self.knots[2][..k])
                    .sum();
                sum / n as f64
            })
            .collect()
    }

    fn control_net_edges(&self) -> Vec<[u32; 2]> {
        let mut edges: Vec<[u32; 2]> = lattice_triangles(self.degree)
            .into_iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        edges
    }
}

/// The knot sequences of a `BPatchRecord`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BPatchKnots {
    /// Knots r_0..r_{n-1}, r_0 at domain corner A.
    pub r: Vec<[f64; 2]>,
    /// Knots s_0..s_{n-1}, s_0 at domain corner B.
    pub s: Vec<[f64; 2]>,
    /// Knots t_0..t_{n-1}, t_0 at domain corner C.
    pub t: Vec<[f64; 2]>,
}

/// The `bpatch` kind's `surface.json` record (schema in `dms::record`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BPatchRecord {
    /// Polynomial degree n.
    pub degree: usize,
    /// Domain corners `[A, B, C]`, counter-clockwise.
    pub domain_triangle: [[f64; 2]; 3],
    /// The three knot sequences, n points each.
    pub knots: BPatchKnots,
    /// `(n + 1)(n + 2) / 2` control points in lattice order (`lattice_index`).
    pub control_points: Vec<[f64; 3]>,
}

impl BPatchRecord {
    /// The record of `patch` with control points `controls` (not checked against the patch).
    pub fn new(patch: &BPatch, controls: &[DVec3]) -> Self {
        let [r, s, t] = patch.knots();
        Self {
            degree: patch.degree(),
            domain_triangle: patch.domain().map(|p| p.to_array()),
            knots: BPatchKnots {
                r: pts2(r),
                s: pts2(s),
                t: pts2(t),
            },
            control_points: pts3(controls),
        }
    }

    /// The checked surface and its controls.
    pub fn surface(&self) -> Result<(BPatch, Vec<DVec3>), BPatchError> {
        let patch = BPatch::new(
            self.degree,
            self.domain_triangle.map(DVec2::from_array),
            [
                vec2(&self.knots.r),
                vec2(&self.knots.s),
                vec2(&self.knots.t),
            ],
        )?;
        let expected = (self.degree + 1) * (self.degree + 2) / 2;
        if self.control_points.len() != expected {
            return Err(BPatchError::ControlCount {
                found: self.control_points.len(),
                expected,
            });
        }
        Ok((patch, vec3(&self.control_points)))
    }
}
