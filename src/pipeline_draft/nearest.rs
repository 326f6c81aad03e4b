//! Nearest data point queries on a uniform grid: the one-sided distance from a tessellated
//! surface to the scan (what a viewer sees as a bulge over a hole).

use glam::DVec3;
use std::collections::HashMap;

pub struct PointGrid<'a> {
    points: &'a [DVec3],
    cell: f64,
    origin: DVec3,
    cells: HashMap<[i64; 3], Vec<u32>>,
}

impl<'a> PointGrid<'a> {
    /// Cells hold about `per_cell` points on a surface-like point set.
    pub fn new(points: &'a [DVec3], per_cell: usize) -> Self {
        let (lo, hi) = points
            .iter()
            .fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        let extent = (hi - lo).max(DVec3::splat(1e-12));
        // Points on a surface fill area, not volume: size cells by the two largest extents.
        let mut e = [extent.x, extent.y, extent.z];
        e.sort_by(f64::total_cmp);
        let area = e[1] * e[2];
        let n = points.len().max(1) as f64;
        let cell = (area * per_cell as f64 / n).sqrt().max(1e-12);
        let mut cells: HashMap<[i64; 3], Vec<u32>> = HashMap::new();
        for (i, p) in points.iter().enumerate() {
            cells.entry(Self::key(lo, cell, *p)).or_default().push(i as u32);
        }
        Self {
            points,
            cell,
            origin: lo,
            cells,
        }
    }

    fn key(origin: DVec3, cell: f64, p: DVec3) -> [i64; 3] {
        let q = ((p - origin) / cell).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    }

    /// Distance to the nearest point, searching shells of cells outwards until no closer
    /// point can exist.
    pub fn nearest_distance(&self, q: DVec3) -> f64 {
        if self.points.is_empty() {
            return f64::INFINITY;
        }
        let c = Self::key(self.origin, self.cell, q);
        let mut best = f64::INFINITY;
        for ring in 0i64..=4096 {
            for dz in -ring..=ring {
                for dy in -ring..=ring {
                    for dx in -ring..=ring {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                            continue;
                        }
                        if let Some(ids) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                            for &i in ids {
                                best = best.min((self.points[i as usize] - q).length_squared());
                            }
                        }
                    }
                }
            }
            // Every point outside the searched block is at least `ring * cell` away.
            let reach = ring as f64 * self.cell;
            if best.is_finite() && best.sqrt() <= reach {
                break;
            }
        }
        best.sqrt()
    }
}
