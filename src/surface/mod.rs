//! Triangular surfaces behind one trait: value, derivatives and sparse basis rows.
#![warn(missing_docs)]

pub mod bezier;
pub mod box_spline;
pub mod bpatch;
pub mod dms;
pub mod grid_spline;
pub mod loop_limit;
pub mod simplex_spline;

use glam::DVec3;

/// A parameter: a domain face and barycentric (u, v) w.r.t. its corners 0 and 1
/// (w = 1 - u - v belongs to corner 2).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceParam {
    /// The domain face.
    pub face: u32,
    /// Barycentric weight of the face's corner 0.
    pub u: f64,
    /// Barycentric weight of the face's corner 1.
    pub v: f64,
}

/// Value and partial derivatives with respect to (u, v), w eliminated.
#[derive(Clone, Copy, Debug, Default)]
pub struct Derivatives {
    /// The surface point.
    pub position: DVec3,
    /// First derivative along u.
    pub du: DVec3,
    /// First derivative along v.
    pub dv: DVec3,
    /// Second derivative along u.
    pub duu: DVec3,
    /// Mixed second derivative.
    pub duv: DVec3,
    /// Second derivative along v.
    pub dvv: DVec3,
}

/// Basis rows of value and the five derivatives, sharing one index list.
#[derive(Clone, Debug, Default)]
pub struct BasisDerivRows {
    /// Control indices of the non-zero basis functions.
    pub indices: Vec<u32>,
    /// value, du, dv, duu, duv, dvv per index.
    pub weights: Vec<[f64; 6]>,
}

/// A surface over triangular domain faces, linear in its control points: what the fitting engine needs (basis rows) and what evaluation needs (derivatives).
pub trait TriSurface: Send + Sync {
    /// Number of control points.
    fn control_count(&self) -> usize;
    /// Number of domain faces.
    fn domain_face_count(&self) -> usize;
    /// The sparse basis row at `p`: (control index, weight), weights >= 0 summing to 1.
    /// By default the value column of the rows with derivatives.
    fn basis_row(&self, p: SurfaceParam, out: &mut Vec<(u32, f64)>) {
        let mut rows = BasisDerivRows::default();
        self.basis_rows_with_derivatives(p, &mut rows);
        out.clear();
        out.extend(
            rows.indices
                .iter()
                .zip(&rows.weights)
                .map(|(&i, w)| (i, w[0])),
        );
    }
    /// The basis row at `p` with the five derivative columns.
    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows);
    /// Position and derivatives at `p` for these control points.
    fn evaluate(&self, controls: &[DVec3], p: SurfaceParam) -> Derivatives {
        let mut rows = BasisDerivRows::default();
        self.basis_rows_with_derivatives(p, &mut rows);
        let mut d = Derivatives::default();
        for (&i, w) in rows.indices.iter().zip(&rows.weights) {
            let c = controls[i as usize];
            d.position += c * w[0];
            d.du += c * w[1];
            d.dv += c * w[2];
            d.duu += c * w[3];
            d.duv += c * w[4];
            d.dvv += c * w[5];
        }
        d
    }
    /// An evaluator for many parameters with one control set (foot-point searches,
    /// tessellation): surfaces that can precompute per-face data for `controls` do so.
    fn evaluator<'a>(
        &'a self,
        controls: &'a [DVec3],
    ) -> Box<dyn Fn(SurfaceParam) -> Derivatives + Sync + 'a> {
        Box::new(move |p| self.evaluate(controls, p))
    }
    /// The single Bezier patch behind this surface, if that is what it is: its lattice
    /// data get a matrix-free collocation operator.
    fn as_bezier(&self) -> Option<&bezier::BezierTriangle> {
        None
    }
    /// Moves a parameter by (du, dv), staying in the domain (clamped at its boundary).
    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam;
}
