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
    /// Cells of a grid: the surface samples itself through
    /// [`DerivativeSurface::own_lattice`].
    Cells,
}

/// Position and first and second partial derivatives at a parameter.
pub trait DerivativeSurface: Sync {
    fn domain(&self) -> Domain;
    fn derivatives(&self, u: f64, v: f64) -> Derivatives;
    /// Domains other than a rectangle or the triangle: parameters and counter-clockwise
    /// triangles of a sampling with about `n` samples across.
    fn own_lattice(&self, _n: usize) -> (Vec<(f64, f64)>, Vec<[u32; 3]>) {
        (Vec::new(), Vec::new())
    }
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

/// The Loop surface over grid cells that `trispline fit` writes for scans.
pub struct GridPatch {
    pub surface: crate::surface::grid_spline::GridSpline,
    pub controls: Vec<DVec3>,
}

impl DerivativeSurface for GridPatch {
    fn domain(&self) -> Domain {
        Domain::Cells
    }
    fn derivatives(&self, u: f64, v: f64) -> Derivatives {
        self.surface
            .evaluate(&self.controls, SurfaceParam { face: 0, u, v })
    }
    fn own_lattice(&self, n: usize) -> (Vec<(f64, f64)>, Vec<[u32; 3]>) {
        let per_cell = n as f64 / (self.surface.cells().len().max(1) as f64).sqrt();
        let (params, tris) = self
            .surface
            .sample_lattice((per_cell.ceil() as usize).max(2));
        (params.into_iter().map(|p| (p.u, p.v)).collect(), tris)
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

/// A triangular Bezier patch evaluated by de Casteljau on its control points (one reused
/// buffer per thread): the same surface as `Triangular<BezierTriangle>` without building
/// basis rows, which dominates sampling at high degree.
pub struct BezierPatch {
    pub degree: usize,
    pub controls: Vec<DVec3>,
}

impl BezierPatch {
    fn eval_with(&self, buf: &mut Vec<DVec3>, u: f64, v: f64) -> Derivatives {
        use crate::surface::bezier::lattice_index;
        let n = self.degree;
        let w = 1.0 - u - v;
        buf.clear();
        buf.extend_from_slice(&self.controls);
        // Reduce to degree 2 in place: level r - 1 overwrites level r (index order allows it:
        // (i, j) of level r - 1 reads (i, j), (i + 1, j), (i, j + 1) of level r, all at or
        // after its own index in level r's numbering, which is not yet overwritten).
        for r in (3..=n).rev() {
            for j in 0..r {
                for i in 0..r - j {
                    let x = buf[lattice_index(r, i + 1, j)] * u
                        + buf[lattice_index(r, i, j + 1)] * v
                        + buf[lattice_index(r, i, j)] * w;
                    buf[lattice_index(r - 1, i, j)] = x;
                }
            }
        }
        if n == 1 {
            let (p100, p010, p001) = (buf[1], buf[2], buf[0]);
            return Derivatives {
                position: p100 * u + p010 * v + p001 * w,
                du: p100 - p001,
                dv: p010 - p001,
                ..Default::default()
            };
        }
        let at = |i: usize, j: usize| buf[lattice_index(2, i, j)];
        let (p200, p020, p002) = (at(2, 0), at(0, 2), at(0, 0));
        let (p110, p101, p011) = (at(1, 1), at(1, 0), at(0, 1));
        let q100 = p200 * u + p110 * v + p101 * w;
        let q010 = p110 * u + p020 * v + p011 * w;
        let q001 = p101 * u + p011 * v + p002 * w;
        let (a, b) = (n as f64, (n * (n - 1)) as f64);
        Derivatives {
            position: q100 * u + q010 * v + q001 * w,
            du: (q100 - q001) * a,
            dv: (q010 - q001) * a,
            duu: (p200 - p101 * 2.0 + p002) * b,
            duv: (p110 - p101 - p011 + p002) * b,
            dvv: (p020 - p011 * 2.0 + p002) * b,
        }
    }
}

impl DerivativeSurface for BezierPatch {
    fn domain(&self) -> Domain {
        Domain::Triangle
    }
    fn derivatives(&self, u: f64, v: f64) -> Derivatives {
        self.eval_with(&mut Vec::new(), u, v)
    }
    fn derivatives_at(&self, params: &[(f64, f64)]) -> Vec<Derivatives> {
        params
            .par_iter()
            .map_init(Vec::new, |buf, &(u, v)| self.eval_with(buf, u, v))
            .collect()
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
