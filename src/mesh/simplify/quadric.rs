//! Garland-Heckbert error quadrics: the sum of squared distances to a set of weighted
//! planes, `x^T A x + 2 b.x + c`.

use super::SimplifyOptions;
use crate::mesh::topology::{Topology, NONE};
use crate::mesh::{triangle_area_normal, TriMesh};
use glam::{DMat3, DVec3};

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Quadric {
    /// Symmetric A as xx, xy, xz, yy, yz, zz.
    a: [f64; 6],
    b: DVec3,
    c: f64,
}

impl Quadric {
    /// The plane through `point` with unit normal `normal`, weighted by `weight`.
    pub(super) fn plane(normal: DVec3, point: DVec3, weight: f64) -> Quadric {
        let n = normal;
        let d = -n.dot(point);
        Quadric {
            a: crate::numeric::packed_outer(n, weight),
            b: n * (weight * d),
            c: weight * d * d,
        }
    }

    pub(super) fn add(&mut self, o: &Quadric) {
        for (s, t) in self.a.iter_mut().zip(&o.a) {
            *s += t;
        }
        self.b += o.b;
        self.c += o.c;
    }

    pub(super) fn sum(&self, o: &Quadric) -> Quadric {
        let mut q = *self;
        q.add(o);
        q
    }

    fn matrix(&self) -> DMat3 {
        let a = &self.a;
        DMat3::from_cols(
            DVec3::new(a[0], a[1], a[2]),
            DVec3::new(a[1], a[3], a[4]),
            DVec3::new(a[2], a[4], a[5]),
        )
    }

    /// The error at `x`, never negative (rounding can push a zero error below 0).
    pub(super) fn error(&self, x: DVec3) -> f64 {
        let ax = self.matrix() * x;
        (x.dot(ax) + 2.0 * self.b.dot(x) + self.c).max(0.0)
    }

    /// The minimiser of the error where A is well conditioned and the minimiser stays
    /// within `reach` of `near`; `None` otherwise (a flat or cylindrical neighbourhood
    /// leaves a line or plane of minimisers, and a nearly singular A puts the solution
    /// far from the edge).
    pub(super) fn minimiser(&self, near: DVec3, reach: f64) -> Option<DVec3> {
        let m = self.matrix();
        let scale = (self.a[0] + self.a[3] + self.a[5]) / 3.0;
        let det = m.determinant();
        if scale.is_nan() || scale <= 0.0 || det.abs() <= 1e-9 * scale * scale * scale {
            return None;
        }
        let x = m.inverse() * -self.b;
        (x.is_finite() && (x - near).length() <= reach).then_some(x)
    }

    /// The minimiser on the segment from `p` to `q`.
    pub(super) fn segment_minimiser(&self, p: DVec3, q: DVec3) -> DVec3 {
        let d = q - p;
        let m = self.matrix();
        let curvature = d.dot(m * d);
        let slope = 2.0 * (p.dot(m * d) + self.b.dot(d));
        if curvature > 0.0 {
            let t = (-slope / (2.0 * curvature)).clamp(0.0, 1.0);
            return p + d * t;
        }
        let mid = (p + q) * 0.5;
        [p, mid, q]
            .into_iter()
            .min_by(|x, y| self.error(*x).total_cmp(&self.error(*y)))
            .unwrap_or(mid)
    }
}

/// Every `wanted` vertex's quadric (the others' stay zero): the planes of its faces,
/// weighted by their areas, and the constraint planes of its boundary edges
/// (perpendicular to their face through the edge), which keep a hole's rim in shape.
/// A face none of whose corners is wanted is skipped, so a vertex's sum does not depend
/// on which others are wanted.
pub(super) fn initial_quadrics(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &SimplifyOptions,
    wanted: impl Fn(usize) -> bool,
) -> Vec<Quadric> {
    let pos = &mesh.positions;
    let mut quadric = vec![Quadric::default(); pos.len()];
    for (f, t) in mesh.triangles.iter().enumerate() {
        if !t.iter().any(|&v| wanted(v as usize)) {
            continue;
        }
        let p = t.map(|v| pos[v as usize]);
        let n = triangle_area_normal(p);
        let area = 0.5 * n.length();
        let unit = n.normalize_or_zero();
        let plane = Quadric::plane(unit, p[0], area);
        for (k, &v) in t.iter().enumerate() {
            quadric[v as usize].add(&plane);
            if topo.twin[3 * f + k] == NONE {
                let (a, b) = (p[k], p[(k + 1) % 3]);
                let side = (b - a).cross(unit).normalize_or_zero();
                let weight = opts.boundary_weight * (b - a).length_squared();
                let constraint = Quadric::plane(side, a, weight);
                quadric[v as usize].add(&constraint);
                quadric[t[(k + 1) % 3] as usize].add(&constraint);
            }
        }
    }
    quadric
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn three_planes_meet_at_their_corner() {
        let corner = DVec3::new(0.3, -0.2, 0.7);
        let mut q = Quadric::default();
        for n in [DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 1.0).normalize()] {
            q.add(&Quadric::plane(n, corner, 2.0));
        }
        let x = q
            .minimiser(DVec3::ZERO, 10.0)
            .expect("three independent planes");
        assert!((x - corner).length() < 1e-12);
        assert!(q.error(corner) < 1e-24);
        // One unit along x: 1 from the x plane, 1/sqrt(3) from the diagonal one.
        assert!((q.error(corner + DVec3::X) - (2.0 + 2.0 / 3.0)).abs() < 1e-12);
    }

    #[test]
    fn one_plane_is_singular_and_the_segment_falls_back() {
        let q = Quadric::plane(DVec3::Z, DVec3::ZERO, 1.0);
        assert!(q.minimiser(DVec3::ZERO, 1.0).is_none());
        let x = q.segment_minimiser(DVec3::new(0.0, 0.0, 1.0), DVec3::new(0.0, 0.0, -3.0));
        assert!(x.z.abs() < 1e-12, "{x}");
    }
}
