//! A Loop limit surface over any control mesh as CAD patches: one Bezier patch of degree
//! (4, 4) per control face, or per sub-triangle when every face is split `depth` times,
//! each the tensor-product form of a quartic triangle (degenerate along one side, as a
//! CAD sphere is at its poles). STEP and IGES carry them as B-spline surfaces.
//!
//! Why quartic triangles: a regular face's limit patch is a quartic box spline, i.e. a
//! quartic triangle, so its patch is the surface itself (to rounding); only faces at an
//! extraordinary, boundary or crease vertex, where the limit is no polynomial, are
//! approximated, and splitting shrinks that approximation where it is needed.
//!
//! Watertight by construction: each patch edge is one quartic curve, fitted once to the
//! exact limit curve (ends interpolated) and shared by the two patches that meet there.
//! The three interior ordinates of each patch are then fitted to the limit surface by
//! least squares. The deviation is measured on a lattice denser than the fit's, in
//! position and in normal direction.

use super::{BSplineError, BSplineSurface};
use crate::surface::loop_limit::LoopLimitSurface;
use crate::surface::{Derivatives, SurfaceParam, TriSurface};
use glam::DVec3;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use std::collections::HashMap;

/// Deepest uniform split taken: each control face becomes 4^depth patches.
pub const MAX_DEPTH: u32 = 4;

/// Segments of the samples along a patch edge that its curve is fitted to.
const EDGE_SEGMENTS: usize = 16;
/// Side of the lattice whose interior points fit a patch's interior ordinates.
const FIT_LATTICE: usize = 8;
/// Side of the lattice (boundary included) on which the deviation is measured: not a
/// divisor of the fit's lattices, so the check sees points the fit did not.
const CHECK_LATTICE: usize = 11;
/// Foot-point corrections of the fitted parameters (edges and interiors).
const CORRECTION_ROUNDS: usize = 2;
/// Newton steps of a foot point on a patch or an edge curve.
const FOOT_STEPS: usize = 8;

/// How far a patchwork is from its limit surface.
#[derive(Clone, Copy, Debug, Default)]
pub struct PatchDeviation {
    /// Points compared (patch against limit surface at the same parameter).
    pub samples: usize,
    /// Largest distance.
    pub max: f64,
    /// Root mean square distance.
    pub rms: f64,
    /// Largest angle between a patch's normal and the surface's, in degrees (at sliver
    /// faces, where the limit surface's own normal turns fast, it can be large).
    pub normal_max_deg: f64,
    /// The 99th percentile of that angle, in degrees.
    pub normal_p99_deg: f64,
}

/// A limit surface as patches.
#[derive(Debug)]
pub struct Patchwork {
    /// Degree (4, 4) Bezier patches, `4^depth` per control face, in face order.
    pub patches: Vec<BSplineSurface>,
    /// Splits of each control face.
    pub depth: u32,
    /// Control faces whose patches are exact (regular box-spline faces).
    pub exact_faces: usize,
    /// Measured deviation from the limit surface.
    pub deviation: PatchDeviation,
}

/// A point of the split lattice, named so that the faces meeting there agree on it.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Debug)]
enum Node {
    /// A control vertex.
    Corner(u32),
    /// On the control edge (low, high), this many lattice steps from `low`.
    OnEdge(u32, u32, u32),
    /// Inside a control face, at lattice (i, j).
    Inside(u32, u32, u32),
}

/// Lattice point (i, j) of `face` split into `n` steps per side: barycentric weights
/// (i, j, n - i - j) / n of the face's corners.
fn node(face: usize, corners: [u32; 3], n: u32, (i, j): (u32, u32)) -> Node {
    let w = [i, j, n - i - j];
    if let Some(c) = (0..3).find(|&c| w[c] == n) {
        return Node::Corner(corners[c]);
    }
    if let Some(zero) = (0..3).find(|&c| w[c] == 0) {
        let (a, b) = ((zero + 1) % 3, (zero + 2) % 3);
        return if corners[a] < corners[b] {
            Node::OnEdge(corners[a], corners[b], w[b])
        } else {
            Node::OnEdge(corners[b], corners[a], w[a])
        };
    }
    Node::Inside(face as u32, i, j)
}

/// The n^2 sub-triangles of a face split n times, as lattice corners in the face's own
/// orientation.
fn sub_triangles(n: u32) -> Vec<[(u32, u32); 3]> {
    let mut out = Vec::with_capacity((n * n) as usize);
    for i in 0..n {
        for j in 0..n - i {
            out.push([(i + 1, j), (i, j + 1), (i, j)]);
            if i + j + 2 <= n {
                out.push([(i + 1, j + 1), (i, j + 1), (i + 1, j)]);
            }
        }
    }
    out
}

/// Index of the ordinate with exponents (a, b, 4 - a - b) among the 15 of a quartic.
const fn ordinate(a: usize, b: usize) -> usize {
    [0, 5, 9, 12, 14][a] + b
}

const FACTORIAL: [f64; 5] = [1.0, 1.0, 2.0, 6.0, 24.0];

fn factorial(n: usize) -> f64 {
    FACTORIAL[n]
}

/// 1, x, x^2, x^3, x^4.
fn powers(x: f64) -> [f64; 5] {
    let x2 = x * x;
    [1.0, x, x2, x2 * x, x2 * x2]
}

/// The 15 quartic Bernstein values at barycentric (x, y, 1 - x - y).
fn bernstein4(x: f64, y: f64) -> [f64; 15] {
    let (px, py, pz) = (powers(x), powers(y), powers(1.0 - x - y));
    let mut out = [0.0; 15];
    for a in 0..=4 {
        for b in 0..=4 - a {
            let c = 4 - a - b;
            out[ordinate(a, b)] =
                24.0 / (factorial(a) * factorial(b) * factorial(c)) * px[a] * py[b] * pz[c];
        }
    }
    out
}

/// Position and first derivatives (along x and y, z = 1 - x - y eliminated) of a quartic
/// triangle at barycentric (x, y).
fn triangle_point(b: &[DVec3; 15], x: f64, y: f64) -> [DVec3; 3] {
    let position = bernstein4(x, y)
        .iter()
        .zip(b)
        .fold(DVec3::ZERO, |s, (w, p)| s + *p * *w);
    // 4 sum (b_(+x) - b_(+z)) B3, and likewise along y.
    let (px, py, pz) = (powers(x), powers(y), powers(1.0 - x - y));
    let (mut dx, mut dy) = (DVec3::ZERO, DVec3::ZERO);
    for a in 0..=3usize {
        for bb in 0..=3 - a {
            let c = 3 - a - bb;
            let w = 24.0 / (factorial(a) * factorial(bb) * factorial(c)) * px[a] * py[bb] * pz[c];
            let base = b[ordinate(a, bb)];
            dx += (b[ordinate(a + 1, bb)] - base) * w;
            dy += (b[ordinate(a, bb + 1)] - base) * w;
        }
    }
    [position, dx, dy]
}

/// The point of the triangle patch nearest `target`, by Gauss-Newton from (x, y), kept
/// in the triangle: its parameter and distance.
fn triangle_foot(b: &[DVec3; 15], target: DVec3, (mut x, mut y): (f64, f64)) -> ((f64, f64), f64) {
    for _ in 0..FOOT_STEPS {
        let [p, dx, dy] = triangle_point(b, x, y);
        let r = target - p;
        let (a11, a12, a22) = (dx.dot(dx), dx.dot(dy), dy.dot(dy));
        let det = a11 * a22 - a12 * a12;
        if det.is_nan() || det <= 0.0 {
            break;
        }
        let (g1, g2) = (dx.dot(r), dy.dot(r));
        x = (x + (a22 * g1 - a12 * g2) / det).max(0.0);
        y = (y + (a11 * g2 - a12 * g1) / det).max(0.0);
        if x + y > 1.0 {
            let t = x + y;
            (x, y) = (x / t, y / t);
        }
    }
    ((x, y), triangle_point(b, x, y)[0].distance(target))
}

/// The five quartic Bernstein values at t.
fn bernstein4_curve(t: f64) -> [f64; 5] {
    let (pt, ps) = (powers(t), powers(1.0 - t));
    std::array::from_fn(|m| factorial(4) / (factorial(m) * factorial(4 - m)) * pt[m] * ps[4 - m])
}

/// The parameter of the point of the quartic curve `c` nearest `target`, by Newton from
/// t, kept in [0, 1].
fn curve_foot(c: &[DVec3; 5], target: DVec3, mut t: f64) -> f64 {
    for _ in 0..FOOT_STEPS {
        let w = bernstein4_curve(t);
        let p = c.iter().zip(w).fold(DVec3::ZERO, |s, (q, w)| s + *q * w);
        // Derivative: 4 sum (c_(m+1) - c_m) B3_m.
        let (pt, ps) = (powers(t), powers(1.0 - t));
        let d: DVec3 = (0..4)
            .map(|m| {
                (c[m + 1] - c[m])
                    * (4.0 * factorial(3) / (factorial(m) * factorial(3 - m)))
                    * pt[m]
                    * ps[3 - m]
            })
            .sum();
        let dd = d.length_squared();
        if dd.is_nan() || dd <= 0.0 {
            break;
        }
        t = (t + (target - p).dot(d) / dd).clamp(0.0, 1.0);
    }
    t
}

/// Three free points of a linear least-squares problem: rows of their basis values, and
/// the right-hand sides (the samples less the fixed points' share). `None` when the
/// normal matrix is singular.
fn least_squares3(rows: &[[f64; 3]], rhs: &[DVec3]) -> Option<[DVec3; 3]> {
    let mut normal = Matrix3::zeros();
    let mut right = [DVec3::ZERO; 3];
    for (r, x) in rows.iter().zip(rhs) {
        for i in 0..3 {
            right[i] += *x * r[i];
            for j in 0..3 {
                normal[(i, j)] += r[i] * r[j];
            }
        }
    }
    let chol = normal.cholesky()?;
    let mut out = [DVec3::ZERO; 3];
    for axis in 0..3 {
        let v = chol.solve(&Vector3::from_fn(|i, _| right[i][axis]));
        for i in 0..3 {
            out[i][axis] = v[i];
        }
    }
    Some(out)
}

/// Sample parameters shared by every patch.
struct Fits {
    /// Interior samples along a patch edge.
    edge: Vec<f64>,
    /// Interior samples of a patch (barycentric x, y).
    inner: Vec<(f64, f64)>,
}

const INNER: [usize; 3] = [ordinate(2, 1), ordinate(1, 2), ordinate(1, 1)];

impl Fits {
    fn new() -> Fits {
        let m = FIT_LATTICE;
        Fits {
            edge: (1..EDGE_SEGMENTS)
                .map(|s| s as f64 / EDGE_SEGMENTS as f64)
                .collect(),
            inner: (1..m)
                .flat_map(|a| (1..m - a).map(move |b| (a, b)))
                .map(|(a, b)| (a as f64 / m as f64, b as f64 / m as f64))
                .collect(),
        }
    }

    /// The quartic from `start` to `end` (the limit curve's ends) nearest the limit curve
    /// `p` over [0, 1]: its middle points
    /// fitted at the samples' parameters, then at their foot points on the curve (the
    /// limit curve's own parameter is not the polynomial's near an extraordinary vertex).
    fn edge(&self, [start, end]: [DVec3; 2], p: impl Fn(f64) -> DVec3) -> [DVec3; 5] {
        let samples: Vec<DVec3> = self.edge.iter().map(|&t| p(t)).collect();
        let mut params = self.edge.clone();
        let mut c = [
            start,
            (start * 3.0 + end) / 4.0,
            (start + end) / 2.0,
            (start + end * 3.0) / 4.0,
            end,
        ];
        for round in 0..=CORRECTION_ROUNDS {
            if round > 0 {
                for (t, x) in params.iter_mut().zip(&samples) {
                    *t = curve_foot(&c, *x, *t);
                }
            }
            let (rows, rhs): (Vec<[f64; 3]>, Vec<DVec3>) = params
                .iter()
                .zip(&samples)
                .map(|(&t, x)| {
                    let w = bernstein4_curve(t);
                    ([w[1], w[2], w[3]], *x - start * w[0] - end * w[4])
                })
                .unzip();
            match least_squares3(&rows, &rhs) {
                Some(mid) => c[1..4].copy_from_slice(&mid),
                None => break,
            }
        }
        c
    }

    /// The interior ordinates of a quartic triangle whose boundary is set, nearest the
    /// limit surface `limit` over the triangle: fitted at the samples' parameters, then at
    /// their foot points on the patch.
    fn interior(&self, b: &mut [DVec3; 15], limit: impl Fn(f64, f64) -> DVec3) {
        let samples: Vec<DVec3> = self.inner.iter().map(|&(x, y)| limit(x, y)).collect();
        let mut params = self.inner.clone();
        for slot in INNER {
            b[slot] = DVec3::ZERO;
        }
        // A start that is a plane through the boundary's average, so the first feet land.
        let mut fitted = false;
        for round in 0..=CORRECTION_ROUNDS {
            if round > 0 && fitted {
                for (q, x) in params.iter_mut().zip(&samples) {
                    *q = triangle_foot(b, *x, *q).0;
                }
            }
            let (rows, rhs): (Vec<[f64; 3]>, Vec<DVec3>) = params
                .iter()
                .zip(&samples)
                .map(|(&(x, y), target)| {
                    let w = bernstein4(x, y);
                    let fixed = (0..15)
                        .filter(|k| !INNER.contains(k))
                        .fold(DVec3::ZERO, |s, k| s + b[k] * w[k]);
                    (INNER.map(|k| w[k]), *target - fixed)
                })
                .unzip();
            match least_squares3(&rows, &rhs) {
                Some(inner) => {
                    for (slot, p) in INNER.iter().zip(inner) {
                        b[*slot] = p;
                    }
                    fitted = true;
                }
                None => break,
            }
        }
    }
}

/// A patch edge's ends in its face's parameters (u, v).
type Span = ((f64, f64), (f64, f64));

/// A sub-triangle's corners in its face's parameters (u, v).
type Corners = [(f64, f64); 3];

fn at(c: &Corners, x: f64, y: f64) -> (f64, f64) {
    let z = 1.0 - x - y;
    (
        c[0].0 * x + c[1].0 * y + c[2].0 * z,
        c[0].1 * x + c[1].1 * y + c[2].1 * z,
    )
}

/// The limit surface of `surface` over `controls` as patches, each control face split
/// `depth` times (at most [`MAX_DEPTH`]).
pub fn loop_patchwork(
    surface: &LoopLimitSurface,
    controls: &[DVec3],
    depth: u32,
) -> Result<Patchwork, BSplineError> {
    if controls.len() != surface.control_count() {
        return Err(BSplineError::ControlCount {
            got: controls.len(),
            expected: surface.control_count(),
        });
    }
    let depth = depth.min(MAX_DEPTH);
    let n = 1u32 << depth;
    let eval = surface.evaluator(controls);
    let point = |face: usize, (u, v): (f64, f64)| -> Derivatives {
        eval(SurfaceParam {
            face: face as u32,
            u,
            v,
        })
    };
    let fits = Fits::new();
    let subs = sub_triangles(n);
    let faces = surface.faces();
    let param = |(i, j): (u32, u32)| (i as f64 / n as f64, j as f64 / n as f64);

    let curves = edge_curves(faces, n, &fits, &|f, p| point(f, p).position);

    let per_face: Vec<Vec<([DVec3; 15], Stats)>> = faces
        .par_iter()
        .enumerate()
        .map(|(f, &corners)| {
            subs.iter()
                .map(|tri| {
                    let nodes = tri.map(|l| node(f, corners, n, l));
                    let c: Corners = tri.map(param);
                    let mut b = boundary_ordinates(&nodes, &curves);
                    fits.interior(&mut b, |x, y| point(f, at(&c, x, y)).position);
                    let stats = measure(&b, |x, y| point(f, at(&c, x, y)));
                    (b, stats)
                })
                .collect()
        })
        .collect();

    let mut total = Stats::default();
    let mut patches = Vec::with_capacity(faces.len() * subs.len());
    for (b, stats) in per_face.iter().flatten() {
        total.add(stats);
        patches.push(tensor_form(b)?);
    }
    Ok(Patchwork {
        patches,
        depth,
        exact_faces: (0..faces.len())
            .filter(|&f| surface.is_regular_face(f))
            .count(),
        deviation: total.finish(),
    })
}

/// Every patch edge of the split, once, in the direction from its lower node to its
/// higher. Each lattice node's limit point is evaluated once, from one of its faces, so
/// the patches meeting at a node share its position to the bit.
fn edge_curves(
    faces: &[[u32; 3]],
    n: u32,
    fits: &Fits,
    limit: &(dyn Fn(usize, (f64, f64)) -> DVec3 + Sync),
) -> HashMap<(Node, Node), [DVec3; 5]> {
    let param = |(i, j): (u32, u32)| (i as f64 / n as f64, j as f64 / n as f64);
    let mut nodes: HashMap<Node, (usize, (f64, f64))> = HashMap::new();
    let mut edges: HashMap<(Node, Node), (usize, Span)> = HashMap::new();
    for (f, &corners) in faces.iter().enumerate() {
        for tri in sub_triangles(n) {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let (na, nb) = (node(f, corners, n, a), node(f, corners, n, b));
                nodes.entry(na).or_insert((f, param(a)));
                let (key, pa, pb) = if na < nb {
                    ((na, nb), a, b)
                } else {
                    ((nb, na), b, a)
                };
                edges.entry(key).or_insert((f, (param(pa), param(pb))));
            }
        }
    }
    let positions: HashMap<Node, DVec3> = nodes
        .into_par_iter()
        .map(|(key, (f, p))| (key, limit(f, p)))
        .collect();
    edges
        .into_par_iter()
        .map(|(key, (f, (pa, pb)))| {
            let along = |t: f64| limit(f, (pa.0 + (pb.0 - pa.0) * t, pa.1 + (pb.1 - pa.1) * t));
            let ends = [key.0, key.1].map(|k| positions.get(&k).copied().unwrap_or(DVec3::ZERO));
            (key, fits.edge(ends, along))
        })
        .collect()
}

/// The 12 boundary ordinates of the sub-triangle with these corner nodes, from the shared
/// edge curves (the interior three are left zero).
fn boundary_ordinates(
    nodes: &[Node; 3],
    curves: &HashMap<(Node, Node), [DVec3; 5]>,
) -> [DVec3; 15] {
    // From corner `from` to corner `to`: the stored curve, reversed when stored the
    // other way.
    let curve = |from: usize, to: usize| -> [DVec3; 5] {
        let (a, b) = (nodes[from], nodes[to]);
        match curves.get(&(a.min(b), a.max(b))) {
            Some(c) if a < b => *c,
            Some(c) => [c[4], c[3], c[2], c[1], c[0]],
            None => [DVec3::ZERO; 5],
        }
    };
    let mut b = [DVec3::ZERO; 15];
    let (ab, bc, ca) = (curve(0, 1), curve(1, 2), curve(2, 0));
    for m in 0..=4 {
        b[ordinate(4 - m, m)] = ab[m];
        b[ordinate(0, 4 - m)] = bc[m];
        b[ordinate(m, 0)] = ca[m];
    }
    b
}

#[derive(Default)]
struct Stats {
    samples: usize,
    sum_sq: f64,
    max: f64,
    normal_deg: Vec<f32>,
}

impl Stats {
    fn add(&mut self, o: &Stats) {
        self.samples += o.samples;
        self.sum_sq += o.sum_sq;
        self.max = self.max.max(o.max);
        self.normal_deg.extend_from_slice(&o.normal_deg);
    }

    fn finish(mut self) -> PatchDeviation {
        self.normal_deg.sort_by(f32::total_cmp);
        let at = |q: f64| {
            let n = self.normal_deg.len();
            if n == 0 {
                0.0
            } else {
                f64::from(self.normal_deg[((n - 1) as f64 * q).round() as usize])
            }
        };
        PatchDeviation {
            samples: self.samples,
            max: self.max,
            rms: (self.sum_sq / self.samples.max(1) as f64).sqrt(),
            normal_max_deg: at(1.0),
            normal_p99_deg: at(0.99),
        }
    }
}

/// Limit surface against patch on the check lattice: the distance from each limit point
/// to the patch (its foot point, or the point at the same parameter when that is nearer),
/// which is what a CAD user's tolerance is about; the patch's parameter is not the limit
/// surface's near an extraordinary vertex, and need not be. Normals are compared at the
/// foot, away from the sub-triangle's corners: at an extraordinary vertex the limit's
/// parametric derivatives vanish or blow up.
fn measure(b: &[DVec3; 15], limit: impl Fn(f64, f64) -> Derivatives) -> Stats {
    let m = CHECK_LATTICE;
    let mut s = Stats::default();
    for a in 0..=m {
        for bb in 0..=m - a {
            let (x, y) = (a as f64 / m as f64, bb as f64 / m as f64);
            let exact = limit(x, y);
            let same = triangle_point(b, x, y)[0].distance(exact.position);
            let (foot, along) = triangle_foot(b, exact.position, (x, y));
            let (d, (fx, fy)) = if along < same {
                (along, foot)
            } else {
                (same, (x, y))
            };
            s.samples += 1;
            s.sum_sq += d * d;
            s.max = s.max.max(d);
            let corner = a == m || bb == m || a + bb == 0;
            let [_, dx, dy] = triangle_point(b, fx, fy);
            let (normal, exact_normal) = (dx.cross(dy), exact.du.cross(exact.dv));
            if !corner && exact_normal.length() > 0.0 && normal.length() > 0.0 {
                let angle = exact_normal.angle_between(normal).to_degrees();
                s.normal_deg.push(angle as f32);
            }
        }
    }
    s
}

/// The quartic triangle as a degree (4, 4) tensor-product Bezier patch: with
/// x = s, y = (1 - s) t, z = (1 - s)(1 - t), B4_abc(x, y, z) = B4_a(s) B(4-a)_b(t), so row a
/// (along t) is the degree 4 - a curve of the ordinates (a, ., .), degree-elevated to 4;
/// the row at s = 1 collapses to corner x.
fn tensor_form(b: &[DVec3; 15]) -> Result<BSplineSurface, BSplineError> {
    let mut grid = Vec::with_capacity(25);
    for a in 0..=4usize {
        let degree = 4 - a;
        let mut row: Vec<DVec3> = (0..=degree).map(|j| b[ordinate(a, j)]).collect();
        // The row's curve runs from t = 0 (ordinate (a, 0, c): corner z's side) to t = 1.
        // The last row is corner x alone, repeated exactly (elevation would round it).
        if row.len() == 1 {
            row = vec![row[0]; 5];
        }
        while row.len() < 5 {
            let m = row.len(); // new degree
            let mut up = Vec::with_capacity(m + 1);
            for j in 0..=m {
                let w = j as f64 / m as f64;
                let left = if j > 0 { row[j - 1] } else { DVec3::ZERO };
                let right = if j < m { row[j] } else { DVec3::ZERO };
                up.push(left * w + right * (1.0 - w));
            }
            row = up;
        }
        grid.extend(row);
    }
    let knots = vec![0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0];
    BSplineSurface::new((4, 4), knots.clone(), knots, (5, 5), grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tensor_form_is_the_triangle() {
        let b: [DVec3; 15] =
            std::array::from_fn(|k| DVec3::new(k as f64, (k * k) as f64 * 0.1, (k as f64).sin()));
        let t = tensor_form(&b).expect("finite");
        for &(s, tt) in &[(0.0, 0.0), (0.3, 0.7), (0.9, 0.2), (0.5, 1.0), (1.0, 0.4)] {
            let (x, y) = (s, (1.0 - s) * tt);
            let [p, ..] = triangle_point(&b, x, y);
            assert!(t.point(s, tt).distance(p) < 1e-12, "{s} {tt}");
        }
    }

    #[test]
    fn lattice_nodes_agree_across_a_shared_edge() {
        // Faces (0, 1, 2) and (1, 0, 3) share edge 0-1 with opposite orientation.
        let n = 4;
        for k in 0..=n {
            let here = node(0, [0, 1, 2], n, (n - k, k));
            let there = node(1, [1, 0, 3], n, (k, n - k));
            assert_eq!(here, there);
        }
        assert_eq!(node(0, [0, 1, 2], n, (1, 1)), Node::Inside(0, 1, 1));
    }
}
