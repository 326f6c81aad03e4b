//! A compressed-sparse-row matrix of f64 weights with products against per-column
//! points (`DVec3`) or scalars; the stored form of the collocation and fairness operators.

use glam::DVec3;
use rayon::prelude::*;

/// Below this many rows a product is cheaper on one thread than split across the pool.
const PARALLEL_ROWS: usize = 20_000;

#[derive(Clone, Debug, Default)]
/// A sparse matrix in compressed-row form.
pub struct Csr {
    /// Number of rows.
    pub nrows: usize,
    /// Number of columns.
    pub ncols: usize,
    /// Row r's entries are `row_ptr[r]..row_ptr[r + 1]`.
    pub row_ptr: Vec<usize>,
    /// Column of every entry.
    pub col_idx: Vec<u32>,
    /// Value of every entry.
    pub values: Vec<f64>,
}

impl Csr {
    /// A matrix of `ncols` columns from (column, value) rows; zero values are not stored.
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

    /// The transpose; each of its rows lists the original rows in increasing order.
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
    pub(crate) fn mul_scalar(&self, x: &[f64], y: &mut [f64]) {
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

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.values.len()
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
