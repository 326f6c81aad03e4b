//! Tensor-product B-spline curves and surfaces: basis, evaluation, least-squares fitting.
//!
//! Parameters live on the clamped domain `[knots[p], knots[count]]` (the fitters use [0, 1]).
//! Surface control points are stored row-major: control (i, j), i along u, sits at
//! `i * count_v + j`. Pure geometry: no file formats here (`io::iges`, `io::surface_json`).
#![warn(missing_docs)]

pub mod basis;
pub mod curve;
mod error;
pub mod fit;
pub mod loop_patches;
pub mod lsq;
pub mod scattered;
pub mod surface;

pub use basis::ParamMethod;
pub use curve::BSplineCurve;
pub use error::BSplineError;
pub use surface::BSplineSurface;
