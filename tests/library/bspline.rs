//! B-spline basis, curve and surface fitting against independent references.

use nalgebra::{DMatrix, DVector};
use trispline::bspline::basis::{basis_row, cox_de_boor, parameters, ParamMethod};
use trispline::bspline::fit::{
    adaptive_curve, adaptive_grid, approximate_curve, fit_grid, interpolate_curve,
    interpolate_grid, lsq_shared, Ends, Grid, GridMethod,
};
use trispline::DVec3;

fn knot_vectors() -> Vec<(Vec<f64>, usize, usize)> {
    vec![
        (vec![0.0, 0.0, 1.0, 1.0], 2, 1),
        (vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0], 4, 3),
        (
            vec![0.0, 0.0, 0.0, 0.0, 0.1, 0.4, 0.4, 0.8, 1.0, 1.0, 1.0, 1.0],
            8,
            3,
        ),
        (vec![0.0, 0.0, 0.0, 0.3, 0.3, 0.5, 0.9, 1.0, 1.0, 1.0], 7, 2),
        (
            [vec![0.0; 6], vec![0.25, 0.5, 0.75], vec![1.0; 6]].concat(),
            9,
            5,
        ),
    ]
}

#[test]
fn basis_is_a_partition_of_unity_and_matches_cox_de_boor() {
    for (k, n, p) in knot_vectors() {
        for s in 0..=200 {
            let t = s as f64 / 200.0;
            let row = basis_row(&k, n, p, t, 2);
            let sum: f64 = row.d[0][..=p].iter().sum();
            assert!((sum - 1.0).abs() < 1e-14, "p={p} t={t} sum={sum}");
            assert!(row.d[0][..=p].iter().all(|&v| v >= -1e-15));
            // Derivatives of a partition of unity sum to zero.
            for d in 1..=2.min(p) {
                let s: f64 = row.d[d][..=p].iter().sum();
                assert!(s.abs() < 1e-9, "p={p} t={t} d={d} sum={s}");
            }
            if t < 1.0 {
                for r in 0..=p {
                    let i = row.first(p) + r;
                    assert!((row.d[0][r] - cox_de_boor(&k, i, p, t)).abs() < 1e-14);
                }
            }
        }
    }
}

#[test]
fn basis_derivatives_match_finite_differences() {
    let h = 1e-6;
    for (k, n, p) in knot_vectors() {
        for s in 1..50 {
            let t = s as f64 / 50.0 + 0.003;
            // Stay off knots, where derivatives of low-continuity bases jump.
            if k.iter().any(|&x| (x - t).abs() < 10.0 * h) || t >= 1.0 - 10.0 * h {
                continue;
            }
            let full = |t: f64, d: usize| -> Vec<f64> {
                let r = basis_row(&k, n, p, t, 2);
                let mut v = vec![0.0; n];
                for j in 0..=p {
                    v[r.first(p) + j] = r.d[d][j];
                }
                v
            };
            let (a, b, c) = (full(t - h, 0), full(t + h, 0), full(t, 1));
            let (a1, b1, c2) = (full(t - h, 1), full(t + h, 1), full(t, 2));
            for i in 0..n {
                let fd = (b[i] - a[i]) / (2.0 * h);
                assert!(
                    (fd - c[i]).abs() < 1e-6 * (1.0 + c[i].abs()),
                    "p={p} t={t} i={i}"
                );
                if p >= 2 {
                    let fd2 = (b1[i] - a1[i]) / (2.0 * h);
                    assert!(
                        (fd2 - c2[i]).abs() < 1e-4 * (1.0 + c2[i].abs()),
                        "second p={p} t={t} i={i}: {fd2} vs {}",
                        c2[i]
                    );
                }
            }
        }
    }
}

fn helix(n: usize) -> Vec<DVec3> {
    (0..n)
        .map(|k| {
            let t = k as f64 / (n - 1) as f64 * 9.0;
            DVec3::new(t.cos(), t.sin(), 0.1 * t + 0.05 * (3.0 * t).sin())
        })
        .collect()
}

#[test]
fn interpolation_passes_through_the_data() {
    let pts = helix(40);
    for method in [ParamMethod::ChordLength, ParamMethod::Centripetal] {
        for p in [1, 2, 3, 5] {
            let fit = interpolate_curve(&pts, p, method).expect("fit");
            assert_eq!(fit.curve.controls().len(), pts.len());
            assert!(
                fit.stats.max_error < 1e-12,
                "p={p}: {}",
                fit.stats.max_error
            );
        }
    }
}

#[test]
fn surface_interpolation_passes_through_the_grid() {
    let (rows, cols) = (13, 9);
    let pts: Vec<DVec3> = (0..rows * cols)
        .map(|k| {
            let (x, y) = (
                (k / cols) as f64 * 0.3,
                (k % cols) as f64 * 0.4 + 0.01 * (k / cols) as f64,
            );
            DVec3::new(x, y, (x * 1.7).sin() * (y * 0.9).cos())
        })
        .collect();
    let grid = Grid {
        rows,
        cols,
        points: &pts,
    };
    let fit = interpolate_grid(&grid, (3, 2), ParamMethod::ChordLength).expect("fit");
    assert_eq!(fit.surface.counts(), (rows, cols));
    assert!(fit.stats.max_error < 1e-11, "{}", fit.stats.max_error);
}

/// Dense reference: the normal equations of the same end-constrained problem, solved by an
/// SVD-based least-squares solve of the dense design matrix.
#[test]
fn least_squares_matches_a_dense_reference_solve() {
    let pts = helix(60);
    for (count, p, ends) in [
        (12, 3, Ends::Interpolated),
        (9, 2, Ends::Free),
        (20, 4, Ends::Interpolated),
    ] {
        let fit = approximate_curve(&pts, count, p, ParamMethod::ChordLength, ends).expect("fit");
        let knots = fit.curve.knots().to_vec();
        let t = &fit.params;
        let m = pts.len();
        let mut a = DMatrix::zeros(m, count);
        for (k, &tk) in t.iter().enumerate() {
            for i in 0..count {
                a[(k, i)] = cox_de_boor(&knots, i, p, tk.min(1.0 - 1e-15));
            }
        }
        // The clamped end: N_{count-1}(1) = 1.
        a[(m - 1, count - 1)] = 1.0;
        for d in 0..3 {
            let b = DVector::from_iterator(m, pts.iter().map(|q| q[d]));
            let x = match ends {
                Ends::Free => a.clone().svd(true, true).solve(&b, 1e-14).expect("svd"),
                Ends::Interpolated => {
                    let mut x = DVector::zeros(count);
                    x[0] = b[0];
                    x[count - 1] = b[m - 1];
                    let inner = a.view((1, 1), (m - 2, count - 2)).clone_owned();
                    let rhs = b.rows(1, m - 2)
                        - a.view((1, 0), (m - 2, 1)) * x[0]
                        - a.view((1, count - 1), (m - 2, 1)) * x[count - 1];
                    let xi = inner.svd(true, true).solve(&rhs, 1e-14).expect("svd");
                    x.rows_mut(1, count - 2).copy_from(&xi);
                    x
                }
            };
            for i in 0..count {
                let got = fit.curve.controls()[i][d];
                assert!(
                    (got - x[i]).abs() < 1e-9,
                    "count={count} p={p} i={i} d={d}: {got} vs {}",
                    x[i]
                );
            }
        }
        if ends == Ends::Interpolated {
            assert_eq!(fit.curve.controls()[0], pts[0]);
            assert_eq!(fit.curve.controls()[count - 1], pts[59]);
        }
    }
}

#[test]
fn shared_right_hand_sides_equal_separate_solves() {
    let t = parameters(&helix(30), ParamMethod::ChordLength);
    let knots = trispline::bspline::basis::approximation_knots(&t, 8, 3);
    let data: Vec<f64> = (0..30 * 4).map(|k| ((k * 37) % 11) as f64 * 0.1).collect();
    let all = lsq_shared(&t, &knots, 3, 8, &data, 4, Ends::Free).expect("solve");
    for c in 0..4 {
        let col: Vec<f64> = (0..30).map(|k| data[k * 4 + c]).collect();
        let one = lsq_shared(&t, &knots, 3, 8, &col, 1, Ends::Free).expect("solve");
        for i in 0..8 {
            assert!((one[i] - all[i * 4 + c]).abs() < 1e-12);
        }
    }
}

#[test]
fn adaptive_curve_reaches_the_tolerance_with_few_controls() {
    let pts = helix(400);
    let fit = adaptive_curve(&pts, 3, 1e-4, ParamMethod::ChordLength, 400).expect("fit");
    assert!(fit.stats.max_error <= 1e-4, "{}", fit.stats.max_error);
    let n = fit.curve.controls().len();
    assert!(n < 80, "{n} control points for a smooth helix");
    // A coarser tolerance needs fewer control points.
    let coarse = adaptive_curve(&pts, 3, 1e-2, ParamMethod::ChordLength, 400).expect("fit");
    assert!(coarse.curve.controls().len() < n);
    assert!(coarse.stats.max_error <= 1e-2);
}

fn wave_grid(rows: usize, cols: usize) -> Vec<DVec3> {
    (0..rows * cols)
        .map(|k| {
            let (x, y) = (
                (k / cols) as f64 / (rows - 1) as f64,
                (k % cols) as f64 / (cols - 1) as f64,
            );
            DVec3::new(
                x * 2.0,
                y * 2.0,
                0.3 * (3.0 * x).sin() * (2.0 * y).cos() + 0.1 * x * y,
            )
        })
        .collect()
}

#[test]
fn separable_least_squares_is_the_full_least_squares_solution() {
    // On a grid the all-at-once least-squares problem separates; check against the dense
    // Kronecker-product system.
    let (rows, cols, cu, cv) = (11, 9, 5, 4);
    let pts = wave_grid(rows, cols);
    let grid = Grid {
        rows,
        cols,
        points: &pts,
    };
    let fit = fit_grid(
        &grid,
        (cu, cv),
        (2, 2),
        ParamMethod::ChordLength,
        GridMethod::Lsq,
    )
    .expect("fit");
    let s = &fit.surface;
    let mut a = DMatrix::zeros(rows * cols, cu * cv);
    for (k, &(u, v)) in fit.params.iter().enumerate() {
        let (ru, rv) = (s.row_u(u, 0), s.row_v(v, 0));
        for x in 0..=2 {
            for y in 0..=2 {
                a[(k, (ru.first(2) + x) * cv + rv.first(2) + y)] = ru.d[0][x] * rv.d[0][y];
            }
        }
    }
    let svd = a.svd(true, true);
    for d in 0..3 {
        let b = DVector::from_iterator(rows * cols, pts.iter().map(|q| q[d]));
        let x = svd.solve(&b, 1e-14).expect("svd");
        for i in 0..cu * cv {
            assert!((s.controls()[i][d] - x[i]).abs() < 1e-9);
        }
    }
    // The two-pass method interpolates the grid corners.
    let tp = fit_grid(
        &grid,
        (cu, cv),
        (2, 2),
        ParamMethod::ChordLength,
        GridMethod::TwoPass,
    )
    .expect("fit");
    assert!((tp.surface.point(0.0, 0.0) - pts[0]).length() < 1e-12);
    assert!((tp.surface.point(1.0, 1.0) - pts[rows * cols - 1]).length() < 1e-12);
}

#[test]
fn adaptive_grid_meets_the_tolerance() {
    let (rows, cols) = (40, 30);
    let pts = wave_grid(rows, cols);
    let grid = Grid {
        rows,
        cols,
        points: &pts,
    };
    for method in [GridMethod::Lsq, GridMethod::TwoPass] {
        let fit = adaptive_grid(
            &grid,
            (3, 3),
            1e-4,
            ParamMethod::ChordLength,
            method,
            (40, 30),
        )
        .expect("fit");
        assert!(
            fit.stats.max_error <= 1e-4,
            "{method:?}: {}",
            fit.stats.max_error
        );
        let (cu, cv) = fit.surface.counts();
        assert!(cu * cv < rows * cols / 4, "{method:?}: {cu}x{cv}");
    }
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let pts = helix(10);
    assert!(approximate_curve(&pts, 12, 3, ParamMethod::ChordLength, Ends::Free).is_err());
    assert!(approximate_curve(&pts, 3, 3, ParamMethod::ChordLength, Ends::Free).is_err());
    assert!(approximate_curve(&pts, 5, 0, ParamMethod::ChordLength, Ends::Free).is_err());
    let mut nan = pts.clone();
    nan[3].y = f64::NAN;
    assert!(interpolate_curve(&nan, 3, ParamMethod::ChordLength).is_err());
    let g = wave_grid(5, 5);
    let grid = Grid {
        rows: 5,
        cols: 5,
        points: &g,
    };
    assert!(fit_grid(
        &grid,
        (6, 4),
        (3, 3),
        ParamMethod::ChordLength,
        GridMethod::Lsq
    )
    .is_err());
}

mod scattered {
    use super::*;
    use trispline::bspline::scattered::{
        adaptive_scattered, fit_scattered, planar_parameters, ScatteredOptions, ScatteredSolver,
    };
    use trispline::bspline::BSplineError;

    /// Deterministic scattered samples of a tilted wavy sheet.
    fn cloud(n: usize, hole: bool) -> Vec<DVec3> {
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut out = Vec::new();
        while out.len() < n {
            let (x, y) = (rnd() * 3.0, rnd() * 2.0);
            if hole && (x - 1.5).hypot(y - 1.0) < 0.5 {
                continue;
            }
            let z = 0.2 * (2.0 * x).sin() * y.cos();
            out.push(DVec3::new(x, 0.3 * x + y, z + 0.1 * y));
        }
        out
    }

    fn opts(counts: (usize, usize), smoothing: f64, solver: ScatteredSolver) -> ScatteredOptions {
        ScatteredOptions {
            counts,
            degrees: (3, 3),
            smoothing,
            solver,
            parameter_correction: 0,
        }
    }

    #[test]
    fn direct_scattered_fit_matches_a_dense_reference() {
        let pts = cloud(400, false);
        let params = planar_parameters(&pts);
        assert!(params
            .iter()
            .all(|&(u, v)| (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v)));
        let o = opts((6, 5), 0.0, ScatteredSolver::Direct);
        let fit = fit_scattered(&pts, &params, &o).expect("fit");
        let s = &fit.surface;
        let n = 30;
        let mut a = DMatrix::zeros(pts.len(), n);
        for (k, &(u, v)) in params.iter().enumerate() {
            let (ru, rv) = (s.row_u(u, 0), s.row_v(v, 0));
            for x in 0..=3 {
                for y in 0..=3 {
                    a[(k, (ru.first(3) + x) * 5 + rv.first(3) + y)] = ru.d[0][x] * rv.d[0][y];
                }
            }
        }
        let svd = a.svd(true, true);
        for d in 0..3 {
            let b = DVector::from_iterator(pts.len(), pts.iter().map(|q| q[d]));
            let x = svd.solve(&b, 1e-14).expect("svd");
            for i in 0..n {
                assert!((s.controls()[i][d] - x[i]).abs() < 1e-8, "{i} {d}");
            }
        }
    }

    #[test]
    fn lspia_approaches_the_direct_solution() {
        let pts = cloud(600, false);
        let params = planar_parameters(&pts);
        let direct =
            fit_scattered(&pts, &params, &opts((5, 5), 0.0, ScatteredSolver::Direct)).expect("fit");
        let few = fit_scattered(
            &pts,
            &params,
            &opts((5, 5), 0.0, ScatteredSolver::Lspia { iterations: 20 }),
        )
        .expect("fit");
        let many = fit_scattered(
            &pts,
            &params,
            &opts((5, 5), 0.0, ScatteredSolver::Lspia { iterations: 5000 }),
        )
        .expect("fit");
        assert!(many.stats.rms_error < few.stats.rms_error);
        assert!(
            many.stats.rms_error < direct.stats.rms_error * 1.05,
            "{} vs {}",
            many.stats.rms_error,
            direct.stats.rms_error
        );
        assert!(direct.stats.rms_error <= many.stats.rms_error + 1e-12);
    }

    #[test]
    fn smoothing_bridges_a_hole_that_plain_least_squares_cannot() {
        let pts = cloud(500, true);
        let params = planar_parameters(&pts);
        let plain = fit_scattered(&pts, &params, &opts((14, 14), 0.0, ScatteredSolver::Direct));
        assert!(
            matches!(plain, Err(BSplineError::RankDeficient(_))),
            "{plain:?}"
        );
        let smooth = fit_scattered(
            &pts,
            &params,
            &opts((14, 14), 1e-4, ScatteredSolver::Direct),
        )
        .expect("fit");
        assert!(smooth.stats.max_error < 0.02, "{}", smooth.stats.max_error);
        // The patch over the hole stays near the sheet (no wild oscillation).
        let (u, v) = params[0];
        assert!(smooth.surface.point(u, v).is_finite());
    }

    #[test]
    fn adaptive_scattered_and_parameter_correction() {
        let pts = cloud(1500, false);
        let params = planar_parameters(&pts);
        let mut o = opts((20, 20), 0.0, ScatteredSolver::Direct);
        let fit = adaptive_scattered(&pts, &params, &o, 1e-3).expect("fit");
        assert!(fit.stats.max_error <= 1e-3, "{}", fit.stats.max_error);
        let (cu, cv) = fit.surface.counts();
        assert!(cu * cv < 200, "{cu}x{cv}");
        o.counts = (8, 8);
        let base = fit_scattered(&pts, &params, &o).expect("fit");
        o.parameter_correction = 2;
        let corrected = fit_scattered(&pts, &params, &o).expect("fit");
        assert!(corrected.stats.rms_error < base.stats.rms_error);
    }
}

#[test]
fn adaptive_knots_go_where_the_error_is() {
    // A straight line with a narrow bump around x = 0.7: a cubic needs knots there only.
    let pts: Vec<DVec3> = (0..600)
        .map(|k| {
            let x = k as f64 / 599.0;
            DVec3::new(x, 0.05 * (-((x - 0.7) / 0.02).powi(2)).exp(), 0.0)
        })
        .collect();
    let fit = adaptive_curve(&pts, 3, 1e-4, ParamMethod::ChordLength, 600).expect("fit");
    assert!(fit.stats.max_error <= 1e-4);
    let k = fit.curve.knots();
    let interior: Vec<f64> = k[4..k.len() - 4].to_vec();
    // Chord-length parameters of x = 0.6 and 0.8 (the bump adds length between them).
    let t_at = |x: f64| fit.params[(x * 599.0).round() as usize];
    let near = interior
        .iter()
        .filter(|&&t| t > t_at(0.6) && t < t_at(0.8))
        .count();
    assert!(
        near * 10 >= interior.len() * 8,
        "{near} of {} interior knots near the bump",
        interior.len()
    );
    assert!(
        fit.curve.controls().len() < 60,
        "{}",
        fit.curve.controls().len()
    );
}
