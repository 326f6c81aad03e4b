//! Planar triangle and polygon predicates shared by the projection map (`planar`) and its
//! warp (`warp`): kept apart so that neither of those has to import the other for them.

use glam::DVec2;

/// Twice the signed area of a triangle in the map (positive counter-clockwise).
pub(crate) fn doubled_area(plane: &[DVec2], t: &[u32; 3]) -> f64 {
    let (a, b, c) = (
        plane[t[0] as usize],
        plane[t[1] as usize],
        plane[t[2] as usize],
    );
    (b - a).perp_dot(c - a)
}

/// Triangles with non-positive signed area in the map.
pub fn folded_triangles(tris: &[[u32; 3]], plane: &[DVec2]) -> Vec<usize> {
    tris.iter()
        .enumerate()
        .filter(|(_, t)| doubled_area(plane, t) <= 0.0)
        .map(|(f, _)| f)
        .collect()
}

/// No two non-adjacent edges of the closed polygon meet. Edges are bucketed on a uniform
/// grid over the polygon's box, so only edges sharing a bucket are compared (about linear
/// for a lattice rim, whose edges have similar lengths).
pub(crate) fn simple_polygon(ring: &[DVec2]) -> bool {
    let n = ring.len();
    if n < 4 {
        return n == 3 && (ring[1] - ring[0]).perp_dot(ring[2] - ring[0]) != 0.0;
    }
    let edge = |k: usize| (ring[k], ring[(k + 1) % n]);
    let (mut lo, mut hi) = (ring[0], ring[0]);
    for p in ring {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let side = (n as f64).sqrt().ceil() as usize;
    let cell = ((hi - lo) / side as f64).max(DVec2::splat(1e-300));
    let bucket = |p: DVec2| {
        let q = ((p - lo) / cell).floor();
        (
            (q.x.max(0.0) as usize).min(side - 1),
            (q.y.max(0.0) as usize).min(side - 1),
        )
    };
    let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); side * side];
    for k in 0..n {
        let (p, q) = edge(k);
        let (a, b) = (bucket(p.min(q)), bucket(p.max(q)));
        for y in a.1..=b.1 {
            for x in a.0..=b.0 {
                buckets[y * side + x].push(k);
            }
        }
    }
    let adjacent = |a: usize, b: usize| a.abs_diff(b) <= 1 || a.abs_diff(b) == n - 1;
    buckets.iter().all(|edges| {
        edges.iter().enumerate().all(|(i, &a)| {
            edges[i + 1..]
                .iter()
                .all(|&b| adjacent(a, b) || !segments_meet(edge(a), edge(b)))
        })
    })
}

/// Whether two closed segments share a point. Boxes first: separate edges along one
/// straight side of a lattice are collinear, and only their boxes tell them apart.
fn segments_meet((p, q): (DVec2, DVec2), (r, s): (DVec2, DVec2)) -> bool {
    let boxes_overlap = p.min(q).cmple(r.max(s)).all() && r.min(s).cmple(p.max(q)).all();
    if !boxes_overlap {
        return false;
    }
    let d1 = (q - p).perp_dot(r - p);
    let d2 = (q - p).perp_dot(s - p);
    let d3 = (s - r).perp_dot(p - r);
    let d4 = (s - r).perp_dot(q - r);
    let collinear = d1 == 0.0 && d2 == 0.0;
    collinear || (d1 * d2 <= 0.0 && d3 * d4 <= 0.0)
}
