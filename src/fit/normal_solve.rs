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

/// What `pcg` ended with.
struct CgEnd {
    x: Vec<DVec3>,
    steps: usize,
    /// The residual dropped below the asked share of b.
    converged: bool,
}

/// Preconditioned conjugate gradients on M x = b from `start` (`precondition(c, r_c)` is
/// the preconditioner's block of control c applied to the residual there) until the
/// residual drops by `rel_tol` relative to b or `max_iter` steps.
fn pcg(
    matrix: &impl Apply,
    precondition: impl Fn(usize, DVec3) -> DVec3 + Sync,
    start: Vec<DVec3>,
    max_iter: usize,
    rel_tol: f64,
) -> CgEnd {
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
    let stop = rel_tol * rel_tol * dot_centred(matrix, &x).max(1e-300);
    let mut md = vec![DVec3::ZERO; m];
    for k in 0..max_iter {
        if dot(&r, &r) <= stop {
            return CgEnd {
                x,
                steps: k,
                converged: true,
            };
        }
        matrix.apply_to(&d, &mut md);
        let dmd = dot(&d, &md);
        if dmd <= 0.0 || !dmd.is_finite() {
            return CgEnd {
                x,
                steps: k,
                converged: false,
            };
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
    let converged = dot(&r, &r) <= stop;
    CgEnd {
        x,
        steps: max_iter,
        converged,
    }
}

/// |b - M c|^2 for the constant vector c at the local origin of `start`
/// (`numeric::local_origin`, zero near the origin): the size of the right-hand side in
/// coordinates around the controls. The stop is relative to it, not to |b|: the rows of a
/// fit's systems are partitions of unity and fairness rows that vanish on constants, so b
/// grows with the data's distance from the origin while the solution's shape does not, and
/// a stop relative to |b| ended the solve early for data far from the origin (a range scan
/// moved 100 m away: 6 CG steps instead of 77, RMS 149 um instead of 65 um).
fn dot_centred(matrix: &impl Apply, start: &[DVec3]) -> f64 {
    let b = matrix.rhs();
    let origin = crate::numeric::local_origin(start);
    if origin == DVec3::ZERO {
        return dot(b, b);
    }
    let constant = vec![origin; start.len()];
    let mut mc = vec![DVec3::ZERO; start.len()];
    matrix.apply_to(&constant, &mut mc);
    let centred: Vec<DVec3> = b.iter().zip(&mc).map(|(b, a)| *b - *a).collect();
    dot(&centred, &centred)
}

/// faer's symbolic Cholesky analysis (fill-reducing ordering, elimination tree,
/// supernodes) of one sparsity pattern, kept for the next matrices whose pattern it
/// covers, and the numeric factor's storage. The rounds of a planar fit solve one normal
/// matrix per round over the same controls: a pair of controls is coupled when some data
/// point lies in both supports, which foot points moving by a fraction of a cell rarely
/// change, so one analysis serves every round and each round pays only the numeric
/// factorisation (in the stop-30 profile of a 40k-point DMS fit the analysis was redone
/// every round). A matrix with an entry outside the kept pattern is analysed again over
/// the union of both patterns, so later rounds fit in it.
///
/// Block systems (`block` unknowns per control, coupled in dense blocks) are ordered on
/// the control graph, each control's unknowns kept together: the minimum-degree ordering
/// then runs on a graph `block^2` times smaller (in the profile of the 3m x 3m distance
/// rounds it cost more than the numeric factorisation), and a block's unknowns, which
/// share every neighbour, would land side by side in a supernode anyway.
#[derive(Default)]
pub(crate) struct CholeskyPattern {
    size: usize,
    col_ptr: Vec<usize>,
    rows: Vec<usize>,
    symbolic: Option<faer::sparse::linalg::cholesky::SymbolicCholesky<usize>>,
    /// The numeric factor's values, kept so that a refactorisation writes into memory
    /// already mapped.
    factor: Vec<f64>,
    /// Symbolic analyses run.
    pub analyses: usize,
    /// Factorisations that reused the kept analysis.
    pub reuses: usize,
    /// Rounds solved by warm-started CG, with no factorisation
    /// (`fit::distance::solve_distance_round`).
    pub warm_cg_solves: usize,
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

    /// The union of the kept pattern (when of the same size) and this one, with the
    /// matrix's values in it.
    fn union(
        &self,
        size: usize,
        col_ptr: &[usize],
        rows: &[usize],
        vals: &[f64],
    ) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
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
                if k < new.end && (i >= old.len() || rows[k] <= old[i]) {
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
        (union_ptr, union_rows, union_vals)
    }

    /// Minimum-degree ordering of the control graph (`block` unknowns per control,
    /// consecutive), expanded to the unknowns: (forward, inverse).
    fn block_ordering(
        size: usize,
        col_ptr: &[usize],
        rows: &[usize],
        block: usize,
    ) -> Result<(Vec<usize>, Vec<usize>), DirectFailure> {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::sparse::linalg::amd;
        use faer::sparse::SymbolicSparseColMatRef;
        let controls = size / block;
        let mut coarse_ptr = Vec::with_capacity(controls + 1);
        coarse_ptr.push(0);
        let mut coarse_rows = Vec::new();
        for c in 0..controls {
            let first = coarse_rows.len();
            for &r in &rows[col_ptr[block * c]..col_ptr[block * c + 1]] {
                let j = r / block;
                if coarse_rows.len() == first || coarse_rows[coarse_rows.len() - 1] != j {
                    coarse_rows.push(j);
                }
            }
            coarse_ptr.push(coarse_rows.len());
        }
        let graph = SymbolicSparseColMatRef::new_checked(
            controls,
            controls,
            &coarse_ptr,
            None,
            &coarse_rows,
        );
        let (mut fwd, mut inv) = (vec![0usize; controls], vec![0usize; controls]);
        let mut mem = MemBuffer::new(amd::order_scratch::<usize>(controls, coarse_rows.len()));
        amd::order(
            &mut fwd,
            &mut inv,
            graph,
            amd::Control::default(),
            MemStack::new(&mut mem),
        )
        .map_err(|_| DirectFailure::NotDefinite)?;
        let expand = |p: &[usize]| -> Vec<usize> {
            p.iter()
                .flat_map(|&c| (0..block).map(move |q| block * c + q))
                .collect()
        };
        Ok((expand(&fwd), expand(&inv)))
    }

    /// Analyses the union of the kept pattern and this one (`block`: unknowns per
    /// control, ordered on the control graph when above 1), and returns the matrix's
    /// values in it.
    fn analyse(
        &mut self,
        size: usize,
        col_ptr: &[usize],
        rows: &[usize],
        vals: &[f64],
        block: usize,
    ) -> Result<Vec<f64>, DirectFailure> {
        use faer::perm::PermRef;
        use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, SymmetricOrdering};
        use faer::sparse::SymbolicSparseColMatRef;
        let (union_ptr, union_rows, union_vals) = self.union(size, col_ptr, rows, vals);
        let pattern =
            SymbolicSparseColMatRef::new_checked(size, size, &union_ptr, None, &union_rows);
        let ordering = if block > 1 && size.is_multiple_of(block) {
            Some(Self::block_ordering(size, &union_ptr, &union_rows, block)?)
        } else {
            None
        };
        let ord = match &ordering {
            Some((fwd, inv)) => SymmetricOrdering::Custom(PermRef::new_checked(fwd, inv, size)),
            None => SymmetricOrdering::Amd,
        };
        let symbolic =
            factorize_symbolic_cholesky(pattern, faer::Side::Lower, ord, Default::default())
                .map_err(|_| DirectFailure::NotDefinite)?;
        self.size = size;
        self.col_ptr = union_ptr;
        self.rows = union_rows;
        self.symbolic = Some(symbolic);
        self.analyses += 1;
        Ok(union_vals)
    }

    /// Solves with the lower triangle of a symmetric matrix given by columns (rows sorted
    /// within each column) in place of `b`, reusing the kept analysis where it covers the
    /// pattern.
    fn solve(
        &mut self,
        size: usize,
        (col_ptr, rows, vals): (&[usize], &[usize], &[f64]),
        block: usize,
        b: &mut faer::Mat<f64>,
    ) -> Result<(), DirectFailure> {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::linalg::cholesky::llt::factor::LltRegularization;
        use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
        let values = match self.scatter(size, col_ptr, rows, vals) {
            Some(values) => {
                self.reuses += 1;
                values
            }
            None => self.analyse(size, col_ptr, rows, vals, block)?,
        };
        let symbolic = self.symbolic.as_ref().ok_or(DirectFailure::NotDefinite)?;
        let pattern =
            SymbolicSparseColMatRef::new_checked(size, size, &self.col_ptr, None, &self.rows);
        // One thread: on the 2-core machine faer's parallel supernodal factorisation of a
        // 6000-unknown distance round took as long as the sequential one (45-55 ms) and
        // ~40 % more CPU; the assembly around it is what runs in parallel.
        let par = faer::Par::Seq;
        self.factor.clear();
        self.factor.resize(symbolic.len_val(), 0.0);
        let mut mem = MemBuffer::new(
            symbolic
                .factorize_numeric_llt_scratch::<f64>(par, Default::default())
                .or(symbolic.solve_in_place_scratch::<f64>(b.ncols(), par)),
        );
        let llt = symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.factor,
                SparseColMatRef::new(pattern, &values),
                faer::Side::Lower,
                LltRegularization::default(),
                par,
                MemStack::new(&mut mem),
                Default::default(),
            )
            .map_err(|_| DirectFailure::NotDefinite)?;
        llt.solve_in_place_with_conj(faer::Conj::No, b.as_mut(), par, MemStack::new(&mut mem));
        Ok(())
    }
}

/// Lower triangle of a symmetric matrix given by columns (the `lower_only` assembly),
/// factorised through `pattern` (`block` unknowns per control).
#[allow(clippy::too_many_arguments)]
fn cholesky_solve(
    pattern: &mut CholeskyPattern,
    size: usize,
    col_ptr: &[usize],
    rows: &[usize],
    vals: &[f64],
    rhs: impl Fn(usize, usize) -> f64,
    ncols_rhs: usize,
    block: usize,
) -> Result<faer::Mat<f64>, DirectFailure> {
    let mut b = faer::Mat::<f64>::from_fn(size, ncols_rhs, rhs);
    pattern.solve(size, (col_ptr, rows, vals), block, &mut b)?;
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
        let end = pcg(self, |c, r| r * inv[c], start, max_iter, rel_tol);
        (end.x, end.steps)
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
            1,
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
        let end = self.block_pcg(start, max_iter, rel_tol);
        (end.x, end.steps)
    }

    /// `solve_pcg` when it reaches `rel_tol` within `max_iter` steps with finite controls,
    /// else `None`.
    pub(crate) fn solve_pcg_converged(
        &self,
        start: Vec<DVec3>,
        max_iter: usize,
        rel_tol: f64,
    ) -> Option<Vec<DVec3>> {
        let end = self.block_pcg(start, max_iter, rel_tol);
        (end.converged && end.x.iter().all(|v| v.is_finite())).then_some(end.x)
    }

    fn block_pcg(&self, start: Vec<DVec3>, max_iter: usize, rel_tol: f64) -> CgEnd {
        let inv = self.block_jacobi();
        pcg(self, |c, r| inv[c] * r, start, max_iter, rel_tol)
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
            3,
        )?;
        let x: Vec<DVec3> = (0..m)
            .map(|c| DVec3::new(b[(3 * c, 0)], b[(3 * c + 1, 0)], b[(3 * c + 2, 0)]))
            .collect();
        finite(x)
    }
}
