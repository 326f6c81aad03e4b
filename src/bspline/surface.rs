//! Tensor-product B-spline surfaces: validated construction, evaluation with the first and
//! second partial derivatives, and separable evaluation on parameter grids.

use super::basis::{basis_row, validate_knots, BasisRow};
use super::error::BSplineError;
use crate::surface::Derivatives;
use glam::DVec3;
use rayon::prelude::*;

#[derive(Clone, Debug, PartialEq)]
/// A clamped, non-rational tensor-product B-spline surface.
pub struct BSplineSurface {
    degree_u: usize,
    degree_v: usize,
    knots_u: Vec<f64>,
    knots_v: Vec<f64>,
    count_u: usize,
    count_v: usize,
    /// Row-major: control (i, j) at i * count_v + j.
    controls: Vec<DVec3>,
}

impl BSplineSurface {
    /// Checks degrees, knots and control count (`counts.0 * counts.1`) and the controls for finiteness.
    pub fn new(
        (degree_u, degree_v): (usize, usize),
        knots_u: Vec<f64>,
        knots_v: Vec<f64>,
        (count_u, count_v): (usize, usize),
        controls: Vec<DVec3>,
    ) -> Result<Self, BSplineError> {
        validate_knots(&knots_u, count_u, degree_u)?;
        validate_knots(&knots_v, count_v, degree_v)?;
        if count_u.checked_mul(count_v) != Some(controls.len()) {
            return Err(BSplineError::ControlCount {
                got: controls.len(),
                expected: count_u.saturating_mul(count_v),
            });
        }
        if let Some(i) = controls.iter().position(|c| !c.is_finite()) {
            return Err(BSplineError::NonFinite(i));
        }
        Ok(Self {
            degree_u,
            degree_v,
            knots_u,
            knots_v,
            count_u,
            count_v,
            controls,
        })
    }

    /// Degrees (p along u, q along v).
    pub fn degrees(&self) -> (usize, usize) {
        (self.degree_u, self.degree_v)
    }
    /// Control points along u and along v.
    pub fn counts(&self) -> (usize, usize) {
        (self.count_u, self.count_v)
    }
    /// The knot vector along u.
    pub fn knots_u(&self) -> &[f64] {
        &self.knots_u
    }
    /// The knot vector along v.
    pub fn knots_v(&self) -> &[f64] {
        &self.knots_v
    }
    /// The control points, row-major (see the module docs).
    pub fn controls(&self) -> &[DVec3] {
        &self.controls
    }

    /// ([u0, u1], [v0, v1]) of the parameter domain.
    pub fn domain(&self) -> ((f64, f64), (f64, f64)) {
        (
            (self.knots_u[self.degree_u], self.knots_u[self.count_u]),
            (self.knots_v[self.degree_v], self.knots_v[self.count_v]),
        )
    }

    /// Basis row along u at `u`, with `nd` derivatives (0..=2).
    pub fn row_u(&self, u: f64, nd: usize) -> BasisRow {
        basis_row(&self.knots_u, self.count_u, self.degree_u, u, nd)
    }
    /// Basis row along v at `v`, with `nd` derivatives (0..=2).
    pub fn row_v(&self, v: f64, nd: usize) -> BasisRow {
        basis_row(&self.knots_v, self.count_v, self.degree_v, v, nd)
    }

    /// The surface point at (u, v).
    pub fn point(&self, u: f64, v: f64) -> DVec3 {
        self.combine(&self.row_u(u, 0), &self.row_v(v, 0), false)
            .position
    }

    /// Position from precomputed basis rows (grids evaluate each row once).
    pub(crate) fn point_from_rows(&self, ru: &BasisRow, rv: &BasisRow) -> DVec3 {
        self.combine(ru, rv, false).position
    }

    /// Position and the first and second partials at (u, v).
    pub fn derivatives(&self, u: f64, v: f64) -> Derivatives {
        self.combine(&self.row_u(u, 2), &self.row_v(v, 2), true)
    }

    /// Sums the (p + 1)(q + 1) touched controls against two basis rows.
    fn combine(&self, ru: &BasisRow, rv: &BasisRow, with_derivatives: bool) -> Derivatives {
        let (p, q) = (self.degree_u, self.degree_v);
        let (fu, fv) = (ru.first(p), rv.first(q));
        let mut d = Derivatives::default();
        for a in 0..=p {
            // Contract along v first: value, d/dv, d2/dv2 of row fu + a.
            let base = (fu + a) * self.count_v + fv;
            let (mut c0, mut c1, mut c2) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
            for b in 0..=q {
                let c = self.controls[base + b];
                c0 += c * rv.d[0][b];
                if with_derivatives {
                    c1 += c * rv.d[1][b];
                    c2 += c * rv.d[2][b];
                }
            }
            d.position += c0 * ru.d[0][a];
            if with_derivatives {
                d.du += c0 * ru.d[1][a];
                d.duu += c0 * ru.d[2][a];
                d.dv += c1 * ru.d[0][a];
                d.duv += c1 * ru.d[1][a];
                d.dvv += c2 * ru.d[0][a];
            }
        }
        d
    }

    /// Derivatives at every (us[r], vs[c]), row-major in r. Basis rows are computed once per
    /// grid line, not once per point, and rows of the grid run in parallel.
    pub(crate) fn derivatives_on_grid(&self, us: &[f64], vs: &[f64]) -> Vec<Derivatives> {
        let rows_v: Vec<BasisRow> = vs.iter().map(|&v| self.row_v(v, 2)).collect();
        let mut out = vec![Derivatives::default(); us.len() * vs.len()];
        if vs.is_empty() {
            return out;
        }
        let (p, q, nv) = (self.degree_u, self.degree_v, self.count_v);
        out.par_chunks_mut(vs.len())
            .zip(us.par_iter())
            .for_each_init(
                || vec![[DVec3::ZERO; 3]; nv],
                |curve, (chunk, &u)| {
                    // Contract along u once per grid row: the row is then a curve in v
                    // (value, d/du, d2/du2 control polygons), leaving q + 1 terms per point.
                    let ru = self.row_u(u, 2);
                    let fu = ru.first(p);
                    for (j, c) in curve.iter_mut().enumerate() {
                        *c = [DVec3::ZERO; 3];
                        for a in 0..=p {
                            let x = self.controls[(fu + a) * nv + j];
                            c[0] += x * ru.d[0][a];
                            c[1] += x * ru.d[1][a];
                            c[2] += x * ru.d[2][a];
                        }
                    }
                    for (o, rv) in chunk.iter_mut().zip(&rows_v) {
                        let fv = rv.first(q);
                        let mut d = Derivatives::default();
                        for b in 0..=q {
                            let c = &curve[fv + b];
                            let (n0, n1, n2) = (rv.d[0][b], rv.d[1][b], rv.d[2][b]);
                            d.position += c[0] * n0;
                            d.dv += c[0] * n1;
                            d.dvv += c[0] * n2;
                            d.du += c[1] * n0;
                            d.duv += c[1] * n1;
                            d.duu += c[2] * n0;
                        }
                        *o = d;
                    }
                },
            );
        out
    }

    /// A triangulation of the surface at (segments_u + 1) x (segments_v + 1) uniformly
    /// spaced parameters, with unit normals (zero where the surface is singular).
    pub fn tessellate(&self, segments_u: usize, segments_v: usize) -> (crate::TriMesh, Vec<DVec3>) {
        let (nu, nv) = (segments_u.max(1), segments_v.max(1));
        let ((u0, u1), (v0, v1)) = self.domain();
        let us: Vec<f64> = (0..=nu)
            .map(|k| u0 + (u1 - u0) * k as f64 / nu as f64)
            .collect();
        let vs: Vec<f64> = (0..=nv)
            .map(|k| v0 + (v1 - v0) * k as f64 / nv as f64)
            .collect();
        let d = self.derivatives_on_grid(&us, &vs);
        let positions = d.iter().map(|x| x.position).collect();
        let normals = d
            .iter()
            .map(|x| x.du.cross(x.dv).try_normalize().unwrap_or(DVec3::ZERO))
            .collect();
        (
            crate::TriMesh::new(positions, grid_triangles(nu + 1, nv + 1)),
            normals,
        )
    }

    /// The closest surface point to `x` by Newton's method on the squared distance, started
    /// at `start` and kept inside the domain. Returns the parameters and the distance.
    pub fn closest_point(&self, x: DVec3, start: (f64, f64)) -> ((f64, f64), f64) {
        let ((u0, u1), (v0, v1)) = self.domain();
        let (mut u, mut v) = (start.0.clamp(u0, u1), start.1.clamp(v0, v1));
        let mut best = ((u, v), (self.point(u, v) - x).length());
        for _ in 0..12 {
            let d = self.derivatives(u, v);
            let r = d.position - x;
            // Gradient and Hessian of |S - x|^2 / 2.
            let g = [r.dot(d.du), r.dot(d.dv)];
            let h = [
                d.du.dot(d.du) + r.dot(d.duu),
                d.du.dot(d.dv) + r.dot(d.duv),
                d.dv.dot(d.dv) + r.dot(d.dvv),
            ];
            let det = h[0] * h[2] - h[1] * h[1];
            let (su, sv) = if det > 0.0 && h[0] > 0.0 {
                (
                    -(h[2] * g[0] - h[1] * g[1]) / det,
                    -(h[0] * g[1] - h[1] * g[0]) / det,
                )
            } else {
                // Not convex here: a Gauss-Newton step on the first fundamental form.
                let (e, f, gg) = (d.du.dot(d.du), d.du.dot(d.dv), d.dv.dot(d.dv));
                let det1 = e * gg - f * f;
                if det1 <= 0.0 {
                    break;
                }
                (
                    -(gg * g[0] - f * g[1]) / det1,
                    -(e * g[1] - f * g[0]) / det1,
                )
            };
            let (nu, nv) = ((u + su).clamp(u0, u1), (v + sv).clamp(v0, v1));
            let dist = (self.point(nu, nv) - x).length();
            if dist < best.1 {
                best = ((nu, nv), dist);
            }
            let moved = (nu - u).abs() + (nv - v).abs();
            u = nu;
            v = nv;
            if moved < 1e-14 {
                break;
            }
        }
        best
    }
}

/// Two counter-clockwise (in (u, v)) triangles per cell of a rows x cols vertex grid,
/// row-major vertices, split along the (r, c)-(r + 1, c + 1) diagonal.
pub(crate) fn grid_triangles(rows: usize, cols: usize) -> Vec<[u32; 3]> {
    let id = |r: usize, c: usize| (r * cols + c) as u32;
    let mut t = Vec::with_capacity(2 * rows.saturating_sub(1) * cols.saturating_sub(1));
    for r in 0..rows.saturating_sub(1) {
        for c in 0..cols.saturating_sub(1) {
            t.push([id(r, c), id(r + 1, c), id(r + 1, c + 1)]);
            t.push([id(r, c), id(r + 1, c + 1), id(r, c + 1)]);
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wavy() -> BSplineSurface {
        let (nu, nv) = (6, 5);
        let ku = vec![0.0, 0.0, 0.0, 0.0, 0.3, 0.6, 1.0, 1.0, 1.0, 1.0];
        let kv = vec![0.0, 0.0, 0.0, 0.45, 0.7, 1.0, 1.0, 1.0];
        let c = (0..nu * nv)
            .map(|k| {
                let (i, j) = (k / nv, k % nv);
                DVec3::new(i as f64, j as f64 * 1.3, ((i * 5 + j * 3) % 4) as f64 * 0.4)
            })
            .collect();
        BSplineSurface::new((3, 2), ku, kv, (nu, nv), c).expect("valid")
    }

    #[test]
    fn derivatives_match_finite_differences() {
        let s = wavy();
        let h = 1e-5;
        for &(u, v) in &[(0.1, 0.2), (0.5, 0.5), (0.77, 0.9), (0.31, 0.46)] {
            let d = s.derivatives(u, v);
            let du = (s.point(u + h, v) - s.point(u - h, v)) / (2.0 * h);
            let dv = (s.point(u, v + h) - s.point(u, v - h)) / (2.0 * h);
            let f = |a, b| s.derivatives(a, b);
            let duu = (f(u + h, v).du - f(u - h, v).du) / (2.0 * h);
            let duv = (f(u, v + h).du - f(u, v - h).du) / (2.0 * h);
            let dvv = (f(u, v + h).dv - f(u, v - h).dv) / (2.0 * h);
            assert!((d.du - du).length() < 1e-6, "{:?} {:?}", d.du, du);
            assert!((d.dv - dv).length() < 1e-6);
            assert!((d.duu - duu).length() < 1e-5);
            assert!((d.duv - duv).length() < 1e-5);
            assert!((d.dvv - dvv).length() < 1e-5);
        }
    }

    #[test]
    fn grid_evaluation_equals_pointwise() {
        let s = wavy();
        let us = [0.0, 0.2, 0.65, 1.0];
        let vs = [0.0, 0.5, 0.71, 0.99, 1.0];
        let g = s.derivatives_on_grid(&us, &vs);
        for (r, &u) in us.iter().enumerate() {
            for (c, &v) in vs.iter().enumerate() {
                let a = g[r * vs.len() + c];
                let b = s.derivatives(u, v);
                assert!((a.position - b.position).length() < 1e-14);
                assert!((a.duv - b.duv).length() < 1e-12);
            }
        }
    }

    #[test]
    fn closest_point_recovers_the_parameter() {
        let s = wavy();
        let x = s.point(0.42, 0.58);
        let d = s.derivatives(0.42, 0.58);
        let n = d.du.cross(d.dv).normalize();
        let ((u, v), dist) = s.closest_point(x + n * 1e-3, (0.4, 0.6));
        assert!(
            (u - 0.42).abs() < 1e-6 && (v - 0.58).abs() < 1e-6,
            "{u} {v}"
        );
        assert!((dist - 1e-3).abs() < 1e-9);
    }
}
