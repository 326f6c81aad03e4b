//! Tensor-product B-spline curves and surfaces: basis, evaluation, least-squares fitting.
//!
//! Parameters live on the clamped domain [knots[p], knots[count]] (the fitters use [0, 1]).
//! Surface control points are stored row-major: control (i, j), i along u, sits at
//! `i * count_v + j`. Pure geometry: no file formats here (`io::iges`, `io::surface_json`).

pub mod basis;
pub mod curve;
pub mod fit;
pub mod lsq;
pub mod scattered;
pub mod surface;

pub use basis::ParamMethod;
pub use curve::BSplineCurve;
pub use surface::BSplineSurface;

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum BSplineError {
    #[error("degree {0} is outside 1..={max}", max = basis::MAX_DEGREE)]
    Degree(usize),
    #[error("{count} control points cannot carry degree {degree} (need at least degree + 1)")]
    TooFewControls { count: usize, degree: usize },
    #[error("knot vector: {0}")]
    Knots(String),
    #[error("{got} control points given, {expected} expected")]
    ControlCount { got: usize, expected: usize },
    #[error("{points} data points cannot determine {controls} control points")]
    TooFewPoints { points: usize, controls: usize },
    #[error("non-finite coordinate in the data (point {0})")]
    NonFinite(usize),
    #[error("the least-squares system is rank deficient at unknown {0} (data leaves a knot span empty; add smoothing or fewer control points)")]
    RankDeficient(usize),
}
