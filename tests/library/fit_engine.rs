//! The fitting methods against each other and against known answers, on a degree-6
//! triangular Bezier basis sampled at scattered parameters.

use glam::DVec3;
use trispline::fit::engine::{lambda_max, umbrella_laplacian};
use trispline::fit::{fit, Budget, Collocation, Csr, FitProblem, FitStatus, Method};
use trispline::surface::bezier::{lattice_len, lattice_points, lattice_triangles, BezierTriangle};
use trispline::surface::{SurfaceParam, TriSurface};

fn rng(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed | 1;
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn params(count: usize, seed: u64) -> Vec<SurfaceParam> {
    let mut r = rng(seed);
    (0..count)
        .map(|_| {
            let (mut u, mut v) = (r(), r());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            SurfaceParam { face: 0, u, v }
        })
        .collect()
}

fn collocation(s: &BezierTriangle, ps: &[SurfaceParam]) -> Collocation {
    let rows: Vec<Vec<(u32, f64)>> = ps
        .iter()
        .map(|p| {
            let mut row = Vec::new();
            s.basis_row(*p, &mut row);
            row
        })
        .collect();
    Collocation::new(Csr::from_rows(
        s.control_count(),
        rows.iter().map(|r| r.as_slice()),
    ))
}

fn known_net(n: usize) -> Vec<DVec3> {
    lattice_points(n)
        .into_iter()
        .map(|(i, j)| {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            DVec3::new(x, y, 0.3 * (4.0 * x).sin() * (3.0 * y).cos())
        })
        .collect()
}

fn flat_start(n: usize) -> Vec<DVec3> {
    lattice_points(n)
        .into_iter()
        .map(|(i, j)| DVec3::new(i as f64 / n as f64, j as f64 / n as f64, 0.0))
        .collect()
}

fn exact_budget(iterations: usize) -> Budget {
    Budget {
        max_iterations: iterations,
        stall_steps: 0,
        ..Budget::default()
    }
}

fn max_diff(a: &[DVec3], b: &[DVec3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f64::max)
}

#[test]
fn every_iterative_method_recovers_a_known_net_from_exact_data() {
    let n = 6;
    let s = BezierTriangle::new(n);
    let ps = params(2000, 7);
    let col = collocation(&s, &ps);
    let truth = known_net(n);
    let mut data = vec![DVec3::ZERO; ps.len()];
    col.mul_vec3(&truth, &mut data);
    let problem = FitProblem {
        basis: &col,
        data: &data,
        smoothing: 0.0,
        fairness: None,
        pia_operator: None,
        on_step: None,
    };
    for (method, iters) in [
        (Method::Cg, 200),
        (Method::Direct, 1),
        (Method::Lspia, 20000),
    ] {
        let out = fit(&problem, flat_start(n), method, &exact_budget(iters)).expect("fits");
        let err = max_diff(&out.controls, &truth);
        assert!(
            err < 1e-8,
            "{method:?}: control error {err:e} after {} steps",
            out.iterations
        );
    }
}

#[test]
fn lspia_and_cg_converge_to_the_direct_solution_on_noisy_data() {
    let n = 6;
    let s = BezierTriangle::new(n);
    let ps = params(2000, 11);
    let col = collocation(&s, &ps);
    let mut data = vec![DVec3::ZERO; ps.len()];
    col.mul_vec3(&known_net(n), &mut data);
    let mut r = rng(5);
    data.iter_mut()
        .for_each(|p| *p += DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5) * 0.02);
    for smoothing in [0.0, 1e-3] {
        let lap = Collocation::new(umbrella_laplacian(lattice_len(n), &lattice_triangles(n)));
        let problem = FitProblem {
            basis: &col,
            data: &data,
            smoothing,
            fairness: Some(&lap),
            pia_operator: None,
            on_step: None,
        };
        let direct = fit(&problem, flat_start(n), Method::Direct, &exact_budget(1))
            .expect("direct")
            .controls;
        let scale = direct.iter().map(|p| p.length()).fold(0.0, f64::max);
        for (method, iters) in [(Method::Cg, 500), (Method::Lspia, 40000)] {
            let out = fit(&problem, flat_start(n), method, &exact_budget(iters)).expect("fits");
            let rel = max_diff(&out.controls, &direct) / scale;
            assert!(
                rel < 1e-6,
                "{method:?} s={smoothing}: relative distance to direct {rel:e}"
            );
        }
    }
}

#[test]
fn smoothing_keeps_controls_without_data_sane() {
    let n = 8;
    let s = BezierTriangle::new(n);
    // Data only near corner 2 (u, v small): the far corners have no data at all.
    let ps: Vec<SurfaceParam> = params(3000, 3)
        .into_iter()
        .filter(|p| p.u + p.v < 0.4)
        .collect();
    let col = collocation(&s, &ps);
    let data: Vec<DVec3> = ps
        .iter()
        .map(|p| DVec3::new(p.u, p.v, 0.1 * (p.u * 5.0).sin()))
        .collect();
    let lap = Collocation::new(umbrella_laplacian(lattice_len(n), &lattice_triangles(n)));
    let problem = FitProblem {
        basis: &col,
        data: &data,
        smoothing: 1e-4,
        fairness: Some(&lap),
        pia_operator: None,
        on_step: None,
    };
    let out = fit(&problem, flat_start(n), Method::Cg, &exact_budget(2000)).expect("fits");
    let worst = out.controls.iter().map(|p| p.z.abs()).fold(0.0, f64::max);
    assert!(out.controls.iter().all(|p| p.is_finite()));
    assert!(worst < 1.0, "a control point ran away: |z| = {worst}");
}

#[test]
fn budget_statuses() {
    let n = 6;
    let s = BezierTriangle::new(n);
    let ps = params(1500, 13);
    let col = collocation(&s, &ps);
    let mut data = vec![DVec3::ZERO; ps.len()];
    col.mul_vec3(&known_net(n), &mut data);
    let mut r = rng(9);
    data.iter_mut()
        .for_each(|p| *p += DVec3::new(0.0, 0.0, r() - 0.5) * 0.01);
    let problem = FitProblem {
        basis: &col,
        data: &data,
        smoothing: 0.0,
        fairness: None,
        pia_operator: None,
        on_step: None,
    };
    // Reachable: noise is +-0.005, so a 0.01 max error is attainable.
    let met = Budget {
        tolerance: 0.01,
        max_error: Some(0.01),
        max_iterations: 500,
        ..Budget::default()
    };
    let out = fit(&problem, flat_start(n), Method::Cg, &met).expect("fits");
    assert_eq!(out.status, FitStatus::Met);
    assert!(out.steps.last().is_some_and(|s| s.max_error <= 0.01));
    // Capped: one step cannot get there.
    let capped = Budget {
        max_iterations: 1,
        ..met.clone()
    };
    assert_eq!(
        fit(&problem, flat_start(n), Method::Lspia, &capped)
            .expect("fits")
            .status,
        FitStatus::Capped
    );
    // Unreachable (below the noise): progress stops, status stalled.
    let stalled = Budget {
        tolerance: 1e-6,
        max_error: Some(1e-6),
        max_iterations: 100_000,
        stall_steps: 5,
        stall_rel_improvement: 1e-6,
        ..Budget::default()
    };
    let out = fit(&problem, flat_start(n), Method::Cg, &stalled).expect("fits");
    assert_eq!(out.status, FitStatus::Stalled);
    assert!(out.iterations < 100_000);
}

#[test]
fn pia_converges_on_a_square_problem() {
    // Interpolation at the lattice's own points: N is square and PIA with the identity
    // update is the paper's classical iteration.
    let n = 5;
    let s = BezierTriangle::new(n);
    let ps: Vec<SurfaceParam> = lattice_points(n)
        .into_iter()
        .map(|(i, j)| SurfaceParam {
            face: 0,
            u: i as f64 / n as f64,
            v: j as f64 / n as f64,
        })
        .collect();
    let col = collocation(&s, &ps);
    let truth = known_net(n);
    let mut data = vec![DVec3::ZERO; ps.len()];
    col.mul_vec3(&truth, &mut data);
    let identity = |r: &[DVec3]| r.to_vec();
    let problem = FitProblem {
        basis: &col,
        data: &data,
        smoothing: 0.0,
        fairness: None,
        pia_operator: Some(&identity),
        on_step: None,
    };
    let out = fit(&problem, data.clone(), Method::Pia, &exact_budget(3000)).expect("fits");
    assert!(max_diff(&out.controls, &truth) < 1e-8);
    let missing = FitProblem {
        pia_operator: None,
        ..problem
    };
    assert!(fit(&missing, data.clone(), Method::Pia, &exact_budget(3)).is_err());
}

#[test]
fn power_iteration_estimates_lambda_max() {
    let n = 4;
    let s = BezierTriangle::new(n);
    let ps = params(300, 17);
    let col = collocation(&s, &ps);
    let nc = col.ncols();
    let mut dense = nalgebra::DMatrix::<f64>::zeros(ps.len(), nc);
    let m = col.n();
    for r in 0..m.nrows {
        for k in m.row_ptr[r]..m.row_ptr[r + 1] {
            dense[(r, m.col_idx[k] as usize)] = m.values[k];
        }
    }
    let ata = dense.transpose() * &dense;
    let truth = ata.symmetric_eigen().eigenvalues.max();
    let est = lambda_max(&col, None, 0.0, 40);
    assert!(
        est >= truth / 1.01 && est <= truth * 1.0000001,
        "estimate {est}, true {truth}"
    );
}
