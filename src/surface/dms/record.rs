//! The `surface.json` records of the B-patch and DMS kinds (issue 24's schema): plain data
//! that another program can evaluate, and the way back to a checked surface. (The B-patch
//! record lives in `bpatch`, which depends on this module, not the other way round.)
//!
//! - `bpatch`: `degree`, `domain_triangle` (three 2D points, counter-clockwise), `knots`
//!   `{"r": [...], "s": [...], "t": [...]}` (n 2D points each, the corner first),
//!   `control_points` (Bezier lattice order: index `j (n + 1) - j (j - 1) / 2 + i` for
//!   b = (i, j, n - i - j));
//! - `dms`: `degree`, `domain_vertices` (2D), `domain_triangles` (vertex ids,
//!   counter-clockwise), `knot_clouds` (per domain vertex n + 1 2D points, the vertex
//!   first), `control_points` (triangle by triangle, lattice order within each, corner 0 of
//!   a triangle being the i direction).

use super::{DmsError, DmsSpline};
use glam::{DVec2, DVec3};

pub(crate) fn pts2(v: &[DVec2]) -> Vec<[f64; 2]> {
    v.iter().map(|p| p.to_array()).collect()
}

pub(crate) fn pts3(v: &[DVec3]) -> Vec<[f64; 3]> {
    v.iter().map(|p| p.to_array()).collect()
}

pub(crate) fn vec2(v: &[[f64; 2]]) -> Vec<DVec2> {
    v.iter().map(|p| DVec2::from_array(*p)).collect()
}

pub(crate) fn vec3(v: &[[f64; 3]]) -> Vec<DVec3> {
    v.iter().map(|p| DVec3::from_array(*p)).collect()
}

/// The `dms` kind's `surface.json` record (schema above).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DmsRecord {
    /// Polynomial degree n.
    pub degree: usize,
    /// Domain vertices (2D).
    pub domain_vertices: Vec<[f64; 2]>,
    /// Domain triangles as vertex ids, counter-clockwise.
    pub domain_triangles: Vec<[u32; 3]>,
    /// Per domain vertex, n + 1 knots, the vertex first.
    pub knot_clouds: Vec<Vec<[f64; 2]>>,
    /// Control points, triangle by triangle, lattice order within each.
    pub control_points: Vec<[f64; 3]>,
}

impl DmsRecord {
    /// The record of `spline` with control points `controls` (not checked against it).
    pub fn new(spline: &DmsSpline, controls: &[DVec3]) -> Self {
        Self {
            degree: spline.degree(),
            domain_vertices: pts2(spline.vertices()),
            domain_triangles: spline.triangles().to_vec(),
            knot_clouds: spline.knot_clouds().iter().map(|c| pts2(c)).collect(),
            control_points: pts3(controls),
        }
    }

    /// The checked surface (DMS and boundary conditions) and its controls.
    pub fn surface(&self) -> Result<(DmsSpline, Vec<DVec3>), DmsError> {
        let spline = DmsSpline::with_clouds(
            vec2(&self.domain_vertices),
            self.domain_triangles.clone(),
            self.degree,
            self.knot_clouds.iter().map(|c| vec2(c)).collect(),
        )?;
        let expected = crate::surface::TriSurface::control_count(&spline);
        if self.control_points.len() != expected {
            return Err(DmsError::ControlCount {
                found: self.control_points.len(),
                expected,
            });
        }
        Ok((spline, vec3(&self.control_points)))
    }
}
