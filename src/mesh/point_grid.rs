//! Nearest points among a fixed set by a bucket grid, for queries that mostly lie near the
//! set (a new version of a scanned object against the previous one's points). A query
//! reads the 27 buckets around it and answers only when what it found is provably the
//! nearest; one far from the set (new ground) gets `None`, and the caller asks a
//! structure whose cost does not grow with the distance (an R-tree), rather than the grid
//! searching ring after ring.

use super::bucket_grid::BucketGrid;
use glam::DVec3;

/// Points bucketed on a uniform grid (`BucketGrid`).
pub struct PointGrid<'a> {
    points: &'a [DVec3],
    grid: BucketGrid,
}

impl<'a> PointGrid<'a> {
    /// A grid of buckets of side `cell` (at least the spacing of the points, so that a
    /// query near the set finds its nearest point among the 27 buckets around it) over
    /// the finite points of `points`; `None` without such points or with a `cell` that is
    /// not positive and finite.
    pub fn new(points: &'a [DVec3], cell: f64) -> Option<Self> {
        Some(Self {
            points,
            grid: BucketGrid::new(points, cell)?,
        })
    }

    /// The index of the point nearest `q` (the lowest index among equally near ones) when
    /// the 27 buckets around `q` prove it the nearest; `None` otherwise (no point there,
    /// or a nearer one may lie beyond them).
    pub fn nearest(&self, q: DVec3) -> Option<usize> {
        let mut best: Option<(f64, u32)> = None;
        self.grid.around(q, |run| {
            for &i in &self.grid.members()[run] {
                let d = self.points[i as usize].distance_squared(q);
                if best.is_none_or(|(b, j)| d < b || (d == b && i < j)) {
                    best = Some((d, i));
                }
            }
        });
        let (d, i) = best?;
        // Every point outside the block lies farther than the block's nearest face.
        let cell = self.grid.cell();
        let inside = q / cell - (q / cell).floor();
        let margin = inside.min(DVec3::ONE - inside).min_element() * cell;
        let reach = cell + margin;
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
        assert_eq!(grid.grid.members().len(), points.len());
        for (i, p) in points.iter().enumerate() {
            assert_eq!(grid.nearest(*p), Some(i));
        }
        assert!(grid.nearest(DVec3::splat(f64::NAN)).is_none());
        assert!(PointGrid::new(&points, 0.0).is_none());
        assert!(PointGrid::new(&[], 0.1).is_none());
    }
}
