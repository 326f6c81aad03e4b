//! B-spline curves: validated construction and evaluation with derivatives.

use super::basis::{basis_row, validate_knots};
use super::error::BSplineError;
use glam::DVec3;

#[derive(Clone, Debug, PartialEq)]
/// A clamped, non-rational B-spline curve.
pub struct BSplineCurve {
    degree: usize,
    knots: Vec<f64>,
    controls: Vec<DVec3>,
}

impl BSplineCurve {
    /// Checks the knots against the degree and control count and the controls for finiteness.
    pub fn new(degree: usize, knots: Vec<f64>, controls: Vec<DVec3>) -> Result<Self, BSplineError> {
        validate_knots(&knots, controls.len(), degree)?;
        if let Some(i) = controls.iter().position(|c| !c.is_finite()) {
            return Err(BSplineError::NonFinite(i));
        }
        Ok(Self {
            degree,
            knots,
            controls,
        })
    }

    /// The degree p.
    pub fn degree(&self) -> usize {
        self.degree
    }
    /// The knot vector (count + p + 1 values).
    pub fn knots(&self) -> &[f64] {
        &self.knots
    }
    /// The control points.
    pub fn controls(&self) -> &[DVec3] {
        &self.controls
    }

    /// [start, end] of the parameter domain.
    pub fn domain(&self) -> (f64, f64) {
        (self.knots[self.degree], self.knots[self.controls.len()])
    }

    /// The curve point at parameter t (clamped to the domain).
    pub fn point(&self, t: f64) -> DVec3 {
        self.derivatives(t, 0)[0]
    }

    /// C(t), C'(t), C''(t) (entries above `nd` are zero).
    pub fn derivatives(&self, t: f64, nd: usize) -> [DVec3; 3] {
        let p = self.degree;
        let row = basis_row(&self.knots, self.controls.len(), p, t, nd);
        let first = row.first(p);
        let mut out = [DVec3::ZERO; 3];
        for (k, o) in out.iter_mut().enumerate().take(nd.min(2) + 1) {
            for r in 0..=p {
                *o += self.controls[first + r] * row.d[k][r];
            }
        }
        out
    }
}
