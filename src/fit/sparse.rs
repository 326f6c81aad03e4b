//! The collocation matrix N (rows = data points, columns = control points) in CSR form,
//! with its transpose kept so that both products run row-parallel.

use super::bezier_rows::BezierRows;
use crate::surface::SurfaceParam;
use glam::DVec3;
use rayon::prelude::*;
use std::sync::OnceLock;

/// Below this many rows a product is cheaper on one thread than split across the pool.
const PARALLEL_ROWS: usize = 20_000;

#[derive(Clone, Debug, Default)]
pub struct Csr {
    pub nrows: usize,
    pub ncols: usize,
    pub row_ptr: Vec<usize>,
    pub col_idx: Vec<u32>,
    pub values: Vec<f64>,
}

impl Csr {
    pub fn from_rows<'a>(ncols: usize, rows: impl IntoIterator<Item = &'a [(u32, f64)]>) -> Csr {
        let mut m = Csr {
            ncols,
            row_ptr: vec![0],
            ..Default::default()
        };
        for row in rows {
            for &(c, w) in row {
                if w != 0.0 {
                    m.col_idx.push(c);
                    m.values.push(w);
                }
            }
            m.row_ptr.push(m.col_idx.len());
        }
        m.nrows = m.row_ptr.len() - 1;
        m
    }

    pub fn transpose(&self) -> Csr {
        let mut counts = vec![0usize; self.ncols + 1];
        for &c in &self.col_idx {
            counts[c as usize + 1] += 1;
        }
        for i in 0..self.ncols {
            counts[i + 1] += counts[i];
        }
        let mut fill = counts.clone();
        let mut col_idx = vec![0u32; self.col_idx.len()];
        let mut values = vec![0.0; self.values.len()];
        for r in 0..self.nrows {
            for k in self.row_ptr[r]..self.row_ptr[r + 1] {
                let c = self.col_idx[k] as usize;
                col_idx[fill[c]] = r as u32;
                values[fill[c]] = self.values[k];
                fill[c] += 1;
            }
        }
        Csr {
            nrows: self.ncols,
            ncols: self.nrows,
            row_ptr: counts,
            col_idx,
            values,
        }
    }

    #[inline]
    fn row_dot(&self, r: usize, x: &[DVec3]) -> DVec3 {
        let mut acc = DVec3::ZERO;
        for k in self.row_ptr[r]..self.row_ptr[r + 1] {
            acc += x[self.col_idx[k] as usize] * self.values[k];
        }
        acc
    }

    /// y = A x.
    pub fn mul_vec3(&self, x: &[DVec3], y: &mut [DVec3]) {
        if self.nrows >= PARALLEL_ROWS {
            y.par_iter_mut()
                .enumerate()
                .for_each(|(r, out)| *out = self.row_dot(r, x));
        } else {
            for (r, out) in y.iter_mut().enumerate() {
                *out = self.row_dot(r, x);
            }
        }
    }

    /// y = A x for one scalar field.
    pub fn mul_scalar(&self, x: &[f64], y: &mut [f64]) {
        let row = |r: usize| -> f64 {
            (self.row_ptr[r]..self.row_ptr[r + 1])
                .map(|k| self.values[k] * x[self.col_idx[k] as usize])
                .sum()
        };
        if self.nrows >= PARALLEL_ROWS {
            y.par_iter_mut()
                .enumerate()
                .for_each(|(r, out)| *out = row(r));
        } else {
            y.iter_mut().enumerate().for_each(|(r, out)| *out = row(r));
        }
    }

    pub fn nnz(&self) -> usize {
        self.values.len()
    }
}

/// How N is applied: a stored matrix with its transpose, or a matrix-free factorisation.
#[derive(Clone, Debug)]
enum Operator {
    Sparse,
    BezierRows(BezierRows),
}

/// The collocation operator N (rows = data points, columns = control points); built
/// once per parameter set and reused across steps and warm starts. Products go through
/// `mul_vec3` / `mul_t_vec3`; the explicit matrices (`n()`, `nt()`) exist for every
/// operator, built on first use for a matrix-free one.
#[derive(Debug)]
pub struct Collocation {
    op: Operator,
    nrows: usize,
    ncols: usize,
    matrices: OnceLock<(Csr, Csr)>,
    /// lambda_max(N^T N) as LSPIA estimates it, kept for later fits on the same
    /// parameters (warm starts, budget retries).
    lambda: OnceLock<f64>,
}

impl Clone for Collocation {
    fn clone(&self) -> Self {
        let matrices = OnceLock::new();
        if let Some(m) = self.matrices.get() {
            let _ = matrices.set(m.clone());
        }
        Self {
            op: self.op.clone(),
            nrows: self.nrows,
            ncols: self.ncols,
            matrices,
            lambda: self.lambda.clone(),
        }
    }
}

fn as_arrays(v: &[DVec3]) -> Vec<[f64; 3]> {
    v.iter().map(|p| p.to_array()).collect()
}

fn store(src: &[[f64; 3]], dst: &mut [DVec3]) {
    dst.iter_mut()
        .zip(src)
        .for_each(|(d, s)| *d = DVec3::from_array(*s));
}

impl Collocation {
    /// A stored sparse matrix.
    pub fn new(n: Csr) -> Self {
        let nt = n.transpose();
        let (nrows, ncols) = (n.nrows, n.ncols);
        Self {
            op: Operator::Sparse,
            nrows,
            ncols,
            matrices: OnceLock::from((n, nt)),
            lambda: OnceLock::new(),
        }
    }

    /// The collocation of a degree-`degree` triangular Bezier patch at `params`:
    /// matrix-free when the parameters lie on few lines of constant v (lattice data),
    /// otherwise the stored matrix of `rows` (called only then).
    pub fn bezier(degree: usize, params: &[SurfaceParam], rows: impl FnOnce() -> Csr) -> Self {
        match BezierRows::new(degree, params) {
            Some(op) => Self {
                nrows: op.nrows(),
                ncols: op.ncols(),
                op: Operator::BezierRows(op),
                matrices: OnceLock::new(),
                lambda: OnceLock::new(),
            },
            None => Self::new(rows()),
        }
    }

    pub fn nrows(&self) -> usize {
        self.nrows
    }

    pub fn ncols(&self) -> usize {
        self.ncols
    }

    /// The LSPIA step's lambda_max of N^T N alone, computed by `estimate` on first use.
    pub fn cached_lambda_max(&self, estimate: impl FnOnce() -> f64) -> f64 {
        *self.lambda.get_or_init(estimate)
    }

    /// True when products do not read a stored matrix.
    pub fn is_matrix_free(&self) -> bool {
        !matches!(self.op, Operator::Sparse)
    }

    fn matrices(&self) -> &(Csr, Csr) {
        self.matrices.get_or_init(|| match &self.op {
            Operator::BezierRows(op) => {
                let n = op.to_csr();
                let nt = n.transpose();
                (n, nt)
            }
            // `new` always fills the cell.
            Operator::Sparse => (Csr::default(), Csr::default()),
        })
    }

    /// N as a stored matrix (built on first use for a matrix-free operator).
    pub fn n(&self) -> &Csr {
        &self.matrices().0
    }

    /// N^T as a stored matrix (built on first use for a matrix-free operator).
    pub fn nt(&self) -> &Csr {
        &self.matrices().1
    }

    /// y = N x.
    pub fn mul_vec3(&self, x: &[DVec3], y: &mut [DVec3]) {
        match &self.op {
            Operator::Sparse => self.n().mul_vec3(x, y),
            Operator::BezierRows(op) => {
                let mut out = vec![[0.0; 3]; y.len()];
                op.mul(&as_arrays(x), &mut out);
                store(&out, y);
            }
        }
    }

    /// x = N^T y.
    pub fn mul_t_vec3(&self, y: &[DVec3], x: &mut [DVec3]) {
        match &self.op {
            Operator::Sparse => self.nt().mul_vec3(y, x),
            Operator::BezierRows(op) => {
                let mut out = vec![[0.0; 3]; x.len()];
                op.mul_t(&as_arrays(y), &mut out);
                store(&out, x);
            }
        }
    }

    /// y = N x for one scalar field.
    pub fn mul_scalar(&self, x: &[f64], y: &mut [f64]) {
        match &self.op {
            Operator::Sparse => self.n().mul_scalar(x, y),
            Operator::BezierRows(op) => {
                let xs: Vec<[f64; 1]> = x.iter().map(|&v| [v]).collect();
                let mut out = vec![[0.0; 1]; y.len()];
                op.mul(&xs, &mut out);
                y.iter_mut().zip(&out).for_each(|(d, s)| *d = s[0]);
            }
        }
    }

    /// x = N^T y for one scalar field.
    pub fn mul_t_scalar(&self, y: &[f64], x: &mut [f64]) {
        match &self.op {
            Operator::Sparse => self.nt().mul_scalar(y, x),
            Operator::BezierRows(op) => {
                let ys: Vec<[f64; 1]> = y.iter().map(|&v| [v]).collect();
                let mut out = vec![[0.0; 1]; x.len()];
                op.mul_t(&ys, &mut out);
                x.iter_mut().zip(&out).for_each(|(d, s)| *d = s[0]);
            }
        }
    }
}

/// A test fairness operator: row i is control i minus half of each of two neighbours on a
/// ring of m controls, at offsets 1 and `far`.
#[cfg(test)]
pub(crate) fn ring_laplacian(m: usize, far: u32) -> Csr {
    let rows: Vec<Vec<(u32, f64)>> = (0..m as u32)
        .map(|i| {
            vec![
                (i, 1.0),
                ((i + 1) % m as u32, -0.5),
                ((i + far) % m as u32, -0.5),
            ]
        })
        .collect();
    Csr::from_rows(m, rows.iter().map(|r| r.as_slice()))
}
