//! A single triangular Bezier patch of degree n over the reference triangle.
//!
//! Control point `P_{i,j,k}` (i + j + k = n) has weight `n!/(i! j! k!) u^i v^j w^k` and sits
//! at lattice index `lattice_index(n, i, j)`; its natural domain location is (i/n, j/n).
//! Basis values come from the triangular de Casteljau recurrence on the weights (only
//! sums of products of numbers in [0, 1]), which stays accurate at degree 32 and beyond
//! where factorials times powers lose everything.

use super::{BasisDerivRows, SurfaceParam, TriSurface};

/// Index of lattice point (i, j) in a triangular lattice with n segments a side: rows of
/// constant j, i = 0..=n-j.
#[inline]
pub fn lattice_index(n: usize, i: usize, j: usize) -> usize {
    j * (n + 1) - j * j.saturating_sub(1) / 2 + i
}

/// Number of points of a lattice with n segments a side.
#[inline]
pub fn lattice_len(n: usize) -> usize {
    (n + 1) * (n + 2) / 2
}

/// (i, j) of every lattice index, in index order.
pub fn lattice_points(n: usize) -> Vec<(usize, usize)> {
    (0..=n)
        .flat_map(|j| (0..=n - j).map(move |i| (i, j)))
        .collect()
}

/// The lattice's triangles, counter-clockwise in (u, v): per cell an "up" triangle
/// (i,j),(i+1,j),(i,j+1) and, where it exists, a "down" one (i+1,j),(i+1,j+1),(i,j+1).
pub fn lattice_triangles(n: usize) -> Vec<[u32; 3]> {
    let id = |i: usize, j: usize| lattice_index(n, i, j) as u32;
    let mut t = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n - j {
            t.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
            if i + j + 2 <= n {
                t.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }
    t
}

#[derive(Clone, Debug)]
/// A triangular Bezier patch of one degree over the reference triangle.
pub struct BezierTriangle {
    /// The degree n ((n + 1)(n + 2) / 2 controls).
    pub degree: usize,
}

impl BezierTriangle {
    /// A patch of degree `degree`.
    pub fn new(degree: usize) -> Self {
        Self { degree }
    }

    /// Bernstein values of every degree 0..=n at (u, v, w), level r stored in lattice order.
    fn pyramid(&self, u: f64, v: f64) -> Vec<Vec<f64>> {
        let w = 1.0 - u - v;
        let n = self.degree;
        let mut levels = Vec::with_capacity(n + 1);
        levels.push(vec![1.0]);
        for r in 1..=n {
            let prev: &Vec<f64> = &levels[r - 1];
            let mut cur = vec![0.0; lattice_len(r)];
            for j in 0..=r {
                for i in 0..=r - j {
                    let k = r - i - j;
                    let mut b = 0.0;
                    if i > 0 {
                        b += u * prev[lattice_index(r - 1, i - 1, j)];
                    }
                    if j > 0 {
                        b += v * prev[lattice_index(r - 1, i, j - 1)];
                    }
                    if k > 0 {
                        b += w * prev[lattice_index(r - 1, i, j)];
                    }
                    cur[lattice_index(r, i, j)] = b;
                }
            }
            levels.push(cur);
        }
        levels
    }
}

impl TriSurface for BezierTriangle {
    fn control_count(&self) -> usize {
        lattice_len(self.degree)
    }

    fn domain_face_count(&self) -> usize {
        1
    }

    fn basis_row(&self, p: SurfaceParam, out: &mut Vec<(u32, f64)>) {
        out.clear();
        let levels = self.pyramid(p.u, p.v);
        let top = &levels[self.degree];
        out.extend(top.iter().enumerate().map(|(i, &b)| (i as u32, b)));
    }

    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows) {
        let n = self.degree;
        let levels = self.pyramid(p.u, p.v);
        out.indices.clear();
        out.weights.clear();
        let get = |r: usize, i: isize, j: isize| -> f64 {
            let k = r as isize - i - j;
            if i < 0 || j < 0 || k < 0 {
                0.0
            } else {
                levels[r][lattice_index(r, i as usize, j as usize)]
            }
        };
        let nf = n as f64;
        let n2 = nf * (nf - 1.0);
        for (idx, (i, j)) in lattice_points(n).into_iter().enumerate() {
            let (i, j) = (i as isize, j as isize);
            let val = levels[n][idx];
            // d/du = n (B^{n-1}_{i-1,j,k} - B^{n-1}_{i,j,k-1}); index (i, j) of degree n-1 is
            // the term with k lowered.
            let (d1u, d1v, d2uu, d2uv, d2vv) = if n >= 1 {
                let m = n - 1;
                let du = nf * (get(m, i - 1, j) - get(m, i, j));
                let dv = nf * (get(m, i, j - 1) - get(m, i, j));
                let (uu, uv, vv) = if n >= 2 {
                    let q = n - 2;
                    (
                        n2 * (get(q, i - 2, j) - 2.0 * get(q, i - 1, j) + get(q, i, j)),
                        n2 * (get(q, i - 1, j - 1) - get(q, i - 1, j) - get(q, i, j - 1)
                            + get(q, i, j)),
                        n2 * (get(q, i, j - 2) - 2.0 * get(q, i, j - 1) + get(q, i, j)),
                    )
                } else {
                    (0.0, 0.0, 0.0)
                };
                (du, dv, uu, uv, vv)
            } else {
                (0.0, 0.0, 0.0, 0.0, 0.0)
            };
            out.indices.push(idx as u32);
            out.weights.push([val, d1u, d1v, d2uu, d2uv, d2vv]);
        }
    }

    fn as_bezier(&self) -> Option<&BezierTriangle> {
        Some(self)
    }

    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam {
        // Clamp into the triangle: first the coordinates, then the hypotenuse.
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// Independent reference: repeated de Casteljau on control points (for tests).
    fn de_casteljau(n: usize, controls: &[DVec3], u: f64, v: f64) -> DVec3 {
        let w = 1.0 - u - v;
        let mut pts = controls.to_vec();
        for r in (1..=n).rev() {
            let mut next = vec![DVec3::ZERO; lattice_len(r - 1)];
            for j in 0..r {
                for i in 0..r - j {
                    next[lattice_index(r - 1, i, j)] = pts[lattice_index(r, i + 1, j)] * u
                        + pts[lattice_index(r, i, j + 1)] * v
                        + pts[lattice_index(r, i, j)] * w;
                }
            }
            pts = next;
        }
        pts[0]
    }

    fn controls(n: usize) -> Vec<DVec3> {
        lattice_points(n)
            .into_iter()
            .map(|(i, j)| {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                DVec3::new(
                    x,
                    y,
                    (3.0 * x).sin() * (2.0 * y).cos() + 0.1 * ((i * 7 + j * 13) % 5) as f64,
                )
            })
            .collect()
    }

    #[test]
    fn lattice_index_is_a_bijection() {
        for n in [1, 4, 24] {
            let pts = lattice_points(n);
            assert_eq!(pts.len(), lattice_len(n));
            for (k, (i, j)) in pts.into_iter().enumerate() {
                assert_eq!(lattice_index(n, i, j), k);
            }
            assert_eq!(lattice_triangles(n).len(), n * n);
        }
    }

    #[test]
    fn matches_de_casteljau_up_to_degree_40() {
        for n in [1, 4, 12, 24, 40] {
            let c = controls(n);
            let s = BezierTriangle::new(n);
            for &(u, v) in &[
                (0.2, 0.3),
                (0.0, 0.0),
                (1.0, 0.0),
                (0.05, 0.9),
                (1.0 / 3.0, 1.0 / 3.0),
            ] {
                let a = s.evaluate(&c, SurfaceParam { face: 0, u, v }).position;
                let b = de_casteljau(n, &c, u, v);
                assert!(
                    (a - b).length() <= 1e-12 * b.length().max(1.0),
                    "n={n} ({u},{v}): {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn basis_is_a_partition_of_unity_and_derivatives_match_differences() {
        let n = 9;
        let c = controls(n);
        let s = BezierTriangle::new(n);
        let p = SurfaceParam {
            face: 0,
            u: 0.27,
            v: 0.41,
        };
        let mut row = Vec::new();
        s.basis_row(p, &mut row);
        let sum: f64 = row.iter().map(|r| r.1).sum();
        assert!((sum - 1.0).abs() < 1e-14 && row.iter().all(|r| r.1 >= 0.0));
        let h = 1e-5;
        let at = |u: f64, v: f64| s.evaluate(&c, SurfaceParam { face: 0, u, v });
        let d = at(p.u, p.v);
        let fd_u = (at(p.u + h, p.v).position - at(p.u - h, p.v).position) / (2.0 * h);
        let fd_v = (at(p.u, p.v + h).position - at(p.u, p.v - h).position) / (2.0 * h);
        let fd_uu = (at(p.u + h, p.v).du - at(p.u - h, p.v).du) / (2.0 * h);
        let fd_uv = (at(p.u, p.v + h).du - at(p.u, p.v - h).du) / (2.0 * h);
        let fd_vv = (at(p.u, p.v + h).dv - at(p.u, p.v - h).dv) / (2.0 * h);
        for (a, b) in [
            (d.du, fd_u),
            (d.dv, fd_v),
            (d.duu, fd_uu),
            (d.duv, fd_uv),
            (d.dvv, fd_vv),
        ] {
            assert!((a - b).length() < 1e-5 * b.length().max(1.0), "{a} vs {b}");
        }
    }
}
