//! Floater's mean-value parameterization with the outer boundary on a circle (convex, so the
//! map is bijective): the fallback of `planar` for patches that are no height field; and
//! point location in a planar triangulation.

use super::{FilledPatch, MapFailure, RemeshError, DOMAIN};
use glam::{DVec2, DVec3};
use rayon::prelude::*;

/// Outer boundary on the circle by arc length (starting at the boundary vertex farthest
/// from the boundary's centroid), interior by mean-value weights, solved by sparse LU.
pub(crate) fn mean_value_disk(patch: &FilledPatch) -> Result<Vec<DVec2>, RemeshError> {
    let pos = &patch.mesh.positions;
    let n = pos.len();
    let outer = &patch.outer;
    let centroid = outer.iter().map(|&v| pos[v as usize]).sum::<DVec3>() / outer.len() as f64;
    let start = (0..outer.len())
        .max_by(|&a, &b| {
            (pos[outer[a] as usize] - centroid)
                .length()
                .total_cmp(&(pos[outer[b] as usize] - centroid).length())
        })
        .unwrap_or(0);
    let ring: Vec<u32> = (0..outer.len())
        .map(|k| outer[(start + k) % outer.len()])
        .collect();
    let mut arc = vec![0.0; ring.len() + 1];
    for k in 0..ring.len() {
        arc[k + 1] =
            arc[k] + (pos[ring[(k + 1) % ring.len()] as usize] - pos[ring[k] as usize]).length();
    }
    let total = arc[ring.len()].max(1e-300);
    let mut plane = vec![DVec2::ZERO; n];
    let mut fixed = vec![false; n];
    // The circle inscribed in the equilateral domain, shrunk a little (the caller scales
    // the map to the patch's size).
    let centre = (DOMAIN[0] + DOMAIN[1] + DOMAIN[2]) / 3.0;
    let radius = 0.95 * 3f64.sqrt() / 6.0;
    for (k, &v) in ring.iter().enumerate() {
        let angle = std::f64::consts::TAU * arc[k] / total;
        plane[v as usize] = centre + DVec2::new(angle.cos(), angle.sin()) * radius;
        fixed[v as usize] = true;
    }
    // Mean-value weights: w_ij = (tan(a1/2) + tan(a2/2)) / |x_i - x_j|, angles at i.
    let mut weights: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
    for t in &patch.mesh.triangles {
        for k in 0..3 {
            let (i, j, l) = (t[k] as usize, t[(k + 1) % 3], t[(k + 2) % 3]);
            if fixed[i] {
                continue;
            }
            let (ej, el) = (pos[j as usize] - pos[i], pos[l as usize] - pos[i]);
            let (lj, ll) = (ej.length().max(1e-300), el.length().max(1e-300));
            let angle = (ej.dot(el) / (lj * ll)).clamp(-1.0, 1.0).acos();
            let th = (angle / 2.0).tan();
            weights[i].push((j, th / lj));
            weights[i].push((l, th / ll));
        }
    }
    // Unknowns: the free vertices, numbered densely.
    let free: Vec<usize> = (0..n).filter(|&v| !fixed[v]).collect();
    let mut slot = vec![usize::MAX; n];
    for (k, &v) in free.iter().enumerate() {
        slot[v] = k;
    }
    let mut rows: Vec<Vec<(usize, f64)>> = Vec::with_capacity(free.len());
    let mut rhs = vec![DVec2::ZERO; free.len()];
    for (k, &v) in free.iter().enumerate() {
        let total: f64 = weights[v].iter().map(|w| w.1).sum();
        if !(total > 0.0 && total.is_finite()) {
            return Err(RemeshError::Parameterization(
                MapFailure::NoUsableNeighbours { vertex: v },
            ));
        }
        let mut row = Vec::with_capacity(weights[v].len());
        for &(j, w) in &weights[v] {
            let lambda = w / total;
            if fixed[j as usize] {
                rhs[k] += plane[j as usize] * lambda;
            } else {
                row.push((slot[j as usize], lambda));
            }
        }
        rows.push(row);
    }
    let x = solve_mean_value(&rows, &rhs).map_err(RemeshError::Parameterization)?;
    for (k, &v) in free.iter().enumerate() {
        plane[v] = x[k];
    }
    Ok(plane)
}

/// Solves (I - W) x = b for the mean-value system by a sparse LU factorisation (faer,
/// fill-reducing column ordering): the system is not symmetric. Each coordinate is solved
/// on its own: faer's multi-column sparse solve is the slower here.
fn solve_mean_value(rows: &[Vec<(usize, f64)>], b: &[DVec2]) -> Result<Vec<DVec2>, MapFailure> {
    use faer::linalg::solvers::Solve;
    use faer::sparse::{SparseColMat, Triplet};
    let n = rows.len();
    let mut triplets = Vec::with_capacity(n + rows.iter().map(Vec::len).sum::<usize>());
    for (i, row) in rows.iter().enumerate() {
        triplets.push(Triplet::new(i, i, 1.0));
        triplets.extend(row.iter().map(|&(j, w)| Triplet::new(i, j, -w)));
    }
    let matrix =
        SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &triplets).map_err(|e| {
            MapFailure::Solver {
                detail: format!("{e:?}"),
            }
        })?;
    let lu = matrix.sp_lu().map_err(|e| MapFailure::Solver {
        detail: format!("not factorisable: {e:?}"),
    })?;
    let mut x = vec![DVec2::ZERO; n];
    for axis in 0..2 {
        let mut column = faer::Mat::<f64>::from_fn(n, 1, |i, _| b[i][axis]);
        lu.solve_in_place(column.as_mut());
        for (i, p) in x.iter_mut().enumerate() {
            p[axis] = column[(i, 0)];
        }
    }
    if x.iter().all(|p| p.is_finite()) {
        Ok(x)
    } else {
        Err(MapFailure::Singular)
    }
}

/// Point location in the planar triangulation through a uniform grid of buckets.
pub(crate) struct Locator<'a> {
    tris: &'a [[u32; 3]],
    plane: &'a [DVec2],
    lo: DVec2,
    cell: f64,
    dim: usize,
    /// Triangles of bucket b, in triangle order: `bucketed[start[b]..start[b + 1]]` (one
    /// flat array: a scan's map has ~10^5 buckets, too many for a vector each).
    start: Vec<usize>,
    bucketed: Vec<u32>,
    /// Per bucket, the Chebyshev distance (in buckets) to the nearest non-empty one: a
    /// point outside the map starts its ring search there instead of walking empty rings
    /// (the rings skipped hold no triangle, so the result is the same). Built on first use:
    /// `contains` never needs it.
    empty_rings: std::sync::OnceLock<Vec<u32>>,
}

impl<'a> Locator<'a> {
    pub fn new(tris: &'a [[u32; 3]], plane: &'a [DVec2]) -> Self {
        let (mut lo, mut hi) = (DVec2::splat(f64::MAX), DVec2::splat(f64::MIN));
        for t in tris {
            for &v in t {
                lo = lo.min(plane[v as usize]);
                hi = hi.max(plane[v as usize]);
            }
        }
        if lo.x > hi.x {
            (lo, hi) = (DVec2::ZERO, DVec2::ONE);
        }
        let extent = (hi - lo).max_element().max(1e-300);
        lo -= DVec2::splat(extent * 1e-9);
        let dim = ((tris.len() as f64).sqrt() as usize).clamp(1, 2048);
        let cell = extent * (1.0 + 2e-9) / dim as f64;
        // Bucket ranges fit u32 (dim <= 2048): half the memory of usize, touched fresh.
        let ranges: Vec<[u32; 4]> = tris
            .par_iter()
            .with_min_len(4096)
            .map(|t| {
                let ps = [
                    plane[t[0] as usize],
                    plane[t[1] as usize],
                    plane[t[2] as usize],
                ];
                let mn = ps[0].min(ps[1]).min(ps[2]);
                let mx = ps[0].max(ps[1]).max(ps[2]);
                let (x0, y0) = Self::cell_of(lo, cell, dim, mn);
                let (x1, y1) = Self::cell_of(lo, cell, dim, mx);
                [x0, y0, x1, y1].map(|c| c as u32)
            })
            .collect();
        let mut start = vec![0usize; dim * dim + 1];
        let buckets = |&[x0, y0, x1, y1]: &[u32; 4]| {
            (y0 as usize..=y1 as usize)
                .flat_map(move |y| (x0 as usize..=x1 as usize).map(move |x| y * dim + x))
        };
        for r in &ranges {
            for b in buckets(r) {
                start[b + 1] += 1;
            }
        }
        for b in 0..dim * dim {
            start[b + 1] += start[b];
        }
        // Filled through `start` itself (each bucket's entry advanced past its triangles,
        // so it ends at the next bucket's start), then shifted back: no second index.
        let mut bucketed = vec![0u32; start[dim * dim]];
        for (f, r) in ranges.iter().enumerate() {
            for b in buckets(r) {
                bucketed[start[b]] = f as u32;
                start[b] += 1;
            }
        }
        start.copy_within(0..dim * dim, 1);
        start[0] = 0;
        Self {
            tris,
            plane,
            lo,
            cell,
            dim,
            start,
            bucketed,
            empty_rings: std::sync::OnceLock::new(),
        }
    }

    /// Two-pass chessboard distance transform of the non-empty buckets.
    fn empty_rings(&self) -> &[u32] {
        self.empty_rings.get_or_init(|| {
            let n = self.dim;
            let mut d: Vec<u32> = (0..n * n)
                .map(|b| {
                    if self.start[b + 1] > self.start[b] {
                        0
                    } else {
                        u32::MAX
                    }
                })
                .collect();
            let relax = |d: &mut [u32], k: usize, from: usize| {
                d[k] = d[k].min(d[from].saturating_add(1));
            };
            for y in 0..n {
                for x in 0..n {
                    let k = y * n + x;
                    if x > 0 {
                        relax(&mut d, k, k - 1);
                    }
                    if y > 0 {
                        relax(&mut d, k, k - n);
                        if x > 0 {
                            relax(&mut d, k, k - n - 1);
                        }
                        if x + 1 < n {
                            relax(&mut d, k, k - n + 1);
                        }
                    }
                }
            }
            for y in (0..n).rev() {
                for x in (0..n).rev() {
                    let k = y * n + x;
                    if x + 1 < n {
                        relax(&mut d, k, k + 1);
                    }
                    if y + 1 < n {
                        relax(&mut d, k, k + n);
                        if x + 1 < n {
                            relax(&mut d, k, k + n + 1);
                        }
                        if x > 0 {
                            relax(&mut d, k, k + n - 1);
                        }
                    }
                }
            }
            d
        })
    }

    fn bucket(&self, x: usize, y: usize) -> &[u32] {
        let b = y * self.dim + x;
        &self.bucketed[self.start[b]..self.start[b + 1]]
    }

    fn cell_of(lo: DVec2, cell: f64, dim: usize, p: DVec2) -> (usize, usize) {
        let q = (p - lo) / cell;
        (
            (q.x.max(0.0) as usize).min(dim - 1),
            (q.y.max(0.0) as usize).min(dim - 1),
        )
    }

    fn bary(&self, f: u32, q: DVec2) -> [f64; 3] {
        let t = self.tris[f as usize];
        let (a, b, c) = (
            self.plane[t[0] as usize],
            self.plane[t[1] as usize],
            self.plane[t[2] as usize],
        );
        let det = (b - a).perp_dot(c - a);
        if det == 0.0 {
            return [-1.0, -1.0, -1.0];
        }
        let l1 = (q - a).perp_dot(c - a) / det;
        let l2 = (b - a).perp_dot(q - a) / det;
        [1.0 - l1 - l2, l1, l2]
    }

    /// Whether `q` lies in (or within rounding of) a triangle.
    pub fn contains(&self, q: DVec2) -> bool {
        let (cx, cy) = Self::cell_of(self.lo, self.cell, self.dim, q);
        self.bucket(cx, cy).iter().any(|&f| {
            let b = self.bary(f, q);
            b[0].min(b[1]).min(b[2]) >= -1e-9
        })
    }

    /// The containing triangle and barycentric weights; on the boundary or in a numerical
    /// gap, the nearby triangle whose weights are least negative, clamped.
    pub fn locate(&self, q: DVec2) -> (usize, [f64; 3]) {
        let (cx, cy) = Self::cell_of(self.lo, self.cell, self.dim, q);
        let mut best = (f64::MIN, 0usize, [1.0, 0.0, 0.0]);
        let first = (self.empty_rings()[cy * self.dim + cx] as usize).min(self.dim);
        for r in first..self.dim {
            ring_cells(cx, cy, r, self.dim, |x, y| {
                for &f in self.bucket(x, y) {
                    let b = self.bary(f, q);
                    let worst = b[0].min(b[1]).min(b[2]);
                    if worst > best.0 {
                        best = (worst, f as usize, b);
                    }
                }
            });
            if best.0 >= -1e-12 || (best.0 > f64::MIN && r >= 1) {
                break;
            }
        }
        let b = best.2.map(|x| x.max(0.0));
        let s = b[0] + b[1] + b[2];
        (
            best.1,
            if s > 0.0 {
                b.map(|x| x / s)
            } else {
                [1.0 / 3.0; 3]
            },
        )
    }
}

/// Visits the cells of a `dim` x `dim` bucket grid at Chebyshev distance exactly `r` from
/// (cx, cy), row by row and left to right (the order of a scan of the whole square, which
/// searches that break ties by the first hit rely on), without walking the square's inside.
pub(crate) fn ring_cells(
    cx: usize,
    cy: usize,
    r: usize,
    dim: usize,
    mut visit: impl FnMut(usize, usize),
) {
    let (x0, x1) = (cx.saturating_sub(r), (cx + r).min(dim - 1));
    for y in cy.saturating_sub(r)..=(cy + r).min(dim - 1) {
        if y.abs_diff(cy) == r {
            for x in x0..=x1 {
                visit(x, y);
            }
        } else {
            if cx >= r {
                visit(cx - r, y);
            }
            if cx + r < dim {
                visit(cx + r, y);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mean_value_system_is_solved_exactly() {
        // A path of 30 free vertices, each the weighted mean of its neighbours and, at the
        // ends, of a fixed vertex (folded into b): (I - W) x = b.
        let n = 30;
        let rows: Vec<Vec<(usize, f64)>> = (0..n)
            .map(|i| {
                let w = 0.3 + 0.01 * i as f64;
                let mut row = Vec::new();
                if i > 0 {
                    row.push((i - 1, w));
                }
                if i + 1 < n {
                    row.push((i + 1, 1.0 - w - if i == 0 { 0.2 } else { 0.0 }));
                }
                row
            })
            .collect();
        let b: Vec<DVec2> = (0..n)
            .map(|i| match i {
                0 => DVec2::new(0.2, -0.2),
                i if i == n - 1 => DVec2::new(1.0 - 0.3 - 0.01 * i as f64, 0.5),
                _ => DVec2::ZERO,
            })
            .collect();
        let x = solve_mean_value(&rows, &b).expect("solves");
        for (i, row) in rows.iter().enumerate() {
            let r = x[i] - row.iter().map(|&(j, w)| x[j] * w).sum::<DVec2>() - b[i];
            assert!(r.length() < 1e-12, "row {i}: residual {r}");
        }
    }

    #[test]
    fn ring_cells_visit_the_square_scan_in_its_order() {
        for dim in [1usize, 2, 5, 9] {
            for (cx, cy) in [(0, 0), (dim / 2, dim / 3), (dim - 1, dim - 1), (0, dim - 1)] {
                for r in 0..dim + 1 {
                    let mut scan = Vec::new();
                    for y in cy.saturating_sub(r)..=(cy + r).min(dim - 1) {
                        for x in cx.saturating_sub(r)..=(cx + r).min(dim - 1) {
                            if x.abs_diff(cx).max(y.abs_diff(cy)) == r {
                                scan.push((x, y));
                            }
                        }
                    }
                    let mut ring = Vec::new();
                    ring_cells(cx, cy, r, dim, |x, y| ring.push((x, y)));
                    assert_eq!(ring, scan, "dim {dim} centre ({cx}, {cy}) r {r}");
                }
            }
        }
    }

    #[test]
    fn empty_rings_are_chessboard_distances_and_far_points_find_the_nearest_triangle() {
        // Two triangles in opposite corners of a large empty box (a third, tiny and far away,
        // stretches the bucket grid).
        let plane = vec![
            DVec2::new(0.0, 0.0),
            DVec2::new(1.0, 0.0),
            DVec2::new(0.0, 1.0),
            DVec2::new(9.0, 9.0),
            DVec2::new(10.0, 9.0),
            DVec2::new(10.0, 10.0),
            DVec2::new(0.0, 10.0),
            DVec2::new(0.01, 10.0),
            DVec2::new(0.0, 9.99),
        ];
        let tris = vec![[0, 1, 2], [3, 4, 5], [6, 8, 7]];
        let loc = Locator::new(&tris, &plane);
        let n = loc.dim;
        let rings = loc.empty_rings();
        for y in 0..n {
            for x in 0..n {
                let brute = (0..n * n)
                    .filter(|&b| !loc.bucket(b % n, b / n).is_empty())
                    .map(|b| (b % n).abs_diff(x).max((b / n).abs_diff(y)))
                    .min()
                    .map_or(u32::MAX, |d| d as u32);
                assert_eq!(rings[y * n + x], brute, "bucket ({x}, {y})");
            }
        }
        let (f, b) = loc.locate(DVec2::new(0.2, 0.2));
        assert_eq!(f, 0);
        assert!((b[0] - 0.6).abs() < 1e-12);
        // Outside everything, near the second triangle: its nearest corner, clamped.
        let (f, b) = loc.locate(DVec2::new(10.5, 10.5));
        assert_eq!(f, 1);
        assert!((b[2] - 1.0).abs() < 1e-12, "{b:?}");
    }
}
