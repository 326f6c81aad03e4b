//! Nearest points among a fixed set by a bucket grid, for queries that mostly lie near the
//! set (a new version of a scanned object against the previous one's points). A query
//! reads the 27 buckets around it and answers only when what it found is provably the
//! nearest; one far from the set (new ground) gets `None`, and the caller asks a
//! structure whose cost does not grow with the distance (an R-tree), rather than the grid
//! searching ring after ring.

use glam::DVec3;

/// Points bucketed on a uniform grid, each bucket's indices side by side.
pub struct PointGrid<'a> {
    points: &'a [DVec3],
    cell: f64,
    low: [i64; 3],
    size: [i64; 3],
    /// Indices of bucket b: `bucketed[start[b]..start[b + 1]]`, ascending.
    start: Vec<u32>,
    bucketed: Vec<u32>,
}

/// Buckets the grid may hold per point; a set spread wider than that (far-apart pieces)
/// gets coarser buckets, which only makes queries read more points.
const BUCKETS_PER_POINT: i64 = 8;

impl<'a> PointGrid<'a> {
    /// A grid of buckets of side `cell` (at least the spacing of the points, so that a
    /// query near the set finds its nearest point among the 27 buckets around it) over
    /// the finite points of `points`; `None` without such points or with a `cell` that is
    /// not positive and finite.
    pub fn new(points: &'a [DVec3], cell: f64) -> Option<Self> {
        if !(cell.is_finite() && cell > 0.0) {
            return None;
        }
        let finite = || points.iter().filter(|p| p.is_finite());
        let lo = finite().fold(DVec3::splat(f64::INFINITY), |a, p| a.min(*p));
        let hi = finite().fold(DVec3::splat(f64::NEG_INFINITY), |a, p| a.max(*p));
        if !lo.is_finite() {
            return None;
        }
        let limit = (BUCKETS_PER_POINT * points.len() as i64).max(1 << 12);
        let mut cell = cell;
        // The buckets from the lowest point's to the highest's, both ends included.
        let (low, size) = loop {
            let (first, last) = ((lo / cell).floor(), (hi / cell).floor());
            let extent = last - first + DVec3::ONE;
            let count = extent.x * extent.y * extent.z;
            if count <= limit as f64 {
                break (
                    [first.x as i64, first.y as i64, first.z as i64],
                    [extent.x as i64, extent.y as i64, extent.z as i64],
                );
            }
            cell *= (count / limit as f64).cbrt().max(1.01);
        };
        let mut grid = Self {
            points,
            cell,
            low,
            size,
            start: Vec::new(),
            bucketed: Vec::new(),
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
        let mut bucketed = vec![0u32; start[buckets] as usize];
        for (i, s) in slots.iter().enumerate() {
            if let Some(s) = s {
                bucketed[next[*s] as usize] = i as u32;
                next[*s] += 1;
            }
        }
        grid.start = start;
        grid.bucketed = bucketed;
        Some(grid)
    }

    fn key(&self, p: DVec3) -> [i64; 3] {
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

    /// The index of the point nearest `q` (the lowest index among equally near ones) when
    /// the 27 buckets around `q` prove it the nearest; `None` otherwise (no point there,
    /// or a nearer one may lie beyond them).
    pub fn nearest(&self, q: DVec3) -> Option<usize> {
        if !q.is_finite() {
            return None;
        }
        let k = self.key(q);
        let mut best: Option<(f64, u32)> = None;
        for dz in -1..=1 {
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let Some(s) = self.slot_of_key([k[0] + dx, k[1] + dy, k[2] + dz]) else {
                        continue;
                    };
                    let bucket = &self.bucketed[self.start[s] as usize..self.start[s + 1] as usize];
                    for &i in bucket {
                        let d = self.points[i as usize].distance_squared(q);
                        if best.is_none_or(|(b, j)| d < b || (d == b && i < j)) {
                            best = Some((d, i));
                        }
                    }
                }
            }
        }
        let (d, i) = best?;
        // Every point outside the block lies farther than the block's nearest face.
        let inside = q / self.cell - (q / self.cell).floor();
        let margin = inside.min(DVec3::ONE - inside).min_element() * self.cell;
        let reach = self.cell + margin;
        (d.sqrt() <= reach).then_some(i as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(points: &[DVec3], q: DVec3) -> usize {
        let mut best = (f64::INFINITY, 0);
        for (i, p) in points.iter().enumerate() {
            let d = p.distance_squared(q);
            if d < best.0 {
                best = (d, i);
            }
        }
        best.1
    }

    #[test]
    fn an_answer_is_the_nearest_point_and_far_queries_get_none() {
        let mut seed = 7u64;
        let mut next = || crate::testdata::uniform(&mut seed);
        // Points on a wavy sheet, spacing about 0.01.
        let points: Vec<DVec3> = (0..4000)
            .map(|_| {
                let (x, y) = (next(), next());
                DVec3::new(x, y, 0.05 * (6.0 * x).sin())
            })
            .collect();
        let grid = PointGrid::new(&points, 0.02).expect("a grid");
        let (mut answered, mut far) = (0, 0);
        for n in 0..3000 {
            // Near the sheet (within about a spacing), or anywhere in a box around it.
            let (x, y) = (next() * 1.4 - 0.2, next() * 1.4 - 0.2);
            let z = if n % 2 == 0 {
                0.05 * (6.0 * x).sin() + 0.02 * next() - 0.01
            } else {
                next() * 0.6 - 0.3
            };
            let q = DVec3::new(x, y, z);
            match grid.nearest(q) {
                Some(i) => {
                    answered += 1;
                    let j = brute(&points, q);
                    assert_eq!(points[i].distance(q), points[j].distance(q), "query {q}");
                }
                None => far += 1,
            }
        }
        // Both kinds happen: most queries near the sheet are answered, far ones are not.
        assert!(
            answered > 300 && far > 300,
            "answered {answered}, far {far}"
        );
        // Every point of the set is bucketed, and is its own nearest.
        assert_eq!(grid.bucketed.len(), points.len());
        for (i, p) in points.iter().enumerate() {
            assert_eq!(grid.nearest(*p), Some(i));
        }
        assert!(grid.nearest(DVec3::splat(f64::NAN)).is_none());
        assert!(PointGrid::new(&points, 0.0).is_none());
        assert!(PointGrid::new(&[], 0.1).is_none());
    }
}
