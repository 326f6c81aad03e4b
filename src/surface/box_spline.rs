//! The Loop limit surface of a regular triangular lattice control net: the quartic
//! three-direction box spline. Each domain triangle's patch depends on 12 control points.
//!
//! The 15 Bezier ordinates of a patch as combinations of its 12 control points are not
//! typed in from a table: they are derived once from Loop subdivision itself (two levels of
//! subdivision of a regular lattice, the limit-position mask at the 15 points of the
//! quarter lattice of one face, then quartic interpolation). The tests check the result
//! against limit masks at points it was not derived from.
//!
//! Control net: a lattice of `n + 3` segments whose origin is shifted by (-1, -1), so that
//! every triangle of the domain lattice (n segments, parameter (u, v) = (x / n, y / n)) has
//! its full 12-point neighbourhood; the outer ring of control points has no data of its own.

use super::bezier::{lattice_index, lattice_len, lattice_points, BezierTriangle};
use super::{BasisDerivRows, Derivatives, SurfaceParam, TriSurface};
use crate::mesh::detect::Hierarchy;
use crate::mesh::loop_subdiv::loop_step;
use crate::mesh::topology::Topology;
use glam::DVec3;
use std::sync::OnceLock;

/// Offsets of the 12 control points of the up triangle (0,0),(1,0),(0,1).
pub(crate) const STENCIL: [(i64, i64); 12] = [
    (0, 0),
    (1, 0),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (0, -1),
    (1, -1),
    (2, 0),
    (1, 1),
    (2, -1),
    (0, 2),
    (-1, 2),
];

/// 15 x 12: Bezier ordinate (lattice order of degree 4) from the 12 stencil points.
fn bezier_from_stencil() -> &'static [[f64; 12]; 15] {
    static MATRIX: OnceLock<[[f64; 12]; 15]> = OnceLock::new();
    MATRIX.get_or_init(derive_matrix)
}

fn derive_matrix() -> [[f64; 12]; 15] {
    // A regular planar lattice large enough that the face at (4, 3) and everything within
    // two rings of it stay regular through two subdivisions.
    let n = 10;
    let pts = lattice_points(n);
    let tris = super::bezier::lattice_triangles(n);
    let topo = match Topology::build(pts.len(), &tris) {
        Ok(t) => t,
        Err(_) => return [[0.0; 12]; 15],
    };
    let s1 = loop_step(&topo);
    let topo1 = Topology::build(s1.operator.rows(), &s1.triangles).unwrap_or_else(|_| topo.clone());
    let s2 = loop_step(&topo1);
    let topo2 =
        Topology::build(s2.operator.rows(), &s2.triangles).unwrap_or_else(|_| topo1.clone());
    // Where each fine vertex sits: its coarse face and barycentric weights.
    let (h, _) = Hierarchy::detect(&topo2, 2);
    let params = h.fine_vertex_params(&topo2);
    let coarse_tris = h
        .levels
        .last()
        .map(|l| l.coarse_triangles.clone())
        .unwrap_or_default();
    let coarse_map = h.coarsest_to_fine();
    // Lattice coordinates of every fine vertex.
    let coord_of_fine = |v: usize| -> (f64, f64) {
        let (f, u, w1) = params[v];
        let t = coarse_tris[f as usize];
        let c = |k: usize| {
            let (i, j) = pts[coarse_map[t[k] as usize] as usize];
            (i as f64, j as f64)
        };
        let w = 1.0 - u - w1;
        let (a, b, cc) = (c(0), c(1), c(2));
        (u * a.0 + w1 * b.0 + w * cc.0, u * a.1 + w1 * b.1 + w * cc.1)
    };
    let (fi, fj) = (4i64, 3i64);
    let mut targets = Vec::new();
    for (a, b) in lattice_points(4) {
        let want = (fi as f64 + a as f64 / 4.0, fj as f64 + b as f64 / 4.0);
        let found = (0..params.len()).find(|&v| {
            let c = coord_of_fine(v);
            (c.0 - want.0).abs() < 1e-9 && (c.1 - want.1).abs() < 1e-9
        });
        targets.push(found.unwrap_or(0));
    }
    let bern = BezierTriangle::new(4);
    let mut bmat = nalgebra::DMatrix::<f64>::zeros(15, 15);
    for (r, (a, b)) in lattice_points(4).into_iter().enumerate() {
        let mut row = Vec::new();
        bern.basis_row(
            SurfaceParam {
                face: 0,
                u: a as f64 / 4.0,
                v: b as f64 / 4.0,
            },
            &mut row,
        );
        for (c, w) in row {
            bmat[(r, c as usize)] = w;
        }
    }
    let Some(inv) = bmat.try_inverse() else {
        return [[0.0; 12]; 15];
    };
    let mut out = [[0.0; 12]; 15];
    for (k, (di, dj)) in STENCIL.iter().enumerate() {
        let mut field = vec![0.0; pts.len()];
        let idx = lattice_index(n, (fi + di) as usize, (fj + dj) as usize);
        field[idx] = 1.0;
        let apply = |op: &crate::mesh::loop_subdiv::SparseOperator, x: &[f64]| -> Vec<f64> {
            (0..op.rows())
                .map(|i| {
                    let (c, w) = op.row(i);
                    c.iter().zip(w).map(|(&j, &w)| x[j as usize] * w).sum()
                })
                .collect()
        };
        let fine = apply(&s2.operator, &apply(&s1.operator, &field));
        // Regular interior limit mask: chi = 1/12.
        let values: Vec<f64> = targets
            .iter()
            .map(|&v| {
                let ring = topo2.ring(v as u32);
                0.5 * fine[v] + ring.iter().map(|&w| fine[w as usize]).sum::<f64>() / 12.0
            })
            .collect();
        let coeffs = &inv * nalgebra::DVector::from_vec(values);
        for (r, row) in out.iter_mut().enumerate() {
            row[k] = coeffs[r];
        }
    }
    out
}

/// Value and (u, v) derivative weights of the 12 stencil points at local coordinates
/// (lu, lv) of an up triangle, or of a down triangle reflected onto one (its first
/// derivatives change sign). `scale` is the number of lattice cells per unit parameter.
pub(crate) fn stencil_weights(lu: f64, lv: f64, down: bool, scale: f64) -> [[f64; 6]; 12] {
    let m = bezier_from_stencil();
    let bern = quartic_bernstein(lu, lv);
    let (s1, s2) = if down {
        (-scale, scale * scale)
    } else {
        (scale, scale * scale)
    };
    let mut out = [[0.0; 6]; 12];
    for (k, w) in out.iter_mut().enumerate() {
        for (r, bw) in bern.iter().enumerate() {
            let c = m[r][k];
            w[0] += c * bw[0];
            w[1] += c * bw[1] * s1;
            w[2] += c * bw[2] * s1;
            w[3] += c * bw[3] * s2;
            w[4] += c * bw[4] * s2;
            w[5] += c * bw[5] * s2;
        }
    }
    out
}

/// Value weights alone of the 12 stencil points (see `stencil_weights`): collocation rows
/// need no derivatives.
pub(crate) fn stencil_values(lu: f64, lv: f64) -> [f64; 12] {
    let m = bezier_from_stencil();
    let bern = quartic_bernstein_values(lu, lv);
    let mut out = [0.0; 12];
    for (row, b) in m.iter().zip(&bern) {
        for (o, c) in out.iter_mut().zip(row) {
            *o += c * b;
        }
    }
    out
}

/// The values alone of `quartic_bernstein`: collocation rows are built for every data point
/// in every round. A plain loop over constant coefficients: `QUARTIC_LATTICE.map` with the
/// coefficient divided out per term was not inlined (a call and a division per value).
fn quartic_bernstein_values(u: f64, v: f64) -> [f64; 15] {
    let w = 1.0 - u - v;
    let pow = |x: f64| [1.0, x, x * x, x * x * x, x * x * x * x];
    let (pu, pv, pw) = (pow(u), pow(v), pow(w));
    let mut out = [0.0; 15];
    for (n, &(i, j)) in QUARTIC_LATTICE.iter().enumerate() {
        out[n] = QUARTIC_MULTINOMIALS[n] * pu[i] * pv[j] * pw[4 - i - j];
    }
    out
}

/// 4! / (i! j! k!) for each lattice point (i, j), k = 4 - i - j: whole numbers, so exactly
/// the quotient of the factorials in floating point too.
const QUARTIC_MULTINOMIALS: [f64; 15] = {
    const FACT: [usize; 5] = [1, 1, 2, 6, 24];
    let mut out = [0.0; 15];
    let mut n = 0;
    while n < 15 {
        let (i, j) = QUARTIC_LATTICE[n];
        out[n] = (24 / (FACT[i] * FACT[j] * FACT[4 - i - j])) as f64;
        n += 1;
    }
    out
};

/// The 15 Bezier ordinates (lattice order of degree 4) of the patch over the up triangle
/// whose stencil points, in `STENCIL` order, are `stencil`: computed once per cell and control
/// set, they make every later evaluation a 15-term sum.
pub(crate) fn bezier_ordinates(stencil: &[DVec3; 12]) -> [DVec3; 15] {
    let m = bezier_from_stencil();
    let mut out = [DVec3::ZERO; 15];
    for (o, row) in out.iter_mut().zip(m.iter()) {
        *o = row.iter().zip(stencil).map(|(w, c)| *c * *w).sum();
    }
    out
}

/// Value and derivatives of a patch from its Bezier ordinates, with the local coordinates,
/// orientation and scale of `stencil_weights`.
pub(crate) fn evaluate_ordinates(
    net: &[DVec3; 15],
    lu: f64,
    lv: f64,
    down: bool,
    scale: f64,
) -> Derivatives {
    // De Casteljau down to degree 2 and 1: the quadratic points give the second derivatives
    // and the linear ones the first derivatives and the value (blossoming), in a quarter of
    // the operations of summing 15 Bernstein values with their derivatives.
    let lw = 1.0 - lu - lv;
    let mut cubic = [DVec3::ZERO; 10];
    casteljau_step::<4>(net, &mut cubic, lu, lv, lw);
    let mut quad = [DVec3::ZERO; 6];
    casteljau_step::<3>(&cubic, &mut quad, lu, lv, lw);
    let mut lin = [DVec3::ZERO; 3];
    casteljau_step::<2>(&quad, &mut lin, lu, lv, lw);
    // Quadratic points in lattice order: (0,0) w^2, (1,0) uw, (2,0) u^2, (0,1) vw, (1,1) uv,
    // (0,2) v^2; linear: (0,0) w, (1,0) u, (0,1) v.
    let (c002, c101, c200, c011, c110, c020) =
        (quad[0], quad[1], quad[2], quad[3], quad[4], quad[5]);
    let (d001, d100, d010) = (lin[0], lin[1], lin[2]);
    let s1 = if down { -scale } else { scale };
    let s2 = scale * scale;
    Derivatives {
        position: d100 * lu + d010 * lv + d001 * lw,
        du: (d100 - d001) * (4.0 * s1),
        dv: (d010 - d001) * (4.0 * s1),
        duu: (c200 + c002 - c101 * 2.0) * (12.0 * s2),
        duv: (c002 + c110 - c101 - c011) * (12.0 * s2),
        dvv: (c020 + c002 - c011 * 2.0) * (12.0 * s2),
    }
}

/// One de Casteljau step from degree M to M - 1 on triangular lattices in lattice order
/// (row j holds M + 1 - j points). M is a constant so that the loops unroll: this runs
/// three times per surface evaluation, millions of times per fit.
#[inline(always)]
fn casteljau_step<const M: usize>(from: &[DVec3], to: &mut [DVec3], lu: f64, lv: f64, lw: f64) {
    let row = |m: usize, j: usize| j * (m + 1) - j * j.saturating_sub(1) / 2;
    for j in 0..M {
        for i in 0..M - j {
            to[row(M - 1, j) + i] = from[row(M, j) + i + 1] * lu
                + from[row(M, j + 1) + i] * lv
                + from[row(M, j) + i] * lw;
        }
    }
}

/// `lattice_points(4)` as a constant: the Bernstein values below run millions of times per
/// fit and must not allocate.
#[rustfmt::skip]
const QUARTIC_LATTICE: [(usize, usize); 15] = [
    (0, 0), (1, 0), (2, 0), (3, 0), (4, 0),
    (0, 1), (1, 1), (2, 1), (3, 1),
    (0, 2), (1, 2), (2, 2),
    (0, 3), (1, 3),
    (0, 4),
];

/// The 15 quartic Bernstein polynomials u^i v^j w^k 4!/(i! j! k!) in lattice order, with
/// their (u, v) derivatives (w = 1 - u - v): value, du, dv, duu, duv, dvv. Closed form
/// without allocation: this runs for every data point at every foot-point step.
fn quartic_bernstein(u: f64, v: f64) -> [[f64; 6]; 15] {
    let w = 1.0 - u - v;
    let pow = |x: f64| [1.0, x, x * x, x * x * x, x * x * x * x];
    let (pu, pv, pw) = (pow(u), pow(v), pow(w));
    // x^e and its first and second derivatives in x.
    let term = |p: &[f64; 5], e: usize| -> [f64; 3] {
        let e_f = e as f64;
        [
            p[e],
            if e >= 1 { e_f * p[e - 1] } else { 0.0 },
            if e >= 2 {
                e_f * (e_f - 1.0) * p[e - 2]
            } else {
                0.0
            },
        ]
    };
    let mut out = [[0.0; 6]; 15];
    for (idx, &(i, j)) in QUARTIC_LATTICE.iter().enumerate() {
        {
            let k = 4 - i - j;
            let c = QUARTIC_MULTINOMIALS[idx];
            let (a, b, d) = (term(&pu, i), term(&pv, j), term(&pw, k));
            // Partials in the independent (u, v, w), then the chain rule with w = 1 - u - v.
            let f_u = a[1] * b[0] * d[0];
            let f_v = a[0] * b[1] * d[0];
            let f_w = a[0] * b[0] * d[1];
            let f_uu = a[2] * b[0] * d[0];
            let f_vv = a[0] * b[2] * d[0];
            let f_ww = a[0] * b[0] * d[2];
            let f_uv = a[1] * b[1] * d[0];
            let f_uw = a[1] * b[0] * d[1];
            let f_vw = a[0] * b[1] * d[1];
            out[idx] = [
                c * a[0] * b[0] * d[0],
                c * (f_u - f_w),
                c * (f_v - f_w),
                c * (f_uu - 2.0 * f_uw + f_ww),
                c * (f_uv - f_uw - f_vw + f_ww),
                c * (f_vv - 2.0 * f_vw + f_ww),
            ];
        }
    }
    out
}

#[derive(Clone, Debug)]
/// The Loop limit surface of a regular triangular lattice net (a quartic box spline).
pub struct LatticeSpline {
    /// Domain lattice segments per side.
    pub n: usize,
}

impl LatticeSpline {
    /// The surface over a domain lattice of `n` segments a side (at least 1).
    pub fn new(n: usize) -> Self {
        Self { n: n.max(1) }
    }

    /// Segments of the control lattice (one extra ring on every side).
    pub fn control_segments(&self) -> usize {
        self.n + 3
    }

    /// Control index of domain-lattice coordinates (i, j), i, j >= -1, i + j <= n + 1.
    pub(crate) fn control_index(&self, i: i64, j: i64) -> usize {
        lattice_index(self.control_segments(), (i + 1) as usize, (j + 1) as usize)
    }

    /// The patch containing p: its 12 control indices, local (u, v), and whether it is a
    /// down triangle (local coordinates and first derivatives flip sign).
    fn locate(&self, p: SurfaceParam) -> ([usize; 12], f64, f64, bool) {
        let n = self.n as f64;
        let x = (p.u * n).clamp(0.0, n);
        let y = (p.v * n).clamp(0.0, n - x);
        let mut i = (x.floor() as i64).clamp(0, self.n as i64 - 1);
        let j = (y.floor() as i64).clamp(0, self.n as i64 - 1 - i);
        let mut fx = x - i as f64;
        let fy = y - j as f64;
        // Points on the far edge of a cell row may round into a missing cell.
        if i + j > self.n as i64 - 1 {
            let over = i + j - (self.n as i64 - 1);
            i -= over;
            fx += over as f64;
        }
        let down = fx + fy > 1.0 && i + j < self.n as i64 - 1;
        let mut ids = [0usize; 12];
        if down {
            for (k, (di, dj)) in STENCIL.iter().enumerate() {
                ids[k] = self.control_index(i + 1 - di, j + 1 - dj);
            }
            (ids, 1.0 - fx, 1.0 - fy, true)
        } else {
            for (k, (di, dj)) in STENCIL.iter().enumerate() {
                ids[k] = self.control_index(i + di, j + dj);
            }
            (ids, fx, fy, false)
        }
    }
}

impl TriSurface for LatticeSpline {
    fn control_count(&self) -> usize {
        lattice_len(self.control_segments())
    }

    fn domain_face_count(&self) -> usize {
        self.n * self.n
    }

    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows) {
        let (ids, lu, lv, down) = self.locate(p);
        let w = stencil_weights(lu, lv, down, self.n as f64);
        out.indices.clear();
        out.weights.clear();
        out.indices.extend(ids.iter().map(|&i| i as u32));
        out.weights.extend_from_slice(&w);
    }

    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam {
        BezierTriangle::new(1).step(p, du, dv)
    }
}

#[cfg(test)]
mod tests {
    /// The value-only weights are the value column of the weights with derivatives, and
    /// they sum to one (the box spline reproduces constants).
    #[test]
    fn stencil_values_are_the_value_part_of_the_stencil_weights() {
        for (lu, lv) in [(0.0, 0.0), (1.0, 0.0), (0.2, 0.3), (0.6, 0.1), (0.33, 0.66)] {
            let values = super::stencil_values(lu, lv);
            let full = super::stencil_weights(lu, lv, false, 1.0);
            for (v, w) in values.iter().zip(&full) {
                assert!((v - w[0]).abs() < 1e-15, "{v} vs {}", w[0]);
            }
            assert!((values.iter().sum::<f64>() - 1.0).abs() < 1e-14);
        }
    }

    #[test]
    fn de_casteljau_evaluation_equals_the_bernstein_sums() {
        use glam::DVec3;
        let net: [DVec3; 15] = std::array::from_fn(|k| {
            let k = k as f64;
            DVec3::new((k * 0.7).sin(), (k * 1.3).cos(), k * k * 0.01)
        });
        for &(u, v, down, scale) in &[
            (0.2, 0.3, false, 1.0),
            (0.0, 0.0, true, 2.5),
            (0.6, 0.1, false, 0.5),
            (0.05, 0.9, true, 1.0),
        ] {
            let fast = super::evaluate_ordinates(&net, u, v, down, scale);
            let bern = super::quartic_bernstein(u, v);
            let (s1, s2) = (if down { -scale } else { scale }, scale * scale);
            let sum = |c: usize, f: f64| -> DVec3 {
                net.iter().zip(&bern).map(|(p, b)| *p * b[c]).sum::<DVec3>() * f
            };
            for (got, want) in [
                (fast.position, sum(0, 1.0)),
                (fast.du, sum(1, s1)),
                (fast.dv, sum(2, s1)),
                (fast.duu, sum(3, s2)),
                (fast.duv, sum(4, s2)),
                (fast.dvv, sum(5, s2)),
            ] {
                assert!((got - want).length() < 1e-12, "{got} vs {want}");
            }
        }
    }

    #[test]
    fn the_quartic_lattice_constant_is_the_lattice_order() {
        assert_eq!(super::QUARTIC_LATTICE.to_vec(), super::lattice_points(4));
    }

    use super::*;
    use glam::DVec3;

    #[test]
    fn equals_loop_limit_masks_at_points_it_was_not_derived_from() {
        // Control net = a lattice mesh with bumpy heights; subdivide it three times and
        // compare the limit mask at interior fine vertices with the spline there.
        let n = 4;
        let s = LatticeSpline::new(n);
        let m = s.control_segments();
        let controls: Vec<DVec3> = lattice_points(m)
            .into_iter()
            .map(|(a, b)| DVec3::new(a as f64, b as f64, ((a * 7 + b * 13) % 5) as f64 * 0.1))
            .collect();
        let mesh =
            crate::TriMesh::new(controls.clone(), super::super::bezier::lattice_triangles(m));
        let fine = crate::mesh::loop_subdiv::subdivide(&mesh, 3).expect("manifold");
        let topo = Topology::from_mesh(&fine).expect("manifold");
        let mut checked = 0;
        for v in 0..fine.positions.len() as u32 {
            let ring = topo.ring(v);
            if topo.is_boundary(v) || ring.len() != 6 {
                continue;
            }
            // Loop keeps linear functions of the lattice: x, y of the fine vertex are its
            // lattice coordinates. The limit of x, y is x, y again on a regular lattice.
            let p = fine.positions[v as usize];
            let (x, y) = (p.x - 1.0, p.y - 1.0);
            if x < 0.0 || y < 0.0 || x + y > n as f64 {
                continue;
            }
            let limit = fine.positions[v as usize] * 0.5
                + ring
                    .iter()
                    .map(|&w| fine.positions[w as usize])
                    .sum::<DVec3>()
                    / 12.0;
            let e = s.evaluate(
                &controls,
                SurfaceParam {
                    face: 0,
                    u: x / n as f64,
                    v: y / n as f64,
                },
            );
            assert!(
                (e.position - limit).length() < 1e-12,
                "at ({x}, {y}): {} vs {}",
                e.position,
                limit
            );
            checked += 1;
        }
        assert!(checked > 100, "only {checked} points checked");
    }

    #[test]
    fn closed_form_quartic_bernstein_matches_the_general_evaluator() {
        for &(u, v) in &[(0.1, 0.2), (0.7, 0.05), (0.0, 0.0), (0.3, 0.7)] {
            let mut rows = BasisDerivRows::default();
            BezierTriangle::new(4)
                .basis_rows_with_derivatives(SurfaceParam { face: 0, u, v }, &mut rows);
            let closed = quartic_bernstein(u, v);
            for (r, &i) in rows.indices.iter().enumerate() {
                for (d, (a, b)) in rows.weights[r].iter().zip(closed[i as usize]).enumerate() {
                    assert!(
                        (a - b).abs() < 1e-12,
                        "({u},{v}) basis {i} derivative {d}: {a} vs {b}"
                    );
                }
            }
        }
    }

    #[test]
    fn basis_is_a_partition_of_unity_and_non_negative() {
        let s = LatticeSpline::new(6);
        for &(u, v) in &[
            (0.1, 0.2),
            (0.5, 0.3),
            (0.0, 0.0),
            (0.33, 0.66),
            (0.9, 0.05),
        ] {
            let mut row = Vec::new();
            s.basis_row(SurfaceParam { face: 0, u, v }, &mut row);
            let sum: f64 = row.iter().map(|r| r.1).sum();
            assert!((sum - 1.0).abs() < 1e-12, "({u},{v}): sum {sum}");
            assert!(row.iter().all(|r| r.1 > -1e-12), "({u},{v}): {row:?}");
        }
    }

    #[test]
    fn reproduces_linear_functions_and_is_continuous() {
        let s = LatticeSpline::new(5);
        let m = s.control_segments();
        // Control points on a plane: the surface is that plane, with (u, v) mapped exactly.
        let controls: Vec<DVec3> = lattice_points(m)
            .into_iter()
            .map(|(a, b)| {
                let (x, y) = ((a as f64 - 1.0) / 5.0, (b as f64 - 1.0) / 5.0);
                DVec3::new(x, y, 0.3 * x - 0.2 * y)
            })
            .collect();
        let p = s.evaluate(
            &controls,
            SurfaceParam {
                face: 0,
                u: 0.37,
                v: 0.21,
            },
        );
        assert!((p.position - DVec3::new(0.37, 0.21, 0.3 * 0.37 - 0.2 * 0.21)).length() < 1e-12);
        assert!(
            (p.du - DVec3::new(1.0, 0.0, 0.3)).length() < 1e-10,
            "{}",
            p.du
        );
        // Continuity across a cell edge with curved data.
        let bumpy: Vec<DVec3> = controls
            .iter()
            .enumerate()
            .map(|(k, c)| *c + DVec3::Z * ((k * 37 % 11) as f64 * 0.01))
            .collect();
        for &(u, v) in &[(0.4, 0.1), (0.2, 0.2), (0.6, 0.2)] {
            let e = 1e-9;
            let a = s.evaluate(
                &bumpy,
                SurfaceParam {
                    face: 0,
                    u: u - e,
                    v,
                },
            );
            let b = s.evaluate(
                &bumpy,
                SurfaceParam {
                    face: 0,
                    u: u + e,
                    v,
                },
            );
            assert!((a.position - b.position).length() < 1e-7);
            assert!((a.du - b.du).length() < 1e-5, "{} vs {}", a.du, b.du);
        }
    }
}
