//! Scalar helpers for hot loops, shared by the surface evaluators and the planar maps, and
//! the bounds, local origin and principal axes of point sets, and the packed symmetric
//! 3x3 matrices.

use glam::DVec3;

/// The six distinct entries of the symmetric matrix w v v^T, packed in the order xx, xy,
/// xz, yy, yz, zz (a plane's quadric, the normal matrix's 3x3 blocks, a curvature term).
#[inline]
pub(crate) fn packed_outer(v: DVec3, w: f64) -> [f64; 6] {
    [
        w * v.x * v.x,
        w * v.x * v.y,
        w * v.x * v.z,
        w * v.y * v.y,
        w * v.y * v.z,
        w * v.z * v.z,
    ]
}

/// S v for a symmetric S packed as [`packed_outer`] packs it.
#[inline]
pub(crate) fn packed_mul(s: &[f64; 6], v: DVec3) -> DVec3 {
    DVec3::new(
        s[0] * v.x + s[1] * v.y + s[2] * v.z,
        s[1] * v.x + s[3] * v.y + s[4] * v.z,
        s[2] * v.x + s[4] * v.y + s[5] * v.z,
    )
}

/// `x.floor()` for |x| < 2^63 without the libm call that `floor` is on baseline x86-64
/// (no SSE4.1 rounding instruction): every surface evaluation locates its cell.
#[inline(always)]
pub(crate) fn floor(x: f64) -> f64 {
    let t = x as i64 as f64;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// `x.floor() as i64` (saturating, NaN to 0) without the libm call.
#[inline(always)]
pub(crate) fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t - 1
    } else {
        t
    }
}

/// The points' axis-aligned bounds (lowest, highest corner), `None` without points.
pub(crate) fn bounds(points: &[DVec3]) -> Option<(DVec3, DVec3)> {
    let first = *points.first()?;
    Some(
        points
            .iter()
            .fold((first, first), |(lo, hi), p| (lo.min(*p), hi.max(*p))),
    )
}

/// The length of the diagonal of the points' bounds (0 without points).
pub(crate) fn bounds_diagonal(points: &[DVec3]) -> f64 {
    bounds(points).map_or(0.0, |(lo, hi)| (hi - lo).length())
}

/// A local origin for `points`: their box's centre rounded to a multiple of the power of two
/// at or above the box's diagonal. Subtracting it is exact (it is a multiple of every far
/// coordinate's unit in the last place, and the difference is smaller than the coordinate),
/// so it moves points without rounding them; it is zero when the box's centre lies within
/// half that power of the origin on every axis, which keeps such points' arithmetic as it
/// was; and it brings points from anywhere (a site frame, UTM's millions of metres) within
/// a diagonal or so of the origin, where sums of squares keep their digits.
pub(crate) fn local_origin(points: &[DVec3]) -> DVec3 {
    let Some((lo, hi)) = bounds(points) else {
        return DVec3::ZERO;
    };
    let diagonal = (hi - lo).length();
    if !diagonal.is_finite() || diagonal <= 0.0 {
        return DVec3::ZERO;
    }
    let cell = 2f64.powi(diagonal.log2().ceil() as i32);
    let centre = 0.5 * (lo + hi);
    (centre / cell).round() * cell
}

/// The principal axes of `points` about `centre`: the eigenvalues of their scatter matrix
/// (the sum of the offsets' outer products), largest first, and the unit eigenvector of
/// each. NaN eigenvalues sort first.
pub(crate) fn principal_axes(
    centre: DVec3,
    points: impl IntoIterator<Item = DVec3>,
) -> ([f64; 3], [DVec3; 3]) {
    let mut scatter = nalgebra::Matrix3::<f64>::zeros();
    for p in points {
        let d = p - centre;
        let d = nalgebra::Vector3::new(d.x, d.y, d.z);
        scatter += d * d.transpose();
    }
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let axis = |k: usize| {
        let c = eig.eigenvectors.column(order[k]);
        DVec3::new(c[0], c[1], c[2])
    };
    (
        order.map(|k| eig.eigenvalues[k]),
        [axis(0), axis(1), axis(2)],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_local_origin_moves_points_exactly_and_leaves_points_near_the_origin_alone() {
        let near = [DVec3::new(-0.07, 0.03, 0.01), DVec3::new(0.06, 0.13, 0.05)];
        assert_eq!(local_origin(&near), DVec3::ZERO);
        let far: Vec<DVec3> = near
            .iter()
            .map(|p| *p + DVec3::new(512_345.678, 4_012_345.5, 101.25))
            .collect();
        let origin = local_origin(&far);
        for p in &far {
            let local = *p - origin;
            assert!(local.length() < 1.0, "{local} from {origin}");
            assert_eq!(local + origin, *p, "not exact");
        }
    }
}
