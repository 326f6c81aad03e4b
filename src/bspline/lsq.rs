//! Banded least squares by Givens rotations, one data row at a time.
//!
//! B-spline collocation rows are banded, so the triangular factor R of A = QR is banded
//! too and Q is never stored: each row is rotated into R as it arrives (the sequential
//! scheme of Lawson & Hanson). Unlike the normal equations A^T A, whose condition number
//! is the square of A's, this works on A itself. Several right-hand sides share one
//! factorisation, which is what makes the two-pass grid fit cheap: every column of a grid
//! has the same parameters, so one factorisation serves all of them.

use super::error::BSplineError;

#[derive(Clone, Debug)]
pub(crate) struct BandedQr {
    n: usize,
    width: usize,
    nrhs: usize,
    /// Row i holds R[i][i..i + width].
    r: Vec<f64>,
    /// Q^T b, row i for unknown i.
    qtb: Vec<f64>,
    /// Sum of squares of the parts of b that no unknown can explain.
    residual: Vec<f64>,
    row: Vec<f64>,
    rhs: Vec<f64>,
}

impl BandedQr {
    /// `n` unknowns, at most `width` consecutive non-zeros per row, `nrhs` right-hand sides.
    pub fn new(n: usize, width: usize, nrhs: usize) -> Self {
        Self {
            n,
            width,
            nrhs,
            r: vec![0.0; n * width],
            qtb: vec![0.0; n * nrhs],
            residual: vec![0.0; nrhs],
            row: vec![0.0; width],
            rhs: vec![0.0; nrhs],
        }
    }

    /// Adds the equation sum_k coeffs[k] x[first + k] = rhs (every right-hand side at once).
    /// `coeffs.len()` must not exceed the width and the row must end inside the unknowns.
    pub(crate) fn add_row(&mut self, first: usize, coeffs: &[f64], rhs: &[f64]) {
        debug_assert!(coeffs.len() <= self.width && first + coeffs.len() <= self.n);
        debug_assert_eq!(rhs.len(), self.nrhs);
        let w = self.width;
        self.row.iter_mut().for_each(|x| *x = 0.0);
        self.row[..coeffs.len()].copy_from_slice(coeffs);
        self.rhs.copy_from_slice(rhs);
        let mut col = first;
        while col < self.n {
            // The row's leading entry sits at column `col`, stored at self.row[0].
            let lead = self.row[0];
            if lead != 0.0 {
                let ri = col * w;
                let d = self.r[ri];
                if d == 0.0 {
                    // Empty pivot row: the data row becomes it.
                    self.r[ri..ri + w].copy_from_slice(&self.row);
                    let bi = col * self.nrhs;
                    self.qtb[bi..bi + self.nrhs].copy_from_slice(&self.rhs);
                    return;
                }
                let h = d.hypot(lead);
                let (c, s) = (d / h, lead / h);
                self.r[ri] = h;
                for k in 1..w {
                    let (a, b) = (self.r[ri + k], self.row[k]);
                    self.r[ri + k] = c * a + s * b;
                    self.row[k - 1] = c * b - s * a;
                }
                let bi = col * self.nrhs;
                for k in 0..self.nrhs {
                    let (a, b) = (self.qtb[bi + k], self.rhs[k]);
                    self.qtb[bi + k] = c * a + s * b;
                    self.rhs[k] = c * b - s * a;
                }
            } else {
                self.row.copy_within(1..w, 0);
            }
            self.row[w - 1] = 0.0;
            col += 1;
            if self.row.iter().all(|&x| x == 0.0) {
                break;
            }
        }
        for k in 0..self.nrhs {
            self.residual[k] += self.rhs[k] * self.rhs[k];
        }
    }

    /// Sum of squared residuals of the least-squares solution, per right-hand side.
    #[cfg(test)]
    pub(crate) fn residual_sum_of_squares(&self) -> &[f64] {
        &self.residual
    }

    /// Back substitution. A pivot below `1e-12` of the largest one means the columns are
    /// dependent (an empty knot span): reported rather than amplified into garbage.
    pub fn solve(&self) -> Result<Vec<f64>, BSplineError> {
        let (n, w, m) = (self.n, self.width, self.nrhs);
        let scale = (0..n).map(|i| self.r[i * w].abs()).fold(0.0, f64::max);
        let mut x = vec![0.0; n * m];
        for i in (0..n).rev() {
            let d = self.r[i * w];
            if d.abs() <= 1e-12 * scale || scale == 0.0 {
                return Err(BSplineError::RankDeficient(i));
            }
            for k in 0..m {
                let mut s = self.qtb[i * m + k];
                for j in 1..w.min(n - i) {
                    s -= self.r[i * w + j] * x[(i + j) * m + k];
                }
                x[i * m + k] = s / d;
            }
        }
        Ok(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    #[test]
    fn matches_a_dense_qr_solve() {
        // A random-ish banded overdetermined system (width 3, 6 unknowns, 15 rows).
        let (n, w, rows) = (6, 3, 15);
        let mut qr = BandedQr::new(n, w, 1);
        let mut dense = DMatrix::zeros(rows, n);
        let mut b = DVector::zeros(rows);
        for r in 0..rows {
            let first = (r * (n - w + 1)) / rows;
            let c: Vec<f64> = (0..w)
                .map(|k| 1.0 + ((r * 7 + k * 3) % 5) as f64 * 0.37)
                .collect();
            let rhs = ((r * 13) % 7) as f64 - 2.5;
            qr.add_row(first, &c, &[rhs]);
            for k in 0..w {
                dense[(r, first + k)] = c[k];
            }
            b[r] = rhs;
        }
        let x = qr.solve().expect("full rank");
        let svd = dense.clone().svd(true, true);
        let xr = svd.solve(&b, 1e-14).expect("svd");
        for i in 0..n {
            assert!((x[i] - xr[i]).abs() < 1e-10, "{i}: {} vs {}", x[i], xr[i]);
        }
        let res: f64 = (&dense * DVector::from_vec(x) - &b).norm_squared();
        assert!((res - qr.residual_sum_of_squares()[0]).abs() < 1e-9);
    }

    #[test]
    fn rank_deficiency_is_reported() {
        let mut qr = BandedQr::new(3, 2, 1);
        qr.add_row(0, &[1.0, 1.0], &[1.0]);
        qr.add_row(0, &[2.0, 2.0], &[2.0]);
        assert!(matches!(qr.solve(), Err(BSplineError::RankDeficient(_))));
    }
}
