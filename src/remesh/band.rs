//! Symmetric positive definite band matrices: Cholesky factorisation and solves, for
//! Laplacian-like systems on lattices numbered row by row (the plane warp's).

/// A symmetric positive definite matrix with nonzeros only within `band` of the diagonal:
/// row i keeps entries i - band ..= i, stored contiguously so that the factorisation's
/// inner products run over slices.
pub(crate) struct BandMatrix {
    band: usize,
    rows: Vec<f64>,
}

impl BandMatrix {
    pub(crate) fn new(n: usize, band: usize) -> Self {
        Self {
            band,
            rows: vec![0.0; n * (band + 1)],
        }
    }

    fn at(&mut self, i: usize, j: usize) -> &mut f64 {
        debug_assert!(j <= i && i - j <= self.band);
        &mut self.rows[i * (self.band + 1) + self.band + j - i]
    }

    /// Adds w (x_i - x_j)^2 to the quadratic form (w x_i^2 for i == j).
    pub(crate) fn add_edge(&mut self, i: usize, j: usize, w: f64) {
        if i == j {
            *self.at(i, i) += w;
            return;
        }
        let (hi, lo) = (i.max(j), i.min(j));
        *self.at(hi, hi) += w;
        *self.at(lo, lo) += w;
        *self.at(hi, lo) -= w;
    }

    /// L with L L^T = self, in the same band layout; `None` if not positive definite.
    pub(crate) fn cholesky(mut self) -> Option<Self> {
        let (b, width) = (self.band, self.band + 1);
        let n = self.rows.len() / width;
        for i in 0..n {
            let first = i.saturating_sub(b);
            for j in first..=i {
                // L_ij = (A_ij - sum_{m < j} L_im L_jm) / L_jj over the columns both keep.
                let from = first.max(j.saturating_sub(b));
                let (row_i, row_j) = (i * width + b - i, j * width + b - j);
                let dot = dot(
                    &self.rows[row_i + from..row_i + j],
                    &self.rows[row_j + from..row_j + j],
                );
                let a = self.rows[row_i + j] - dot;
                if i == j {
                    if a.is_nan() || a <= 0.0 {
                        return None;
                    }
                    self.rows[row_i + j] = a.sqrt();
                } else {
                    self.rows[row_i + j] = a / self.rows[row_j + j];
                }
            }
        }
        Some(self)
    }

    /// Solves L L^T x = b in place (self factored).
    pub(crate) fn solve(&self, x: &mut [f64]) {
        let (b, width) = (self.band, self.band + 1);
        let n = x.len();
        for i in 0..n {
            let row = i * width + b - i;
            let first = i.saturating_sub(b);
            let dot = dot(&self.rows[row + first..row + i], &x[first..i]);
            x[i] = (x[i] - dot) / self.rows[row + i];
        }
        for i in (0..n).rev() {
            let row = i * width + b - i;
            x[i] /= self.rows[row + i];
            let (xi, first) = (x[i], i.saturating_sub(b));
            for (xm, l) in x[first..i].iter_mut().zip(&self.rows[row + first..row + i]) {
                *xm -= l * xi;
            }
        }
    }
}

/// Inner product in four independent sums (vectorisable, unlike one running sum).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut lanes = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for k in 0..4 {
            lanes[k] += x[k] * y[k];
        }
    }
    (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]) + tail
}

#[cfg(test)]
mod tests {
    use super::BandMatrix;

    #[test]
    fn band_cholesky_solves_a_weighted_path_laplacian() {
        // Edges (i, i + 1) and (i, i + 3) with varied weights, plus a diagonal pull.
        let n = 40;
        let mut m = BandMatrix::new(n, 3);
        let mut dense = vec![vec![0.0; n]; n];
        let mut add = |i: usize, j: usize, w: f64| {
            m.add_edge(i, j, w);
            dense[i][i] += w;
            if i != j {
                dense[j][j] += w;
                dense[i][j] -= w;
                dense[j][i] -= w;
            }
        };
        for i in 0..n {
            add(i, i, 0.01 + 0.001 * i as f64);
            if i + 1 < n {
                add(i, i + 1, 1.0 + (i % 5) as f64);
            }
            if i + 3 < n {
                add(i + 3, i, 0.5);
            }
        }
        let x_true: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut b: Vec<f64> = (0..n)
            .map(|i| (0..n).map(|j| dense[i][j] * x_true[j]).sum())
            .collect();
        m.cholesky().expect("definite").solve(&mut b);
        let err = b
            .iter()
            .zip(&x_true)
            .map(|(a, e)| (a - e).abs())
            .fold(0.0, f64::max);
        assert!(err < 1e-9, "error {err}");
    }

    #[test]
    fn band_cholesky_refuses_an_indefinite_matrix() {
        let mut m = BandMatrix::new(3, 1);
        m.add_edge(1, 0, 1.0);
        m.add_edge(2, 1, 1.0);
        // A pure Laplacian is singular: no pull on any vertex.
        assert!(m.cholesky().is_none());
    }
}
