//! Normal equations of weighted least-squares fits, assembled once per solve:
//!     M = N^T W N + s L^T L,    b = N^T W p
//! with W = I (point-to-point fits: M is the same scalar matrix for x, y and z) or, per
//! data point, W_j = n_j n_j^T + t I (squared-distance rounds: M couples the coordinates in
//! 3x3 blocks).
//!
//! Data rows with the same column pattern are summed first into one small dense matrix per
//! pattern: on a grid spline every point of a cell has that cell's 12-control stencil, so a
//! scan of 40k points has only a few thousand patterns. The per-point work is then a dense
//! triangular update without index lookups, and each control gathers its row of M from the
//! few dozen pattern matrices it appears in, in parallel and without write conflicts.
//!
//! Per control pair an entry keeps `K` sums: for the scalar matrix (K = 1) the sum
//! w_a w_b + s (L^T L)_ab; for blocks (K = 6) the six distinct entries of the symmetric
//! block sum w_a w_b (n n^T + t I), the fairness term s (L^T L)_ab added on its diagonal.
//! Assembled in that form, a CG product reads the entries as they are (no repacking per
//! solve) and a row costs six multiplies per pair.

use super::csr::Csr;
use crate::numeric::{packed_mul, packed_outer};
use glam::{DMat3, DVec3};
use rayon::prelude::*;
use rustc_hash::FxHashMap;

/// Index of the scalar matrix's value in its entry.
pub(super) const SCALAR: usize = 0;

/// The lanes of an entry on the block's diagonal, where the scalar fairness term adds: the
/// one lane of a scalar entry, (0, 0), (1, 1) and (2, 2) of a packed block.
pub(super) const fn diagonal_lanes(k: usize) -> &'static [usize] {
    match k {
        1 => &[0],
        6 => &[0, 3, 5],
        _ => panic!("entries are scalars (1) or symmetric 3x3 blocks (6)"),
    }
}

/// Control pairs of a pattern with k columns, a <= b, packed row by row.
pub(super) fn packed_len(k: usize) -> usize {
    k * (k + 1) / 2
}

#[inline]
pub(super) fn packed_index(a: usize, b: usize, k: usize) -> usize {
    let (a, b) = if a <= b { (a, b) } else { (b, a) };
    // Rows 0..a hold k, k - 1, ..., k - a + 1 pairs.
    a * k - a * a.saturating_sub(1) / 2 + (b - a)
}

/// Row-wise sparse storage of M: for control c its neighbours `idx[ptr[c]..ptr[c + 1]]`
/// (sorted) and the sums of each pair.
#[derive(Clone, Debug)]
pub(crate) struct NormalMatrix<const K: usize> {
    pub ptr: Vec<usize>,
    pub idx: Vec<u32>,
    pub entries: Vec<[f64; K]>,
    /// b = N^T W p.
    pub rhs: Vec<DVec3>,
}

/// Point-to-point: the same matrix for all three coordinates.
pub(crate) type ScalarMatrix = NormalMatrix<1>;
/// Squared distance: symmetric 3x3 blocks, six sums each (`BlockMatrix::block`).
pub(crate) type BlockMatrix = NormalMatrix<6>;

/// The fairness term s L^T L: L by rows and by columns (its transpose).
#[derive(Clone, Copy)]
pub(crate) struct Fairness<'a> {
    pub l: &'a Csr,
    pub lt: &'a Csr,
    pub smoothing: f64,
}

/// Rows of N grouped by identical column lists.
struct Patterns<'a> {
    columns: Vec<&'a [u32]>,
    /// Rows of pattern g: `rows[start[g]..start[g + 1]]`.
    start: Vec<usize>,
    rows: Vec<u32>,
}

impl<'a> Patterns<'a> {
    fn group(n: &'a Csr) -> Self {
        let mut id: FxHashMap<&'a [u32], u32> = FxHashMap::default();
        let mut columns = Vec::new();
        let of_row: Vec<u32> = (0..n.nrows)
            .map(|r| {
                let cols = &n.col_idx[n.row_ptr[r]..n.row_ptr[r + 1]];
                *id.entry(cols).or_insert_with(|| {
                    columns.push(cols);
                    (columns.len() - 1) as u32
                })
            })
            .collect();
        let mut start = vec![0usize; columns.len() + 1];
        for &g in &of_row {
            start[g as usize + 1] += 1;
        }
        for g in 0..columns.len() {
            start[g + 1] += start[g];
        }
        let mut fill = start.clone();
        let mut rows = vec![0u32; n.nrows];
        for (r, &g) in of_row.iter().enumerate() {
            rows[fill[g as usize]] = r as u32;
            fill[g as usize] += 1;
        }
        Self {
            columns,
            start,
            rows,
        }
    }
}

/// The weights of data row r (its columns are known to the caller).
pub(super) trait RowValues: Sync {
    fn values(&self, r: usize) -> &[f64];
}

impl RowValues for Csr {
    #[inline(always)]
    fn values(&self, r: usize) -> &[f64] {
        &self.values[self.row_ptr[r]..self.row_ptr[r + 1]]
    }
}

/// Sum over `rows` (all with pattern length k) of w w^T q and w (W p), packed.
pub(super) fn accumulate<const K: usize>(
    n: &(impl RowValues + ?Sized),
    rows: &[u32],
    k: usize,
    weight: &(impl Fn(usize) -> ([f64; K], DVec3) + Sync),
    pairs: &mut [[f64; K]],
    rhs: &mut [DVec3],
) {
    #[cfg(target_arch = "x86_64")]
    if super::simd::wide() {
        // SAFETY: `wide()` checked that the CPU supports AVX2 and FMA.
        unsafe { accumulate_wide(n, rows, k, weight, pairs, rhs) };
        return;
    }
    accumulate_with(n, rows, k, weight, pairs, rhs)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn accumulate_wide<const K: usize>(
    n: &(impl RowValues + ?Sized),
    rows: &[u32],
    k: usize,
    weight: &(impl Fn(usize) -> ([f64; K], DVec3) + Sync),
    pairs: &mut [[f64; K]],
    rhs: &mut [DVec3],
) {
    accumulate_with(n, rows, k, weight, pairs, rhs)
}

#[inline(always)]
fn accumulate_with<const K: usize>(
    n: &(impl RowValues + ?Sized),
    rows: &[u32],
    k: usize,
    weight: &(impl Fn(usize) -> ([f64; K], DVec3) + Sync),
    pairs: &mut [[f64; K]],
    rhs: &mut [DVec3],
) {
    for &r in rows {
        let r = r as usize;
        let w = n.values(r);
        let (q, wp) = weight(r);
        let mut pos = 0;
        for a in 0..k {
            let wa = w[a];
            rhs[a] += wp * wa;
            let wq = q.map(|x| x * wa);
            for (e, &wb) in pairs[pos..pos + k - a].iter_mut().zip(&w[a..k]) {
                for c in 0..K {
                    e[c] += wq[c] * wb;
                }
            }
            pos += k - a;
        }
    }
}

/// Above this many pair updates a pattern's rows are summed in parallel.
const PARALLEL_PATTERN_WORK: usize = 1 << 20;

fn assemble<const K: usize>(
    n: &Csr,
    weight: impl Fn(usize) -> ([f64; K], DVec3) + Sync,
    fairness: Option<Fairness>,
    lower_only: bool,
) -> NormalMatrix<K> {
    let m = n.ncols;
    let patterns = Patterns::group(n);
    let groups = patterns.columns.len();
    let local: Vec<(Vec<[f64; K]>, Vec<DVec3>)> = (0..groups)
        .into_par_iter()
        .map(|g| {
            let k = patterns.columns[g].len();
            let rows = &patterns.rows[patterns.start[g]..patterns.start[g + 1]];
            let zero = || (vec![[0.0; K]; packed_len(k)], vec![DVec3::ZERO; k]);
            if rows.len() * packed_len(k) < PARALLEL_PATTERN_WORK {
                let (mut pairs, mut rhs) = zero();
                accumulate(n, rows, k, &weight, &mut pairs, &mut rhs);
                (pairs, rhs)
            } else {
                // One pattern holding most rows (a single Bezier patch): split the rows.
                rows.par_chunks(256)
                    .fold(zero, |(mut pairs, mut rhs), chunk| {
                        accumulate(n, chunk, k, &weight, &mut pairs, &mut rhs);
                        (pairs, rhs)
                    })
                    .reduce(zero, |(mut pa, mut ra), (pb, rb)| {
                        pa.iter_mut().zip(&pb).for_each(|(a, b)| {
                            for c in 0..K {
                                a[c] += b[c];
                            }
                        });
                        ra.iter_mut().zip(&rb).for_each(|(a, b)| *a += *b);
                        (pa, ra)
                    })
            }
        })
        .collect();

    // Where each control appears: (pattern, position in it).
    let mut start = vec![0usize; m + 1];
    for cols in &patterns.columns {
        for &c in *cols {
            start[c as usize + 1] += 1;
        }
    }
    for c in 0..m {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut incidence = vec![(0u32, 0u32); start[m]];
    for (g, cols) in patterns.columns.iter().enumerate() {
        for (a, &c) in cols.iter().enumerate() {
            incidence[fill[c as usize]] = (g as u32, a as u32);
            fill[c as usize] += 1;
        }
    }

    let gather = Gather {
        patterns: &patterns,
        local: &local,
        incidence: &incidence,
        start: &start,
        fairness: fairness.filter(|f| f.smoothing > 0.0),
        lower_only,
    };
    // Controls in chunks, each with one scratch over all controls (zeroed once, reset
    // entry by entry) and flat outputs.
    let chunks: Vec<GatheredRows<K>> = (0..m)
        .collect::<Vec<usize>>()
        .par_chunks(GATHER_CHUNK)
        .map(|controls| {
            let mut scratch = (vec![[0.0f64; K]; m], vec![false; m], Vec::new());
            let mut out = (
                Vec::with_capacity(controls.len()),
                Vec::new(),
                Vec::new(),
                Vec::new(),
            );
            for &c in controls {
                let before = out.1.len();
                let rhs = gather.row(c, &mut scratch, &mut out.1, &mut out.2);
                out.0.push(out.1.len() - before);
                out.3.push(rhs);
            }
            out
        })
        .collect();
    let nnz = chunks.iter().map(|c| c.1.len()).sum();
    let mut ptr = Vec::with_capacity(m + 1);
    ptr.push(0);
    let (mut idx, mut entries, mut rhs) = (
        Vec::with_capacity(nnz),
        Vec::with_capacity(nnz),
        Vec::with_capacity(m),
    );
    for (lens, i, e, b) in chunks {
        for len in lens {
            ptr.push(ptr[ptr.len() - 1] + len);
        }
        idx.extend(i);
        entries.extend(e);
        rhs.extend(b);
    }
    NormalMatrix {
        ptr,
        idx,
        entries,
        rhs,
    }
}

/// A chunk of gathered rows: row lengths, neighbours, entries and right-hand sides.
type GatheredRows<const K: usize> = (Vec<usize>, Vec<u32>, Vec<[f64; K]>, Vec<DVec3>);

/// Controls gathered per task.
const GATHER_CHUNK: usize = 128;

/// What a control's row of M is gathered from.
struct Gather<'a, const K: usize> {
    patterns: &'a Patterns<'a>,
    local: &'a [(Vec<[f64; K]>, Vec<DVec3>)],
    /// (pattern, position) of control c: `incidence[start[c]..start[c + 1]]`.
    incidence: &'a [(u32, u32)],
    start: &'a [usize],
    fairness: Option<Fairness<'a>>,
    lower_only: bool,
}

/// Per-thread accumulators over all controls, the touched flags and list.
type GatherScratch<const K: usize> = (Vec<[f64; K]>, Vec<bool>, Vec<usize>);

impl<const K: usize> Gather<'_, K> {
    /// Appends control c's neighbours and entries (sorted) to `idx` and `entries`;
    /// returns its b.
    fn row(
        &self,
        c: usize,
        scratch: &mut GatherScratch<K>,
        idx: &mut Vec<u32>,
        entries: &mut Vec<[f64; K]>,
    ) -> DVec3 {
        #[cfg(target_arch = "x86_64")]
        if super::simd::wide() {
            // SAFETY: `wide()` checked that the CPU supports AVX2 and FMA.
            return unsafe { self.row_wide(c, scratch, idx, entries) };
        }
        self.row_with(c, scratch, idx, entries)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn row_wide(
        &self,
        c: usize,
        scratch: &mut GatherScratch<K>,
        idx: &mut Vec<u32>,
        entries: &mut Vec<[f64; K]>,
    ) -> DVec3 {
        self.row_with(c, scratch, idx, entries)
    }

    #[inline(always)]
    fn row_with(
        &self,
        c: usize,
        (acc, seen, touched): &mut GatherScratch<K>,
        idx: &mut Vec<u32>,
        entries: &mut Vec<[f64; K]>,
    ) -> DVec3 {
        touched.clear();
        let mut rhs = DVec3::ZERO;
        for &(g, a) in &self.incidence[self.start[c]..self.start[c + 1]] {
            let (g, a) = (g as usize, a as usize);
            let cols = self.patterns.columns[g];
            let k = cols.len();
            let (pairs, local_rhs) = &self.local[g];
            rhs += local_rhs[a];
            // Pair (a, b) is stored at (min, max): column a of the packed rows before a,
            // then row a itself, contiguous.
            let mut row_start = 0;
            for (b, &j) in cols.iter().enumerate() {
                let pos = if b < a {
                    row_start + (a - b)
                } else {
                    packed_index(a, b, k)
                };
                row_start += k - b;
                let j = j as usize;
                if self.lower_only && j < c {
                    continue;
                }
                if !seen[j] {
                    seen[j] = true;
                    touched.push(j);
                }
                for (s, v) in acc[j].iter_mut().zip(&pairs[pos]) {
                    *s += v;
                }
            }
        }
        if let Some(f) = self.fairness {
            for k in f.lt.row_ptr[c]..f.lt.row_ptr[c + 1] {
                let (r, wc) = (f.lt.col_idx[k] as usize, f.lt.values[k] * f.smoothing);
                for e in f.l.row_ptr[r]..f.l.row_ptr[r + 1] {
                    let j = f.l.col_idx[e] as usize;
                    if self.lower_only && j < c {
                        continue;
                    }
                    if !seen[j] {
                        seen[j] = true;
                        touched.push(j);
                    }
                    let v = wc * f.l.values[e];
                    for &d in diagonal_lanes(K) {
                        acc[j][d] += v;
                    }
                }
            }
        }
        touched.sort_unstable();
        for &j in touched.iter() {
            seen[j] = false;
            idx.push(j as u32);
            entries.push(std::mem::replace(&mut acc[j], [0.0; K]));
        }
        rhs
    }
}

impl ScalarMatrix {
    /// N^T N + s L^T L and N^T p.
    pub(crate) fn assemble(
        n: &Csr,
        data: &[DVec3],
        fairness: Option<Fairness>,
        lower_only: bool,
    ) -> Self {
        assemble::<1>(n, Self::weight(data), fairness, lower_only)
    }

    /// Per data row: W = I.
    pub(super) fn weight(data: &[DVec3]) -> impl Fn(usize) -> ([f64; 1], DVec3) + Sync + '_ {
        |r| ([1.0], data[r])
    }

    pub fn apply(&self, x: &[DVec3], out: &mut [DVec3]) {
        row_products(&self.ptr, &self.idx, x, out, |k, v| {
            v * self.entries[k][SCALAR]
        });
    }

    /// Inverse diagonal (1 where a control has no term).
    pub(crate) fn jacobi(&self) -> Vec<f64> {
        (0..self.ptr.len() - 1)
            .map(|c| {
                let range = self.ptr[c]..self.ptr[c + 1];
                range
                    .clone()
                    .find(|&k| self.idx[k] as usize == c)
                    .map(|k| self.entries[k][SCALAR])
                    .filter(|d| *d > 0.0)
                    .map_or(1.0, |d| 1.0 / d)
            })
            .collect()
    }
}

impl BlockMatrix {
    /// N^T W N + s L^T L and N^T W p with W_j = n_j n_j^T + t_j I + C_j (`tangential`: t_j
    /// per data row; `curvature`: C_j, a symmetric 3x3 tangential term per data row, or none).
    pub(crate) fn assemble(
        n: &Csr,
        data: &[DVec3],
        normals: &[DVec3],
        (tangential, curvature): (&[f64], Option<&[[f64; 6]]>),
        fairness: Option<Fairness>,
        lower_only: bool,
    ) -> Self {
        assemble::<6>(
            n,
            Self::weight(data, normals, tangential, curvature),
            fairness,
            lower_only,
        )
    }

    /// Per data row: W = n n^T + t I + C, its six distinct entries (in the order
    /// xx, xy, xz, yy, yz, zz, as C's), and W p.
    pub(super) fn weight<'a>(
        data: &'a [DVec3],
        normals: &'a [DVec3],
        tangential: &'a [f64],
        curvature: Option<&'a [[f64; 6]]>,
    ) -> impl Fn(usize) -> ([f64; 6], DVec3) + Sync + 'a {
        move |r: usize| {
            let (q, p, t) = (normals[r], data[r], tangential[r]);
            let mut w = packed_outer(q, 1.0);
            for diagonal in [0, 3, 5] {
                w[diagonal] += t;
            }
            let mut wp = q * q.dot(p) + p * t;
            if let Some(c) = curvature.and_then(|c| c.get(r)) {
                for (w, c) in w.iter_mut().zip(c) {
                    *w += c;
                }
                wp += packed_mul(c, p);
            }
            (w, wp)
        }
    }

    /// The 3x3 block of an entry, row-major (symmetric, so also column-major).
    #[inline]
    pub fn block(e: &[f64; 6]) -> [f64; 9] {
        [e[0], e[1], e[2], e[1], e[3], e[4], e[2], e[4], e[5]]
    }

    /// M x.
    pub fn apply(&self, x: &[DVec3], out: &mut [DVec3]) {
        row_products(&self.ptr, &self.idx, x, out, |k, v| {
            packed_mul(&self.entries[k], v)
        });
    }

    /// Inverses of the diagonal blocks; one that cannot be inverted (no data, no fairness)
    /// becomes the identity.
    pub(crate) fn block_jacobi(&self) -> Vec<DMat3> {
        (0..self.ptr.len() - 1)
            .into_par_iter()
            .map(|c| {
                let range = self.ptr[c]..self.ptr[c + 1];
                let Some(k) = range.clone().find(|&k| self.idx[k] as usize == c) else {
                    return DMat3::IDENTITY;
                };
                let b = Self::block(&self.entries[k]);
                let mat = DMat3::from_cols_array(&b);
                let scale = b[0].max(b[4]).max(b[8]);
                let det = mat.determinant();
                if scale > 0.0 && det.is_finite() && det > 1e-12 * scale * scale * scale {
                    mat.inverse()
                } else {
                    DMat3::IDENTITY
                }
            })
            .collect()
    }
}

/// out_c = sum over c's entries k of `term(k, x[idx[k]])`, rows in parallel.
#[inline(always)]
fn row_products(
    ptr: &[usize],
    idx: &[u32],
    x: &[DVec3],
    out: &mut [DVec3],
    term: impl Fn(usize, DVec3) -> DVec3 + Sync,
) {
    out.par_iter_mut()
        .enumerate()
        .with_min_len(128)
        .for_each(|(c, o)| {
            let mut sum = DVec3::ZERO;
            for k in ptr[c]..ptr[c + 1] {
                sum += term(k, x[idx[k] as usize]);
            }
            *o = sum;
        });
}

#[cfg(test)]
mod tests;
