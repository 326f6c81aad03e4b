//! B-patches and DMS triangular B-splines: equivalences, basis properties, derivatives,
//! polynomial reproduction, and fits through the engine.

use glam::{DVec2, DVec3};
use trispline::fit::{fit, Budget, Collocation, FitProblem, Method};
use trispline::scattered_fit::{collocation_matrix, fit_scattered, ScatteredOptions};
use trispline::surface::bezier::{lattice_points, BezierTriangle};
use trispline::surface::bpatch::{bezier_blossom, de_boor, BPatch};
use trispline::surface::dms::{DmsError, DmsSpline, KnotRule, PlanarSurface};
use trispline::surface::{SurfaceParam, TriSurface};

/// xorshift64*: deterministic pseudo-random numbers in [0, 1).
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    pub(crate) fn param(&mut self, faces: usize) -> SurfaceParam {
        let face = ((self.next() * faces as f64) as u32).min(faces as u32 - 1);
        let (mut u, mut v) = (self.next(), self.next());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        SurfaceParam { face, u, v }
    }
}

fn domain_triangle() -> [DVec2; 3] {
    [
        DVec2::new(0.1, -0.2),
        DVec2::new(1.3, 0.1),
        DVec2::new(0.4, 1.1),
    ]
}

fn wavy_controls(n: usize) -> Vec<DVec3> {
    lattice_points(n)
        .into_iter()
        .map(|(i, j)| {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            DVec3::new(
                x + 0.1 * y,
                y,
                (3.0 * x).sin() * (2.0 * y).cos() + 0.05 * ((i * 7 + j * 3) % 4) as f64,
            )
        })
        .collect()
}

fn close(a: DVec3, b: DVec3, tol: f64) -> bool {
    (a - b).length() <= tol * b.length().max(1.0)
}

#[test]
fn bpatch_with_corner_knots_is_the_bezier_patch() {
    for n in [1, 2, 3, 5, 8] {
        let dom = domain_triangle();
        let knots = dom.map(|c| vec![c; n]);
        let bp = BPatch::new(n, dom, knots).expect("valid");
        let bz = BezierTriangle::new(n);
        let c = wavy_controls(n);
        let mut rng = Rng(7 + n as u64);
        for _ in 0..20 {
            let p = rng.param(1);
            let (a, b) = (bp.evaluate(&c, p), bz.evaluate(&c, p));
            for (x, y) in [
                (a.position, b.position),
                (a.du, b.du),
                (a.dv, b.dv),
                (a.duu, b.duu),
                (a.duv, b.duv),
                (a.dvv, b.dvv),
            ] {
                assert!(close(x, y, 1e-12), "n={n}: {x} vs {y}");
            }
        }
    }
}

#[test]
fn bpatch_with_outward_knots_represents_the_same_polynomial() {
    for n in [2, 3, 6] {
        let dom = domain_triangle();
        let bp = BPatch::outward(n, dom, 0.5).expect("valid");
        let bezier = wavy_controls(n);
        let controls = bp.controls_from_bezier(&bezier);
        let bz = BezierTriangle::new(n);
        let mut rng = Rng(11);
        let mut row = Vec::new();
        for _ in 0..20 {
            let p = rng.param(1);
            let want = bz.evaluate(&bezier, p);
            let got = bp.evaluate(&controls, p);
            assert!(close(got.position, want.position, 1e-11), "n={n}");
            assert!(close(got.du, want.du, 1e-10) && close(got.dvv, want.dvv, 1e-9));
            // Seidel's recursion on the points themselves: an independent code path.
            let reference = de_boor(&bp, &controls, p.u, p.v);
            assert!(close(got.position, reference, 1e-12));
            bp.basis_row(p, &mut row);
            let sum: f64 = row.iter().map(|r| r.1).sum();
            assert!((sum - 1.0).abs() < 1e-13);
            assert!(
                row.iter().all(|r| r.1 >= 0.0),
                "outward knots keep the basis non-negative"
            );
        }
    }
}

fn finite_difference_check(
    surface: &dyn TriSurface,
    controls: &[DVec3],
    p: SurfaceParam,
    h: f64,
    tol: f64,
) {
    let at = |u: f64, v: f64| surface.evaluate(controls, SurfaceParam { u, v, ..p });
    let d = at(p.u, p.v);
    let fd = |f: &dyn Fn(f64, f64) -> DVec3, du: f64, dv: f64| {
        (f(p.u + du, p.v + dv) - f(p.u - du, p.v - dv)) / (2.0 * h)
    };
    let pos = |u, v| at(u, v).position;
    let du = |u, v| at(u, v).du;
    let dv = |u, v| at(u, v).dv;
    for (name, a, b) in [
        ("du", d.du, fd(&pos, h, 0.0)),
        ("dv", d.dv, fd(&pos, 0.0, h)),
        ("duu", d.duu, fd(&du, h, 0.0)),
        ("duv", d.duv, fd(&du, 0.0, h)),
        ("dvv", d.dvv, fd(&dv, 0.0, h)),
    ] {
        assert!(
            (a - b).length() <= tol * b.length().max(1.0),
            "{name} at {p:?}: {a} vs {b}"
        );
    }
}

#[test]
fn bpatch_derivatives_match_finite_differences() {
    let bp = BPatch::outward(4, domain_triangle(), 0.7).expect("valid");
    let c = wavy_controls(4);
    let mut rng = Rng(3);
    for _ in 0..10 {
        let mut p = rng.param(1);
        p.u = 0.05 + 0.8 * p.u;
        p.v = 0.05 + 0.8 * p.v;
        finite_difference_check(&bp, &c, p, 1e-5, 1e-6);
    }
}

/// An L-shaped domain (a 3x3 grid of jittered squares without its top-right one): interior
/// vertices, a reflex boundary vertex, and both diagonal directions.
fn l_domain() -> (Vec<DVec2>, Vec<[u32; 3]>) {
    let mut rng = Rng(99);
    let mut vertices = Vec::new();
    for j in 0..4 {
        for i in 0..4 {
            let interior = (1..3).contains(&i) && (1..3).contains(&j);
            let jitter = if interior { 0.15 } else { 0.0 };
            vertices.push(DVec2::new(
                i as f64 + jitter * (rng.next() - 0.5),
                j as f64 + jitter * (rng.next() - 0.5),
            ));
        }
    }
    let id = |i: u32, j: u32| j * 4 + i;
    let mut triangles = Vec::new();
    for j in 0..3 {
        for i in 0..3 {
            if (i, j) == (2, 2) {
                continue;
            }
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if (i + j) % 2 == 0 {
                triangles.push([a, b, c]);
                triangles.push([a, c, d]);
            } else {
                triangles.push([a, b, d]);
                triangles.push([b, c, d]);
            }
        }
    }
    (vertices, triangles)
}

/// Random clouds (radius up to a quarter of the unit edge), redrawn per vertex until the
/// spline accepts them.
pub(crate) fn random_dms(degree: usize, seed: u64) -> DmsSpline {
    let (vertices, triangles) = l_domain();
    let mut rng = Rng(seed);
    let draw = |rng: &mut Rng, v: DVec2| -> Vec<DVec2> {
        std::iter::once(v)
            .chain((0..degree).map(|_| {
                let phi = rng.next() * std::f64::consts::TAU;
                v + DVec2::new(phi.cos(), phi.sin()) * (0.05 + 0.2 * rng.next())
            }))
            .collect()
    };
    let mut clouds: Vec<Vec<DVec2>> = vertices.iter().map(|&v| draw(&mut rng, v)).collect();
    for _ in 0..10_000 {
        match DmsSpline::with_clouds(vertices.clone(), triangles.clone(), degree, clouds.clone()) {
            Ok(s) => return s,
            Err(DmsError::BoundaryKnotInside(v)) => {
                clouds[v as usize] = draw(&mut rng, vertices[v as usize]);
            }
            Err(DmsError::KnotTriangle { triangle, .. }) => {
                for &v in &triangles[triangle as usize] {
                    clouds[v as usize] = draw(&mut rng, vertices[v as usize]);
                }
            }
            Err(e) => panic!("unexpected: {e}"),
        }
    }
    panic!("no random clouds accepted");
}

/// Parameters at random, plus every face's corners, edge midpoints and an edge point.
pub(crate) fn test_params(faces: usize, rng: &mut Rng, count: usize) -> Vec<SurfaceParam> {
    let mut params: Vec<SurfaceParam> = (0..count).map(|_| rng.param(faces)).collect();
    for face in 0..faces as u32 {
        for (u, v) in [
            (1.0, 0.0),
            (0.0, 1.0),
            (0.0, 0.0),
            (0.5, 0.5),
            (0.0, 0.5),
            (0.3, 0.0),
        ] {
            params.push(SurfaceParam { face, u, v });
        }
    }
    params
}

#[test]
fn dms_basis_is_a_non_negative_partition_of_unity_on_random_clouds() {
    for degree in 1..=3 {
        for seed in [1, 2, 3] {
            let s = random_dms(degree, seed * 31 + degree as u64);
            let mut rng = Rng(seed + 100);
            let mut row = Vec::new();
            for p in test_params(s.domain_face_count(), &mut rng, 300) {
                s.basis_row(p, &mut row);
                let sum: f64 = row.iter().map(|r| r.1).sum();
                assert!(
                    (sum - 1.0).abs() < 1e-10,
                    "degree {degree} seed {seed} {p:?}: sum {sum}"
                );
                // Exact zeros where the recurrence multiplies by vanishing indicators come
                // out of a cell's polynomial (the evaluation path) as cancellations of its
                // coefficients (measured down to -1.07e-11 at a knot): zero within the sum's
                // 1e-10.
                let low = row.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
                assert!(low >= -1e-10, "negative basis value {low:e} at {p:?}");
            }
        }
    }
}

#[test]
fn dms_knot_rule_keeps_the_conditions_and_the_partition() {
    let (vertices, triangles) = l_domain();
    for degree in 1..=3 {
        let s = DmsSpline::new(
            vertices.clone(),
            triangles.clone(),
            degree,
            KnotRule::default(),
        )
        .expect("rule keeps the DMS conditions");
        let mut rng = Rng(5);
        let mut row = Vec::new();
        for p in test_params(s.domain_face_count(), &mut rng, 200) {
            s.basis_row(p, &mut row);
            let sum: f64 = row.iter().map(|r| r.1).sum();
            assert!((sum - 1.0).abs() < 1e-10, "degree {degree}: sum {sum}");
        }
        // The parameter round trip through the domain.
        for p in test_params(s.domain_face_count(), &mut rng, 50) {
            let x = s.domain_point(p);
            let q = s.locate(x).expect("in the domain");
            assert!(s.domain_point(q).distance(x) < 1e-12);
        }
    }
}

#[test]
fn dms_derivatives_match_finite_differences() {
    for degree in [2, 3] {
        let s = random_dms(degree, 77 + degree as u64);
        let c: Vec<DVec3> = (0..s.control_count())
            .map(|i| {
                let t = i as f64;
                DVec3::new((t * 0.37).sin(), (t * 0.11).cos(), (t * 0.23).sin() * 0.5)
            })
            .collect();
        let mut rng = Rng(8);
        for _ in 0..30 {
            let mut p = rng.param(s.domain_face_count());
            p.u = 0.1 + 0.7 * p.u;
            p.v = 0.1 + 0.7 * p.v;
            // Second derivatives of degree 2 jump across knot lines; a 1e-6 step crosses one
            // only by rare chance (the seed is fixed).
            finite_difference_check(&s, &c, p, 1e-6, 2e-5);
        }
    }
}

/// A surface evaluation's six vectors, for comparing bit for bit.
fn parts(d: &trispline::surface::Derivatives) -> [DVec3; 6] {
    [d.position, d.du, d.dv, d.duu, d.duv, d.dvv]
}

/// The evaluator for one control set (degree <= 2: the triangles' shares of the surface
/// frozen per kept cell) equals `evaluate` up to rounding, and gives the same bits whether
/// the cells it meets were kept before it was made or not.
#[test]
fn dms_evaluator_matches_evaluate_whichever_cells_are_kept() {
    for degree in 1..=3 {
        let s = random_dms(degree, 900 + degree as u64);
        let c: Vec<DVec3> = (0..s.control_count())
            .map(|i| {
                let t = i as f64;
                DVec3::new((t * 0.29).sin(), (t * 0.17).cos(), (t * 0.41).sin() * 0.5)
            })
            .collect();
        let mut rng = Rng(31 + degree as u64);
        let params = test_params(s.domain_face_count(), &mut rng, 400);
        // A fresh spline keeps no cells: the first evaluator freezes none.
        let first: Vec<[DVec3; 6]> = {
            let cold = s.evaluator(&c);
            params.iter().map(|p| parts(&cold(*p))).collect()
        };
        let warm = s.evaluator(&c);
        for (p, want) in params.iter().zip(&first) {
            let got = parts(&warm(*p));
            assert_eq!(
                &got, want,
                "degree {degree} at {p:?}: frozen cells changed bits"
            );
            let reference = parts(&s.evaluate(&c, *p));
            for (g, r) in got.iter().zip(&reference) {
                assert!(
                    (*g - *r).length() <= 1e-9 * (1.0 + r.length()),
                    "degree {degree} at {p:?}: {g} vs {r}"
                );
            }
        }
    }
}

/// A polynomial of degree n over a reference triangle, in Bezier form.
fn polynomial(n: usize) -> ([DVec2; 3], Vec<DVec3>) {
    let reference = [
        DVec2::new(0.0, 0.0),
        DVec2::new(3.0, 0.0),
        DVec2::new(0.0, 3.0),
    ];
    let mut rng = Rng(2024 + n as u64);
    let controls = lattice_points(n)
        .into_iter()
        .map(|_| DVec3::new(rng.next(), rng.next(), rng.next()) * 2.0 - 1.0)
        .collect();
    (reference, controls)
}

fn dms_blossom_controls(s: &DmsSpline, reference: [DVec2; 3], poly: &[DVec3]) -> Vec<DVec3> {
    let n = s.degree();
    let mut controls = vec![DVec3::ZERO; s.control_count()];
    for (t, tri) in s.triangles().iter().enumerate() {
        let [a, b, c] = tri.map(|v| &s.knot_clouds()[v as usize]);
        for (i, j) in lattice_points(n) {
            let k = n - i - j;
            let args: Vec<DVec2> = a[..i]
                .iter()
                .chain(&b[..j])
                .chain(&c[..k])
                .copied()
                .collect();
            controls[s.control_index(t, i, j)] = bezier_blossom(n, reference, poly, &args);
        }
    }
    controls
}

#[test]
fn dms_reproduces_polynomials_of_its_degree_from_blossoms() {
    for degree in 1..=3 {
        let s = random_dms(degree, 500 + degree as u64);
        let (reference, poly) = polynomial(degree);
        let controls = dms_blossom_controls(&s, reference, &poly);
        let mut rng = Rng(9);
        for p in test_params(s.domain_face_count(), &mut rng, 200) {
            let x = s.domain_point(p);
            let want = bezier_blossom(degree, reference, &poly, &vec![x; degree]);
            let got = s.evaluate(&controls, p).position;
            assert!(
                close(got, want, 1e-10),
                "degree {degree} at {x}: {got} vs {want}"
            );
        }
    }
}

fn samples(
    s: &dyn PlanarSurface,
    count: usize,
    seed: u64,
    f: impl Fn(DVec2) -> DVec3,
) -> (Vec<SurfaceParam>, Vec<DVec3>) {
    let mut rng = Rng(seed);
    let params: Vec<SurfaceParam> = (0..count)
        .map(|_| rng.param(s.domain_face_count()))
        .collect();
    let data = params.iter().map(|p| f(s.domain_point(*p))).collect();
    (params, data)
}

#[test]
fn dms_least_squares_fit_reproduces_a_polynomial_exactly() {
    for degree in [2, 3] {
        let (vertices, triangles) = l_domain();
        let s = DmsSpline::new(vertices, triangles, degree, KnotRule::default()).expect("valid");
        let (reference, poly) = polynomial(degree);
        let (params, data) = samples(&s, 4000, 12, |x| {
            bezier_blossom(degree, reference, &poly, &vec![x; degree])
        });
        let options = ScatteredOptions {
            method: Method::Direct,
            ..ScatteredOptions::default()
        };
        let out = fit_scattered(&s, &params, &data, &options, None).expect("fit");
        let last = out.rounds[0].steps.last().expect("steps");
        assert!(
            last.max_error < 1e-9,
            "degree {degree}: max residual {}",
            last.max_error
        );
    }
}

fn wavy(x: DVec2) -> DVec3 {
    DVec3::new(
        x.x,
        x.y,
        0.3 * (2.0 * x.x).sin() * (1.5 * x.y).cos() + 0.1 * x.x * x.y,
    )
}

#[test]
fn bpatch_direct_fit_reaches_the_bezier_least_squares_optimum() {
    let dom = domain_triangle();
    for n in [3, 5] {
        let bp = BPatch::outward(n, dom, 0.5).expect("valid");
        let (params, data) = samples(&bp, 400, 4, wavy);
        let direct = ScatteredOptions {
            method: Method::Direct,
            ..ScatteredOptions::default()
        };
        let b_fit = fit_scattered(&bp, &params, &data, &direct, None).expect("bpatch fit");
        let bz = BezierTriangle::new(n);
        let basis = Collocation::new(collocation_matrix(&bz, &params));
        let problem = FitProblem {
            basis: &basis,
            data: &data,
            smoothing: 0.0,
            fairness: None,
            pia_operator: None,
            on_step: None,
        };
        let z_fit = fit(
            &problem,
            vec![DVec3::ZERO; bz.control_count()],
            Method::Direct,
            &Budget::default(),
        )
        .expect("bezier fit");
        let mut rng = Rng(6);
        for _ in 0..50 {
            let p = rng.param(1);
            let a = bp.evaluate(&b_fit.controls, p).position;
            let b = bz.evaluate(&z_fit.controls, p).position;
            assert!(close(a, b, 1e-6), "n={n}: {a} vs {b}");
        }
        let (rb, rz) = (
            b_fit.rounds[0].steps.last().expect("steps").rms_error,
            z_fit.steps.last().expect("steps").rms_error,
        );
        assert!((rb - rz).abs() <= 1e-6 * rz, "rms {rb} vs {rz}");
    }
}

#[test]
fn iterative_dms_fits_reach_the_direct_solve() {
    let (vertices, triangles) = l_domain();
    let s = DmsSpline::new(vertices, triangles, 2, KnotRule::default()).expect("valid");
    let (params, data) = samples(&s, 3000, 21, wavy);
    let run = |method, iterations| {
        let options = ScatteredOptions {
            method,
            budget: Budget {
                max_iterations: iterations,
                stall_steps: 0,
                ..Budget::default()
            },
            ..ScatteredOptions::default()
        };
        fit_scattered(&s, &params, &data, &options, None).expect("fit")
    };
    let direct = run(Method::Direct, 1);
    for (method, iterations) in [
        (Method::Cg, 400),
        (Method::Lspia, 20_000),
        (Method::Pia, 20_000),
    ] {
        let out = run(method, iterations);
        let mut rng = Rng(1);
        for _ in 0..50 {
            let p = rng.param(s.domain_face_count());
            let a = s.evaluate(&out.controls, p).position;
            let b = s.evaluate(&direct.controls, p).position;
            assert!(close(a, b, 1e-5), "{method:?}: {a} vs {b}");
        }
    }
}

#[test]
fn foot_point_rounds_lower_the_geometric_error() {
    let (vertices, triangles) = l_domain();
    let s = DmsSpline::new(vertices, triangles, 3, KnotRule::default()).expect("valid");
    // The data's true parameters are shifted: the first fit sees a distorted sampling.
    let (params, _) = samples(&s, 2500, 33, wavy);
    let data: Vec<DVec3> = params
        .iter()
        .map(|p| {
            let x = s.domain_point(*p);
            wavy(x + DVec2::new(0.04 * (2.0 * x.y).sin(), 0.04 * (1.7 * x.x).cos()))
        })
        .collect();
    let options = ScatteredOptions {
        method: Method::Direct,
        correction_rounds: 3,
        ..ScatteredOptions::default()
    };
    let out = fit_scattered(&s, &params, &data, &options, None).expect("fit");
    let rms: Vec<f64> = out
        .rounds
        .iter()
        .map(|r| r.steps.last().expect("steps").rms_error)
        .collect();
    // Point-to-point correction is slow (it only moves parameters); it must still help
    // every round.
    assert!(rms.windows(2).all(|w| w[1] < w[0]), "rms by round: {rms:?}");
    assert!(rms[3] < 0.9 * rms[0], "rms by round: {rms:?}");
}

#[test]
fn dms_rejects_bad_domains_and_clouds_with_typed_errors() {
    let (vertices, mut triangles) = l_domain();
    assert!(matches!(
        DmsSpline::new(vertices.clone(), triangles.clone(), 4, KnotRule::default()),
        Err(DmsError::Degree(4))
    ));
    let mut clockwise = triangles.clone();
    clockwise[3].swap(0, 1);
    assert!(matches!(
        DmsSpline::new(vertices.clone(), clockwise, 2, KnotRule::default()),
        Err(DmsError::NotCounterClockwise(3))
    ));
    // Corner (0, 0) is a boundary vertex: a knot inside the domain breaks the partition.
    let s =
        DmsSpline::new(vertices.clone(), triangles.clone(), 2, KnotRule::default()).expect("valid");
    let mut clouds = s.knot_clouds().to_vec();
    clouds[0][1] = DVec2::new(0.1, 0.1);
    assert!(matches!(
        DmsSpline::with_clouds(vertices.clone(), triangles.clone(), 2, clouds),
        Err(DmsError::BoundaryKnotInside(0))
    ));
    // A knot of an interior vertex thrown across its triangles flips knot triangles.
    let mut clouds = s.knot_clouds().to_vec();
    clouds[5][2] = vertices[5] + DVec2::new(1.5, 1.5);
    assert!(matches!(
        DmsSpline::with_clouds(vertices.clone(), triangles.clone(), 2, clouds),
        Err(DmsError::KnotTriangle { .. })
    ));
    triangles[0][0] = 99;
    assert!(matches!(
        DmsSpline::new(vertices, triangles, 2, KnotRule::default()),
        Err(DmsError::VertexIndex { vertex: 99, .. })
    ));
}

#[test]
fn records_round_trip_through_json() {
    use trispline::surface::bpatch::BPatchRecord;
    use trispline::surface::dms::record::DmsRecord;
    let bp = BPatch::outward(3, domain_triangle(), 0.5).expect("valid");
    let c = wavy_controls(3);
    let json = serde_json::to_string(&BPatchRecord::new(&bp, &c)).expect("serialises");
    let back: BPatchRecord = serde_json::from_str(&json).expect("parses");
    let (bp2, c2) = back.surface().expect("valid record");
    let p = SurfaceParam {
        face: 0,
        u: 0.3,
        v: 0.2,
    };
    // serde_json's default float parsing may be off by an ulp.
    assert!(close(
        bp.evaluate(&c, p).position,
        bp2.evaluate(&c2, p).position,
        1e-14
    ));

    let s = random_dms(2, 8);
    let controls: Vec<DVec3> = (0..s.control_count())
        .map(|i| DVec3::splat(i as f64))
        .collect();
    let json = serde_json::to_string(&DmsRecord::new(&s, &controls)).expect("serialises");
    let mut back: DmsRecord = serde_json::from_str(&json).expect("parses");
    let (s2, c2) = back.clone().surface().expect("valid record");
    let mut rng = Rng(4);
    for _ in 0..20 {
        let p = rng.param(s.domain_face_count());
        let (a, b) = (
            s.evaluate(&controls, p).position,
            s2.evaluate(&c2, p).position,
        );
        assert!(close(a, b, 1e-13), "{a} vs {b}");
    }
    back.control_points.pop();
    assert!(back.surface().is_err());
}

#[test]
fn dms_is_continuous_across_domain_edges_with_its_derivatives_to_order_n_minus_1() {
    for degree in [2, 3] {
        let s = random_dms(degree, 60 + degree as u64);
        let c: Vec<DVec3> = (0..s.control_count())
            .map(|i| {
                DVec3::new(
                    (i as f64 * 0.7).sin(),
                    (i as f64 * 0.3).cos(),
                    i as f64 * 0.01,
                )
            })
            .collect();
        // Every interior edge point seen from both faces: the limits from the two sides.
        let tris = s.triangles();
        for (f, t) in tris.iter().enumerate() {
            for (g, q) in tris.iter().enumerate().skip(f + 1) {
                let shared: Vec<usize> = (0..3).filter(|&k| q.contains(&t[k])).collect();
                if shared.len() != 2 {
                    continue;
                }
                let x = s.vertices()[t[shared[0]] as usize] * 0.37
                    + s.vertices()[t[shared[1]] as usize] * 0.63;
                let from = |face: usize| -> (DVec3, [f64; 2]) {
                    // x in `face`'s barycentrics: the limit from that side.
                    let mut p = s.locate(x).expect("inside");
                    let [a, b, cc] = tris[face].map(|v| s.vertices()[v as usize]);
                    let d = (b - a).perp_dot(cc - a);
                    p.face = face as u32;
                    p.u = (b - x).perp_dot(cc - x) / d;
                    p.v = (cc - x).perp_dot(a - x) / d;
                    let e = s.evaluate(&c, p);
                    // The domain gradient of z from the face's (u, v) derivatives.
                    let (eu, ev) = (a - cc, b - cc);
                    let m = eu.x * ev.y - eu.y * ev.x;
                    let gx = (e.du.z * ev.y - e.dv.z * eu.y) / m;
                    let gy = (e.dv.z * eu.x - e.du.z * ev.x) / m;
                    (e.position, [gx, gy])
                };
                let (pf, gf) = from(f);
                let (pg, gg) = from(g);
                assert!(
                    close(pf, pg, 1e-11),
                    "degree {degree} value across edge {f}/{g}: {pf} vs {pg}"
                );
                assert!(
                    (gf[0] - gg[0]).abs() + (gf[1] - gg[1]).abs()
                        < 1e-8 * (1.0 + gf[0].abs() + gf[1].abs()),
                    "degree {degree} gradient across edge {f}/{g}: {gf:?} vs {gg:?}"
                );
            }
        }
    }
}
