//! Knot clouds of a DMS spline: the placement rule and the conditions it must keep.
//!
//! Conditions (checked for any clouds, ours or a caller's):
//! - DMS: for every domain triangle (a, b, c) and i + j + k <= n, the knot triangle
//!   [t_{a,i}, t_{b,j}, t_{c,k}] is non-degenerate and counter-clockwise like (a, b, c);
//! - boundary: the knots of a boundary vertex lie outside the domain, on the outer side of
//!   both its boundary edges. The basis sums to one wherever the knot-set hulls of boundary
//!   edges (uncancelled terms of the DMS identity) stay off the domain; this keeps them there.
//!
//! Rule (`KnotRule::Perturbed`, after Pfeifle and Seidel's "small perturbations of the
//! vertices"): `t_{v,i} = v + rho_v (i / n) (cos phi_i, sin phi_i)` for i = 1..n, with
//! rho_v = spread times the shortest edge at v. Interior vertices turn phi by the golden
//! angle (distinct, well-spread directions: no three knots of a cloud collinear); boundary
//! vertices spread phi over the middle 60% of their exterior wedge (the directions on the
//! outer side of both boundary edges). When the result breaks a condition the spread is
//! halved, up to eight times.

use super::error::DmsError;
use crate::surface::simplex_spline::orient_sign;
use glam::DVec2;
use std::collections::HashMap;

/// How knot clouds are placed around the domain vertices (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum KnotRule {
    /// Clouds of radius `spread` times the shortest incident edge (0.3 is a good start).
    Perturbed {
        /// Cloud radius as a fraction of the vertex's shortest edge; halved on failure.
        spread: f64,
    },
}

impl Default for KnotRule {
    fn default() -> Self {
        Self::Perturbed { spread: 0.3 }
    }
}

const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;
const GOLDEN_FRACTION: f64 = 0.618_033_988_749_895;

/// Per boundary vertex: (previous, next) along the boundary, the domain on the left.
pub(super) fn boundary_neighbours(
    vertex_count: usize,
    triangles: &[[u32; 3]],
) -> Result<Vec<Option<(u32, u32)>>, DmsError> {
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    for t in triangles {
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    let mut result: Vec<Option<(u32, u32)>> = vec![None; vertex_count];
    let mut prev: Vec<Option<u32>> = vec![None; vertex_count];
    let mut next: Vec<Option<u32>> = vec![None; vertex_count];
    for (&(a, b), &count) in &directed {
        if count > 1 || directed.get(&(b, a)).is_some_and(|&c| c > 1) {
            return Err(DmsError::NonManifoldEdge(a, b));
        }
        let is_boundary = !directed.contains_key(&(b, a));
        if is_boundary && next[a as usize].replace(b).is_some() {
            return Err(DmsError::NonManifoldVertex(a));
        }
        if is_boundary && prev[b as usize].replace(a).is_some() {
            return Err(DmsError::NonManifoldVertex(b));
        }
    }
    for v in 0..vertex_count {
        result[v] = match (prev[v], next[v]) {
            (Some(p), Some(q)) => Some((p, q)),
            (None, None) => None,
            _ => return Err(DmsError::NonManifoldVertex(v as u32)),
        };
    }
    Ok(result)
}

/// The clouds of `rule` (already halved `halvings` times).
pub(super) fn place(
    vertices: &[DVec2],
    triangles: &[[u32; 3]],
    boundary: &[Option<(u32, u32)>],
    degree: usize,
    spread: f64,
) -> Vec<Vec<DVec2>> {
    let mut shortest = vec![f64::INFINITY; vertices.len()];
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
            let len = vertices[a].distance(vertices[b]);
            shortest[a] = shortest[a].min(len);
            shortest[b] = shortest[b].min(len);
        }
    }
    let n = degree as f64;
    vertices
        .iter()
        .enumerate()
        .map(|(v, &x)| {
            // A vertex in no triangle gets a cloud that nothing reads.
            let rho = if shortest[v].is_finite() {
                spread * shortest[v]
            } else {
                0.0
            };
            let mut cloud = vec![x];
            for i in 1..=degree {
                let phi = match boundary[v] {
                    None => 0.5 + GOLDEN_ANGLE * i as f64,
                    Some((p, q)) => {
                        let (start, width) =
                            exterior_wedge(vertices[p as usize], x, vertices[q as usize]);
                        let f = 0.2 + 0.6 * ((i as f64 * GOLDEN_FRACTION) % 1.0);
                        start + width * f
                    }
                };
                cloud.push(x + DVec2::new(phi.cos(), phi.sin()) * (rho * i as f64 / n));
            }
            cloud
        })
        .collect()
}

/// Directions from v on the outer side of both boundary edges p -> v and v -> q: the arc
/// from max(angle in, angle out) - pi to min(angle in, angle out), as (start, width).
fn exterior_wedge(p: DVec2, v: DVec2, q: DVec2) -> (f64, f64) {
    let din = v - p;
    let dout = q - v;
    let t1 = din.y.atan2(din.x);
    let turn = din.perp_dot(dout).atan2(din.dot(dout));
    let t2 = t1 + turn;
    let start = t1.max(t2) - std::f64::consts::PI;
    (start, std::f64::consts::PI - turn.abs())
}

/// Checks the DMS and boundary conditions of `clouds`.
pub(super) fn check(
    vertices: &[DVec2],
    triangles: &[[u32; 3]],
    boundary: &[Option<(u32, u32)>],
    degree: usize,
    clouds: &[Vec<DVec2>],
) -> Result<(), DmsError> {
    for (v, cloud) in clouds.iter().enumerate() {
        if cloud.len() != degree + 1 {
            return Err(DmsError::CloudLength {
                vertex: v as u32,
                found: cloud.len(),
                expected: degree + 1,
            });
        }
        if cloud[0] != vertices[v] || cloud.iter().any(|p| !p.is_finite()) {
            return Err(DmsError::CloudNotAtVertex(v as u32));
        }
        if let Some((p, q)) = boundary[v] {
            let (p, x, q) = (vertices[p as usize], vertices[v], vertices[q as usize]);
            let inside = cloud[1..]
                .iter()
                .any(|k| orient_sign(p, x, *k) > 0 || orient_sign(x, q, *k) > 0);
            if inside {
                return Err(DmsError::BoundaryKnotInside(v as u32));
            }
        }
    }
    for (ti, t) in triangles.iter().enumerate() {
        let [a, b, c] = t.map(|v| &clouds[v as usize]);
        for (i, &p) in a.iter().enumerate() {
            for (j, &q) in b.iter().enumerate().take(degree + 1 - i) {
                for (k, &r) in c.iter().enumerate().take(degree + 1 - i - j) {
                    let area = (q - p).perp_dot(r - p);
                    let scale = (q - p).length_squared().max((r - p).length_squared());
                    if orient_sign(p, q, r) <= 0 || area <= 1e-9 * scale {
                        return Err(DmsError::KnotTriangle {
                            triangle: ti as u32,
                            knots: [i, j, k],
                        });
                    }
                }
            }
        }
    }
    Ok(())
}
