//! Triangular B-splines in the sense of Dahmen, Micchelli and Seidel (1992): piecewise
//! polynomials of degree n over an arbitrary domain triangulation, C^(n-1) for knots in
//! general position, with no patch joining.
//!
//! Every domain vertex v carries a knot cloud t_{v,0} = v, t_{v,1..n} (`knots`). For a
//! counter-clockwise domain triangle I = (a, b, c) and |b| = n the basis function is
//! `N_b^I(x) = |det(t_{a,b0}, t_{b,b1}, t_{c,b2})| M(x | t_{a,0..b0}, t_{b,0..b1}, t_{c,0..b2})`,
//! M the simplex spline (`simplex_spline`). Control point (I, b) sits at
//! `I * (n+1)(n+2)/2 + lattice_index(n, b0, b1)`: triangle by triangle, Bezier lattice order
//! within a triangle (corner 0 of I is the b0 direction). For a polynomial p, the control
//! point (I, b) reproducing it is p's blossom at (t_{a,0..b0-1}, t_{b,0..b1-1}, t_{c,0..b2-1}).
//!
//! Knot-only data is computed once: per domain triangle one `SimplexFamily` (its
//! (n+1)(n+2)/2 basis functions share one recurrence DAG over the triangle's 3(n+1) knots;
//! each cell of the knot-line arrangement a point meets is converted once to polynomials
//! (expanded about the cell's centre) and kept, so later points in the cell cost a sign key
//! and a polynomial per function)
//! and a grid that lists, per cell, the triangles whose knot clouds' bounding box may cover
//! it (the support of every N^I lies in the hull of I's clouds).
//!
//! Parameters: a domain face and barycentric (u, v) w.r.t. its corners 0 and 1. Knot-line
//! points are evaluated as the limit from inside that face (the perturbation direction
//! points to its centroid), so derivatives on domain edges are those of the face's piece.

mod error;
mod knots;
mod locate;
pub mod record;

pub use error::DmsError;
pub use knots::KnotRule;

use super::bezier::{lattice_index, lattice_len, lattice_points, lattice_triangles};
use super::simplex_spline::{det2, FrozenCells, Jet, SimplexFamily};
use super::{BasisDerivRows, Derivatives, SurfaceParam, TriSurface};
use glam::{DVec2, DVec3};
use locate::BoxGrid;
use rayon::prelude::*;
use std::cell::RefCell;
use std::collections::HashMap;

/// A surface over a planar domain: what scattered-data fitting needs beyond `TriSurface`.
pub trait PlanarSurface: TriSurface {
    /// The domain point of a parameter.
    fn domain_point(&self, p: SurfaceParam) -> DVec2;
    /// The parameter of a domain point, `None` outside the domain.
    fn locate(&self, x: DVec2) -> Option<SurfaceParam>;
    /// Per control point, the mean of its knots (the domain point an affine function's
    /// control point is the value at).
    fn greville_sites(&self) -> Vec<DVec2>;
    /// Neighbouring control points (for a fairness term over the control net).
    fn control_net_edges(&self) -> Vec<[u32; 2]>;
}

/// A checked DMS spline: domain, knot clouds and the compiled basis (control points are
/// kept apart).
#[derive(Clone, Debug)]
pub struct DmsSpline {
    degree: usize,
    vertices: Vec<DVec2>,
    triangles: Vec<[u32; 3]>,
    clouds: Vec<Vec<DVec2>>,
    families: Vec<SimplexFamily>,
    basis_grid: BoxGrid,
    face_grid: BoxGrid,
}

thread_local! {
    static SCRATCH: RefCell<(Vec<Jet>, Vec<Jet>)> = const { RefCell::new((Vec::new(), Vec::new())) };
    static ROWS: RefCell<Vec<(u32, Jet)>> = const { RefCell::new(Vec::new()) };
}

/// Halvings of the rule's spread tried before giving up.
const MAX_HALVINGS: usize = 8;

impl DmsSpline {
    /// A DMS spline of `degree` over the triangulation, knot clouds placed by `rule`.
    pub fn new(
        vertices: Vec<DVec2>,
        triangles: Vec<[u32; 3]>,
        degree: usize,
        rule: KnotRule,
    ) -> Result<Self, DmsError> {
        let boundary = validate_domain(&vertices, &triangles, degree)?;
        let KnotRule::Perturbed { spread } = rule;
        if !(spread.is_finite() && spread > 0.0) {
            return Err(DmsError::Spread(spread));
        }
        let mut spread = spread;
        let mut last = None;
        for _ in 0..=MAX_HALVINGS {
            let clouds = knots::place(&vertices, &triangles, &boundary, degree, spread);
            match knots::check(&vertices, &triangles, &boundary, degree, &clouds) {
                Ok(()) => return Self::build(vertices, triangles, degree, clouds),
                Err(e) => last = Some(e),
            }
            spread *= 0.5;
        }
        Err(DmsError::KnotsRejected {
            halvings: MAX_HALVINGS,
            last: Box::new(last.unwrap_or(DmsError::Empty)),
        })
    }

    /// A DMS spline with given knot clouds (per vertex n + 1 points, the vertex first),
    /// checked against the DMS and boundary conditions.
    pub fn with_clouds(
        vertices: Vec<DVec2>,
        triangles: Vec<[u32; 3]>,
        degree: usize,
        clouds: Vec<Vec<DVec2>>,
    ) -> Result<Self, DmsError> {
        let boundary = validate_domain(&vertices, &triangles, degree)?;
        if clouds.len() != vertices.len() {
            return Err(DmsError::CloudCount {
                found: clouds.len(),
                expected: vertices.len(),
            });
        }
        knots::check(&vertices, &triangles, &boundary, degree, &clouds)?;
        Self::build(vertices, triangles, degree, clouds)
    }

    fn build(
        vertices: Vec<DVec2>,
        triangles: Vec<[u32; 3]>,
        degree: usize,
        clouds: Vec<Vec<DVec2>>,
    ) -> Result<Self, DmsError> {
        let n = degree;
        let families = triangles
            .par_iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| &clouds[v as usize]);
                let pool: Vec<DVec2> = a.iter().chain(b).chain(c).copied().collect();
                let bits =
                    |first: usize, count: usize| -> u16 { (((1u32 << count) - 1) as u16) << first };
                let roots: Vec<(u16, f64)> = lattice_points(n)
                    .into_iter()
                    .map(|(i, j)| {
                        let k = n - i - j;
                        let mask = bits(0, i + 1) | bits(n + 1, j + 1) | bits(2 * (n + 1), k + 1);
                        (mask, det2(a[i], b[j], c[k]).abs())
                    })
                    .collect();
                SimplexFamily::compile(&pool, &roots)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let support_boxes: Vec<(DVec2, DVec2)> = triangles
            .iter()
            .map(|t| bounding_box(t.iter().flat_map(|&v| clouds[v as usize].iter().copied())))
            .collect();
        let face_boxes: Vec<(DVec2, DVec2)> = triangles
            .iter()
            .map(|t| bounding_box(t.iter().map(|&v| vertices[v as usize])))
            .collect();
        Ok(Self {
            degree,
            basis_grid: BoxGrid::new(&support_boxes),
            face_grid: BoxGrid::new(&face_boxes),
            vertices,
            triangles,
            clouds,
            families,
        })
    }

    /// The polynomial degree n.
    pub fn degree(&self) -> usize {
        self.degree
    }

    /// The domain vertices.
    pub fn vertices(&self) -> &[DVec2] {
        &self.vertices
    }

    /// The domain triangles, counter-clockwise.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Per domain vertex, n + 1 knots, the vertex first.
    pub fn knot_clouds(&self) -> &[Vec<DVec2>] {
        &self.clouds
    }

    /// Control points per domain triangle.
    pub fn controls_per_triangle(&self) -> usize {
        lattice_len(self.degree)
    }

    /// The control index of (triangle, b) with b = (i, j, n - i - j).
    pub fn control_index(&self, triangle: usize, i: usize, j: usize) -> usize {
        triangle * lattice_len(self.degree) + lattice_index(self.degree, i, j)
    }

    /// Knot-recurrence nodes over all triangles (a size figure for reports).
    pub fn node_count(&self) -> usize {
        self.families.iter().map(SimplexFamily::node_count).sum()
    }

    /// The compiled basis of domain triangle `triangle` (its roots in lattice order): for
    /// checking the kept pieces against the recurrence.
    pub fn family(&self, triangle: usize) -> Option<&SimplexFamily> {
        self.families.get(triangle)
    }

    /// Polynomial pieces (knot-line cells) converted and kept so far over all triangles.
    pub fn piece_count(&self) -> usize {
        self.families.iter().map(SimplexFamily::piece_count).sum()
    }

    fn corners(&self, face: usize) -> [DVec2; 3] {
        self.triangles[face].map(|v| self.vertices[v as usize])
    }

    /// Basis functions nonzero at domain point x (knot lines resolved towards `dir`), with
    /// x/y derivatives when `DERIV`; `out` gets (control, jet).
    pub fn basis_at<const DERIV: bool>(&self, x: DVec2, dir: DVec2, out: &mut Vec<(u32, Jet)>) {
        out.clear();
        let per = lattice_len(self.degree) as u32;
        SCRATCH.with(|cell| {
            let mut guard = cell.borrow_mut();
            let (scratch, values) = &mut *guard;
            for &t in self.basis_grid.candidates(x) {
                let family = &self.families[t as usize];
                if !family.may_touch(x) {
                    continue;
                }
                family.evaluate_cached::<DERIV>(x, dir, scratch, values);
                for (b, jet) in values.iter().enumerate() {
                    if jet[0] != 0.0 || (DERIV && jet.iter().any(|&v| v != 0.0)) {
                        out.push((t * per + b as u32, *jet));
                    }
                }
            }
        });
    }

    fn param_point_and_direction(&self, p: SurfaceParam) -> (DVec2, DVec2) {
        let [a, b, c] = self.corners(p.face as usize);
        let x = c + (a - c) * p.u + (b - c) * p.v;
        (x, (a + b + c) / 3.0 - x)
    }
}

/// Derivatives along a face's parameter directions `eu`, `ev` from the x/y jet `sum`
/// (value, d/dx, d/dy, d2/dx2, d2/dxdy, d2/dy2).
fn in_face_directions(sum: [DVec3; 6], eu: DVec2, ev: DVec2) -> Derivatives {
    let hess = |p: DVec2, q: DVec2| {
        (sum[3] * q.x + sum[4] * q.y) * p.x + (sum[4] * q.x + sum[5] * q.y) * p.y
    };
    Derivatives {
        position: sum[0],
        du: sum[1] * eu.x + sum[2] * eu.y,
        dv: sum[1] * ev.x + sum[2] * ev.y,
        duu: hess(eu, eu),
        duv: hess(eu, ev),
        dvv: hess(ev, ev),
    }
}

fn bounding_box(points: impl Iterator<Item = DVec2>) -> (DVec2, DVec2) {
    points.fold(
        (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(p), hi.max(p)),
    )
}

/// Indices, orientation, manifoldness; returns each vertex's boundary neighbours.
fn validate_domain(
    vertices: &[DVec2],
    triangles: &[[u32; 3]],
    degree: usize,
) -> Result<Vec<Option<(u32, u32)>>, DmsError> {
    if !(1..=3).contains(&degree) {
        return Err(DmsError::Degree(degree));
    }
    if triangles.is_empty() {
        return Err(DmsError::Empty);
    }
    for (ti, t) in triangles.iter().enumerate() {
        if let Some(&v) = t.iter().find(|&&v| v as usize >= vertices.len()) {
            return Err(DmsError::VertexIndex {
                triangle: ti as u32,
                vertex: v,
            });
        }
        let [a, b, c] = t.map(|v| vertices[v as usize]);
        let det = det2(a, b, c);
        if det.is_nan() || det <= 0.0 {
            return Err(DmsError::NotCounterClockwise(ti as u32));
        }
    }
    knots::boundary_neighbours(vertices.len(), triangles)
}

impl TriSurface for DmsSpline {
    fn control_count(&self) -> usize {
        self.triangles.len() * lattice_len(self.degree)
    }

    fn domain_face_count(&self) -> usize {
        self.triangles.len()
    }

    fn basis_row(&self, p: SurfaceParam, out: &mut Vec<(u32, f64)>) {
        let (x, dir) = self.param_point_and_direction(p);
        out.clear();
        ROWS.with(|cell| {
            let mut rows = cell.borrow_mut();
            self.basis_at::<false>(x, dir, &mut rows);
            out.extend(rows.iter().map(|(i, j)| (*i, j[0])));
        });
    }

    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows) {
        let (x, dir) = self.param_point_and_direction(p);
        let [a, b, c] = self.corners(p.face as usize);
        let (eu, ev) = (a - c, b - c);
        let mut rows = Vec::new();
        self.basis_at::<true>(x, dir, &mut rows);
        out.indices.clear();
        out.weights.clear();
        for (i, j) in rows {
            let grad = DVec2::new(j[1], j[2]);
            let hess = |p: DVec2, q: DVec2| {
                p.x * (j[3] * q.x + j[4] * q.y) + p.y * (j[4] * q.x + j[5] * q.y)
            };
            out.indices.push(i);
            out.weights.push([
                j[0],
                grad.dot(eu),
                grad.dot(ev),
                hess(eu, eu),
                hess(eu, ev),
                hess(ev, ev),
            ]);
        }
    }

    /// Accumulates the jets directly (no row buffers): foot-point searches call this at
    /// every Newton step.
    fn evaluate(&self, controls: &[DVec3], p: SurfaceParam) -> Derivatives {
        let (x, dir) = self.param_point_and_direction(p);
        let [a, b, c] = self.corners(p.face as usize);
        let (eu, ev) = (a - c, b - c);
        let mut sum = [DVec3::ZERO; 6];
        ROWS.with(|cell| {
            let mut rows = cell.borrow_mut();
            self.basis_at::<true>(x, dir, &mut rows);
            for (i, j) in rows.iter() {
                let c = controls[*i as usize];
                for (s, w) in sum.iter_mut().zip(j) {
                    *s += c * *w;
                }
            }
        });
        in_face_directions(sum, eu, ev)
    }

    /// Per domain triangle, its share of the surface of `controls` frozen on the cells
    /// kept so far (`SimplexFamily::freeze`): a foot-point search evaluates one surface at
    /// every Newton step, and a frozen cell costs one polynomial in place of one per basis
    /// function.
    fn evaluator<'a>(
        &'a self,
        controls: &'a [DVec3],
    ) -> Box<dyn Fn(SurfaceParam) -> Derivatives + Sync + 'a> {
        let per = lattice_len(self.degree);
        let frozen: Vec<Option<FrozenCells>> = self
            .families
            .par_iter()
            .enumerate()
            .map(|(t, family)| {
                controls
                    .get(t * per..(t + 1) * per)
                    .and_then(|c| family.freeze(c))
            })
            .collect();
        if frozen.iter().any(Option::is_none) {
            return Box::new(move |p| self.evaluate(controls, p));
        }
        let empty = FrozenCells::default();
        Box::new(move |p| {
            let (x, dir) = self.param_point_and_direction(p);
            let [a, b, c] = self.corners(p.face as usize);
            let mut sum = [DVec3::ZERO; 6];
            for &t in self.basis_grid.candidates(x) {
                let t = t as usize;
                let family = &self.families[t];
                if !family.may_touch(x) {
                    continue;
                }
                let share = family.surface_jet(
                    frozen[t].as_ref().unwrap_or(&empty),
                    x,
                    dir,
                    &controls[t * per..(t + 1) * per],
                );
                for (s, v) in sum.iter_mut().zip(share) {
                    *s += v;
                }
            }
            in_face_directions(sum, a - c, b - c)
        })
    }

    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam {
        let (u, v) = (p.u + du, p.v + dv);
        // Most Newton steps stay inside their face: no look-up then (`locate` gives the
        // same parameter for a point strictly inside one face).
        if u > 0.0 && v > 0.0 && u + v < 1.0 {
            return SurfaceParam { face: p.face, u, v };
        }
        let [a, b, c] = self.corners(p.face as usize);
        let x = c + (a - c) * u + (b - c) * v;
        if let Some(q) = self.locate(x) {
            return q;
        }
        // Outside the domain: clamp into the current face.
        let mut u = (p.u + du).max(0.0);
        let mut v = (p.v + dv).max(0.0);
        let s = u + v;
        if s > 1.0 {
            u /= s;
            v /= s;
        }
        SurfaceParam { face: p.face, u, v }
    }
}

impl PlanarSurface for DmsSpline {
    fn domain_point(&self, p: SurfaceParam) -> DVec2 {
        self.param_point_and_direction(p).0
    }

    fn locate(&self, x: DVec2) -> Option<SurfaceParam> {
        let mut best: Option<(f64, SurfaceParam)> = None;
        for &t in self.face_grid.candidates(x) {
            let [a, b, c] = self.corners(t as usize);
            let d = det2(a, b, c);
            let (u, v) = (det2(x, b, c) / d, det2(a, x, c) / d);
            let worst = u.min(v).min(1.0 - u - v);
            if best.is_none_or(|(w, _)| worst > w) {
                best = Some((worst, SurfaceParam { face: t, u, v }));
            }
        }
        best.filter(|(w, _)| *w >= -1e-12).map(|(_, p)| {
            // Clamp round-off so that the parameter is in its face.
            let u = p.u.max(0.0);
            let v = p.v.max(0.0);
            let s = (u + v).max(1.0);
            SurfaceParam {
                u: u / s,
                v: v / s,
                ..p
            }
        })
    }

    fn greville_sites(&self) -> Vec<DVec2> {
        let n = self.degree;
        self.triangles
            .iter()
            .flat_map(|t| {
                let [a, b, c] = t.map(|v| &self.clouds[v as usize]);
                lattice_points(n).into_iter().map(move |(i, j)| {
                    let k = n - i - j;
                    let sum: DVec2 = a[..i].iter().chain(&b[..j]).chain(&c[..k]).sum();
                    sum / n as f64
                })
            })
            .collect()
    }

    /// Lattice edges within each triangle, and links between the controls of different
    /// triangles that share their knots (edge rows across a domain edge, corners around a
    /// vertex): those have the same Greville site.
    fn control_net_edges(&self) -> Vec<[u32; 2]> {
        let n = self.degree;
        let per = lattice_len(n) as u32;
        let lattice = lattice_triangles(n);
        let mut edges = Vec::new();
        let mut shared: HashMap<Vec<(u32, usize)>, Vec<u32>> = HashMap::new();
        for (ti, t) in self.triangles.iter().enumerate() {
            let base = ti as u32 * per;
            for l in &lattice {
                for k in 0..3 {
                    edges.push([base + l[k], base + l[(k + 1) % 3]]);
                }
            }
            for (idx, (i, j)) in lattice_points(n).into_iter().enumerate() {
                let counts = [i, j, n - i - j];
                if counts.iter().all(|&c| c > 0) {
                    continue;
                }
                let mut key: Vec<(u32, usize)> = t
                    .iter()
                    .zip(counts)
                    .filter(|(_, c)| *c > 0)
                    .map(|(&v, c)| (v, c))
                    .collect();
                key.sort_unstable();
                shared.entry(key).or_default().push(base + idx as u32);
            }
        }
        for group in shared.values() {
            for (k, &a) in group.iter().enumerate() {
                edges.extend(group[k + 1..].iter().map(|&b| [a, b]));
            }
        }
        for e in &mut edges {
            *e = [e[0].min(e[1]), e[0].max(e[1])];
        }
        edges.sort_unstable();
        edges.dedup();
        edges
    }
}
