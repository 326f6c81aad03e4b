//! `[fit.dms]` and `[fit.bpatch]`: the shape of the two planar-domain kinds. How many
//! controls a DMS spline gets follows `fit.scan.target_controls_pct` like the Loop grid, so
//! that the kinds compare at a similar control count; smoothing and correction rounds come
//! from `[fit.scan]` and `[fit.correction]` as for every scan.

/// `[fit.dms]`: a DMS triangular B-spline over a triangulation of the scan's planar map.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DmsConfig {
    /// Polynomial degree n (2 or 3): C^(n-1) surfaces, (n + 1)(n + 2) / 2 controls per
    /// domain triangle.
    pub degree: usize,
    /// Knot cloud radius as a fraction of each domain vertex's shortest edge (halved by
    /// the library until the DMS conditions hold). 0.6 fitted bun045 (degree 2, 2004
    /// controls, point-to-point rounds) to 140 um RMS where 0.3 gave 152, 0.1 162 and 0.9
    /// 143: wider clouds make the basis functions of a triangle less alike.
    pub knot_spread: f64,
}

impl Default for DmsConfig {
    fn default() -> Self {
        Self {
            degree: 2,
            knot_spread: 0.6,
        }
    }
}

/// `[fit.bpatch]`: one B-patch over a triangle around the scan's planar map.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BPatchConfig {
    /// Polynomial degree n.
    pub degree: usize,
    /// Knots on the medians pushed out of the triangle by this fraction (0: the Bezier
    /// patch; see `surface::bpatch::BPatch::outward`).
    pub knot_spread: f64,
}

impl Default for BPatchConfig {
    fn default() -> Self {
        Self {
            degree: 8,
            knot_spread: 0.5,
        }
    }
}

/// Accepted DMS degrees: degree 1 is a piecewise-linear surface, above 3 the simplex
/// recurrence is not compiled.
pub const DMS_DEGREES: std::ops::RangeInclusive<usize> = 2..=3;

/// Accepted B-patch degrees: above 20 the patch holds 231 controls and its O(n^3) recursion
/// per point costs more than a DMS spline of the same control count.
pub const BPATCH_DEGREES: std::ops::RangeInclusive<usize> = 1..=20;
