//! Scalar helpers for hot loops, shared by the surface evaluators and the planar maps.

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
