//! The paper's B-patch and DMS cases, shared by `paper_table` and `bpatch_dms_bench` (not an
//! example of its own: cargo only takes `examples/*.rs` and `examples/*/main.rs`).
//!
//! Surface (the Bezier rows' one): over the reference triangle (u, v >= 0, u + v <= 1),
//!   S(u, v) = (u + v / 2,  v sqrt(3) / 2,  0.12 sin(2 pi u) cos(pi v) + 0.08 (u^2 + v^2)),
//! whose domain plane (the first two coordinates) is the equilateral triangle of side 1.
//!
//! - B-patch, degree 3 (the paper: 91 points, 144 faces, 2 inverse levels, 10 controls):
//!   the lattice of 12 segments a side (91 points, 144 triangles) sampled from S; two levels
//!   of exact inverse Loop give the 3-segment net, read as a Bezier net and converted to the
//!   B-patch's controls (same surface, `BPatch::controls_from_bezier`). Knots by the
//!   outward rule with spread 0.5. The PIA update is that conversion applied to the inverse
//!   Loop of the residuals (the paper's `P += R(eps)` in the B-patch's coordinates).
//! - DMS, degree 2 (the paper: 453 points, result 13 faces): 453 scattered points (Halton
//!   bases 2 and 3, folded into the triangle) sampled from S; the domain is the 3-segment
//!   lattice of the equilateral triangle with its two lower "down" triangles split at their
//!   centroids: 12 vertices, 13 triangles, 78 controls. Knots by `KnotRule::default()`.
//!   Start: the affine least-squares net; PIA: the column-average update.

#![allow(dead_code)]

use glam::{DVec2, DVec3};
use trispline::mesh::detect::Hierarchy;
use trispline::mesh::inverse::{coarsen, composed_exact_inverse, InverseMethod};
use trispline::mesh::loop_subdiv::SparseOperator;
use trispline::mesh::topology::Topology;
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::surface::bpatch::BPatch;
use trispline::surface::dms::{DmsSpline, KnotRule, PlanarSurface};
use trispline::surface::SurfaceParam;
use trispline::TriMesh;

pub fn surface(u: f64, v: f64) -> DVec3 {
    let pi = std::f64::consts::PI;
    DVec3::new(
        u + v / 2.0,
        v * 3f64.sqrt() / 2.0,
        0.12 * (2.0 * pi * u).sin() * (pi * v).cos() + 0.08 * (u * u + v * v),
    )
}

/// The domain plane point of reference coordinates (u, v).
pub fn plane(u: f64, v: f64) -> DVec2 {
    DVec2::new(u + v / 2.0, v * 3f64.sqrt() / 2.0)
}

pub struct BPatchCase {
    pub patch: BPatch,
    pub params: Vec<SurfaceParam>,
    pub data: Vec<DVec3>,
    /// The inverse-Loop net, as Bezier controls.
    pub bezier_net: Vec<DVec3>,
    /// The same surface in the B-patch's controls.
    pub start: Vec<DVec3>,
    pub inverse: SparseOperator,
}

impl BPatchCase {
    pub fn new(spread: f64) -> Self {
        let (fine_n, levels) = (12, 2);
        let points = lattice_points(fine_n);
        let uv: Vec<(f64, f64)> = points
            .iter()
            .map(|&(i, j)| (i as f64 / fine_n as f64, j as f64 / fine_n as f64))
            .collect();
        let data: Vec<DVec3> = uv.iter().map(|&(u, v)| surface(u, v)).collect();
        let mesh = TriMesh::new(data.clone(), lattice_triangles(fine_n));
        let topo = Topology::from_mesh(&mesh).expect("the lattice is manifold");
        let (hierarchy, _) = Hierarchy::detect(&topo, levels);
        assert_eq!(hierarchy.depth(), levels, "the lattice is a subdivision");
        let bezier_net = coarsen(&mesh, levels, InverseMethod::Exact)
            .expect("subdivided")
            .mesh
            .positions;
        let inverse = composed_exact_inverse(&topo, &hierarchy).expect("manifold");
        let domain = [plane(1.0, 0.0), plane(0.0, 1.0), plane(0.0, 0.0)];
        let patch = BPatch::outward(fine_n >> levels, domain, spread).expect("valid knots");
        let start = patch.controls_from_bezier(&bezier_net);
        let params = uv
            .iter()
            .map(|&(u, v)| SurfaceParam { face: 0, u, v })
            .collect();
        Self {
            patch,
            params,
            data,
            bezier_net,
            start,
            inverse,
        }
    }

    /// The paper's PIA update in this patch's controls.
    pub fn pia_update(&self, residuals: &[DVec3]) -> Vec<DVec3> {
        self.patch
            .controls_from_bezier(&self.inverse.apply(residuals))
    }
}

fn halton(mut i: usize, base: usize) -> f64 {
    let (mut f, mut r) = (1.0, 0.0);
    while i > 0 {
        f /= base as f64;
        r += f * (i % base) as f64;
        i /= base;
    }
    r
}

/// `count` quasi-random reference coordinates in the triangle.
pub fn scattered_uv(count: usize) -> Vec<(f64, f64)> {
    (1..=count)
        .map(|i| {
            let (u, v) = (halton(i, 2), halton(i, 3));
            if u + v > 1.0 {
                (1.0 - u, 1.0 - v)
            } else {
                (u, v)
            }
        })
        .collect()
}

/// The 13-triangle domain (module docs) over the equilateral triangle.
pub fn paper_domain() -> (Vec<DVec2>, Vec<[u32; 3]>) {
    let n = 3;
    let mut vertices: Vec<DVec2> = lattice_points(n)
        .into_iter()
        .map(|(i, j)| plane(i as f64 / n as f64, j as f64 / n as f64))
        .collect();
    let mut triangles = Vec::new();
    for (k, t) in lattice_triangles(n).into_iter().enumerate() {
        // The two "down" triangles of the bottom row: indices 1 and 3.
        if k == 1 || k == 3 {
            let centroid = t.iter().map(|&v| vertices[v as usize]).sum::<DVec2>() / 3.0;
            let c = vertices.len() as u32;
            vertices.push(centroid);
            triangles.extend([[t[0], t[1], c], [t[1], t[2], c], [t[2], t[0], c]]);
        } else {
            triangles.push(t);
        }
    }
    (vertices, triangles)
}

/// A `segments`-lattice domain over the equilateral triangle.
pub fn lattice_domain(segments: usize) -> (Vec<DVec2>, Vec<[u32; 3]>) {
    let vertices = lattice_points(segments)
        .into_iter()
        .map(|(i, j)| plane(i as f64 / segments as f64, j as f64 / segments as f64))
        .collect();
    (vertices, lattice_triangles(segments))
}

pub struct DmsCase {
    pub spline: DmsSpline,
    pub params: Vec<SurfaceParam>,
    pub data: Vec<DVec3>,
}

impl DmsCase {
    pub fn new(domain: (Vec<DVec2>, Vec<[u32; 3]>), degree: usize, points: usize) -> Self {
        let spline =
            DmsSpline::new(domain.0, domain.1, degree, KnotRule::default()).expect("valid knots");
        let uv = scattered_uv(points);
        let params = uv
            .iter()
            .map(|&(u, v)| spline.locate(plane(u, v)).expect("inside the domain"))
            .collect();
        let data = uv.iter().map(|&(u, v)| surface(u, v)).collect();
        Self {
            spline,
            params,
            data,
        }
    }

    /// The paper's DMS case.
    pub fn paper() -> Self {
        Self::new(paper_domain(), 2, 453)
    }
}
