//! How far a point stands beyond the samples around it, in their tangent plane: the
//! distance from the point to the convex hull of the samples' projections (0 inside).
//! Hand-written: 2D hulls of a hundred points, the only geometry the merge needs from a
//! computational-geometry crate (`geo` would bring its own types and dependencies).

use glam::DVec2;

/// The distance from the origin to the convex hull of `points` (0 when the origin lies
/// inside it or on it); `None` for fewer than three points or a hull without area.
#[cfg(test)]
pub(super) fn distance_to_hull(points: &mut [DVec2]) -> Option<f64> {
    nearest_on_hull(points).map(|p| p.length())
}

/// The point of the convex hull of `points` nearest to the origin (the origin itself when
/// it lies inside the hull or on it); `None` for fewer than three points or a hull
/// without area.
pub(super) fn nearest_on_hull(points: &mut [DVec2]) -> Option<DVec2> {
    // Most merged vertices lie inside the data, where the hull (a sort and a chain, 14 %
    // of a merge's CPU on the bunny's scans) is not needed to say so.
    if surrounds_origin(points) {
        return Some(DVec2::ZERO);
    }
    nearest_by_hull(points)
}

/// [`nearest_on_hull`] from the hull itself.
fn nearest_by_hull(points: &mut [DVec2]) -> Option<DVec2> {
    let hull = convex_hull(points);
    if hull.len() < 3 {
        return None;
    }
    let mut inside = true;
    let mut nearest = DVec2::splat(f64::MAX);
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        // Counter-clockwise hull: the origin is inside when left of every edge.
        if (b - a).perp_dot(-a) < 0.0 {
            inside = false;
        }
        let on_edge = nearest_on_segment(a, b);
        if on_edge.length_squared() < nearest.length_squared() {
            nearest = on_edge;
        }
    }
    Some(if inside { DVec2::ZERO } else { nearest })
}

/// Whether some point lies in each of the four open quadrants: then the origin lies inside
/// their hull (a line through the origin leaves a whole quadrant on one side of it, so no
/// line separates the origin from all the points), and the hull has area.
fn surrounds_origin(points: &[DVec2]) -> bool {
    let mut seen = 0u8;
    for p in points {
        seen |= match (p.x > 0.0, p.x < 0.0, p.y > 0.0, p.y < 0.0) {
            (true, _, true, _) => 1,
            (_, true, true, _) => 2,
            (_, true, _, true) => 4,
            (true, _, _, true) => 8,
            _ => 0,
        };
        if seen == 15 {
            return true;
        }
    }
    false
}

/// The point of the segment [a, b] nearest to the origin.
fn nearest_on_segment(a: DVec2, b: DVec2) -> DVec2 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 {
        (-a.dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    a + t * ab
}

/// Andrew's monotone chain: the hull counter-clockwise, collinear points left out.
fn convex_hull(points: &mut [DVec2]) -> Vec<DVec2> {
    points.sort_by(|p, q| p.x.total_cmp(&q.x).then(p.y.total_cmp(&q.y)));
    let turn = |o: DVec2, a: DVec2, b: DVec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<DVec2> = Vec::with_capacity(points.len() + 1);
    for &p in points.iter() {
        while hull.len() >= 2 && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    let lower = hull.len() + 1;
    for &p in points.iter().rev().skip(1) {
        while hull.len() >= lower && turn(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
            hull.pop();
        }
        hull.push(p);
    }
    hull.pop();
    hull
}

#[cfg(test)]
mod tests {
    use super::{distance_to_hull, nearest_by_hull, nearest_on_hull, surrounds_origin};
    use crate::testdata::uniform;
    use glam::DVec2;

    fn grid(x0: f64, x1: f64) -> Vec<DVec2> {
        let mut g = Vec::new();
        for i in 0..=10 {
            for j in 0..=10 {
                let t = i as f64 / 10.0;
                g.push(DVec2::new(x0 + (x1 - x0) * t, -1.0 + 0.2 * j as f64));
            }
        }
        g
    }

    /// The quadrant shortcut says "inside" exactly where the hull does: random clouds
    /// around, beside and far from the origin, and points on the axes (no quadrant).
    #[test]
    fn the_quadrant_shortcut_agrees_with_the_hull() {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = || uniform(&mut seed) * 2.0 - 1.0;
        let (mut inside, mut shortcut) = (0, 0);
        for case in 0..2000 {
            let n = 3 + case % 40;
            let offset = DVec2::new(next(), next()) * (case % 3) as f64;
            let mut points: Vec<DVec2> = (0..n)
                .map(|_| DVec2::new(next(), next()) + offset)
                .collect();
            if case % 7 == 0 {
                points.extend([DVec2::new(0.5, 0.0), DVec2::new(0.0, -0.5)]);
            }
            let by_hull = nearest_by_hull(&mut points.clone()) == Some(DVec2::ZERO);
            let quick = surrounds_origin(&points);
            assert!(
                !quick || by_hull,
                "case {case}: the shortcut says inside, the hull not"
            );
            inside += usize::from(by_hull);
            shortcut += usize::from(quick);
            let mut copy = points.clone();
            assert_eq!(
                distance_to_hull(&mut copy) == Some(0.0),
                by_hull,
                "case {case}"
            );
        }
        // Both kinds of case occur, and the shortcut takes most inside ones.
        assert!(inside > 300 && inside < 1700, "{inside} inside");
        assert!(
            shortcut * 10 > inside * 8,
            "{shortcut} of {inside} by the shortcut"
        );
        // On the axes only: the shortcut cannot say, the hull does.
        let mut cross = vec![
            DVec2::new(1.0, 0.0),
            DVec2::new(-1.0, 0.0),
            DVec2::new(0.0, 1.0),
            DVec2::new(0.0, -1.0),
        ];
        assert!(!surrounds_origin(&cross));
        assert_eq!(distance_to_hull(&mut cross), Some(0.0));
        assert_eq!(nearest_by_hull(&mut cross), Some(DVec2::ZERO));
    }

    #[test]
    fn inside_the_samples_is_zero_and_beyond_their_rim_is_the_gap() {
        assert_eq!(distance_to_hull(&mut grid(-1.0, 1.0)), Some(0.0));
        // Samples from x = -1 to x = -0.3: the origin stands 0.3 beyond their rim, and
        // the rim's point nearest to it is straight across.
        let d = distance_to_hull(&mut grid(-1.0, -0.3)).expect("hull");
        assert!((d - 0.3).abs() < 1e-12, "{d}");
        let p = nearest_on_hull(&mut grid(-1.0, -0.3)).expect("hull");
        assert!(p.distance(DVec2::new(-0.3, 0.0)) < 1e-12, "{p}");
        // On the rim itself.
        let d = distance_to_hull(&mut grid(-1.0, 0.0)).expect("hull");
        assert!(d.abs() < 1e-12, "{d}");
        // Samples in a line hold no hull.
        let mut line: Vec<DVec2> = (0..5).map(|i| DVec2::new(i as f64, 0.0)).collect();
        assert_eq!(distance_to_hull(&mut line), None);
    }
}
