//! The `surface.json` records of the B-patch and DMS kinds (issue 24's schema): plain data
//! that another program can evaluate, and the way back to a checked surface.
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
use crate::surface::bpatch::{BPatch, BPatchError};
use glam::{DVec2, DVec3};

fn pts2(v: &[DVec2]) -> Vec<[f64; 2]> {
    v.iter().map(|p| p.to_array()).collect()
}

fn pts3(v: &[DVec3]) -> Vec<[f64; 3]> {
    v.iter().map(|p| p.to_array()).collect()
}

fn vec2(v: &[[f64; 2]]) -> Vec<DVec2> {
    v.iter().map(|p| DVec2::from_array(*p)).collect()
}

fn vec3(v: &[[f64; 3]]) -> Vec<DVec3> {
    v.iter().map(|p| DVec3::from_array(*p)).collect()
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BPatchKnots {
    pub r: Vec<[f64; 2]>,
    pub s: Vec<[f64; 2]>,
    pub t: Vec<[f64; 2]>,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BPatchRecord {
    pub degree: usize,
    pub domain_triangle: [[f64; 2]; 3],
    pub knots: BPatchKnots,
    pub control_points: Vec<[f64; 3]>,
}

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RecordError {
    #[error("{found} control points, the surface has {expected}")]
    ControlCount { found: usize, expected: usize },
    #[error("invalid B-patch")]
    BPatch(#[from] BPatchError),
    #[error("invalid DMS spline")]
    Dms(#[from] DmsError),
}

impl BPatchRecord {
    pub fn new(patch: &BPatch, controls: &[DVec3]) -> Self {
        let [r, s, t] = patch.knots();
        Self {
            degree: patch.degree(),
            domain_triangle: patch.domain().map(|p| p.to_array()),
            knots: BPatchKnots {
                r: pts2(r),
                s: pts2(s),
                t: pts2(t),
            },
            control_points: pts3(controls),
        }
    }

    /// The checked surface and its controls.
    pub fn surface(&self) -> Result<(BPatch, Vec<DVec3>), RecordError> {
        let patch = BPatch::new(
            self.degree,
            self.domain_triangle.map(DVec2::from_array),
            [
                vec2(&self.knots.r),
                vec2(&self.knots.s),
                vec2(&self.knots.t),
            ],
        )?;
        let expected = (self.degree + 1) * (self.degree + 2) / 2;
        if self.control_points.len() != expected {
            return Err(RecordError::ControlCount {
                found: self.control_points.len(),
                expected,
            });
        }
        Ok((patch, vec3(&self.control_points)))
    }
}

#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DmsRecord {
    pub degree: usize,
    pub domain_vertices: Vec<[f64; 2]>,
    pub domain_triangles: Vec<[u32; 3]>,
    pub knot_clouds: Vec<Vec<[f64; 2]>>,
    pub control_points: Vec<[f64; 3]>,
}

impl DmsRecord {
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
    pub fn surface(&self) -> Result<(DmsSpline, Vec<DVec3>), RecordError> {
        let spline = DmsSpline::with_clouds(
            vec2(&self.domain_vertices),
            self.domain_triangles.clone(),
            self.degree,
            self.knot_clouds.iter().map(|c| vec2(c)).collect(),
        )?;
        let expected = crate::surface::TriSurface::control_count(&spline);
        if self.control_points.len() != expected {
            return Err(RecordError::ControlCount {
                found: self.control_points.len(),
                expected,
            });
        }
        Ok((spline, vec3(&self.control_points)))
    }
}
