//! The collocation operator N (rows = data points, columns = control points): a stored
//! CSR matrix with its transpose kept so that both products run row-parallel, or the
//! matrix-free Bezier factorisation of `bezier_rows`.

use super::bezier_rows::BezierRows;
use super::csr::Csr;
use crate::surface::SurfaceParam;
use glam::DVec3;
use std::sync::OnceLock;

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

    /// Rows: data points.
    pub fn nrows(&self) -> usize {
        self.nrows
    }

    /// Columns: control points.
    pub fn ncols(&self) -> usize {
        self.ncols
    }

    /// The LSPIA step's lambda_max of N^T N alone, computed by `estimate` on first use.
    pub(crate) fn cached_lambda_max(&self, estimate: impl FnOnce() -> f64) -> f64 {
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
    pub(crate) fn mul_scalar(&self, x: &[f64], y: &mut [f64]) {
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
    pub(crate) fn mul_t_scalar(&self, y: &[f64], x: &mut [f64]) {
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
