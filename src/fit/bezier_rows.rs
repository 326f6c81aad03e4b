//! A matrix-free collocation operator for a degree-n triangular Bezier patch whose data
//! parameters lie on few lines of constant v (a regular lattice has one per lattice row).
//!
//! With u = (1 - v) t and w = (1 - v)(1 - t) the Bernstein basis factors:
//!     B^n_{a,s,c}(u, v, w) = B^n_s(v) B^{n-s}_a(t).
//! Raising each inner degree-(n-s) curve to degree n turns the patch into a bidegree
//! (n, n) tensor-product patch in (t, v) with control grid
//!     Q_{i,s} = sum_a E(s, i, a) P_{a,s},   E = C(n-s, a) C(s, i-a) / C(n, i),
//! whose weights are non-negative and sum to one (stable at any degree). Then
//!     N P at a point (t, v) = sum_i B^n_i(t) sum_s B^n_s(v) Q_{i,s}.
//! Per product that is O(n^3) for Q, O(n^2) per distinct v and O(n) per point, against
//! (n+1)(n+2)/2 stored weights per point for the CSR matrix: for the paper's degree-24
//! lattice 25 instead of 325 numbers per point, and nothing streamed from memory.
//!
//! The transpose is the exact adjoint of the same three stages in reverse order.
//! Parallel over blocks of rows; the blocks depend only on the problem (never on the
//! thread count), and the transpose sums block partials in block order, so results are
//! reproducible.

use super::csr::Csr;
use super::simd::{axpy, axpy3, dot, dot3, wide};
use crate::surface::bezier::{lattice_index, lattice_len};
use crate::surface::SurfaceParam;
use rayon::prelude::*;

/// Below this many point-basis products a product runs on one thread: spreading a few
/// tens of microseconds of work over the pool costs more than it saves.
const PARALLEL_WORK: usize = 200_000;

/// Roughly this much point-basis work per block of rows.
const BLOCK_WORK: usize = 40_000;

#[derive(Clone, Debug)]
pub(crate) struct BezierRows {
    degree: usize,
    npoints: usize,
    /// Row r holds sorted positions `start[r]..start[r + 1]`.
    start: Vec<usize>,
    /// Data index of every sorted position; `None` when the data already come row by row.
    order: Option<Vec<u32>>,
    /// B^n_s(v_r), n + 1 per row.
    bv: Vec<f64>,
    /// Row r's t-basis, (n + 1) planes of its points: `bt[start[r] * (n + 1) + i * len + p]`.
    bt: Vec<f64>,
    /// Elevation weights (grid index s * (n + 1) + i, control index, weight).
    elevation: Vec<(u32, u32, f64)>,
    /// Row blocks for parallel products, as row ranges.
    blocks: Vec<(usize, usize)>,
}

/// Bernstein values of degree n at t, by the convex recurrence (no powers or binomials).
fn bernstein(n: usize, t: f64, out: &mut [f64]) {
    let s = 1.0 - t;
    out[0] = 1.0;
    for k in 1..=n {
        out[k] = t * out[k - 1];
        for i in (1..k).rev() {
            out[i] = s * out[i] + t * out[i - 1];
        }
        out[0] *= s;
    }
}

fn binomial(n: usize, k: usize) -> f64 {
    let k = k.min(n - k);
    (0..k).fold(1.0, |acc, j| acc * (n - j) as f64 / (j + 1) as f64)
}

impl BezierRows {
    /// The operator for `params` on a degree-`degree` patch, or `None` when it would not
    /// pay (about as many distinct v as points) or cannot be used (a parameter outside
    /// the triangle, where t = u / (1 - v) is unbounded).
    pub fn new(degree: usize, params: &[SurfaceParam]) -> Option<Self> {
        let n = degree;
        if params.is_empty() || n > 64 {
            return None;
        }
        let eps = 1e-12;
        let inside = |p: &SurfaceParam| {
            p.u >= -eps && p.v >= -eps && p.v <= 1.0 + eps && p.u + p.v <= 1.0 + eps
        };
        if !params.iter().all(inside) {
            return None;
        }
        // Group by the exact v: lattice rows repeat the same f64.
        let mut sorted: Vec<u32> = (0..params.len() as u32).collect();
        sorted.sort_by(|&a, &b| params[a as usize].v.total_cmp(&params[b as usize].v));
        let mut start = vec![0];
        for k in 1..sorted.len() {
            if params[sorted[k] as usize].v.to_bits() != params[sorted[k - 1] as usize].v.to_bits()
            {
                start.push(k);
            }
        }
        start.push(sorted.len());
        let rows = start.len() - 1;
        if 2 * rows > params.len() {
            return None;
        }
        let identity = sorted.iter().enumerate().all(|(k, &i)| k == i as usize);
        let n1 = n + 1;
        let mut bv = vec![0.0; rows * n1];
        let mut bt = vec![0.0; params.len() * n1];
        let mut scratch = vec![0.0; n1];
        for r in 0..rows {
            let (a, b) = (start[r], start[r + 1]);
            let v = params[sorted[a] as usize].v.clamp(0.0, 1.0);
            bernstein(n, v, &mut bv[r * n1..(r + 1) * n1]);
            let len = b - a;
            let plane = &mut bt[a * n1..b * n1];
            for (p, &idx) in sorted[a..b].iter().enumerate() {
                let u = params[idx as usize].u;
                let span = 1.0 - v;
                // At the apex (v = 1) every t gives the same point; t = 0 is as good as any.
                let t = if span > 0.0 {
                    (u / span).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                bernstein(n, t, &mut scratch);
                for (i, &w) in scratch.iter().enumerate() {
                    plane[i * len + p] = w;
                }
            }
        }
        let mut elevation = Vec::new();
        for s in 0..=n {
            for i in 0..=n {
                let lo = i.saturating_sub(s);
                let hi = i.min(n - s);
                for a in lo..=hi {
                    let w = binomial(n - s, a) * binomial(s, i - a) / binomial(n, i);
                    elevation.push(((s * n1 + i) as u32, lattice_index(n, a, s) as u32, w));
                }
            }
        }
        let mut blocks = Vec::new();
        let mut first = 0;
        let mut work = 0;
        for r in 0..rows {
            work += (start[r + 1] - start[r] + n1) * n1;
            if work >= BLOCK_WORK || r + 1 == rows {
                blocks.push((first, r + 1));
                first = r + 1;
                work = 0;
            }
        }
        Some(Self {
            degree: n,
            npoints: params.len(),
            start,
            order: (!identity).then_some(sorted),
            bv,
            bt,
            elevation,
            blocks,
        })
    }

    pub fn nrows(&self) -> usize {
        self.npoints
    }

    pub fn ncols(&self) -> usize {
        lattice_len(self.degree)
    }

    /// Number of distinct v (rows of the lattice).
    pub fn rows(&self) -> usize {
        self.start.len() - 1
    }

    fn parallel(&self) -> bool {
        self.npoints * (self.degree + 1) >= PARALLEL_WORK && self.blocks.len() > 1
    }

    /// The tensor grid Q (lane-major: L planes of (n+1)^2) from control points.
    fn grid<const L: usize>(&self, x: &[[f64; L]]) -> Vec<f64> {
        let g = (self.degree + 1) * (self.degree + 1);
        let mut q = vec![0.0; L * g];
        for &(qi, pi, w) in &self.elevation {
            let p = x[pi as usize];
            for l in 0..L {
                q[l * g + qi as usize] += w * p[l];
            }
        }
        q
    }

    /// `forward_block_with` for this CPU: the AVX2 + FMA build where the CPU has them.
    fn forward_block<const L: usize>(&self, q: &[f64], rows: (usize, usize), out: &mut [[f64; L]]) {
        #[cfg(target_arch = "x86_64")]
        if wide() {
            // SAFETY: `wide()` checked that the CPU supports AVX2 and FMA.
            unsafe { self.forward_block_wide(q, rows, out) };
            return;
        }
        self.forward_block_with::<L, false>(q, rows, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn forward_block_wide<const L: usize>(
        &self,
        q: &[f64],
        rows: (usize, usize),
        out: &mut [[f64; L]],
    ) {
        self.forward_block_with::<L, true>(q, rows, out)
    }

    /// `adjoint_block_with` for this CPU.
    fn adjoint_block<const L: usize>(&self, y: &[[f64; L]], rows: (usize, usize)) -> Vec<f64> {
        #[cfg(target_arch = "x86_64")]
        if wide() {
            // SAFETY: `wide()` checked that the CPU supports AVX2 and FMA.
            return unsafe { self.adjoint_block_wide(y, rows) };
        }
        self.adjoint_block_with::<L, false>(y, rows)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn adjoint_block_wide<const L: usize>(&self, y: &[[f64; L]], rows: (usize, usize)) -> Vec<f64> {
        self.adjoint_block_with::<L, true>(y, rows)
    }

    /// Row curves and their points for rows `rows`, written to `out` (sorted positions
    /// of those rows).
    #[inline(always)]
    fn forward_block_with<const L: usize, const F: bool>(
        &self,
        q: &[f64],
        rows: (usize, usize),
        out: &mut [[f64; L]],
    ) {
        let n1 = self.degree + 1;
        let g = n1 * n1;
        let base = self.start[rows.0];
        let mut curve = vec![0.0; L * n1];
        let mut acc: Vec<f64> = Vec::new();
        for r in rows.0..rows.1 {
            let bv = &self.bv[r * n1..(r + 1) * n1];
            curve.iter_mut().for_each(|c| *c = 0.0);
            for l in 0..L {
                let c = &mut curve[l * n1..(l + 1) * n1];
                for (s, &b) in bv.iter().enumerate() {
                    axpy::<F>(b, &q[l * g + s * n1..l * g + (s + 1) * n1], c);
                }
            }
            let (a, e) = (self.start[r], self.start[r + 1]);
            let len = e - a;
            let planes = &self.bt[a * n1..e * n1];
            acc.clear();
            acc.resize(L * len, 0.0);
            if L == 3 {
                for i in 0..n1 {
                    let c = [curve[i], curve[n1 + i], curve[2 * n1 + i]];
                    axpy3::<F>(c, &planes[i * len..(i + 1) * len], &mut acc);
                }
            } else {
                for l in 0..L {
                    let y = &mut acc[l * len..(l + 1) * len];
                    for i in 0..n1 {
                        axpy::<F>(curve[l * n1 + i], &planes[i * len..(i + 1) * len], y);
                    }
                }
            }
            for p in 0..len {
                let o = &mut out[a - base + p];
                for l in 0..L {
                    o[l] = acc[l * len + p];
                }
            }
        }
    }

    /// Adjoint of `forward_block` up to the grid: the partial grid G of rows `rows`
    /// (lane-major, L planes of (n+1)^2) from residuals in data order.
    #[inline(always)]
    fn adjoint_block_with<const L: usize, const F: bool>(
        &self,
        y: &[[f64; L]],
        rows: (usize, usize),
    ) -> Vec<f64> {
        let n1 = self.degree + 1;
        let g = n1 * n1;
        let mut grid = vec![0.0; L * g];
        let mut vals: Vec<f64> = Vec::new();
        let mut d = vec![0.0; L * n1];
        for r in rows.0..rows.1 {
            let (a, e) = (self.start[r], self.start[r + 1]);
            let len = e - a;
            vals.clear();
            vals.resize(L * len, 0.0);
            for p in 0..len {
                let src = match &self.order {
                    Some(o) => y[o[a + p] as usize],
                    None => y[a + p],
                };
                for l in 0..L {
                    vals[l * len + p] = src[l];
                }
            }
            let planes = &self.bt[a * n1..e * n1];
            let bv = &self.bv[r * n1..(r + 1) * n1];
            if L == 3 {
                for i in 0..n1 {
                    let v = dot3::<F>(&planes[i * len..(i + 1) * len], &vals);
                    for (l, v) in v.into_iter().enumerate() {
                        d[l * n1 + i] = v;
                    }
                }
            } else {
                for l in 0..L {
                    let yl = &vals[l * len..(l + 1) * len];
                    for i in 0..n1 {
                        d[l * n1 + i] = dot::<F>(&planes[i * len..(i + 1) * len], yl);
                    }
                }
            }
            for l in 0..L {
                let dl = &d[l * n1..(l + 1) * n1];
                for (s, &b) in bv.iter().enumerate() {
                    axpy::<F>(b, dl, &mut grid[l * g + s * n1..l * g + (s + 1) * n1]);
                }
            }
        }
        grid
    }

    /// y = N x.
    pub(crate) fn mul<const L: usize>(&self, x: &[[f64; L]], y: &mut [[f64; L]]) {
        let q = self.grid(x);
        let sorted_out = |out: &mut [[f64; L]]| {
            if self.parallel() {
                let mut parts = Vec::with_capacity(self.blocks.len());
                let mut rest = out;
                for &(r0, r1) in &self.blocks {
                    let (head, tail) = rest.split_at_mut(self.start[r1] - self.start[r0]);
                    parts.push(((r0, r1), head));
                    rest = tail;
                }
                parts
                    .into_par_iter()
                    .for_each(|(rows, part)| self.forward_block(&q, rows, part));
            } else {
                self.forward_block(&q, (0, self.rows()), out);
            }
        };
        match &self.order {
            None => sorted_out(y),
            Some(order) => {
                let mut tmp = vec![[0.0; L]; self.npoints];
                sorted_out(&mut tmp);
                for (k, &i) in order.iter().enumerate() {
                    y[i as usize] = tmp[k];
                }
            }
        }
    }

    /// x = N^T y.
    pub(crate) fn mul_t<const L: usize>(&self, y: &[[f64; L]], x: &mut [[f64; L]]) {
        let grid = if self.parallel() {
            let parts: Vec<Vec<f64>> = self
                .blocks
                .par_iter()
                .map(|&rows| self.adjoint_block(y, rows))
                .collect();
            let mut iter = parts.into_iter();
            let mut total = iter.next().unwrap_or_default();
            for part in iter {
                total.iter_mut().zip(&part).for_each(|(t, p)| *t += p);
            }
            total
        } else {
            self.adjoint_block(y, (0, self.rows()))
        };
        let g = (self.degree + 1) * (self.degree + 1);
        x.iter_mut().for_each(|v| *v = [0.0; L]);
        for &(qi, pi, w) in &self.elevation {
            let o = &mut x[pi as usize];
            for l in 0..L {
                o[l] += w * grid[l * g + qi as usize];
            }
        }
    }

    /// The same operator as an explicit CSR matrix (for the direct solve and for tests).
    pub(crate) fn to_csr(&self) -> Csr {
        let n1 = self.degree + 1;
        let nc = self.ncols();
        let mut rows: Vec<Vec<(u32, f64)>> = vec![Vec::new(); self.npoints];
        let mut dense = vec![0.0; nc];
        for r in 0..self.rows() {
            let (a, e) = (self.start[r], self.start[r + 1]);
            let len = e - a;
            let bv = &self.bv[r * n1..(r + 1) * n1];
            for p in 0..len {
                dense.iter_mut().for_each(|d| *d = 0.0);
                for &(qi, pi, w) in &self.elevation {
                    let (s, i) = (qi as usize / n1, qi as usize % n1);
                    dense[pi as usize] += w * bv[s] * self.bt[a * n1 + i * len + p];
                }
                let data = self.order.as_ref().map_or(a + p, |o| o[a + p] as usize);
                rows[data] = dense
                    .iter()
                    .enumerate()
                    .map(|(c, &w)| (c as u32, w))
                    .collect();
            }
        }
        Csr::from_rows(nc, rows.iter().map(|r| r.as_slice()))
    }
}
