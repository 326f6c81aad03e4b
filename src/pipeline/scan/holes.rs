//! Which holes of a scan the surface bridges and which it leaves open (trims out).
//!
//! Over a hole there is no data: the fitted surface continues what surrounds it, and how
//! far that lands from anything measured grows with the hole. A dropout of a sample or two
//! is bridged (the surface there stays close to the rim's data); a wider hole (an occluded
//! nostril, a missing cheek) is trimmed out like the outside of the patch, so what is shown
//! and exported never strays further from the data than `max_bridge`. The width of a hole
//! is its bridging radius: the largest distance from a point of its flat fill to the
//! nearest rim vertex (a long thin slit is narrow however long it is). The same holds for
//! a single data triangle: some triangulations of range images span gaps with triangles
//! many samples wide, and the surface under them is as unmeasured as over a hole, so a
//! data triangle wider than `max_bridge` (largest distance from a point of it to its
//! nearest corner) is trimmed out too.

use crate::TriMesh;
use rayon::prelude::*;
use rustc_hash::FxHashSet;

/// Rim vertices a hole's radius is measured against at most.
const MAX_RIM_SAMPLES: usize = 256;

/// Which holes of a scan the surface bridges and which it leaves open.
#[derive(Clone, Debug, PartialEq)]
pub struct HolePlan {
    /// The largest bridging radius kept (input units).
    pub max_bridge: f64,
    /// Per hole loop (in `hole_loops` order): its bridging radius...
    pub radius: Vec<f64>,
    /// ... and whether it is bridged.
    pub bridged: Vec<bool>,
    /// Data triangles (indices into the mapped triangles) too wide to keep.
    pub wide_triangles: Vec<usize>,
    /// The mapped triangles that make the covered region: all but the fills of trimmed
    /// holes.
    pub covered: Vec<[u32; 3]>,
}

impl HolePlan {
    /// Holes left open.
    pub fn trimmed(&self) -> usize {
        self.bridged.iter().filter(|b| !**b).count()
    }
}

/// `mapped`: the patch as mapped (data triangles, then hole fills over the rims and virtual
/// vertices at index >= `real_vertices`); `data_triangles`: the input's triangles, which
/// tell a data triangle that happens to join three rim vertices from a fill.
pub(crate) fn plan_holes(
    mapped: &TriMesh,
    real_vertices: usize,
    hole_loops: &[Vec<u32>],
    data_triangles: &[[u32; 3]],
    max_bridge: f64,
) -> HolePlan {
    // The hole whose rim a real vertex lies on (u32::MAX: none).
    let mut hole_at = vec![u32::MAX; real_vertices];
    for (h, rim) in hole_loops.iter().enumerate() {
        for &v in rim {
            if let Some(slot) = hole_at.get_mut(v as usize) {
                *slot = h as u32;
            }
        }
    }
    let hole_of = |v: &u32| -> Option<usize> {
        hole_at
            .get(*v as usize)
            .filter(|&&h| h != u32::MAX)
            .map(|&h| h as usize)
    };
    let sorted = |t: &[u32; 3]| {
        let mut s = *t;
        s.sort_unstable();
        s
    };
    // Only data triangles whose corners all lie on rims can be mistaken for fills.
    let data_on_rims: FxHashSet<[u32; 3]> = data_triangles
        .iter()
        .filter(|t| t.iter().all(|v| hole_of(v).is_some()))
        .map(sorted)
        .collect();
    let fill_hole = |t: &[u32; 3]| -> Option<usize> {
        let virtual_corner = t.iter().any(|&v| v as usize >= real_vertices);
        if !virtual_corner && data_on_rims.contains(&sorted(t)) {
            return None;
        }
        // Every real corner on the rim of one hole.
        let mut h = None;
        for &v in t.iter().filter(|&&v| (v as usize) < real_vertices) {
            let g = hole_of(&v)?;
            if *h.get_or_insert(g) != g {
                return None;
            }
        }
        h
    };
    let fills: Vec<Option<usize>> = mapped
        .triangles
        .par_iter()
        .with_min_len(4096)
        .map(fill_hole)
        .collect();
    let at = |v: u32| mapped.positions[v as usize];
    // Largest distance from a sample of the triangle (centroid, edge midpoints, corners)
    // to the nearest of `rim`.
    let reach = |t: &[u32; 3], rim: &[u32]| -> f64 {
        let c = t.map(at);
        [
            (c[0] + c[1] + c[2]) / 3.0,
            (c[0] + c[1]) * 0.5,
            (c[1] + c[2]) * 0.5,
            (c[2] + c[0]) * 0.5,
            c[0],
            c[1],
            c[2],
        ]
        .into_iter()
        .map(|s| {
            rim.iter()
                .map(|&v| (at(v) - s).length_squared())
                .fold(f64::INFINITY, f64::min)
        })
        .filter(|d| d.is_finite())
        .fold(0.0f64, f64::max)
        .sqrt()
    };
    // Long rims are measured against every k-th vertex: the work per hole stays near
    // linear, and the radius can only come out larger (such a hole is trimmed sooner).
    let sampled: Vec<Vec<u32>> = hole_loops
        .iter()
        .map(|rim| {
            let stride = rim.len().div_ceil(MAX_RIM_SAMPLES).max(1);
            rim.iter().step_by(stride).copied().collect()
        })
        .collect();
    let mut radius = vec![0.0f64; hole_loops.len()];
    for (t, h) in mapped.triangles.iter().zip(&fills) {
        if let Some(h) = *h {
            radius[h] = radius[h].max(reach(t, &sampled[h]));
        }
    }
    let wide_triangles: Vec<usize> = (0..mapped.triangles.len())
        .into_par_iter()
        .with_min_len(4096)
        .filter(|&k| {
            fills[k].is_none() && reach(&mapped.triangles[k], &mapped.triangles[k]) > max_bridge
        })
        .collect();
    let bridged: Vec<bool> = radius.iter().map(|r| *r <= max_bridge).collect();
    let mut keep: Vec<bool> = fills.iter().map(|h| h.is_none_or(|h| bridged[h])).collect();
    for &k in &wide_triangles {
        keep[k] = false;
    }
    // Sized first: a collected filter would grow by doubling, copying as it goes.
    let mut covered = Vec::with_capacity(keep.iter().filter(|k| **k).count());
    covered.extend(
        mapped
            .triangles
            .iter()
            .zip(&keep)
            .filter(|(_, keep)| **keep)
            .map(|(t, _)| *t),
    );
    HolePlan {
        max_bridge,
        radius,
        bridged,
        wide_triangles,
        covered,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    /// A square grid with two holes: one cell missing (bridged) and a 4 x 4 block missing
    /// (trimmed); the holes closed by fans around virtual centres as `fill_holes` does.
    #[test]
    fn narrow_holes_are_bridged_and_wide_ones_trimmed() {
        let n = 12usize;
        let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        let positions: Vec<DVec3> = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| DVec3::new(i as f64, j as f64, 0.0)))
            .collect();
        let small = |i: usize, j: usize| i == 2 && j == 2;
        let large = |i: usize, j: usize| (6..10).contains(&i) && (6..10).contains(&j);
        let mut data = Vec::new();
        for j in 0..n {
            for i in 0..n {
                if small(i, j) || large(i, j) {
                    continue;
                }
                data.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                data.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let ring = |i0: usize, i1: usize| -> Vec<u32> {
            let mut r = Vec::new();
            for i in i0..i1 {
                r.push(id(i, i0));
            }
            for j in i0..i1 {
                r.push(id(i1, j));
            }
            for i in (i0 + 1..=i1).rev() {
                r.push(id(i, i1));
            }
            for j in (i0 + 1..=i1).rev() {
                r.push(id(i0, j));
            }
            r
        };
        let loops = vec![ring(2, 3), ring(6, 10)];
        let real = positions.len();
        let mut mapped = TriMesh {
            positions: positions.clone(),
            triangles: data.clone(),
        };
        for rim in &loops {
            let c = mapped.positions.len() as u32;
            let pts: Vec<DVec3> = rim.iter().map(|&v| positions[v as usize]).collect();
            mapped
                .positions
                .push(pts.iter().copied().sum::<DVec3>() / pts.len() as f64);
            for k in 0..rim.len() {
                mapped.triangles.push([rim[k], rim[(k + 1) % rim.len()], c]);
            }
        }
        let plan = plan_holes(&mapped, real, &loops, &data, 1.0);
        assert!(
            (plan.radius[0] - 0.5f64.sqrt()).abs() < 1e-12,
            "{:?}",
            plan.radius
        );
        assert!((plan.radius[1] - 2.0).abs() < 1e-12, "{:?}", plan.radius);
        assert_eq!(plan.bridged, vec![true, false]);
        assert_eq!(plan.trimmed(), 1);
        assert_eq!(plan.covered.len(), data.len() + loops[0].len());
        assert!(plan.wide_triangles.is_empty(), "unit cells are narrow");
        let wide_open = plan_holes(&mapped, real, &loops, &data, 10.0);
        assert_eq!(wide_open.covered.len(), mapped.triangles.len());
        // Under a bridge of 0.4 the unit data triangles are too wide themselves (the
        // midpoint of the diagonal lies 0.71 from the nearest corner).
        let strict = plan_holes(&mapped, real, &loops, &data, 0.4);
        assert_eq!(strict.wide_triangles.len(), data.len());
    }
}
