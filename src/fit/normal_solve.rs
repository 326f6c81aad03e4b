//! Solving the assembled normal equations of `normal_matrix`: preconditioned conjugate
//! gradients (Jacobi for the scalar matrix, inverse 3x3 diagonal blocks for the coupled
//! one) and sparse Cholesky factorisations (faer, fill-reducing ordering).

use super::normal_matrix::{BlockMatrix, ScalarMatrix, SCALAR};
use glam::DVec3;
use rayon::prelude::*;

/// Below this many controls a vector operation is cheaper on one thread than handing it to
/// the pool (a 2000-control dot product takes ~2 us; a parallel one waits longer than that
/// for the other thread).
const PARALLEL_VECTOR_MIN: usize = 1 << 14;

fn dot(a: &[DVec3], b: &[DVec3]) -> f64 {
    if a.len() < PARALLEL_VECTOR_MIN {
        return a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum();
    }
    a.par_iter().zip(b.par_iter()).map(|(x, y)| x.dot(*y)).sum()
}

/// The product of either kind of normal matrix, for `pcg`.
trait Apply {
    fn apply_to(&self, x: &[DVec3], out: &mut [DVec3]);
    fn rhs(&self) -> &[DVec3];
}

impl Apply for ScalarMatrix {
    fn apply_to(&self, x: &[DVec3], out: &mut [DVec3]) {
        self.apply(x, out)
    }
    fn rhs(&self) -> &[DVec3] {
        &self.rhs
    }
}

impl Apply for BlockMatrix {
    fn apply_to(&self, x: &[DVec3], out: &mut [DVec3]) {
        self.apply(x, out)
    }
    fn rhs(&self) -> &[DVec3] {
        &self.rhs
    }
}

/// Preconditioned conjugate gradients on M x = b from `start` (`precondition(c, r_c)` is
/// the preconditioner's block of control c applied to the residual there) until the
/// residual drops by `rel_tol` relative to b or `max_iter` steps; returns x and the steps.
fn pcg(
    matrix: &impl Apply,
    precondition: impl Fn(usize, DVec3) -> DVec3 + Sync,
    start: Vec<DVec3>,
    max_iter: usize,
    rel_tol: f64,
) -> (Vec<DVec3>, usize) {
    let b = matrix.rhs();
    let precondition_all = |r: &[DVec3], z: &mut Vec<DVec3>| {
        z.clear();
        if r.len() < PARALLEL_VECTOR_MIN {
            z.extend(r.iter().enumerate().map(|(c, r)| precondition(c, *r)));
        } else {
            z.par_extend(r.par_iter().enumerate().map(|(c, r)| precondition(c, *r)));
        }
    };
    let m = start.len();
    let mut x = start;
    let mut mx = vec![DVec3::ZERO; m];
    matrix.apply_to(&x, &mut mx);
    let mut r: Vec<DVec3> = b.iter().zip(&mx).map(|(b, a)| *b - *a).collect();
    let mut z = Vec::with_capacity(m);
    precondition_all(&r, &mut z);
    let mut d = z.clone();
    let mut rz = dot(&r, &z);
    let stop = rel_tol * rel_tol * dot(b, b).max(1e-300);
    let mut md = vec![DVec3::ZERO; m];
    for k in 0..max_iter {
        if dot(&r, &r) <= stop {
            return (x, k);
        }
        matrix.apply_to(&d, &mut md);
        let dmd = dot(&d, &md);
        if dmd <= 0.0 || !dmd.is_finite() {
            return (x, k);
        }
        let alpha = rz / dmd;
        x.iter_mut().zip(&d).for_each(|(x, d)| *x += *d * alpha);
        r.iter_mut().zip(&md).for_each(|(r, v)| *r -= *v * alpha);
        precondition_all(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        d.iter_mut().zip(&z).for_each(|(d, z)| *d = *z + *d * beta);
    }
    (x, max_iter)
}

/// faer's symbolic Cholesky analysis (fill-reducing ordering, elimination tree,
/// supernodes) of one sparsity pattern, kept for the next matrices whose pattern it
/// covers. The rounds of a planar fit solve one normal matrix per round over the same
/// controls: a pair of controls is coupled when some data point lies in both supports,
/// which foot points moving by a fraction of a cell rarely change, so one analysis serves
/// every round and each round pays only the numeric factorisation (in the stop-30 profile
/// of a 40k-point DMS fit the analysis was redone every round). A matrix with an entry
/// outside the kept pattern is analysed again over the union of both patterns, so later
/// rounds fit in it.
#[derive(Default)]
pub(crate) struct CholeskyPattern {
    size: usize,
    col_ptr: Vec<usize>,
    rows: Vec<usize>,
    symbolic: Option<faer::sparse::linalg::solvers::SymbolicLlt<usize>>,
    /// Symbolic analyses run.
    pub analyses: usize,
    /// Factorisations that reused the kept analysis.
    pub reuses: usize,
}

impl CholeskyPattern {
    /// The values of a lower-triangle matrix (`col_ptr`, `rows`, `vals`, rows sorted
    /// within each column) placed in the kept pattern, zero where the matrix has no
    /// entry; `None` when the matrix has an entry the pattern lacks.
    fn scatter(
        &self,
        size: usize,
        col_ptr: &[usize],
        rows: &[usize],
        vals: &[f64],
    ) -> Option<Vec<f64>> {
        if self.symbolic.is_none() || self.size != size {
            return None;
        }
        let mut out = vec![0.0; self.rows.len()];
        for col in 0..size {
            let kept = &self.rows[self.col_ptr[col]..self.col_ptr[col + 1]];
            let mut at = 0;
            for k in col_ptr[col]..col_ptr[col + 1] {
                let offset = kept[at..].iter().position(|&r| r == rows[k])?;
                at += offset;
                out[self.col_ptr[col] + at] = vals[k];
                at += 1;
            }
        }
        Some(out)
    }

    /// Analyses the union of the kept pattern (when of the same size) and this one, and
    /// returns the matrix's values in it.
    fn analyse(
        &mut self,
        size: usize,
        col_ptr: &[usize],
        rows: &[usize],
        vals: &[f64],
    ) -> Result<Vec<f64>, DirectFailure> {
        use faer::sparse::linalg::solvers::SymbolicLlt;
        use faer::sparse::SymbolicSparseColMatRef;
        let keep_old = self.symbolic.is_some() && self.size == size;
        let mut union_ptr = Vec::with_capacity(size + 1);
        union_ptr.push(0);
        let mut union_rows = Vec::with_capacity(rows.len());
        let mut union_vals = Vec::with_capacity(rows.len());
        for col in 0..size {
            let new = col_ptr[col]..col_ptr[col + 1];
            let old: &[usize] = if keep_old {
                &self.rows[self.col_ptr[col]..self.col_ptr[col + 1]]
            } else {
                &[]
            };
            let (mut i, mut k) = (0, new.start);
            while i < old.len() || k < new.end {
                let take_new = k < new.end && (i >= old.len() || rows[k] <= old[i]);
                if take_new {
                    if i < old.len() && old[i] == rows[k] {
                        i += 1;
                    }
                    union_rows.push(rows[k]);
                    union_vals.push(vals[k]);
                    k += 1;
                } else {
                    union_rows.push(old[i]);
                    union_vals.push(0.0);
                    i += 1;
                }
            }
            union_ptr.push(union_rows.len());
        }
        let pattern =
            SymbolicSparseColMatRef::new_checked(size, size, &union_ptr, None, &union_rows);
        let symbolic = SymbolicLlt::try_new(pattern, faer::Side::Lower)
            .map_err(|_| DirectFailure::NotDefinite)?;
        self.size = size;
        self.col_ptr = union_ptr;
        self.rows = union_rows;
        self.symbolic = Some(symbolic);
        self.analyses += 1;
        Ok(union_vals)
    }

    /// Factorises the lower triangle of a symmetric matrix given by columns (rows sorted
    /// within each column), reusing the kept analysis where it covers the pattern.
    fn factorize(
        &mut self,
        size: usize,
        col_ptr: &[usize],
        rows: &[usize],
        vals: &[f64],
    ) -> Result<faer::sparse::linalg::solvers::Llt<usize, f64>, DirectFailure> {
        use faer::sparse::linalg::solvers::Llt;
        use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
        let values = match self.scatter(size, col_ptr, rows, vals) {
            Some(values) => {
                self.reuses += 1;
                values
            }
            None => self.analyse(size, col_ptr, rows, vals)?,
        };
        let symbolic = self.symbolic.clone().ok_or(DirectFailure::NotDefinite)?;
        let pattern =
            SymbolicSparseColMatRef::new_checked(size, size, &self.col_ptr, None, &self.rows);
        Llt::try_new_with_symbolic(
            symbolic,
            SparseColMatRef::new(pattern, &values),
            faer::Side::Lower,
        )
        .map_err(|_| DirectFailure::NotDefinite)
    }
}

/// Lower triangle of a symmetric matrix given by columns (the `lower_only` assembly),
/// factorised through `pattern`.
fn cholesky_solve(
    pattern: &mut CholeskyPattern,
    size: usize,
    col_ptr: &[usize],
    rows: &[usize],
    vals: &[f64],
    rhs: impl Fn(usize, usize) -> f64,
    ncols_rhs: usize,
) -> Result<faer::Mat<f64>, DirectFailure> {
    use faer::linalg::solvers::Solve;
    let llt = pattern.factorize(size, col_ptr, rows, vals)?;
    let mut b = faer::Mat::<f64>::from_fn(size, ncols_rhs, rhs);
    llt.solve_in_place(b.as_mut());
    Ok(b)
}

/// Why a factorisation gave no solution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DirectFailure {
    /// M is not positive definite: controls no term holds.
    #[error("normal matrix is not positive definite: control points without data; add smoothing")]
    NotDefinite,
    /// The solve produced non-finite values (M is ill-conditioned).
    #[error("the factorisation produced non-finite values (ill-conditioned normal matrix)")]
    NotFinite,
}

fn finite(x: Vec<DVec3>) -> Result<Vec<DVec3>, DirectFailure> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(x)
    } else {
        Err(DirectFailure::NotFinite)
    }
}

impl ScalarMatrix {
    /// Jacobi-preconditioned CG.
    pub(crate) fn solve_pcg(
        &self,
        start: Vec<DVec3>,
        max_iter: usize,
        rel_tol: f64,
    ) -> (Vec<DVec3>, usize) {
        let inv = self.jacobi();
        let precondition = |c: usize, r: DVec3| r * inv[c];
        pcg(self, precondition, start, max_iter, rel_tol)
    }

    /// Sparse Cholesky (fill-reducing ordering) of a `lower_only` assembly.
    pub(crate) fn solve_direct(&self) -> Result<Vec<DVec3>, DirectFailure> {
        let m = self.rhs.len();
        let vals: Vec<f64> = self.entries.iter().map(|e| e[SCALAR]).collect();
        let rows: Vec<usize> = self.idx.iter().map(|&j| j as usize).collect();
        let mut pattern = CholeskyPattern::default();
        let b = cholesky_solve(
            &mut pattern,
            m,
            &self.ptr,
            &rows,
            &vals,
            |i, k| self.rhs[i][k],
            3,
        )?;
        let x: Vec<DVec3> = (0..m)
            .map(|i| DVec3::new(b[(i, 0)], b[(i, 1)], b[(i, 2)]))
            .collect();
        finite(x)
    }
}

impl BlockMatrix {
    /// CG preconditioned by the inverse 3x3 diagonal blocks: with a small tangential share
    /// the system is much stiffer along the normals than along the surface, and the blocks,
    /// which see each control's normal, take most of that spread out of the iteration.
    pub(crate) fn solve_pcg(
        &self,
        start: Vec<DVec3>,
        max_iter: usize,
        rel_tol: f64,
    ) -> (Vec<DVec3>, usize) {
        let inv = self.block_jacobi();
        let precondition = |c: usize, r: DVec3| inv[c] * r;
        pcg(self, precondition, start, max_iter, rel_tol)
    }

    /// Sparse Cholesky of the 3m x 3m matrix of a `lower_only` assembly.
    pub(crate) fn solve_direct(&self) -> Result<Vec<DVec3>, DirectFailure> {
        self.solve_direct_reusing(&mut CholeskyPattern::default())
    }

    /// `solve_direct` through a kept analysis (`CholeskyPattern`).
    pub(crate) fn solve_direct_reusing(
        &self,
        pattern: &mut CholeskyPattern,
    ) -> Result<Vec<DVec3>, DirectFailure> {
        let m = self.rhs.len();
        let mut col_ptr = Vec::with_capacity(3 * m + 1);
        col_ptr.push(0);
        let (mut rows, mut vals) = (Vec::new(), Vec::new());
        for c in 0..m {
            let range = self.ptr[c]..self.ptr[c + 1];
            for qc in 0..3 {
                for k in range.clone() {
                    let j = self.idx[k] as usize;
                    let block = Self::block(&self.entries[k]);
                    // Lower triangle: in the diagonal block only rows >= the column.
                    let first = if j == c { qc } else { 0 };
                    for r in first..3 {
                        rows.push(3 * j + r);
                        vals.push(block[3 * r + qc]);
                    }
                }
                col_ptr.push(rows.len());
            }
        }
        let b = cholesky_solve(
            pattern,
            3 * m,
            &col_ptr,
            &rows,
            &vals,
            |i, _| self.rhs[i / 3][i % 3],
            1,
        )?;
        let x: Vec<DVec3> = (0..m)
            .map(|c| DVec3::new(b[(3 * c, 0)], b[(3 * c + 1, 0)], b[(3 * c + 2, 0)]))
            .collect();
        finite(x)
    }
}
