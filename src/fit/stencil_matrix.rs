//! Normal equations of fits whose data rows all come from a fixed set of stencils: on a
//! grid spline a point's row is its cell's 12 controls, and the cells are known before any
//! point is placed. Where every pair of a stencil lands in M (and which entries the
//! fairness term fills) is then the same in every round of a fit, so it is worked out once
//! (`StencilPlan`); an assembly only sums the rows of each stencil into one packed dense
//! matrix (as `normal_matrix` does per pattern) and adds those sums into place, without
//! grouping rows by column lists, sorting neighbours or recomputing L^T L.
//!
//! The result is the same `NormalMatrix` as the general assembly's (same structure, same
//! sums up to the order of floating-point additions), solved by the same code.

use super::csr::Csr;
use super::normal_matrix::{diagonal_lanes, BlockMatrix, Fairness, NormalMatrix, ScalarMatrix};
use glam::DVec3;
use rayon::prelude::*;

/// Controls per stencil (a box-spline cell).
pub(crate) const WIDTH: usize = 12;

/// One data row per point: its stencil and the weights of the stencil's controls.
#[derive(Clone, Debug, Default)]
pub(crate) struct StencilRows {
    pub stencil: Vec<u32>,
    pub weights: Vec<[f64; WIDTH]>,
}

/// Pair sums are formed four columns at a time: the four sums of a row of the 12 x 12
/// block stay in registers over all of a stencil's rows, so a row costs its multiplies
/// and two loads instead of a load and a store of every sum (the 78 sums of a stencil do
/// not fit the registers; summed pair by pair the assembly was bound by those stores).
const BLOCK: usize = 4;
const BLOCKS: usize = WIDTH / BLOCK;

/// The pair sums of one stencil, `sums[a][b]` for `b >= a` (rounded down to a block of
/// four: entries left of the diagonal inside a block are computed and never read).
type PairSums<const K: usize> = [[[f64; K]; WIDTH]; WIDTH];

/// `normal_matrix::accumulate` for rows of exactly WIDTH values. `staged` holds the rows'
/// weights and values while the pairs are summed; the sums per pair run over the rows in
/// the same order as the general assembly's.
#[inline(always)]
fn accumulate_stencil<const K: usize>(
    values: &[[f64; WIDTH]],
    rows: &[u32],
    weight: &impl Fn(usize) -> ([f64; K], DVec3),
    staged: &mut Vec<([f64; K], [f64; WIDTH])>,
    sums: &mut PairSums<K>,
    rhs: &mut [DVec3; WIDTH],
) {
    staged.clear();
    for &r in rows {
        let r = r as usize;
        let w = values[r];
        let (q, wp) = weight(r);
        for a in 0..WIDTH {
            rhs[a] += wp * w[a];
        }
        staged.push((q, w));
    }
    for a in 0..WIDTH {
        for block in a / BLOCK..BLOCKS {
            let mut acc = [[0.0f64; K]; BLOCK];
            for (q, w) in staged.iter() {
                let wq = q.map(|x| x * w[a]);
                for (j, acc) in acc.iter_mut().enumerate() {
                    let wb = w[block * BLOCK + j];
                    for c in 0..K {
                        acc[c] += wq[c] * wb;
                    }
                }
            }
            sums[a][block * BLOCK..(block + 1) * BLOCK].copy_from_slice(&acc);
        }
    }
}

/// What an assembly sums per stencil: the rows' values and weights, and the rows of each
/// stencil (`order[start[g]..start[g + 1]]`).
struct StencilSums<'a, W> {
    values: &'a [[f64; WIDTH]],
    weight: &'a W,
    order: &'a [u32],
    start: &'a [usize],
}

/// The fixed part of every assembly over a set of stencils.
#[derive(Clone, Debug)]
pub(crate) struct StencilPlan {
    controls: usize,
    stencils: Vec<[u32; WIDTH]>,
    ptr: Vec<usize>,
    idx: Vec<u32>,
    /// For stencil g's control c at position a (`g * WIDTH + a`): for each control of
    /// that stencil, the entry of c's row it adds into (counted from the row's start).
    /// Stencil by stencil, as an assembly walks them: kept by control instead (as the
    /// plan's rows are built), each lookup was a cache miss, half of an assembly's time.
    slots: Vec<[u32; WIDTH]>,
    /// The stencils by band: band b holds the stencils whose smallest control lies in
    /// `b * band_width..(b + 1) * band_width`, `band_stencils[bands[b]..bands[b + 1]]`. No
    /// stencil spans `band_width` controls, so a band's stencils touch only controls
    /// `b * band_width..(b + 2) * band_width`, and bands two apart touch disjoint rows.
    band_width: usize,
    bands: Vec<usize>,
    band_stencils: Vec<u32>,
    /// s (L^T L) of every entry.
    fairness: Vec<f64>,
}

/// One control's row of the plan: neighbours, entry slots per membership, fairness.
type PlanRow = (Vec<u32>, Vec<[u32; WIDTH]>, Vec<f64>);

impl StencilPlan {
    /// The plan for `controls` controls, the given stencils (each control at most once in
    /// a stencil) and the fairness term, if any.
    pub fn new(controls: usize, stencils: Vec<[u32; WIDTH]>, fairness: Option<Fairness>) -> Self {
        let fairness = fairness.filter(|f| f.smoothing > 0.0);
        let m = controls;
        let mut member_ptr = vec![0usize; m + 1];
        for s in &stencils {
            for &c in s {
                member_ptr[c as usize + 1] += 1;
            }
        }
        for c in 0..m {
            member_ptr[c + 1] += member_ptr[c];
        }
        let mut fill = member_ptr.clone();
        let mut members = vec![0u32; member_ptr[m]];
        for (g, s) in stencils.iter().enumerate() {
            for (a, &c) in s.iter().enumerate() {
                members[fill[c as usize]] = (g * WIDTH + a) as u32;
                fill[c as usize] += 1;
            }
        }

        let rows: Vec<PlanRow> = (0..m)
            .into_par_iter()
            .with_min_len(64)
            .map_init(
                || vec![u32::MAX; m],
                |slot, c| {
                    let own = &members[member_ptr[c]..member_ptr[c + 1]];
                    let mut idx: Vec<u32> = Vec::new();
                    let mut mark = |j: u32, idx: &mut Vec<u32>| {
                        if slot[j as usize] == u32::MAX {
                            slot[j as usize] = 0;
                            idx.push(j);
                        }
                    };
                    for &member in own {
                        for &j in &stencils[member as usize / WIDTH] {
                            mark(j, &mut idx);
                        }
                    }
                    if let Some(f) = fairness {
                        for k in f.lt.row_ptr[c]..f.lt.row_ptr[c + 1] {
                            let r = f.lt.col_idx[k] as usize;
                            for &j in &f.l.col_idx[f.l.row_ptr[r]..f.l.row_ptr[r + 1]] {
                                mark(j, &mut idx);
                            }
                        }
                    }
                    idx.sort_unstable();
                    for (k, &j) in idx.iter().enumerate() {
                        slot[j as usize] = k as u32;
                    }
                    let slots = own
                        .iter()
                        .map(|&member| stencils[member as usize / WIDTH].map(|j| slot[j as usize]))
                        .collect();
                    let mut fair = vec![0.0; idx.len()];
                    if let Some(f) = fairness {
                        for k in f.lt.row_ptr[c]..f.lt.row_ptr[c + 1] {
                            let (r, wc) = (f.lt.col_idx[k] as usize, f.lt.values[k] * f.smoothing);
                            for e in f.l.row_ptr[r]..f.l.row_ptr[r + 1] {
                                fair[slot[f.l.col_idx[e] as usize] as usize] += wc * f.l.values[e];
                            }
                        }
                    }
                    for &j in &idx {
                        slot[j as usize] = u32::MAX;
                    }
                    (idx, slots, fair)
                },
            )
            .collect();

        let span = |s: &[u32; WIDTH]| {
            let (lo, hi) = (s.iter().min(), s.iter().max());
            (*lo.unwrap_or(&0) as usize, *hi.unwrap_or(&0) as usize)
        };
        let band_width = stencils
            .iter()
            .map(|s| span(s).1 - span(s).0 + 1)
            .max()
            .unwrap_or(1);
        let band_of = |s: &[u32; WIDTH]| span(s).0 / band_width;
        let band_count = m.div_ceil(band_width).max(1);
        let mut bands = vec![0usize; band_count + 1];
        for s in &stencils {
            bands[band_of(s) + 1] += 1;
        }
        for b in 0..band_count {
            bands[b + 1] += bands[b];
        }
        let mut band_fill = bands.clone();
        let mut band_stencils = vec![0u32; stencils.len()];
        for (g, s) in stencils.iter().enumerate() {
            band_stencils[band_fill[band_of(s)]] = g as u32;
            band_fill[band_of(s)] += 1;
        }

        let nnz = rows.iter().map(|r| r.0.len()).sum();
        let mut plan = StencilPlan {
            controls,
            stencils,
            ptr: Vec::with_capacity(m + 1),
            idx: Vec::with_capacity(nnz),
            slots: vec![[0; WIDTH]; members.len()],
            band_width,
            bands,
            band_stencils,
            fairness: Vec::with_capacity(nnz),
        };
        plan.ptr.push(0);
        for (c, (idx, slots, fair)) in rows.into_iter().enumerate() {
            let own = &members[member_ptr[c]..member_ptr[c + 1]];
            for (&member, slot) in own.iter().zip(slots) {
                plan.slots[member as usize] = slot;
            }
            plan.idx.extend(idx);
            plan.fairness.extend(fair);
            plan.ptr.push(plan.idx.len());
        }
        plan
    }

    /// N^T W N + s L^T L and N^T W p, with `weight(r)` giving row r's W (the scalar, or the
    /// six entries of a block) and W p.
    fn assemble<const K: usize>(
        &self,
        rows: &StencilRows,
        weight: impl Fn(usize) -> ([f64; K], DVec3) + Sync,
    ) -> NormalMatrix<K> {
        let groups = self.stencils.len();
        // Rows by stencil (counting sort).
        let mut start = vec![0usize; groups + 1];
        for &g in &rows.stencil {
            start[g as usize + 1] += 1;
        }
        for g in 0..groups {
            start[g + 1] += start[g];
        }
        let mut fill = start.clone();
        let mut order = vec![0u32; rows.stencil.len()];
        for (r, &g) in rows.stencil.iter().enumerate() {
            order[fill[g as usize]] = r as u32;
            fill[g as usize] += 1;
        }

        let mut entries: Vec<[f64; K]> = self
            .fairness
            .iter()
            .map(|&f| {
                let mut e = [0.0; K];
                for &d in diagonal_lanes(K) {
                    e[d] = f;
                }
                e
            })
            .collect();
        let mut rhs = vec![DVec3::ZERO; self.controls];
        let work = StencilSums {
            values: &rows.weights,
            weight: &weight,
            order: &order,
            start: &start,
        };
        // Bands two apart touch disjoint controls: the even bands add into their rows in
        // parallel, then the odd ones.
        for parity in 0..2 {
            let mut pieces = Vec::new();
            let (mut entries_rest, mut rhs_rest) = (entries.as_mut_slice(), rhs.as_mut_slice());
            let mut first = 0;
            for band in (parity..self.bands.len() - 1).step_by(2) {
                let (lo, hi) = self.band_controls(band);
                let (_, e) = entries_rest.split_at_mut(self.ptr[lo] - self.ptr[first]);
                let (piece_e, e) = e.split_at_mut(self.ptr[hi] - self.ptr[lo]);
                let (_, r) = rhs_rest.split_at_mut(lo - first);
                let (piece_r, r) = r.split_at_mut(hi - lo);
                pieces.push((band, lo, piece_e, piece_r));
                (entries_rest, rhs_rest, first) = (e, r, hi);
            }
            pieces
                .into_par_iter()
                .for_each(|(band, lo, piece_e, piece_r)| {
                    self.add_band(band, lo, piece_e, piece_r, &work)
                });
        }
        NormalMatrix {
            ptr: self.ptr.clone(),
            idx: self.idx.clone(),
            entries,
            rhs,
        }
    }

    /// The controls band `b`'s stencils touch: `lo..hi`.
    fn band_controls(&self, b: usize) -> (usize, usize) {
        let lo = (self.band_width * b).min(self.controls);
        let hi = (self.band_width * (b + 2)).min(self.controls);
        (lo, hi)
    }

    /// Sums each stencil of band `band` over its rows and adds the sums into the rows of
    /// its controls (`entries` and `rhs` start at control `lo`).
    fn add_band<const K: usize>(
        &self,
        band: usize,
        lo: usize,
        entries: &mut [[f64; K]],
        rhs: &mut [DVec3],
        work: &StencilSums<impl Fn(usize) -> ([f64; K], DVec3) + Sync>,
    ) {
        #[cfg(target_arch = "x86_64")]
        if super::simd::wide() {
            // SAFETY: `wide()` checked that the CPU supports AVX2 and FMA.
            return unsafe { self.add_band_wide(band, lo, entries, rhs, work) };
        }
        self.add_band_with(band, lo, entries, rhs, work)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn add_band_wide<const K: usize>(
        &self,
        band: usize,
        lo: usize,
        entries: &mut [[f64; K]],
        rhs: &mut [DVec3],
        work: &StencilSums<impl Fn(usize) -> ([f64; K], DVec3) + Sync>,
    ) {
        self.add_band_with(band, lo, entries, rhs, work)
    }

    #[inline(always)]
    fn add_band_with<const K: usize>(
        &self,
        band: usize,
        lo: usize,
        entries: &mut [[f64; K]],
        rhs: &mut [DVec3],
        work: &StencilSums<impl Fn(usize) -> ([f64; K], DVec3) + Sync>,
    ) {
        let row_base = self.ptr[lo];
        let mut sums: PairSums<K> = [[[0.0f64; K]; WIDTH]; WIDTH];
        let mut staged = Vec::new();
        let mut local_rhs = [DVec3::ZERO; WIDTH];
        for &g in &self.band_stencils[self.bands[band]..self.bands[band + 1]] {
            let g = g as usize;
            let members = &work.order[work.start[g]..work.start[g + 1]];
            if members.is_empty() {
                continue;
            }
            local_rhs.iter_mut().for_each(|b| *b = DVec3::ZERO);
            accumulate_stencil(
                work.values,
                members,
                work.weight,
                &mut staged,
                &mut sums,
                &mut local_rhs,
            );
            for (a, &c) in self.stencils[g].iter().enumerate() {
                let c = c as usize;
                rhs[c - lo] += local_rhs[a];
                let row = &mut entries[self.ptr[c] - row_base..self.ptr[c + 1] - row_base];
                let slots = &self.slots[g * WIDTH + a];
                for (b, &k) in slots.iter().enumerate() {
                    let v = &sums[a.min(b)][a.max(b)];
                    let e = &mut row[k as usize];
                    for q in 0..K {
                        e[q] += v[q];
                    }
                }
            }
        }
    }

    /// N^T N + s L^T L and N^T p (point-to-point).
    pub(crate) fn assemble_scalar(&self, rows: &StencilRows, data: &[DVec3]) -> ScalarMatrix {
        self.assemble::<1>(rows, ScalarMatrix::weight(data))
    }

    /// N^T W N + s L^T L and N^T W p with W_j = n_j n_j^T + t_j I (squared distance).
    pub(crate) fn assemble_blocks(
        &self,
        rows: &StencilRows,
        data: &[DVec3],
        normals: &[DVec3],
        tangential: &[f64],
    ) -> BlockMatrix {
        self.assemble::<6>(rows, BlockMatrix::weight(data, normals, tangential, None))
    }
}

impl StencilRows {
    /// out_j = sum_k w_jk x[stencil_j[k]].
    pub fn mul_vec3(&self, plan: &StencilPlan, x: &[DVec3], out: &mut [DVec3]) {
        out.par_iter_mut()
            .zip(self.stencil.par_iter().zip(&self.weights))
            .with_min_len(1024)
            .for_each(|(o, (&g, w))| {
                *o = plan.stencils[g as usize]
                    .iter()
                    .zip(w)
                    .map(|(&c, &wk)| x[c as usize] * wk)
                    .sum();
            });
    }

    /// The same rows as a general sparse matrix (zero weights dropped, as the general
    /// collocation does).
    pub(crate) fn to_csr(&self, plan: &StencilPlan) -> Csr {
        let mut m = Csr {
            nrows: self.stencil.len(),
            ncols: plan.controls,
            row_ptr: Vec::with_capacity(self.stencil.len() + 1),
            col_idx: Vec::with_capacity(self.stencil.len() * WIDTH),
            values: Vec::with_capacity(self.stencil.len() * WIDTH),
        };
        m.row_ptr.push(0);
        for (&g, w) in self.stencil.iter().zip(&self.weights) {
            for (&c, &wk) in plan.stencils[g as usize].iter().zip(w) {
                if wk != 0.0 {
                    m.col_idx.push(c);
                    m.values.push(wk);
                }
            }
            m.row_ptr.push(m.col_idx.len());
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator: the test needs varied numbers, not good ones.
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    fn dense<const K: usize>(m: &NormalMatrix<K>, n: usize) -> Vec<[f64; K]> {
        let mut d = vec![[0.0; K]; n * n];
        for c in 0..n {
            for k in m.ptr[c]..m.ptr[c + 1] {
                d[c * n + m.idx[k] as usize] = m.entries[k];
            }
        }
        d
    }

    /// The planned assembly against the general one over the same rows (random stencils,
    /// weights, normals and fairness): same matrix and right-hand side, scalar and blocks.
    #[test]
    fn planned_assembly_equals_the_general_assembly() {
        let mut rng = Lcg(7);
        let m = 41;
        let stencils: Vec<[u32; WIDTH]> = (0..25)
            .map(|g| std::array::from_fn(|k| ((g * 3 + k * 7) % m) as u32))
            .collect();
        for s in &stencils {
            let mut sorted = s.to_vec();
            sorted.sort_unstable();
            sorted.dedup();
            assert_eq!(sorted.len(), WIDTH, "distinct controls per stencil");
        }
        let points = 600;
        // Some stencils get no rows, as cells without data do.
        let rows = StencilRows {
            stencil: (0..points).map(|j| ((j * 7) % 20) as u32).collect(),
            weights: (0..points)
                .map(|_| std::array::from_fn(|_| rng.next()))
                .collect(),
        };
        let data: Vec<DVec3> = (0..points)
            .map(|_| DVec3::new(rng.next(), rng.next(), rng.next()))
            .collect();
        let normals: Vec<DVec3> = (0..points)
            .map(|_| DVec3::new(rng.next() - 0.5, rng.next() - 0.5, 1.0).normalize())
            .collect();
        let l = crate::fit::csr::ring_laplacian(m, 9);
        let fairness = super::super::Collocation::new(l);
        let fair = Fairness {
            l: fairness.n(),
            lt: fairness.nt(),
            smoothing: 0.3,
        };
        let plan = StencilPlan::new(m, stencils, Some(fair));
        let basis = rows.to_csr(&plan);

        let (a, b) = (
            plan.assemble_scalar(&rows, &data),
            ScalarMatrix::assemble(&basis, &data, Some(fair), false),
        );
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * (1.0 + x.abs().max(y.abs()));
        for (x, y) in dense(&a, m).iter().zip(&dense(&b, m)) {
            assert!(close(x[0], y[0]), "{x:?} vs {y:?}");
        }
        for (x, y) in a.rhs.iter().zip(&b.rhs) {
            assert!(
                (*x - *y).length() < 1e-12 * (1.0 + x.length()),
                "{x} vs {y}"
            );
        }

        let tangential: Vec<f64> = (0..points).map(|j| [0.005, 0.05][j % 2]).collect();
        let (a, b) = (
            plan.assemble_blocks(&rows, &data, &normals, &tangential),
            BlockMatrix::assemble(
                &basis,
                &data,
                &normals,
                (&tangential, None),
                Some(fair),
                false,
            ),
        );
        for (x, y) in dense(&a, m).iter().zip(&dense(&b, m)) {
            for k in 0..6 {
                assert!(close(x[k], y[k]), "{x:?} vs {y:?}");
            }
        }
        for (x, y) in a.rhs.iter().zip(&b.rhs) {
            assert!(
                (*x - *y).length() < 1e-12 * (1.0 + x.length()),
                "{x} vs {y}"
            );
        }

        // And N x through the rows equals N x through the sparse matrix.
        let x: Vec<DVec3> = (0..m)
            .map(|_| DVec3::new(rng.next(), 1.0, -rng.next()))
            .collect();
        let (mut via_rows, mut via_csr) = (vec![DVec3::ZERO; points], vec![DVec3::ZERO; points]);
        rows.mul_vec3(&plan, &x, &mut via_rows);
        basis.mul_vec3(&x, &mut via_csr);
        for (p, q) in via_rows.iter().zip(&via_csr) {
            assert!((*p - *q).length() < 1e-12, "{p} vs {q}");
        }
    }
}
