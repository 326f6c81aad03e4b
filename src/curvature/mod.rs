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
#![warn(missing_docs)]

pub mod planar;
pub mod regions;

use crate::bspline::BSplineSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use rayon::prelude::*;

/// The parameter domain of a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Domain {
    /// [u0, u1] x [v0, v1].
    Rectangle {
        /// (u0, u1).
        u: (f64, f64),
        /// (v0, v1).
        v: (f64, f64),
    },
    /// u, v >= 0, u + v <= 1.
    Triangle,
    /// Cells of a grid, or the faces of a control mesh: the surface samples itself through
    /// [`DerivativeSurface::own_lattice`].
    Cells,
}

/// A sampling built by the surface itself ([`Domain::Cells`]).
#[derive(Clone, Debug, Default)]
pub struct OwnLattice {
    /// One parameter per sample.
    pub params: Vec<(f64, f64)>,
    /// Counter-clockwise triangles of samples.
    pub triangles: Vec<[u32; 3]>,
    /// For surfaces whose parameters are per-face charts rather than one plane (see
    /// [`LoopMeshPatch`]): per triangle, the parameters of its three corners in the chart
    /// of the face holding the triangle. A sample shared by several faces has one entry in
    /// `params` (one face's chart), so points inside a triangle must interpolate these
    /// instead. `None`: `params` are one global chart.
    pub charts: Option<Vec<[(f64, f64); 3]>>,
}

/// Position and first and second partial derivatives at a parameter.
pub trait DerivativeSurface: Sync {
    /// The parameter domain.
    fn domain(&self) -> Domain;
    /// Position and derivatives at (u, v).
    fn derivatives(&self, u: f64, v: f64) -> Derivatives;
    /// Domains other than a rectangle or the triangle: a sampling with about `n` samples
    /// across.
    fn own_lattice(&self, _n: usize) -> OwnLattice {
        OwnLattice::default()
    }
    /// Derivatives at many parameters (in parallel); separable surfaces do better on grids
    /// through [`DerivativeSurface::derivatives_on_grid`].
    fn derivatives_at(&self, params: &[(f64, f64)]) -> Vec<Derivatives> {
        params
            .par_iter()
            .map(|&(u, v)| self.derivatives(u, v))
            .collect()
    }
    /// Derivatives at every `(us[r], vs[c])`, row-major in r.
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
pub(crate) struct GridPatch {
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
    fn own_lattice(&self, n: usize) -> OwnLattice {
        let per_cell = n as f64 / (self.surface.cells().len().max(1) as f64).sqrt();
        let (params, triangles) = self
            .surface
            .sample_lattice((per_cell.ceil() as usize).max(2));
        OwnLattice {
            params: params.into_iter().map(|p| (p.u, p.v)).collect(),
            triangles,
            charts: None,
        }
    }
}

/// The Loop limit surface of an arbitrary control mesh (`surface.json` kind `loop`,
/// layout `mesh`).
///
/// Every control face is its own barycentric chart, so a parameter names a face. It is
/// packed into the two numbers of [`DerivativeSurface::derivatives`] as
/// `(2 face + u, v)`: u lies in [0, 1], so `face = floor(s / 2)` and `u = s - 2 face`
/// are unambiguous, and the corners and edges u = 0, u = 1, v = 0 stay exact (integers
/// are exact in f64; at 10^6 faces the interior u carries about 1e-10 rounding, far below
/// what curvature sees). Region boundaries in `param_loops` are in this packing too.
///
/// Curvature is geometric, so each sample may use the derivatives of any face that
/// contains it; the lattice welds samples on shared control edges and vertices so that
/// regions and boundary loops cross faces.
///
/// At an interior control vertex of valence other than 6 the Loop evaluator returns the
/// exact tangent plane but zero second derivatives (the parametric ones vanish or blow
/// up there), which would read as a flat point. Such a sample keeps its exact position
/// but takes its derivatives 2^-30 towards the centre of the face it is sampled in: the
/// curvature approached along that direction (at valence 3..5 the limit, at valence > 6
/// large, as the surface's curvature is unbounded there).
pub struct LoopMeshPatch {
    /// The surface of the control mesh.
    pub surface: std::sync::Arc<crate::surface::loop_limit::LoopLimitSurface>,
    /// Its control points.
    pub controls: Vec<DVec3>,
    /// Per control: an interior vertex of valence other than 6.
    irregular: Vec<bool>,
}

/// Parameter offset for derivatives at an irregular interior vertex (see [`LoopMeshPatch`]).
const IRREGULAR_NUDGE: f64 = 1.0 / (1u64 << 30) as f64;

impl LoopMeshPatch {
    /// Wraps a Loop surface and its controls, marking the irregular interior vertices.
    pub fn new(
        surface: std::sync::Arc<crate::surface::loop_limit::LoopLimitSurface>,
        controls: Vec<DVec3>,
    ) -> Self {
        let mut valence = vec![0usize; controls.len()];
        let mut edge_use: std::collections::HashMap<(u32, u32), u32> =
            std::collections::HashMap::new();
        for t in surface.faces() {
            for c in 0..3 {
                valence[t[c] as usize] += 1;
                let (a, b) = (t[c], t[(c + 1) % 3]);
                *edge_use.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let mut boundary = vec![false; controls.len()];
        for (&(a, b), &n) in &edge_use {
            if n == 1 {
                boundary[a as usize] = true;
                boundary[b as usize] = true;
            }
        }
        let irregular = (0..controls.len())
            .map(|v| !boundary[v] && valence[v] != 6)
            .collect();
        Self {
            surface,
            controls,
            irregular,
        }
    }

    /// Derivatives at `p` by `eval`, moved off an irregular interior vertex (see above).
    fn sample(&self, eval: &dyn Fn(SurfaceParam) -> Derivatives, p: SurfaceParam) -> Derivatives {
        let d = eval(p);
        let w = 1.0 - p.u - p.v;
        let corner = [p.u, p.v, w].iter().position(|&x| x == 1.0);
        let on_irregular = corner.is_some_and(|c| {
            self.surface
                .faces()
                .get(p.face as usize)
                .is_some_and(|t| self.irregular[t[c] as usize])
        });
        if !on_irregular {
            return d;
        }
        let e = IRREGULAR_NUDGE;
        let moved = eval(SurfaceParam {
            u: (1.0 - e) * p.u + e / 3.0,
            v: (1.0 - e) * p.v + e / 3.0,
            ..p
        });
        Derivatives {
            position: d.position,
            ..moved
        }
    }

    /// The packed parameter of (face, u, v).
    pub(crate) fn pack(face: usize, u: f64, v: f64) -> (f64, f64) {
        (2.0 * face as f64 + u, v)
    }

    /// The (face, u, v) of a packed parameter; faces out of range are clamped.
    pub(crate) fn unpack(&self, s: f64, v: f64) -> SurfaceParam {
        let last = self.surface.faces().len().saturating_sub(1);
        let face = if s.is_finite() && s > 0.0 {
            ((s / 2.0).floor() as usize).min(last)
        } else {
            0
        };
        SurfaceParam {
            face: face as u32,
            u: s - 2.0 * face as f64,
            v,
        }
    }

    /// Derivatives in one face's chart (another face sharing the point gives other
    /// derivatives but the same curvature).
    pub fn derivatives_in_face(&self, face: usize, u: f64, v: f64) -> Derivatives {
        self.surface.evaluate(
            &self.controls,
            SurfaceParam {
                face: face as u32,
                u,
                v,
            },
        )
    }

    /// `m` segments on every face side (m >= 1), samples welded across faces: a sample
    /// on a control vertex is keyed by the vertex, one on a control edge by the edge and
    /// its integer step along it, so neighbours find it without comparing coordinates.
    pub fn lattice_with_segments(&self, m: usize) -> OwnLattice {
        let m = m.max(1);
        let faces = self.surface.faces();
        let mut params = Vec::new();
        let mut at_vertex = vec![u32::MAX; self.controls.len()];
        // (lower control index, higher, steps from the lower one) -> sample.
        let mut on_edge: std::collections::HashMap<(u32, u32, usize), u32> =
            std::collections::HashMap::new();
        let mut triangles = Vec::with_capacity(faces.len() * m * m);
        let mut charts = Vec::with_capacity(faces.len() * m * m);
        // This face's samples by local lattice index (i, j) at (u, v) = (i, j) / m.
        let mut local = vec![0u32; (m + 1) * (m + 1)];
        for (f, t) in faces.iter().enumerate() {
            for j in 0..=m {
                for i in 0..=m - j {
                    // Steps towards corners 0, 1, 2 (barycentric weights times m).
                    let steps = [i, j, m - i - j];
                    let p = Self::pack(f, i as f64 / m as f64, j as f64 / m as f64);
                    let mut fresh = || {
                        params.push(p);
                        (params.len() - 1) as u32
                    };
                    let zeros = steps.iter().filter(|&&k| k == 0).count();
                    local[j * (m + 1) + i] = if zeros == 2 {
                        let c = t[steps.iter().position(|&k| k == m).unwrap_or(0)];
                        if at_vertex[c as usize] == u32::MAX {
                            at_vertex[c as usize] = fresh();
                        }
                        at_vertex[c as usize]
                    } else if zeros == 1 {
                        // On the side opposite the corner with weight 0.
                        let z = steps.iter().position(|&k| k == 0).unwrap_or(0);
                        let (a, b) = ((z + 1) % 3, (z + 2) % 3);
                        let (lo, hi, k) = if t[a] < t[b] {
                            (t[a], t[b], steps[a])
                        } else {
                            (t[b], t[a], steps[b])
                        };
                        *on_edge.entry((lo, hi, k)).or_insert_with(fresh)
                    } else {
                        fresh()
                    };
                }
            }
            let id = |i: usize, j: usize| local[j * (m + 1) + i];
            let chart =
                |i: usize, j: usize| Self::pack(f, i as f64 / m as f64, j as f64 / m as f64);
            for j in 0..m {
                for i in 0..m - j {
                    // Up and down triangles, counter-clockwise in (u, v) as the face is on
                    // the surface (du x dv points along the face's orientation).
                    triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                    charts.push([chart(i, j), chart(i + 1, j), chart(i, j + 1)]);
                    if i + j + 1 < m {
                        triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
                        charts.push([chart(i + 1, j), chart(i + 1, j + 1), chart(i, j + 1)]);
                    }
                }
            }
        }
        OwnLattice {
            params,
            triangles,
            charts: Some(charts),
        }
    }
}

impl DerivativeSurface for LoopMeshPatch {
    fn domain(&self) -> Domain {
        Domain::Cells
    }
    fn derivatives(&self, s: f64, v: f64) -> Derivatives {
        let eval = |p| self.surface.evaluate(&self.controls, p);
        self.sample(&eval, self.unpack(s, v))
    }
    fn derivatives_at(&self, params: &[(f64, f64)]) -> Vec<Derivatives> {
        // One evaluator for all samples: it precomputes per-face data for the controls.
        let eval = self.surface.evaluator(&self.controls);
        params
            .par_iter()
            .map(|&(s, v)| self.sample(&eval, self.unpack(s, v)))
            .collect()
    }
    /// About `n` samples across the whole surface (faces ~ a square of sqrt(F) faces a
    /// side), at least 2 segments a face side so every face has a midpoint on each side.
    fn own_lattice(&self, n: usize) -> OwnLattice {
        let per_face = n as f64 / (self.surface.faces().len().max(1) as f64).sqrt();
        self.lattice_with_segments((per_face.ceil() as usize).max(2))
    }
}

/// A triangular surface (any [`TriSurface`] whose single domain triangle is the reference
/// triangle, as `trispline fit` writes them) with its control points.
pub struct Triangular<S: TriSurface> {
    /// The surface.
    pub surface: S,
    /// Its control points.
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
    /// The patch's degree.
    pub degree: usize,
    /// Its control points, in lattice order.
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
    /// Unit normal (du x dv normalised).
    pub normal: DVec3,
    /// First fundamental form.
    pub e: f64,
    /// First fundamental form, du . dv.
    pub f: f64,
    /// First fundamental form, dv . dv.
    pub g: f64,
    /// Second fundamental form.
    pub l: f64,
    /// Second fundamental form, duv . normal.
    pub m: f64,
    /// Second fundamental form, dvv . normal.
    pub n: f64,
    /// Gaussian curvature K.
    pub gaussian: f64,
    /// Mean curvature H (positive where the surface bends towards its normal).
    pub mean: f64,
    /// Larger principal curvature.
    pub k_max: f64,
    /// Smaller principal curvature.
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
    /// The lowercase name used in output files.
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
    /// Largest |K| read as zero.
    pub gaussian: f64,
    /// Largest |H| read as zero.
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
