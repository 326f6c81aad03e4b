//! The matrix-free Bezier collocation against the stored matrix, the sparse direct solve
//! against the iterative methods, and the per-step hook.

use glam::DVec3;
use std::sync::Mutex;
use trispline::fit::engine::{lambda_max, umbrella_laplacian};
use trispline::fit::{fit, Budget, Collocation, Csr, FitProblem, Method, StepStats};
use trispline::mesh::detect::Hierarchy;
use trispline::mesh::inverse::{coarsen, composed_exact_inverse, InverseMethod};
use trispline::mesh::topology::Topology;
use trispline::surface::bezier::{lattice_points, lattice_triangles, BezierTriangle};
use trispline::surface::grid_spline::GridSpline;
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::TriMesh;

fn rng(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed | 1;
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn stored(surface: &dyn TriSurface, ps: &[SurfaceParam]) -> Collocation {
    let rows: Vec<Vec<(u32, f64)>> = ps
        .iter()
        .map(|p| {
            let mut row = Vec::new();
            surface.basis_row(*p, &mut row);
            row
        })
        .collect();
    Collocation::new(Csr::from_rows(
        surface.control_count(),
        rows.iter().map(|r| r.as_slice()),
    ))
}

fn matrix_free(degree: usize, ps: &[SurfaceParam]) -> Collocation {
    let col = Collocation::bezier(degree, ps, || panic!("expected the matrix-free operator"));
    assert!(col.is_matrix_free());
    col
}

fn lattice_params(n: usize) -> Vec<SurfaceParam> {
    lattice_points(n)
        .into_iter()
        .map(|(i, j)| SurfaceParam {
            face: 0,
            u: i as f64 / n as f64,
            v: j as f64 / n as f64,
        })
        .collect()
}

fn random_vec(len: usize, seed: u64) -> Vec<DVec3> {
    let mut r = rng(seed);
    (0..len)
        .map(|_| DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5))
        .collect()
}

fn rel_diff(a: &[DVec3], b: &[DVec3]) -> f64 {
    let scale = b.iter().map(|p| p.length()).fold(0.0, f64::max).max(1e-300);
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f64::max)
        / scale
}

fn assert_same_products(a: &Collocation, b: &Collocation, seed: u64) {
    assert_eq!((a.nrows(), a.ncols()), (b.nrows(), b.ncols()));
    let x = random_vec(a.ncols(), seed);
    let y = random_vec(a.nrows(), seed + 1);
    let (mut ax, mut bx) = (vec![DVec3::ZERO; a.nrows()], vec![DVec3::ZERO; a.nrows()]);
    a.mul_vec3(&x, &mut ax);
    b.mul_vec3(&x, &mut bx);
    let (mut ay, mut by) = (vec![DVec3::ZERO; a.ncols()], vec![DVec3::ZERO; a.ncols()]);
    a.mul_t_vec3(&y, &mut ay);
    b.mul_t_vec3(&y, &mut by);
    let (fwd, adj) = (rel_diff(&ax, &bx), rel_diff(&ay, &by));
    assert!(fwd < 1e-12, "N x differs by {fwd:e} (relative)");
    assert!(adj < 1e-12, "N^T y differs by {adj:e} (relative)");
}

#[test]
fn matrix_free_bezier_equals_the_stored_matrix() {
    // The paper's shape (degree 24 on a 96-segment lattice) and a degree-40 patch.
    for (degree, fine) in [(24, 96), (40, 80)] {
        let ps = lattice_params(fine);
        let free = matrix_free(degree, &ps);
        let csr = stored(&BezierTriangle::new(degree), &ps);
        assert_same_products(&free, &csr, degree as u64);
        // Its own explicit matrix agrees as well (the direct solve uses it).
        assert_same_products(&Collocation::new(free.n().clone()), &csr, 3);
    }
    // Rows in shuffled order, random u on a few v values, and the apex (v = 1).
    let mut r = rng(21);
    let mut ps: Vec<SurfaceParam> = (0..3000)
        .map(|k| {
            let v = (k % 17) as f64 / 16.0;
            SurfaceParam {
                face: 0,
                u: r() * (1.0 - v),
                v,
            }
        })
        .collect();
    ps.push(SurfaceParam {
        face: 0,
        u: 0.0,
        v: 1.0,
    });
    let free = matrix_free(9, &ps);
    assert_same_products(&free, &stored(&BezierTriangle::new(9), &ps), 5);
}

#[test]
fn scattered_parameters_keep_the_stored_matrix() {
    let mut r = rng(4);
    let ps: Vec<SurfaceParam> = (0..500)
        .map(|_| {
            let (u, v) = (r() * 0.5, r() * 0.5);
            SurfaceParam { face: 0, u, v }
        })
        .collect();
    let col = Collocation::bezier(6, &ps, Csr::default);
    assert!(!col.is_matrix_free());
}

/// The paper's pipeline at a smaller size: a 32-segment lattice, two inverse levels,
/// degree 8, with the exact inverse-Loop PIA update.
#[test]
fn methods_agree_with_both_operators() {
    let (fine, levels) = (32, 2);
    let degree = fine >> levels;
    let ps = lattice_params(fine);
    let data: Vec<DVec3> = ps
        .iter()
        .map(|p| {
            DVec3::new(
                p.u + p.v / 2.0,
                p.v * 0.866,
                0.12 * (6.3 * p.u).sin() * (3.1 * p.v).cos() + 0.08 * (p.u * p.u + p.v * p.v),
            )
        })
        .collect();
    let mesh = TriMesh::new(data.clone(), lattice_triangles(fine));
    let topo = Topology::from_mesh(&mesh).expect("manifold");
    let (hierarchy, _) = Hierarchy::detect(&topo, levels);
    assert_eq!(hierarchy.depth(), levels);
    let r = composed_exact_inverse(&topo, &hierarchy).expect("inverse");
    let pia = |res: &[DVec3]| r.apply(res);
    let free = matrix_free(degree, &ps);
    let csr = stored(&BezierTriangle::new(degree), &ps);
    // The paper's start: the inverse-subdivided net.
    let start = coarsen(&mesh, levels, InverseMethod::Exact)
        .expect("subdivided")
        .mesh
        .positions;
    let budget = Budget {
        max_iterations: 15,
        stall_steps: 0,
        ..Budget::default()
    };
    let la = lambda_max(&free, None, 0.0, 40);
    let lb = lambda_max(&csr, None, 0.0, 40);
    assert!((la - lb).abs() <= 1e-12 * lb, "lambda_max {la} vs {lb}");
    for method in [Method::Pia, Method::Lspia, Method::Cg, Method::Direct] {
        let run = |basis: &Collocation| {
            let problem = FitProblem {
                basis,
                data: &data,
                smoothing: 0.0,
                fairness: None,
                pia_operator: Some(&pia),
                on_step: None,
            };
            // CG on the normal equations of a degree-8 Bernstein basis (cond ~1e10) turns
            // rounding-level differences between operators into visible ones after ~8
            // steps (two CSR matrices differing by 1e-16 do the same); compare it early.
            let budget = Budget {
                max_iterations: if method == Method::Cg { 5 } else { 15 },
                ..budget.clone()
            };
            fit(&problem, start.clone(), method, &budget).expect("fits")
        };
        let (a, b) = (run(&free), run(&csr));
        assert_eq!(a.iterations, b.iterations);
        let (mut fa, mut fb) = (vec![DVec3::ZERO; ps.len()], vec![DVec3::ZERO; ps.len()]);
        csr.mul_vec3(&a.controls, &mut fa);
        csr.mul_vec3(&b.controls, &mut fb);
        let fitted = rel_diff(&fa, &fb);
        assert!(
            fitted < 1e-9,
            "{method:?}: fitted points differ by {fitted:e}"
        );
        let d = rel_diff(&a.controls, &b.controls);
        assert!(d < 1e-9, "{method:?}: controls differ by {d:e}");
        for (ea, eb) in a.steps.iter().zip(&b.steps) {
            assert!((ea.rms_error - eb.rms_error).abs() <= 1e-9 * eb.rms_error.max(1e-12));
        }
    }
}

/// A Loop grid spline over a w x h parallelogram of cells, data sampled k times finer
/// from a smooth height field.
fn grid_problem(w: i64, h: i64, k: usize) -> (GridSpline, Vec<SurfaceParam>, Vec<DVec3>) {
    let cells = (0..h).flat_map(|j| (0..w).flat_map(move |i| [(i, j, false), (i, j, true)]));
    let spline = GridSpline::new(cells);
    let kf = k as f64;
    let params: Vec<SurfaceParam> = (0..h * k as i64)
        .flat_map(|b| {
            (0..w * k as i64).map(move |a| SurfaceParam {
                face: 0,
                u: a as f64 / kf,
                v: b as f64 / kf,
            })
        })
        .collect();
    let data = params
        .iter()
        .map(|p| {
            let (x, y) = (p.u + 0.5 * p.v, 0.866 * p.v);
            DVec3::new(
                x,
                y,
                2.0 * (0.3 * x).sin() * (0.2 * y).cos() + 0.01 * (3.0 * x).sin(),
            )
        })
        .collect();
    (spline, params, data)
}

fn converge_to_direct(w: i64, h: i64, k: usize, min_controls: usize, max_controls: usize) {
    let (spline, params, data) = grid_problem(w, h, k);
    let basis = stored(&spline, &params);
    // Corner controls of the outer ring barely touch the data: a little fairness keeps
    // the normal matrix definite, as in the scan pipeline.
    let fairness = Collocation::new(umbrella_laplacian(
        spline.control_count(),
        &spline.net_triangles(),
    ));
    assert!(
        (min_controls..=max_controls).contains(&basis.ncols()),
        "{} controls",
        basis.ncols()
    );
    let problem = FitProblem {
        basis: &basis,
        data: &data,
        smoothing: 0.1,
        fairness: Some(&fairness),
        pia_operator: None,
        on_step: None,
    };
    let start = vec![DVec3::ZERO; basis.ncols()];
    let exact = Budget {
        max_iterations: 1,
        stall_steps: 0,
        ..Budget::default()
    };
    let direct = fit(&problem, start.clone(), Method::Direct, &exact)
        .expect("direct")
        .controls;
    for (method, iterations) in [(Method::Cg, 3000), (Method::Lspia, 20000)] {
        let budget = Budget {
            max_iterations: iterations,
            ..exact.clone()
        };
        let out = fit(&problem, start.clone(), method, &budget).expect("fits");
        let d = rel_diff(&out.controls, &direct);
        assert!(
            d < 1e-6,
            "{method:?}: {d:e} from direct after {} steps ({} controls)",
            out.iterations,
            basis.ncols()
        );
    }
}

#[test]
fn iterative_methods_reach_the_sparse_direct_solve_on_a_loop_grid() {
    converge_to_direct(40, 40, 3, 1000, 6000);
}

#[test]
fn sparse_direct_solve_takes_more_than_6000_controls() {
    converge_to_direct(85, 80, 2, 6001, 20_000);
}

#[test]
fn step_hook_sees_every_step() {
    let ps = lattice_params(24);
    let basis = matrix_free(6, &ps);
    let truth = random_vec(basis.ncols(), 2);
    let mut data = vec![DVec3::ZERO; ps.len()];
    basis.mul_vec3(&truth, &mut data);
    let seen: Mutex<Vec<StepStats>> = Mutex::new(Vec::new());
    let hook = |s: &StepStats| seen.lock().expect("lock").push(s.clone());
    let problem = FitProblem {
        basis: &basis,
        data: &data,
        smoothing: 0.0,
        fairness: None,
        pia_operator: None,
        on_step: Some(&hook),
    };
    let budget = Budget {
        max_iterations: 7,
        stall_steps: 0,
        ..Budget::default()
    };
    let out = fit(
        &problem,
        vec![DVec3::ZERO; basis.ncols()],
        Method::Cg,
        &budget,
    )
    .expect("fit");
    let seen = seen.into_inner().expect("lock");
    assert_eq!(seen.len(), out.steps.len());
    assert!(seen
        .iter()
        .zip(&out.steps)
        .all(|(a, b)| a.k == b.k && a.rms_error == b.rms_error));
}
