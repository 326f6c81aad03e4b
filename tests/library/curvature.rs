//! Curvature against closed forms, on analytic surfaces (through the derivative
//! interface), on a B-spline and a triangular Bezier patch that reproduce a quadric
//! exactly, and region counts on a surface with known regions.

use trispline::bspline::basis::ParamMethod;
use trispline::bspline::fit::{interpolate_grid, Grid};
use trispline::bspline::BSplineSurface;
use trispline::curvature::regions::{analyze, AnalysisOptions};
use trispline::curvature::{
    classify, curvature, BezierPatch, DerivativeSurface, Domain, RegionKind, Triangular,
    ZeroTolerance,
};
use trispline::surface::bezier::{lattice_points, BezierTriangle};
use trispline::surface::Derivatives;
use trispline::DVec3;

struct Sphere(f64);
impl DerivativeSurface for Sphere {
    fn domain(&self) -> Domain {
        Domain::Rectangle {
            u: (0.0, 6.0),
            v: (-1.5, 1.5),
        }
    }
    fn derivatives(&self, u: f64, v: f64) -> Derivatives {
        let r = self.0;
        let (su, cu, sv, cv) = (u.sin(), u.cos(), v.sin(), v.cos());
        Derivatives {
            position: DVec3::new(cu * cv, su * cv, sv) * r,
            du: DVec3::new(-su * cv, cu * cv, 0.0) * r,
            dv: DVec3::new(-cu * sv, -su * sv, cv) * r,
            duu: DVec3::new(-cu * cv, -su * cv, 0.0) * r,
            duv: DVec3::new(su * sv, -cu * sv, 0.0) * r,
            dvv: DVec3::new(-cu * cv, -su * cv, -sv) * r,
        }
    }
}

struct Cylinder(f64);
impl DerivativeSurface for Cylinder {
    fn domain(&self) -> Domain {
        Domain::Rectangle {
            u: (0.0, 6.0),
            v: (0.0, 2.0),
        }
    }
    fn derivatives(&self, u: f64, v: f64) -> Derivatives {
        let r = self.0;
        Derivatives {
            position: DVec3::new(r * u.cos(), r * u.sin(), v),
            du: DVec3::new(-r * u.sin(), r * u.cos(), 0.0),
            dv: DVec3::Z,
            duu: DVec3::new(-r * u.cos(), -r * u.sin(), 0.0),
            duv: DVec3::ZERO,
            dvv: DVec3::ZERO,
        }
    }
}

/// The graph z = f(x, y) with f and its partials given in closed form.
struct Monge {
    f: fn(f64, f64) -> [f64; 6],
    x: (f64, f64),
    y: (f64, f64),
}
impl DerivativeSurface for Monge {
    fn domain(&self) -> Domain {
        Domain::Rectangle {
            u: self.x,
            v: self.y,
        }
    }
    fn derivatives(&self, x: f64, y: f64) -> Derivatives {
        let [f, fx, fy, fxx, fxy, fyy] = (self.f)(x, y);
        Derivatives {
            position: DVec3::new(x, y, f),
            du: DVec3::new(1.0, 0.0, fx),
            dv: DVec3::new(0.0, 1.0, fy),
            duu: DVec3::new(0.0, 0.0, fxx),
            duv: DVec3::new(0.0, 0.0, fxy),
            dvv: DVec3::new(0.0, 0.0, fyy),
        }
    }
}

fn saddle(x: f64, y: f64) -> [f64; 6] {
    [x * x - y * y, 2.0 * x, -2.0 * y, 2.0, 0.0, -2.0]
}

fn sin_sin(x: f64, y: f64) -> [f64; 6] {
    let (sx, cx, sy, cy) = (x.sin(), x.cos(), y.sin(), y.cos());
    [sx * sy, cx * sy, sx * cy, -sx * sy, cx * cy, -sx * sy]
}

const TOL: ZeroTolerance = ZeroTolerance {
    gaussian: 1e-12,
    mean: 1e-12,
};

#[test]
fn sphere_cylinder_and_saddle_in_closed_form() {
    for r in [0.5, 1.0, 7.25] {
        let s = Sphere(r);
        for &(u, v) in &[(0.3, 0.2), (2.0, -1.1), (4.5, 1.3), (1.0, 0.0)] {
            let c = curvature(&s.derivatives(u, v)).expect("regular");
            assert!(
                (c.gaussian - 1.0 / (r * r)).abs() < 1e-9,
                "K={}",
                c.gaussian
            );
            // Outward normal, the sphere bulges towards it: H = -1/r, convex.
            assert!((c.mean + 1.0 / r).abs() < 1e-9, "H={}", c.mean);
            assert!((c.k_max + 1.0 / r).abs() < 1e-7 && (c.k_min + 1.0 / r).abs() < 1e-7);
            assert_eq!(classify(&c, TOL), RegionKind::Convex);
        }
        let cyl = Cylinder(r);
        for &(u, v) in &[(0.3, 0.2), (2.0, 1.1), (5.9, 1.9)] {
            let c = curvature(&cyl.derivatives(u, v)).expect("regular");
            assert!(c.gaussian.abs() < 1e-9, "K={}", c.gaussian);
            assert!((c.mean.abs() - 0.5 / r).abs() < 1e-9);
            assert!((c.k_max - 0.0).abs() < 1e-9 || (c.k_min - 0.0).abs() < 1e-9);
            assert_eq!(classify(&c, TOL), RegionKind::Convex);
        }
    }
    let m = Monge {
        f: saddle,
        x: (-1.0, 1.0),
        y: (-1.0, 1.0),
    };
    let c = curvature(&m.derivatives(0.0, 0.0)).expect("regular");
    assert!((c.gaussian + 4.0).abs() < 1e-9 && c.mean.abs() < 1e-9);
    assert!((c.k_max - 2.0).abs() < 1e-9 && (c.k_min + 2.0).abs() < 1e-9);
    assert_eq!(classify(&c, TOL), RegionKind::Saddle);
}

/// Biquadratic Bezier (a B-spline without interior knots) with controls at the Greville
/// points of x and y on [-1, 1]: it is z = x^2 - y^2 exactly.
fn saddle_bspline() -> BSplineSurface {
    let k = vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    let xs = [-1.0, 0.0, 1.0];
    // Bernstein coefficients of x^2 for x = 2t - 1: 1, -1, 1.
    let sq = [1.0, -1.0, 1.0];
    let c = (0..9)
        .map(|i| DVec3::new(xs[i / 3], xs[i % 3], sq[i / 3] - sq[i % 3]))
        .collect();
    BSplineSurface::new((2, 2), k.clone(), k, (3, 3), c).expect("valid")
}

#[test]
fn bspline_reproducing_the_saddle_has_its_exact_curvature() {
    let s = saddle_bspline();
    let c = curvature(&DerivativeSurface::derivatives(&s, 0.5, 0.5)).expect("regular");
    assert!((c.gaussian + 4.0).abs() < 1e-9, "K={}", c.gaussian);
    assert!(c.mean.abs() < 1e-9, "H={}", c.mean);
    // Everywhere else: K = -4 / (1 + 4x^2 + 4y^2)^2.
    for &(u, v) in &[(0.1, 0.9), (0.33, 0.71), (1.0, 0.0)] {
        let (x, y) = (2.0 * u - 1.0, 2.0 * v - 1.0);
        let c = curvature(&DerivativeSurface::derivatives(&s, u, v)).expect("regular");
        let k = -4.0 / (1.0 + 4.0 * x * x + 4.0 * y * y).powi(2);
        assert!(
            (c.gaussian - k).abs() < 1e-9,
            "({u},{v}) K={} vs {k}",
            c.gaussian
        );
    }
}

/// Triangular quadratic Bezier patch of z = (x - a)^2 - (y - b)^2 over x = u, y = v:
/// control ordinates are the blossom of the quadratic at the corners.
fn saddle_triangle(a: f64, b: f64, sign: f64) -> Triangular<BezierTriangle> {
    let corner = |i: usize, j: usize| -> [(f64, f64); 2] {
        // i copies of (1, 0), j of (0, 1), the rest (0, 0).
        let mut pts = vec![(1.0, 0.0); i];
        pts.extend(vec![(0.0, 1.0); j]);
        pts.resize(2, (0.0, 0.0));
        [pts[0], pts[1]]
    };
    let controls = lattice_points(2)
        .into_iter()
        .map(|(i, j)| {
            let [(x1, y1), (x2, y2)] = corner(i, j);
            let z = x1 * x2 - a * (x1 + x2) + a * a + sign * (y1 * y2 - b * (y1 + y2) + b * b);
            DVec3::new((x1 + x2) / 2.0, (y1 + y2) / 2.0, z)
        })
        .collect();
    Triangular {
        surface: BezierTriangle::new(2),
        controls,
    }
}

#[test]
fn triangular_bezier_through_the_same_interface() {
    let t = saddle_triangle(0.3, 0.25, -1.0);
    let d = t.derivatives(0.3, 0.25);
    assert!((d.position - DVec3::new(0.3, 0.25, 0.0)).length() < 1e-12);
    let c = curvature(&d).expect("regular");
    assert!((c.gaussian + 4.0).abs() < 1e-9, "K={}", c.gaussian);
    assert!(c.mean.abs() < 1e-9, "H={}", c.mean);
    // Paraboloid: K = 4, H = 2 at its vertex (opens towards the normal: concave).
    let p = saddle_triangle(0.3, 0.25, 1.0);
    let c = curvature(&p.derivatives(0.3, 0.25)).expect("regular");
    assert!((c.gaussian - 4.0).abs() < 1e-9 && (c.mean - 2.0).abs() < 1e-9);
    let a = analyze(
        &p,
        &AnalysisOptions {
            grid: 41,
            ..Default::default()
        },
    );
    assert_eq!(
        (
            a.count(RegionKind::Convex),
            a.count(RegionKind::Concave),
            a.count(RegionKind::Saddle)
        ),
        (0, 1, 0)
    );
    // One region: its single loop is the domain boundary, 3 * 40 lattice edges.
    assert_eq!(a.regions[0].loops.len(), 1);
    assert_eq!(a.regions[0].loops[0].len(), 121);
    let t = analyze(
        &t,
        &AnalysisOptions {
            grid: 41,
            ..Default::default()
        },
    );
    assert_eq!(t.count(RegionKind::Saddle), 1);
    assert_eq!(t.regions.len(), 1);
}

#[test]
fn de_casteljau_patch_equals_the_basis_row_evaluation() {
    for n in [1, 2, 3, 7, 16] {
        let controls: Vec<DVec3> = lattice_points(n)
            .into_iter()
            .map(|(i, j)| {
                let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
                DVec3::new(
                    x + 0.05 * y,
                    y,
                    (4.0 * x).sin() * (3.0 * y).cos() + ((i * 7 + j * 3) % 5) as f64 * 0.03,
                )
            })
            .collect();
        let fast = BezierPatch {
            degree: n,
            controls: controls.clone(),
        };
        let slow = Triangular {
            surface: BezierTriangle::new(n),
            controls,
        };
        let params = [
            (0.2, 0.3),
            (0.0, 0.0),
            (1.0, 0.0),
            (0.0, 1.0),
            (0.05, 0.9),
            (1.0 / 3.0, 1.0 / 3.0),
        ];
        let many = fast.derivatives_at(&params);
        for (&(u, v), m) in params.iter().zip(&many) {
            let (a, b) = (fast.derivatives(u, v), slow.derivatives(u, v));
            let scale = 1.0 + (n * n) as f64;
            for (x, y) in [
                (a.position, b.position),
                (a.du, b.du),
                (a.dv, b.dv),
                (a.duu, b.duu),
                (a.duv, b.duv),
                (a.dvv, b.dvv),
                (m.dvv, b.dvv),
            ] {
                assert!(
                    (x - y).length() < 1e-11 * scale,
                    "n={n} ({u},{v}): {x} vs {y}"
                );
            }
        }
    }
}

/// Shoelace area of a closed (u, v) loop: positive when counter-clockwise.
fn signed_area(l: &[(f64, f64)]) -> f64 {
    l.windows(2)
        .map(|w| w[0].0 * w[1].1 - w[1].0 * w[0].1)
        .sum::<f64>()
        / 2.0
}

/// Region loops partition the domain: outer loops counter-clockwise, holes clockwise, and
/// the signed areas of all loops add up to the domain's area.
fn assert_partition(a: &trispline::curvature::regions::Analysis, domain_area: f64) {
    let mut total = 0.0;
    for r in &a.regions {
        let areas: Vec<f64> = r.param_loops.iter().map(|l| signed_area(l)).collect();
        let region: f64 = areas.iter().sum();
        assert!(region > 0.0, "region {} has area {region}", r.id);
        assert_eq!(
            areas.iter().filter(|&&x| x > 0.0).count(),
            1,
            "one outer loop"
        );
        total += region;
    }
    assert!(
        (total - domain_area).abs() < 1e-9 * domain_area,
        "{total} vs {domain_area}"
    );
}

fn counts(a: &trispline::curvature::regions::Analysis) -> (usize, usize, usize) {
    (
        a.count(RegionKind::Convex),
        a.count(RegionKind::Concave),
        a.count(RegionKind::Saddle),
    )
}

/// z = sin x sin y over [-3, 3] x [0.1, 1.4]: K < 0 where cos(x + y) cos(x - y) > 0. The
/// window holds the zero lines x + y = +-pi/2 and x - y = +-pi/2 but none of their
/// crossings: one convex region (around the peak at (pi/2, pi/2)), one concave (around the
/// pit at (-pi/2, pi/2)) and three saddle regions (around (-pi, 0), (0, 0), (pi, 0)).
#[test]
fn known_regions_of_sin_x_sin_y() {
    let m = Monge {
        f: sin_sin,
        x: (-3.0, 3.0),
        y: (0.1, 1.4),
    };
    for grid in [41, 201] {
        let a = analyze(
            &m,
            &AnalysisOptions {
                grid,
                ..Default::default()
            },
        );
        assert_eq!(counts(&a), (1, 1, 3), "grid {grid}");
        for r in &a.regions {
            assert_eq!(r.loops.len(), 1, "region {} has holes", r.id);
            let l = &r.loops[0];
            assert_eq!(l.first(), l.last(), "closed");
            // Points of the loop inside the domain lie where K changes sign.
            let (dx, dy) = (6.0 / (grid - 1) as f64, 1.3 / (grid - 1) as f64);
            for (p, &(x, y)) in l.iter().zip(&r.param_loops[0]) {
                assert!((p.z - x.sin() * y.sin()).abs() < 1e-12);
                let inside = x > -3.0 + 1e-9 && x < 3.0 - 1e-9 && y > 0.1 + 1e-9 && y < 1.4 - 1e-9;
                if inside {
                    let k = -(x + y).cos() * (x - y).cos();
                    assert!(k.abs() < 2.0 * (dx + dy), "grid {grid}: K~{k} at ({x},{y})");
                }
            }
        }
        let samples: usize = a.regions.iter().map(|r| r.samples).sum();
        assert_eq!(samples, grid * grid);
        assert_partition(&a, 6.0 * 1.3);
    }
    // The same surface as an interpolating bicubic B-spline gives the same partition.
    let (rows, cols) = (121, 41);
    let pts: Vec<DVec3> = (0..rows * cols)
        .map(|k| {
            let x = -3.0 + 6.0 * (k / cols) as f64 / (rows - 1) as f64;
            let y = 0.1 + 1.3 * (k % cols) as f64 / (cols - 1) as f64;
            DVec3::new(x, y, x.sin() * y.sin())
        })
        .collect();
    let grid = Grid {
        rows,
        cols,
        points: &pts,
    };
    let s = interpolate_grid(&grid, (3, 3), ParamMethod::Uniform)
        .expect("fit")
        .surface;
    let a = analyze(
        &s,
        &AnalysisOptions {
            grid: 201,
            ..Default::default()
        },
    );
    assert_eq!(counts(&a), (1, 1, 3));
}

#[test]
fn small_regions_are_merged() {
    // A flat sheet with a tiny dimple a few samples wide: a concave spot, a saddle ring.
    fn dimple(x: f64, y: f64) -> [f64; 6] {
        let s = 0.002;
        let e = (-(x * x + y * y) / s).exp() * 1e-3;
        let (fx, fy) = (-2.0 * x / s * e, -2.0 * y / s * e);
        let fxx = (4.0 * x * x / (s * s) - 2.0 / s) * e;
        let fyy = (4.0 * y * y / (s * s) - 2.0 / s) * e;
        let fxy = 4.0 * x * y / (s * s) * e;
        [e, fx, fy, fxx, fxy, fyy]
    }
    let m = Monge {
        f: dimple,
        x: (-1.0, 1.0),
        y: (-1.0, 1.0),
    };
    let raw = analyze(
        &m,
        &AnalysisOptions {
            grid: 101,
            min_region: 1,
            zero_eps: 1e-6,
        },
    );
    assert!(raw.regions.len() >= 2, "{:?}", counts(&raw));
    // The sheet around the dimple is a region with a hole.
    assert!(raw.regions.iter().any(|r| r.loops.len() >= 2));
    assert_partition(&raw, 4.0);
    let cleaned = analyze(
        &m,
        &AnalysisOptions {
            grid: 101,
            min_region: 200,
            zero_eps: 1e-6,
        },
    );
    assert_eq!(cleaned.regions.len(), 1, "{:?}", counts(&cleaned));
}

// ---- Loop limit surface of an arbitrary control mesh (surface.json layout `mesh`) ----

use std::sync::Arc;
use trispline::curvature::LoopMeshPatch;
use trispline::surface::loop_limit::LoopLimitSurface;

fn mesh_patch(controls: Vec<DVec3>, faces: &[[u32; 3]]) -> LoopMeshPatch {
    let surface = LoopLimitSurface::new(controls.len(), faces).expect("manifold net");
    LoopMeshPatch::new(Arc::new(surface), controls)
}

/// The octahedron of radius 1, faces oriented outwards (valence 4 everywhere).
fn octahedron_patch() -> LoopMeshPatch {
    let controls = vec![
        DVec3::X,
        DVec3::Y,
        -DVec3::X,
        -DVec3::Y,
        DVec3::Z,
        -DVec3::Z,
    ];
    let mut faces = Vec::new();
    for i in 0..4u32 {
        faces.push([i, (i + 1) % 4, 4]);
        faces.push([(i + 1) % 4, i, 5]);
    }
    mesh_patch(controls, &faces)
}

/// An open disc of five lattice sectors of `r` segments around a centre of valence 5
/// (control 0), lifted by z = x^2 - y^2.
fn pentagonal_saddle(r: usize) -> LoopMeshPatch {
    let corner = |s: usize| {
        let a = std::f64::consts::TAU * (s % 5) as f64 / 5.0;
        DVec3::new(a.cos(), a.sin(), 0.0)
    };
    // Control id of ring q (0 at the centre), position p along it (5 q per ring).
    let id = |q: usize, p: usize| {
        if q == 0 {
            0
        } else {
            (1 + 5 * q * (q - 1) / 2 + p % (5 * q)) as u32
        }
    };
    let mut controls = vec![DVec3::ZERO; 1 + 5 * r * (r + 1) / 2];
    let mut faces = Vec::new();
    for s in 0..5 {
        let sector_id = |(i, j): (usize, usize)| id(i + j, s * (i + j) + j);
        for (i, j) in lattice_points(r) {
            let p = (corner(s) * i as f64 + corner(s + 1) * j as f64) / r as f64;
            controls[sector_id((i, j)) as usize] = DVec3::new(p.x, p.y, p.x * p.x - p.y * p.y);
        }
        let pts = lattice_points(r);
        for t in trispline::surface::bezier::lattice_triangles(r) {
            faces.push(t.map(|k| sector_id(pts[k as usize])));
        }
    }
    mesh_patch(controls, &faces)
}

#[test]
fn loop_mesh_lattice_welds_shared_samples() {
    let p = octahedron_patch();
    let m = 5;
    let own = p.lattice_with_segments(m);
    let (v, e, f) = (6, 12, 8);
    // One sample per control vertex, m - 1 per control edge, the rest inside faces.
    assert_eq!(
        own.params.len(),
        v + e * (m - 1) + f * (m - 1) * (m - 2) / 2
    );
    assert_eq!(own.triangles.len(), f * m * m);
    let lattice = trispline::curvature::regions::Lattice::for_surface(&p, 12);
    assert!(lattice.boundary.is_empty(), "a closed net has no boundary");
    // Every welded sample's position agrees with its position in each triangle's chart.
    let charts = own.charts.as_ref().expect("per-face charts");
    for (t, ch) in own.triangles.iter().zip(charts) {
        for (&s, &(a, b)) in t.iter().zip(ch) {
            let (x, y) = own.params[s as usize];
            let d = p.derivatives(x, y).position - p.derivatives(a, b).position;
            assert!(d.length() < 1e-12, "sample {s}: {d}");
        }
    }
}

#[test]
fn loop_limit_of_an_octahedron_is_one_convex_region() {
    let p = octahedron_patch();
    let a = analyze(
        &p,
        &AnalysisOptions {
            grid: 40,
            ..Default::default()
        },
    );
    assert!(a.lattice.boundary.is_empty());
    for (k, c) in a.curvature.iter().enumerate() {
        let c = c.unwrap_or_else(|| panic!("sample {k} singular"));
        assert!(c.gaussian > 0.0, "sample {k}: K = {}", c.gaussian);
        // Outward faces: the cap bulges towards the normal.
        assert!(c.mean < 0.0, "sample {k}: H = {}", c.mean);
    }
    assert!(a.kinds.iter().all(|&k| k == RegionKind::Convex));
    assert_eq!(a.regions.len(), 1);
    assert!(a.regions[0].loops.is_empty(), "{:?}", a.regions[0].loops);
}

#[test]
fn loop_limit_of_a_saddle_net_is_a_saddle_at_the_centre() {
    let r = 4;
    let p = pentagonal_saddle(r);
    let a = analyze(
        &p,
        &AnalysisOptions {
            grid: 60,
            ..Default::default()
        },
    );
    // The open net's boundary: its 5 r control boundary edges, each cut into m segments.
    let faces = p.surface.faces().len();
    let m = ((60.0 / (faces as f64).sqrt()).ceil() as usize).max(2);
    assert_eq!(a.lattice.boundary.len(), 5 * r * m);
    // The sample on the centre control vertex (welded: exactly one) and its neighbours.
    let (f, c) = p
        .surface
        .faces()
        .iter()
        .enumerate()
        .find_map(|(f, t)| t.iter().position(|&x| x == 0).map(|c| (f, c)))
        .expect("the centre is used");
    let centre = p.derivatives_in_face(f, f64::from(c == 0), f64::from(c == 1));
    let nearest: Vec<usize> = (0..a.positions.len())
        .filter(|&k| (a.positions[k] - centre.position).length() < 0.5 / r as f64)
        .collect();
    assert!(
        nearest.len() > 10,
        "{} samples near the centre",
        nearest.len()
    );
    for &k in &nearest {
        assert_eq!(a.kinds[k], RegionKind::Saddle, "sample {k}");
    }
    let centre_region = a.region[nearest[0]];
    assert_eq!(a.regions[centre_region as usize].kind, RegionKind::Saddle);
    // Off the extraordinary vertex itself, K < 0 outright.
    let strict = nearest
        .iter()
        .filter(|&&k| (a.positions[k] - centre.position).length() > 1e-9)
        .filter(|&&k| a.curvature[k].is_some_and(|c| c.gaussian < 0.0))
        .count();
    assert!(strict + 1 >= nearest.len(), "{strict} of {}", nearest.len());
}

#[test]
fn loop_mesh_curvature_agrees_across_shared_edges() {
    for p in [octahedron_patch(), pentagonal_saddle(3)] {
        let faces = p.surface.faces();
        let mut owners: std::collections::HashMap<(u32, u32), Vec<usize>> = Default::default();
        for (f, t) in faces.iter().enumerate() {
            for c in 0..3 {
                let (a, b) = (t[c], t[(c + 1) % 3]);
                owners.entry((a.min(b), a.max(b))).or_default().push(f);
            }
        }
        // (u, v) in face f of the point with weight `alpha` on control a, 1 - alpha on b.
        let local = |f: usize, a: u32, b: u32, alpha: f64| {
            let mut w = [0.0; 3];
            for (c, &x) in faces[f].iter().enumerate() {
                if x == a {
                    w[c] = alpha;
                } else if x == b {
                    w[c] = 1.0 - alpha;
                }
            }
            (w[0], w[1])
        };
        let mut checked = 0;
        for (&(a, b), fs) in &owners {
            let [f, g] = fs[..] else { continue };
            for k in 1..8 {
                let alpha = k as f64 / 8.0;
                let (u0, v0) = local(f, a, b, alpha);
                let (u1, v1) = local(g, a, b, alpha);
                let d0 = p.derivatives_in_face(f, u0, v0);
                let d1 = p.derivatives_in_face(g, u1, v1);
                assert!((d0.position - d1.position).length() < 1e-12);
                let (c0, c1) = (
                    curvature(&d0).expect("regular"),
                    curvature(&d1).expect("regular"),
                );
                let scale = c0.gaussian.abs().max(c1.gaussian.abs()).max(1e-12);
                assert!(
                    (c0.gaussian - c1.gaussian).abs() <= 1e-6 * scale,
                    "edge ({a}, {b}) at {alpha}: K {} vs {}",
                    c0.gaussian,
                    c1.gaussian
                );
                assert!((c0.mean - c1.mean).abs() <= 1e-6 * c0.mean.abs().max(1e-12));
                checked += 1;
            }
        }
        assert!(checked > 50, "{checked} edge points");
    }
}
