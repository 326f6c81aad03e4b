//! Curvature of parametric surfaces from exact derivatives, and partition into convex,
//! concave and saddle regions (the Matlab document's method, without finite differences).
//!
//! Every surface kind enters through [`DerivativeSurface`]: position and the first and
//! second partials at a parameter. Tensor-product B-splines live on a rectangle;
//! triangular surfaces (Bezier, Loop) on the reference triangle with barycentric (u, v)
//! and w = 1 - u - v eliminated, as `TriSurface::evaluate` gives them.
//!
//! Sign convention (the document's): n = S_u x S_v / |S_u x S_v|; a cap bulging towards
//! n has H < 0 and counts as convex.

pub mod regions;

use crate::bspline::BSplineSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use rayon::prelude::*;

/// The parameter domain of a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Domain {
    Rectangle {
        u: (f64, f64),
        v: (f64, f64),
    },
    /// u, v >= 0, u + v <= 1.
    Triangle,
}

/// Position and first and second partial derivatives at a parameter.
pub trait DerivativeSurface: Sync {
    fn domain(&self) -> Domain;
    fn derivatives(&self, u: f64, v: f64) -> Derivatives;
    /// Derivatives at many parameters (in parallel); separable surfaces do better on grids
    /// through [`DerivativeSurface::derivatives_on_grid`].
    fn derivatives_at(&self, params: &[(f64, f64)]) -> Vec<Derivatives> {
        params
            .par_iter()
            .map(|&(u, v)| self.derivatives(u, v))
            .collect()
    }
    /// Derivatives at every (us[r], vs[c]), row-major in r.
    fn derivatives_on_grid(&self, us: &[f64], vs: &[f64]) -> Vec<Derivatives> {
        let params: Vec<(f64, f64)> = us
            .iter()
            .flat_map(|&u| vs.iter().map(move |&v| (u, v)))
            .collect();
        self.derivatives_at(&params)
    }
}

impl DerivativeSurface for BSplineSurface {
    fn domain(&self) -> Domain {
        let (u, v) = BSplineSurface::domain(self);
        Domain::Rectangle { u, v }
    }
    fn derivatives(&self, u: f64, v: f64) -> Derivatives {
        BSplineSurface::derivatives(self, u, v)
    }
    fn derivatives_on_grid(&self, us: &[f64], vs: &[f64]) -> Vec<Derivatives> {
        BSplineSurface::derivatives_on_grid(self, us, vs)
    }
}

/// A triangular surface (any [`TriSurface`] whose single domain triangle is the reference
/// triangle, as `trispline fit` writes them) with its control points.
pub struct Triangular<S: TriSurface> {
    pub surface: S,
    pub controls: Vec<DVec3>,
}

impl<S: TriSurface> DerivativeSurface for Triangular<S> {
    fn domain(&self) -> Domain {
        Domain::Triangle
    }
    fn derivatives(&self, u: f64, v: f64) -> Derivatives {
        self.surface
            .evaluate(&self.controls, SurfaceParam { face: 0, u, v })
    }
}

/// Differential geometry at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Curvature {
    pub normal: DVec3,
    /// First fundamental form.
    pub e: f64,
    pub f: f64,
    pub g: f64,
    /// Second fundamental form.
    pub l: f64,
    pub m: f64,
    pub n: f64,
    pub gaussian: f64,
    pub mean: f64,
    pub k_max: f64,
    pub k_min: f64,
}

/// Curvature from derivatives; `None` where the parametrisation is singular
/// (EG - F^2 <= 1e-24 EG, e.g. a collapsed edge or a pole).
pub fn curvature(d: &Derivatives) -> Option<Curvature> {
    let (e, f, g) = (d.du.dot(d.du), d.du.dot(d.dv), d.dv.dot(d.dv));
    let w = e * g - f * f;
    if !w.is_finite() || w <= 1e-24 * e * g {
        return None;
    }
    let normal = d.du.cross(d.dv) / w.sqrt();
    let (l, m, n) = (d.duu.dot(normal), d.duv.dot(normal), d.dvv.dot(normal));
    let gaussian = (l * n - m * m) / w;
    let mean = (e * n + g * l - 2.0 * f * m) / (2.0 * w);
    // H^2 - K >= 0 in exact arithmetic; rounding can make it slightly negative at umbilics.
    let root = (mean * mean - gaussian).max(0.0).sqrt();
    Some(Curvature {
        normal,
        e,
        f,
        g,
        l,
        m,
        n,
        gaussian,
        mean,
        k_max: mean + root,
        k_min: mean - root,
    })
}

/// The three region types of the document, with its codes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RegionKind {
    /// K >= 0 and H <= 0 (flat included), code 1.
    Convex = 1,
    /// K >= 0 and H > 0, code 2.
    Concave = 2,
    /// K < 0, code 3.
    Saddle = 3,
}

impl RegionKind {
    pub fn name(self) -> &'static str {
        match self {
            RegionKind::Convex => "convex",
            RegionKind::Concave => "concave",
            RegionKind::Saddle => "saddle",
        }
    }
}

/// What counts as zero: |K| <= `gaussian` and |H| <= `mean` (absolute values, in the
/// units of 1/length^2 and 1/length).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ZeroTolerance {
    pub gaussian: f64,
    pub mean: f64,
}

impl ZeroTolerance {
    /// Scale-free tolerance: `eps / size^2` for K and `eps / size` for H, with `size` a
    /// length of the surface (the bounding-box diagonal of the samples).
    pub fn relative(eps: f64, size: f64) -> Self {
        let s = if size > 0.0 && size.is_finite() {
            size
        } else {
            1.0
        };
        Self {
            gaussian: eps / (s * s),
            mean: eps / s,
        }
    }
}

/// The document's classification with zeros snapped: K within tolerance is 0 (so parabolic
/// and planar points are never saddles), H within tolerance is 0 (so flat is convex).
pub fn classify(c: &Curvature, tol: ZeroTolerance) -> RegionKind {
    let k = if c.gaussian.abs() <= tol.gaussian {
        0.0
    } else {
        c.gaussian
    };
    let h = if c.mean.abs() <= tol.mean {
        0.0
    } else {
        c.mean
    };
    if k < 0.0 {
        RegionKind::Saddle
    } else if h > 0.0 {
        RegionKind::Concave
    } else {
        RegionKind::Convex
    }
}
