//! Squared-distance minimisation (point-to-plane with a tangential share) at fixed foot
//! points: minimise
//!     sum_j (n_j . (S(u_j) - p_j))^2 + t |S(u_j) - p_j|^2  +  s |L P|^2
//! over the control points P, where u_j are foot points of the data on the current surface
//! and n_j the surface normals there. Unlike point-to-point fitting with parameter
//! correction, the surface may slide along itself at no cost, so a few rounds reach what
//! many rounds of parameter correction approach slowly. `t` keeps the system definite
//! where the normals alone leave a direction free (flat regions, no data).
//!
//! Solved by conjugate gradients on the (symmetric positive definite) normal equations,
//! with the three coordinates coupled through n_j n_j^T, preconditioned by the 3x3 diagonal
//! blocks: with a small `t` the system is ~1/t times stiffer along the normals than along
//! the surface, and the blocks, which see each control's local normal, take most of that
//! spread out of the iteration.

use super::sparse::Collocation;
use glam::DVec3;
use rayon::prelude::*;

pub struct DistanceProblem<'a> {
    pub basis: &'a Collocation,
    pub data: &'a [DVec3],
    /// Unit surface normals at the foot points, one per data point.
    pub normals: &'a [DVec3],
    /// Weight of the full point-to-point term beside the point-to-plane one.
    pub tangential: f64,
    pub fairness: Option<&'a Collocation>,
    pub smoothing: f64,
}

impl DistanceProblem<'_> {
    /// (n n^T + t I) r for every data point.
    fn weigh(&self, r: &mut [DVec3]) {
        let t = self.tangential;
        r.par_iter_mut()
            .zip(self.normals.par_iter())
            .for_each(|(r, n)| *r = *n * n.dot(*r) + *r * t);
    }

    /// N^T W p.
    fn rhs(&self) -> Vec<DVec3> {
        let mut wp = self.data.to_vec();
        self.weigh(&mut wp);
        let mut b = vec![DVec3::ZERO; self.basis.ncols()];
        self.basis.mul_t_vec3(&wp, &mut b);
        b
    }

    /// M x = N^T W N x + s L^T L x without assembling M: the reference the assembled
    /// blocks are tested against.
    #[cfg(test)]
    fn apply(&self, x: &[DVec3], scratch: &mut Vec<DVec3>, out: &mut [DVec3]) {
        scratch.resize(self.basis.nrows(), DVec3::ZERO);
        self.basis.mul_vec3(x, scratch);
        self.weigh(scratch);
        self.basis.mul_t_vec3(scratch, out);
        if let Some(l) = self.fairness.filter(|_| self.smoothing > 0.0) {
            let mut lx = vec![DVec3::ZERO; l.nrows()];
            l.mul_vec3(x, &mut lx);
            let mut ltlx = vec![DVec3::ZERO; x.len()];
            l.mul_t_vec3(&lx, &mut ltlx);
            out.iter_mut()
                .zip(&ltlx)
                .for_each(|(o, v)| *o += *v * self.smoothing);
        }
    }
}

fn dot(a: &[DVec3], b: &[DVec3]) -> f64 {
    a.par_iter().zip(b.par_iter()).map(|(x, y)| x.dot(*y)).sum()
}

/// Conjugate gradients from `start` until the residual of the normal equations drops by
/// `rel_tol` or `max_iter` steps; returns the controls and the steps taken.
pub fn solve_distance(
    p: &DistanceProblem,
    start: Vec<DVec3>,
    max_iter: usize,
    rel_tol: f64,
) -> (Vec<DVec3>, usize) {
    let m = start.len();
    let mut x = start;
    let b = p.rhs();
    let matrix = BlockMatrix::assemble(p, false);
    let mut mx = vec![DVec3::ZERO; m];
    matrix.apply(&x, &mut mx);
    let mut r: Vec<DVec3> = b.iter().zip(&mx).map(|(b, a)| *b - *a).collect();
    let precond = matrix.block_jacobi();
    let apply_precond = |r: &[DVec3], z: &mut Vec<DVec3>| {
        z.clear();
        z.par_extend(r.par_iter().zip(precond.par_iter()).map(|(r, m)| *m * *r));
    };
    let mut z = Vec::with_capacity(m);
    apply_precond(&r, &mut z);
    let mut d = z.clone();
    let mut rz = dot(&r, &z);
    let stop = rel_tol * rel_tol * dot(&b, &b).max(1e-300);
    let mut md = vec![DVec3::ZERO; m];
    for k in 0..max_iter {
        if dot(&r, &r) <= stop {
            return (x, k);
        }
        matrix.apply(&d, &mut md);
        let dmd = dot(&d, &md);
        if dmd <= 0.0 || !dmd.is_finite() {
            return (x, k);
        }
        let alpha = rz / dmd;
        x.iter_mut().zip(&d).for_each(|(x, d)| *x += *d * alpha);
        r.iter_mut().zip(&md).for_each(|(r, v)| *r -= *v * alpha);
        apply_precond(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        d.iter_mut().zip(&z).for_each(|(d, z)| *d = *z + *d * beta);
    }
    (x, max_iter)
}

/// The same minimiser by a sparse Cholesky factorisation of the 3m x 3m normal matrix
/// (faer, fill-reducing ordering): on scan-sized nets one factorisation costs less than the
/// 25-45 preconditioned CG steps a round needs, and it is exact. `None` when the matrix is
/// not positive definite (controls no term holds): callers fall back to `solve_distance`.
pub fn solve_distance_direct(p: &DistanceProblem) -> Option<Vec<DVec3>> {
    use faer::linalg::solvers::Solve;
    use faer::sparse::{SparseColMat, SymbolicSparseColMat};
    let m = p.basis.ncols();
    let lower = BlockMatrix::assemble(p, true);
    let mut col_ptr = Vec::with_capacity(3 * m + 1);
    col_ptr.push(0);
    let (mut rows, mut vals) = (Vec::new(), Vec::new());
    for c in 0..m {
        let range = lower.ptr[c]..lower.ptr[c + 1];
        for qc in 0..3 {
            for k in range.clone() {
                let j = lower.idx[k] as usize;
                // Lower triangle: in the diagonal block only rows >= the column.
                let first = if j == c { qc } else { 0 };
                for r in first..3 {
                    rows.push(3 * j + r);
                    vals.push(lower.blocks[k][3 * r + qc]);
                }
            }
            col_ptr.push(rows.len());
        }
    }
    let symbolic = SymbolicSparseColMat::new_checked(3 * m, 3 * m, col_ptr, None, rows);
    let llt = SparseColMat::new(symbolic, vals)
        .sp_cholesky(faer::Side::Lower)
        .ok()?;
    let b = p.rhs();
    let mut rhs = faer::Mat::<f64>::from_fn(3 * m, 1, |i, _| b[i / 3][i % 3]);
    llt.solve_in_place(rhs.as_mut());
    let x: Vec<DVec3> = (0..m)
        .map(|c| DVec3::new(rhs[(3 * c, 0)], rhs[(3 * c + 1, 0)], rhs[(3 * c + 2, 0)]))
        .collect();
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// M = N^T W N + s L^T L assembled as 3x3 blocks per pair of controls sharing a data point
/// (or a fairness row): per control c its neighbours j and the blocks M_jc (symmetric, since
/// every weight n n^T + t I is). A product with M then reads ~37 blocks per control instead
/// of going through the data twice (N, then N^T), four to five times less work per CG step
/// on a scan, for one assembly per solve.
struct BlockMatrix {
    ptr: Vec<usize>,
    idx: Vec<u32>,
    blocks: Vec<[f64; 9]>,
}

impl BlockMatrix {
    /// `lower_only`: only the blocks with j >= c (for the factorisation).
    fn assemble(p: &DistanceProblem, lower_only: bool) -> Self {
        let (n, nt) = (p.basis.n(), p.basis.nt());
        let m = n.ncols;
        let t = p.tangential;
        let fair = p
            .fairness
            .filter(|_| p.smoothing > 0.0)
            .map(|l| (l.n(), l.nt()));
        let columns: Vec<(Vec<u32>, Vec<[f64; 9]>)> = (0..m)
            .into_par_iter()
            .map_init(
                || (vec![[0.0f64; 9]; m], vec![false; m], Vec::<usize>::new()),
                |(acc, seen, touched), c| {
                    touched.clear();
                    let mut add = |j: usize, w: f64, block: &[f64; 9]| {
                        if lower_only && j < c {
                            return;
                        }
                        if !seen[j] {
                            seen[j] = true;
                            touched.push(j);
                        }
                        for (a, b) in acc[j].iter_mut().zip(block) {
                            *a += w * b;
                        }
                    };
                    for k in nt.row_ptr[c]..nt.row_ptr[c + 1] {
                        let (r, wc) = (nt.col_idx[k] as usize, nt.values[k]);
                        let q = p.normals[r];
                        let block = [
                            q.x * q.x + t,
                            q.x * q.y,
                            q.x * q.z,
                            q.y * q.x,
                            q.y * q.y + t,
                            q.y * q.z,
                            q.z * q.x,
                            q.z * q.y,
                            q.z * q.z + t,
                        ];
                        for e in n.row_ptr[r]..n.row_ptr[r + 1] {
                            add(n.col_idx[e] as usize, wc * n.values[e], &block);
                        }
                    }
                    if let Some((l, lt)) = fair {
                        let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
                        for k in lt.row_ptr[c]..lt.row_ptr[c + 1] {
                            let (r, wc) = (lt.col_idx[k] as usize, lt.values[k] * p.smoothing);
                            for e in l.row_ptr[r]..l.row_ptr[r + 1] {
                                add(l.col_idx[e] as usize, wc * l.values[e], &identity);
                            }
                        }
                    }
                    touched.sort_unstable();
                    let idx: Vec<u32> = touched.iter().map(|&j| j as u32).collect();
                    let blocks = touched
                        .iter()
                        .map(|&j| {
                            seen[j] = false;
                            std::mem::replace(&mut acc[j], [0.0; 9])
                        })
                        .collect();
                    (idx, blocks)
                },
            )
            .collect();
        let mut ptr = Vec::with_capacity(m + 1);
        ptr.push(0);
        let (mut idx, mut blocks) = (Vec::new(), Vec::new());
        for (i, b) in columns {
            idx.extend(i);
            blocks.extend(b);
            ptr.push(idx.len());
        }
        Self { ptr, idx, blocks }
    }

    fn apply(&self, x: &[DVec3], out: &mut [DVec3]) {
        out.par_iter_mut().enumerate().for_each(|(c, o)| {
            let mut sum = DVec3::ZERO;
            for k in self.ptr[c]..self.ptr[c + 1] {
                let (b, v) = (&self.blocks[k], x[self.idx[k] as usize]);
                sum += DVec3::new(
                    b[0] * v.x + b[1] * v.y + b[2] * v.z,
                    b[3] * v.x + b[4] * v.y + b[5] * v.z,
                    b[6] * v.x + b[7] * v.y + b[8] * v.z,
                );
            }
            *o = sum;
        });
    }

    /// Inverses of the diagonal blocks; one that cannot be inverted (no data, no fairness)
    /// becomes the identity.
    fn block_jacobi(&self) -> Vec<glam::DMat3> {
        (0..self.ptr.len() - 1)
            .into_par_iter()
            .map(|c| {
                let range = self.ptr[c]..self.ptr[c + 1];
                let Some(k) = range.clone().find(|&k| self.idx[k] as usize == c) else {
                    return glam::DMat3::IDENTITY;
                };
                let b = self.blocks[k];
                // Row-major storage of a symmetric block: the transpose is the same matrix.
                let mat = glam::DMat3::from_cols_array(&b);
                let scale = b[0].max(b[4]).max(b[8]);
                let det = mat.determinant();
                if scale > 0.0 && det.is_finite() && det > 1e-12 * scale * scale * scale {
                    mat.inverse()
                } else {
                    glam::DMat3::IDENTITY
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::Csr;

    /// With t = 1 and zero normals the problem is plain least squares: compare with the
    /// normal equations solved densely.
    #[test]
    fn reduces_to_least_squares_and_matches_a_dense_solve() {
        let rows: Vec<Vec<(u32, f64)>> = (0..40)
            .map(|j| {
                let a = (j % 7) as u32;
                vec![
                    (a, 0.6),
                    ((a + 1) % 7, 0.3),
                    ((a + 3) % 7, 0.1 + 0.001 * j as f64),
                ]
            })
            .collect();
        let basis = Collocation::new(Csr::from_rows(7, rows.iter().map(|r| r.as_slice())));
        let data: Vec<DVec3> = (0..40)
            .map(|j| DVec3::new(j as f64 * 0.1, (j as f64).sin(), (j * j % 5) as f64))
            .collect();
        let normals = vec![DVec3::ZERO; 40];
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: 1.0,
            fairness: None,
            smoothing: 0.0,
        };
        let (x, _) = solve_distance(&p, vec![DVec3::ZERO; 7], 200, 1e-14);
        let mut a = nalgebra::DMatrix::<f64>::zeros(40, 7);
        for (j, row) in rows.iter().enumerate() {
            for &(c, w) in row {
                a[(j, c as usize)] += w;
            }
        }
        let ata = a.transpose() * &a;
        for axis in 0..3 {
            let rhs = nalgebra::DVector::from_iterator(40, data.iter().map(|d| d[axis]));
            let want = ata
                .clone()
                .cholesky()
                .expect("definite")
                .solve(&(a.transpose() * rhs));
            for c in 0..7 {
                assert!(
                    (x[c][axis] - want[c]).abs() < 1e-9,
                    "{} vs {}",
                    x[c][axis],
                    want[c]
                );
            }
        }
    }

    /// Point-to-plane only moves controls along the normals: data displaced tangentially
    /// leave a plane fit where it is.
    #[test]
    fn tangential_offsets_cost_nothing_without_the_tangential_share() {
        let rows: Vec<Vec<(u32, f64)>> = (0..20).map(|j| vec![((j % 4) as u32, 1.0)]).collect();
        let basis = Collocation::new(Csr::from_rows(4, rows.iter().map(|r| r.as_slice())));
        let data: Vec<DVec3> = (0..20)
            .map(|j| DVec3::new((j % 3) as f64, (j % 5) as f64, 0.25))
            .collect();
        let normals = vec![DVec3::Z; 20];
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: 0.0,
            fairness: None,
            smoothing: 0.0,
        };
        let start = vec![DVec3::new(9.0, -3.0, 0.0); 4];
        let (x, _) = solve_distance(&p, start, 100, 1e-14);
        for c in &x {
            assert!(
                (c.z - 0.25).abs() < 1e-12 && c.x == 9.0 && c.y == -3.0,
                "{c}"
            );
        }
    }
    /// The coupled system with a small tangential share and varied normals (what the
    /// block preconditioner is for) against a dense solve of the 3m x 3m normal equations.
    #[test]
    fn coupled_system_matches_a_dense_solve() {
        let m = 9;
        let rows: Vec<Vec<(u32, f64)>> = (0..60)
            .map(|j| {
                let a = (j % m) as u32;
                vec![
                    (a, 0.5),
                    ((a + 1) % m as u32, 0.3),
                    ((a + 4) % m as u32, 0.2),
                ]
            })
            .collect();
        let basis = Collocation::new(Csr::from_rows(m, rows.iter().map(|r| r.as_slice())));
        let data: Vec<DVec3> = (0..60)
            .map(|j| {
                DVec3::new(
                    (j as f64 * 0.7).sin(),
                    (j as f64 * 0.3).cos(),
                    j as f64 * 0.01,
                )
            })
            .collect();
        let normals: Vec<DVec3> = (0..60)
            .map(|j| DVec3::new(0.3 * (j as f64).sin(), 0.2, 1.0).normalize())
            .collect();
        let t = 0.02;
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: t,
            fairness: None,
            smoothing: 0.0,
        };
        let (x, steps) = solve_distance(&p, vec![DVec3::ZERO; m], 500, 1e-13);
        assert!(steps < 500, "converged");
        let mut mat = nalgebra::DMatrix::<f64>::zeros(3 * m, 3 * m);
        let mut rhs = nalgebra::DVector::<f64>::zeros(3 * m);
        for (j, row) in rows.iter().enumerate() {
            let n = normals[j];
            let w = glam::DMat3::from_cols(n * n.x, n * n.y, n * n.z) + glam::DMat3::IDENTITY * t;
            let wp = w * data[j];
            for &(a, wa) in row {
                for r in 0..3 {
                    rhs[3 * a as usize + r] += wa * wp[r];
                }
                for &(b, wb) in row {
                    for r in 0..3 {
                        for c in 0..3 {
                            mat[(3 * a as usize + r, 3 * b as usize + c)] += wa * wb * w.col(c)[r];
                        }
                    }
                }
            }
        }
        let want = mat.cholesky().expect("definite").solve(&rhs);
        let direct = solve_distance_direct(&p).expect("definite");
        for c in 0..m {
            for r in 0..3 {
                assert!(
                    (x[c][r] - want[3 * c + r]).abs() < 1e-8,
                    "{} vs {}",
                    x[c][r],
                    want[3 * c + r]
                );
                assert!(
                    (direct[c][r] - want[3 * c + r]).abs() < 1e-10,
                    "direct {} vs {}",
                    direct[c][r],
                    want[3 * c + r]
                );
            }
        }
    }
    /// The assembled blocks (with a fairness term) against the product through N and N^T.
    #[test]
    fn assembled_blocks_equal_the_product_through_the_data() {
        let m = 8;
        let rows: Vec<Vec<(u32, f64)>> = (0..50)
            .map(|j| {
                let a = (j % m) as u32;
                vec![
                    (a, 0.6),
                    ((a + 2) % m as u32, 0.3),
                    ((a + 5) % m as u32, 0.1),
                ]
            })
            .collect();
        let basis = Collocation::new(Csr::from_rows(m, rows.iter().map(|r| r.as_slice())));
        let lap: Vec<Vec<(u32, f64)>> = (0..m as u32)
            .map(|i| {
                vec![
                    (i, 1.0),
                    ((i + 1) % m as u32, -0.5),
                    ((i + 7) % m as u32, -0.5),
                ]
            })
            .collect();
        let fairness = Collocation::new(Csr::from_rows(m, lap.iter().map(|r| r.as_slice())));
        let data: Vec<DVec3> = (0..50).map(|j| DVec3::splat(j as f64)).collect();
        let normals: Vec<DVec3> = (0..50)
            .map(|j| DVec3::new((j as f64).cos(), 0.3, (j as f64).sin()).normalize())
            .collect();
        let p = DistanceProblem {
            basis: &basis,
            data: &data,
            normals: &normals,
            tangential: 0.05,
            fairness: Some(&fairness),
            smoothing: 0.7,
        };
        let x: Vec<DVec3> = (0..m)
            .map(|c| DVec3::new(c as f64, (c * c) as f64 * 0.1, -(c as f64)))
            .collect();
        let (mut want, mut got) = (vec![DVec3::ZERO; m], vec![DVec3::ZERO; m]);
        p.apply(&x, &mut Vec::new(), &mut want);
        BlockMatrix::assemble(&p, false).apply(&x, &mut got);
        for (a, b) in want.iter().zip(&got) {
            assert!(
                (*a - *b).length() < 1e-12 * a.length().max(1.0),
                "{a} vs {b}"
            );
        }
    }
}
