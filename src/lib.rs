//! trispline: scan patches in, smooth triangular surfaces out.
//!
//! Layering (see ARCHITECTURE.md): `io` is the only module that knows file formats;
//! `mesh`, `surface` and `fit` are pure geometry on `f64`.

#![warn(missing_docs)]

pub mod allocator;
pub mod bspline;
pub mod cli;
pub mod cluster;
pub mod curvature;
pub mod daemon;
pub mod fit;
pub mod io;
pub mod mesh;
pub mod names;
mod numeric;
pub mod pipeline;
pub mod remesh;
pub mod scattered_fit;
pub mod surface;
pub mod testdata;

pub use glam::DVec3;
pub use mesh::TriMesh;
