//! Quartic triangles: Bernstein values, points and feet on a patch or an edge curve, the
//! least-squares fits of edge curves and interiors to the limit surface, and the
//! tensor-product form written to CAD files.

use crate::bspline::{BSplineError, BSplineSurface};
use glam::DVec3;
use nalgebra::{Matrix3, Vector3};

/// Segments of the samples along a patch edge that its curve is fitted to.
const EDGE_SEGMENTS: usize = 16;
/// Side of the lattice whose interior points fit a patch's interior ordinates.
const FIT_LATTICE: usize = 8;
/// Foot-point corrections of the fitted parameters (edges and interiors).
const CORRECTION_ROUNDS: usize = 2;
/// Newton steps of a foot point on a patch or an edge curve.
const FOOT_STEPS: usize = 8;

/// Index of the ordinate with exponents (a, b, 4 - a - b) among the 15 of a quartic.
pub(super) const fn ordinate(a: usize, b: usize) -> usize {
    [0, 5, 9, 12, 14][a] + b
}

const FACTORIAL: [f64; 5] = [1.0, 1.0, 2.0, 6.0, 24.0];

fn factorial(n: usize) -> f64 {
    FACTORIAL[n]
}

/// 1, x, x^2, x^3, x^4.
fn powers(x: f64) -> [f64; 5] {
    let x2 = x * x;
    [1.0, x, x2, x2 * x, x2 * x2]
}

/// The 15 quartic Bernstein values at barycentric (x, y, 1 - x - y).
fn bernstein4(x: f64, y: f64) -> [f64; 15] {
    let (px, py, pz) = (powers(x), powers(y), powers(1.0 - x - y));
    let mut out = [0.0; 15];
    for a in 0..=4 {
        for b in 0..=4 - a {
            let c = 4 - a - b;
            out[ordinate(a, b)] =
                24.0 / (factorial(a) * factorial(b) * factorial(c)) * px[a] * py[b] * pz[c];
        }
    }
    out
}

/// Position and first derivatives (along x and y, z = 1 - x - y eliminated) of a quartic
/// triangle at barycentric (x, y).
pub(super) fn triangle_point(b: &[DVec3; 15], x: f64, y: f64) -> [DVec3; 3] {
    let position = bernstein4(x, y)
        .iter()
        .zip(b)
        .fold(DVec3::ZERO, |s, (w, p)| s + *p * *w);
    // 4 sum (b_(+x) - b_(+z)) B3, and likewise along y.
    let (px, py, pz) = (powers(x), powers(y), powers(1.0 - x - y));
    let (mut dx, mut dy) = (DVec3::ZERO, DVec3::ZERO);
    for a in 0..=3usize {
        for bb in 0..=3 - a {
            let c = 3 - a - bb;
            let w = 24.0 / (factorial(a) * factorial(bb) * factorial(c)) * px[a] * py[bb] * pz[c];
            let base = b[ordinate(a, bb)];
            dx += (b[ordinate(a + 1, bb)] - base) * w;
            dy += (b[ordinate(a, bb + 1)] - base) * w;
        }
    }
    [position, dx, dy]
}

/// The point of the triangle patch nearest `target`, by Gauss-Newton from (x, y), kept
/// in the triangle: its parameter and distance.
pub(super) fn triangle_foot(
    b: &[DVec3; 15],
    target: DVec3,
    (mut x, mut y): (f64, f64),
) -> ((f64, f64), f64) {
    for _ in 0..FOOT_STEPS {
        let [p, dx, dy] = triangle_point(b, x, y);
        let r = target - p;
        let (a11, a12, a22) = (dx.dot(dx), dx.dot(dy), dy.dot(dy));
        let det = a11 * a22 - a12 * a12;
        if det.is_nan() || det <= 0.0 {
            break;
        }
        let (g1, g2) = (dx.dot(r), dy.dot(r));
        x = (x + (a22 * g1 - a12 * g2) / det).max(0.0);
        y = (y + (a11 * g2 - a12 * g1) / det).max(0.0);
        if x + y > 1.0 {
            let t = x + y;
            (x, y) = (x / t, y / t);
        }
    }
    ((x, y), triangle_point(b, x, y)[0].distance(target))
}

/// The five quartic Bernstein values at t.
fn bernstein4_curve(t: f64) -> [f64; 5] {
    let (pt, ps) = (powers(t), powers(1.0 - t));
    std::array::from_fn(|m| factorial(4) / (factorial(m) * factorial(4 - m)) * pt[m] * ps[4 - m])
}

/// The parameter of the point of the quartic curve `c` nearest `target`, by Newton from
/// t, kept in [0, 1].
fn curve_foot(c: &[DVec3; 5], target: DVec3, mut t: f64) -> f64 {
    for _ in 0..FOOT_STEPS {
        let w = bernstein4_curve(t);
        let p = c.iter().zip(w).fold(DVec3::ZERO, |s, (q, w)| s + *q * w);
        // Derivative: 4 sum (c_(m+1) - c_m) B3_m.
        let (pt, ps) = (powers(t), powers(1.0 - t));
        let d: DVec3 = (0..4)
            .map(|m| {
                (c[m + 1] - c[m])
                    * (4.0 * factorial(3) / (factorial(m) * factorial(3 - m)))
                    * pt[m]
                    * ps[3 - m]
            })
            .sum();
        let dd = d.length_squared();
        if dd.is_nan() || dd <= 0.0 {
            break;
        }
        t = (t + (target - p).dot(d) / dd).clamp(0.0, 1.0);
    }
    t
}

/// Three free points of a linear least-squares problem: rows of their basis values, and
/// the right-hand sides (the samples less the fixed points' share). `None` when the
/// normal matrix is singular.
fn least_squares3(rows: &[[f64; 3]], rhs: &[DVec3]) -> Option<[DVec3; 3]> {
    let mut normal = Matrix3::zeros();
    let mut right = [DVec3::ZERO; 3];
    for (r, x) in rows.iter().zip(rhs) {
        for i in 0..3 {
            right[i] += *x * r[i];
            for j in 0..3 {
                normal[(i, j)] += r[i] * r[j];
            }
        }
    }
    let chol = normal.cholesky()?;
    let mut out = [DVec3::ZERO; 3];
    for axis in 0..3 {
        let v = chol.solve(&Vector3::from_fn(|i, _| right[i][axis]));
        for i in 0..3 {
            out[i][axis] = v[i];
        }
    }
    Some(out)
}

/// Sample parameters shared by every patch.
pub(super) struct Fits {
    /// Interior samples along a patch edge.
    edge: Vec<f64>,
    /// Interior samples of a patch (barycentric x, y).
    inner: Vec<(f64, f64)>,
}

const INNER: [usize; 3] = [ordinate(2, 1), ordinate(1, 2), ordinate(1, 1)];

impl Fits {
    pub(super) fn new() -> Fits {
        let m = FIT_LATTICE;
        Fits {
            edge: (1..EDGE_SEGMENTS)
                .map(|s| s as f64 / EDGE_SEGMENTS as f64)
                .collect(),
            inner: (1..m)
                .flat_map(|a| (1..m - a).map(move |b| (a, b)))
                .map(|(a, b)| (a as f64 / m as f64, b as f64 / m as f64))
                .collect(),
        }
    }

    /// The quartic from `start` to `end` (the limit curve's ends) nearest the limit curve
    /// `p` over [0, 1]: its middle points fitted at the samples' parameters, then at their
    /// foot points on the curve (near an extraordinary vertex the limit curve's own
    /// parameter is not the polynomial's).
    pub(super) fn edge(&self, [start, end]: [DVec3; 2], p: impl Fn(f64) -> DVec3) -> [DVec3; 5] {
        let samples: Vec<DVec3> = self.edge.iter().map(|&t| p(t)).collect();
        let mut params = self.edge.clone();
        let mut c = [
            start,
            (start * 3.0 + end) / 4.0,
            (start + end) / 2.0,
            (start + end * 3.0) / 4.0,
            end,
        ];
        for round in 0..=CORRECTION_ROUNDS {
            if round > 0 {
                for (t, x) in params.iter_mut().zip(&samples) {
                    *t = curve_foot(&c, *x, *t);
                }
            }
            let (rows, rhs): (Vec<[f64; 3]>, Vec<DVec3>) = params
                .iter()
                .zip(&samples)
                .map(|(&t, x)| {
                    let w = bernstein4_curve(t);
                    ([w[1], w[2], w[3]], *x - start * w[0] - end * w[4])
                })
                .unzip();
            match least_squares3(&rows, &rhs) {
                Some(mid) => c[1..4].copy_from_slice(&mid),
                None => break,
            }
        }
        c
    }

    /// The interior ordinates of a quartic triangle whose boundary is set (the interior
    /// ones are overwritten), nearest the limit surface `limit` over the triangle: fitted at
    /// the samples' parameters, then at their foot points on the patch.
    pub(super) fn interior(&self, b: &mut [DVec3; 15], limit: impl Fn(f64, f64) -> DVec3) {
        let samples: Vec<DVec3> = self.inner.iter().map(|&(x, y)| limit(x, y)).collect();
        let mut params = self.inner.clone();
        for round in 0..=CORRECTION_ROUNDS {
            if round > 0 {
                for (q, x) in params.iter_mut().zip(&samples) {
                    *q = triangle_foot(b, *x, *q).0;
                }
            }
            let (rows, rhs): (Vec<[f64; 3]>, Vec<DVec3>) = params
                .iter()
                .zip(&samples)
                .map(|(&(x, y), target)| {
                    let w = bernstein4(x, y);
                    let fixed = (0..15)
                        .filter(|k| !INNER.contains(k))
                        .fold(DVec3::ZERO, |s, k| s + b[k] * w[k]);
                    (INNER.map(|k| w[k]), *target - fixed)
                })
                .unzip();
            match least_squares3(&rows, &rhs) {
                Some(inner) => {
                    for (slot, p) in INNER.iter().zip(inner) {
                        b[*slot] = p;
                    }
                }
                // Distinct lattice parameters keep the normal matrix regular; feet that
                // all fell together would not, and the last fit stays.
                None => break,
            }
        }
    }
}

/// The quartic triangle as a degree (4, 4) tensor-product Bezier patch: with
/// x = s, y = (1 - s) t, z = (1 - s)(1 - t), B4_abc(x, y, z) = B4_a(s) B(4-a)_b(t), so row a
/// (along t) is the degree 4 - a curve of the ordinates (a, ., .), degree-elevated to 4;
/// the row at s = 1 collapses to corner x.
pub(super) fn tensor_form(b: &[DVec3; 15]) -> Result<BSplineSurface, BSplineError> {
    let mut grid = Vec::with_capacity(25);
    for a in 0..=4usize {
        let degree = 4 - a;
        let mut row: Vec<DVec3> = (0..=degree).map(|j| b[ordinate(a, j)]).collect();
        // The row's curve runs from t = 0 (ordinate (a, 0, c): corner z's side) to t = 1.
        // The last row is corner x alone, repeated exactly (elevation would round it).
        if row.len() == 1 {
            row = vec![row[0]; 5];
        }
        while row.len() < 5 {
            let m = row.len(); // new degree
            let mut up = Vec::with_capacity(m + 1);
            for j in 0..=m {
                let w = j as f64 / m as f64;
                let left = if j > 0 { row[j - 1] } else { DVec3::ZERO };
                let right = if j < m { row[j] } else { DVec3::ZERO };
                up.push(left * w + right * (1.0 - w));
            }
            row = up;
        }
        grid.extend(row);
    }
    let knots = vec![0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    BSplineSurface::new((4, 4), knots.clone(), knots, (5, 5), grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tensor_form_is_the_triangle() {
        let b: [DVec3; 15] =
            std::array::from_fn(|k| DVec3::new(k as f64, (k * k) as f64 * 0.1, (k as f64).sin()));
        let t = tensor_form(&b).expect("finite");
        for &(s, tt) in &[(0.0, 0.0), (0.3, 0.7), (0.9, 0.2), (0.5, 1.0), (1.0, 0.4)] {
            let (x, y) = (s, (1.0 - s) * tt);
            let [p, ..] = triangle_point(&b, x, y);
            assert!(t.point(s, tt).distance(p) < 1e-12, "{s} {tt}");
        }
    }
}
