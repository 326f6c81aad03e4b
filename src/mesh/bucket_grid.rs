//! Points bucketed on a uniform grid: each bucket's point indices side by side (a counting
//! sort, ascending within a bucket), the buckets in a dense array over the points' box,
//! x fastest. Neighbour queries read the 27 buckets around a point; the three buckets of a
//! row along x are adjacent, so such a query reads 9 runs.
//!
//! Hand-written: the spatial-index crates (rstar, kiddo) answer nearest and radius queries
//! through a tree, in an order that depends on how the tree was built; the merge's
//! function sums every sample of a neighbourhood, and its bits must not depend on the
//! order the scans arrived in, so it reads buckets in a fixed order.

use glam::DVec3;
use std::ops::Range;

/// The buckets of a point set (see the module docs).
#[derive(Clone, Debug)]
pub struct BucketGrid {
    cell: f64,
    low: [i64; 3],
    size: [i64; 3],
    /// Indices of bucket b: `members[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    members: Vec<u32>,
}

/// Buckets the grid may hold per point (at least `MIN_BUCKETS`); a set spread wider than
/// that (far-apart pieces) gets coarser buckets, which only makes queries read more points.
const BUCKETS_PER_POINT: f64 = 8.0;
const MIN_BUCKETS: f64 = 65536.0;

impl BucketGrid {
    /// Buckets of side `cell`, or coarser where the finite points of `points` span too
    /// many of them; `None` without finite points or with a `cell` that is not positive
    /// and finite. Non-finite points are in no bucket.
    pub fn new(points: &[DVec3], cell: f64) -> Option<Self> {
        if !(cell.is_finite() && cell > 0.0) {
            return None;
        }
        let finite = || points.iter().filter(|p| p.is_finite());
        let lo = finite().fold(DVec3::splat(f64::INFINITY), |a, p| a.min(*p));
        let hi = finite().fold(DVec3::splat(f64::NEG_INFINITY), |a, p| a.max(*p));
        if !lo.is_finite() {
            return None;
        }
        let limit = (BUCKETS_PER_POINT * points.len() as f64).max(MIN_BUCKETS);
        let mut cell = cell;
        // The buckets from the lowest point's to the highest's, both ends included.
        let (low, size) = loop {
            let (first, last) = ((lo / cell).floor(), (hi / cell).floor());
            let extent = last - first + DVec3::ONE;
            let count = extent.x * extent.y * extent.z;
            if count <= limit {
                break (
                    [first.x as i64, first.y as i64, first.z as i64],
                    [extent.x as i64, extent.y as i64, extent.z as i64],
                );
            }
            cell *= (count / limit).cbrt().max(1.01);
        };
        let mut grid = Self {
            cell,
            low,
            size,
            start: Vec::new(),
            members: Vec::new(),
        };
        let slots: Vec<Option<usize>> = points.iter().map(|p| grid.slot(*p)).collect();
        let buckets = (size[0] * size[1] * size[2]) as usize;
        let mut start = vec![0u32; buckets + 1];
        for s in slots.iter().flatten() {
            start[s + 1] += 1;
        }
        for b in 0..buckets {
            start[b + 1] += start[b];
        }
        let mut next = start.clone();
        let mut members = vec![0u32; start[buckets] as usize];
        for (i, s) in slots.iter().enumerate() {
            if let Some(s) = s {
                members[next[*s] as usize] = i as u32;
                next[*s] += 1;
            }
        }
        grid.start = start;
        grid.members = members;
        Some(grid)
    }

    /// The side of the buckets (at least the `cell` asked for).
    pub fn cell(&self) -> f64 {
        self.cell
    }

    /// The point indices in bucket order: what `row` ranges index.
    pub fn members(&self) -> &[u32] {
        &self.members
    }

    /// The bucket of `p` (any point, inside the grid's box or not).
    pub fn key(&self, p: DVec3) -> [i64; 3] {
        let q = (p / self.cell).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    }

    fn slot_of_key(&self, k: [i64; 3]) -> Option<usize> {
        let [x, y, z] = [0, 1, 2].map(|a| k[a] - self.low[a]);
        let inside = (0..3).all(|a| (0..self.size[a]).contains(&[x, y, z][a]));
        inside.then(|| ((z * self.size[1] + y) * self.size[0] + x) as usize)
    }

    fn slot(&self, p: DVec3) -> Option<usize> {
        if !p.is_finite() {
            return None;
        }
        self.slot_of_key(self.key(p))
    }

    /// The members of buckets `k` - 1, `k` and `k` + 1 along x, as one range of
    /// `members` (empty where none of them is inside the grid).
    pub fn row(&self, k: [i64; 3]) -> Range<usize> {
        let (y, z) = (k[1] - self.low[1], k[2] - self.low[2]);
        if !(0..self.size[1]).contains(&y) || !(0..self.size[2]).contains(&z) {
            return 0..0;
        }
        let from = (k[0] - 1 - self.low[0]).max(0);
        let to = (k[0] + 1 - self.low[0]).min(self.size[0] - 1);
        if from > to {
            return 0..0;
        }
        let base = ((z * self.size[1] + y) * self.size[0]) as usize;
        self.start[base + from as usize] as usize..self.start[base + to as usize + 1] as usize
    }

    /// Calls `visit` with the 9 rows (`row`) of the 27 buckets around `p`, in (z, y)
    /// order; nothing for a point that is not finite.
    pub fn around(&self, p: DVec3, mut visit: impl FnMut(Range<usize>)) {
        if !p.is_finite() {
            return;
        }
        let [x, y, z] = self.key(p);
        for dz in -1..=1 {
            for dy in -1..=1 {
                let run = self.row([x, y + dy, z + dz]);
                if !run.is_empty() {
                    visit(run);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 27 buckets around a query hold exactly the points whose bucket is within one
    /// of the query's along every axis, each once, bucket by bucket in (z, y, x) order and
    /// ascending within a bucket; far-apart points coarsen the buckets.
    #[test]
    fn the_rows_around_a_point_hold_its_neighbour_buckets_in_order() {
        let mut seed = 11u64;
        let mut next = || crate::testdata::uniform(&mut seed);
        let points: Vec<DVec3> = (0..3000)
            .map(|_| DVec3::new(next(), next(), 0.3 * next()))
            .chain([DVec3::splat(f64::NAN)])
            .collect();
        let grid = BucketGrid::new(&points, 0.05).expect("a grid");
        assert_eq!(grid.cell(), 0.05);
        assert_eq!(
            grid.members().len(),
            points.len() - 1,
            "NaN is in no bucket"
        );
        for q in 0..200 {
            let p = DVec3::new(next() * 1.2 - 0.1, next() * 1.2 - 0.1, next() * 0.5 - 0.1);
            let mut got = Vec::new();
            grid.around(p, |run| got.extend_from_slice(&grid.members()[run]));
            let k = grid.key(p);
            let mut want: Vec<(i64, i64, i64, u32)> = (0..points.len() as u32)
                .filter(|&i| points[i as usize].is_finite())
                .filter_map(|i| {
                    let b = grid.key(points[i as usize]);
                    (0..3)
                        .all(|a| (b[a] - k[a]).abs() <= 1)
                        .then_some((b[2], b[1], b[0], i))
                })
                .collect();
            want.sort_unstable();
            let want: Vec<u32> = want.iter().map(|w| w.3).collect();
            assert_eq!(got, want, "query {q} at {p}");
        }
        let mut none = 0;
        grid.around(DVec3::splat(f64::NAN), |_| none += 1);
        assert_eq!(none, 0);
        let far = [DVec3::ZERO, DVec3::splat(1e6)];
        let coarse = BucketGrid::new(&far, 1.0).expect("a grid");
        assert!(coarse.cell() > 1.0);
        assert!(BucketGrid::new(&far, 0.0).is_none());
        assert!(BucketGrid::new(&[], 1.0).is_none());
    }
}
