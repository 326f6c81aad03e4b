//! The compiled recurrence's nodes, shared by the walk (`evaluate`) and the pieces.

use glam::DVec2;

/// Value, d/dx, d/dy, d2/dx2, d2/dxdy, d2/dy2.
pub type Jet = [f64; 6];

#[derive(Clone, Debug)]
pub(super) enum Node {
    /// A knot set with all knots collinear: a line measure, zero as a function (its
    /// parent's barycentric factor vanishes on that line).
    Zero,
    Leaf {
        /// Counter-clockwise.
        tri: [DVec2; 3],
        /// The pool indices of `tri`'s knots.
        knots: [u8; 3],
        inv_abs_det: f64,
    },
    Inner {
        lambda: [[f64; 3]; 3],
        children: [u32; 3],
    },
}

#[derive(Clone, Debug)]
pub(super) struct CompiledNode {
    pub(super) node: Node,
    /// Bounding box of the subset's knots: the spline vanishes outside it.
    pub(super) min: DVec2,
    pub(super) max: DVec2,
}
