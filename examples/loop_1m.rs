//! A 1M-point `loop` fit: time per step against the memory-bandwidth bound of the step's
//! two sparse products.
//!
//! Surface: the Loop box-spline grid surface (`GridSpline`) over a parallelogram of
//! W x H grid cells (up and down triangles), data sampled on the grid refined K times,
//!   z = 2 sin(0.3 x) cos(0.2 y) + 0.01 sin(3 x),  (x, y) the plane point of the grid point,
//! which is smooth at the cell scale but not a spline, so the fit never becomes exact.
//!
//! The bound: one CG or LSPIA step reads N (to form N x) and N^T (to form N^T r), each a
//! CSR matrix (8-byte values, 4-byte column indices, 8-byte row pointers), reads the vector
//! it multiplies and writes the product. Bytes touched / measured read bandwidth is the
//! least time a step can take; the figure of merit is measured / bound (goal <= 2).
//! Read bandwidth: a parallel sum over a 512 MB array, best of 5 (STREAM-like "sum").
//! Then steps to a max-error budget for lspia and cg, and sparse direct solve times
//! (this problem, and a 20k-control one).
//!
//! Run: cargo run --release --example loop_1m

use glam::DVec3;
use rayon::prelude::*;
use std::time::Instant;
use trispline::fit::engine::umbrella_laplacian;
use trispline::fit::{fit, Budget, Collocation, FitProblem, FitStatus, Method};
use trispline::pipeline::collocation;
use trispline::surface::grid_spline::GridSpline;
use trispline::surface::{SurfaceParam, TriSurface};

const W: i64 = 170;
const H: i64 = 170;
const K: i64 = 6;

fn read_bandwidth_gbs() -> (f64, f64) {
    let len = 64 << 20; // 64 Mi f64 = 512 MB
    let a: Vec<f64> = (0..len).into_par_iter().map(|i| (i % 7) as f64).collect();
    let mut best_par = f64::MAX;
    let mut best_seq = f64::MAX;
    let mut check = 0.0;
    for _ in 0..5 {
        let t = Instant::now();
        let s: f64 = a.par_chunks(1 << 16).map(|c| c.iter().sum::<f64>()).sum();
        best_par = best_par.min(t.elapsed().as_secs_f64());
        check += s;
        let t = Instant::now();
        let s: f64 = a.chunks(1 << 16).map(|c| c.iter().sum::<f64>()).sum();
        best_seq = best_seq.min(t.elapsed().as_secs_f64());
        check += s;
    }
    std::hint::black_box(check);
    let bytes = (len * 8) as f64;
    (bytes / best_par / 1e9, bytes / best_seq / 1e9)
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let (bw, bw_seq) = read_bandwidth_gbs();
    println!(
        "read bandwidth (sum over 512 MB, best of 5): {bw:.2} GB/s on {} threads, {bw_seq:.2} GB/s on one",
        rayon::current_num_threads()
    );

    let t0 = Instant::now();
    let cells = (0..H).flat_map(|j| (0..W).flat_map(move |i| [(i, j, false), (i, j, true)]));
    let spline = GridSpline::new(cells);
    let kf = K as f64;
    let params: Vec<SurfaceParam> = (0..H * K)
        .flat_map(|b| {
            (0..W * K).map(move |a| SurfaceParam {
                face: 0,
                u: a as f64 / kf,
                v: b as f64 / kf,
            })
        })
        .collect();
    let data: Vec<DVec3> = params.par_iter().map(|p| height(p.u, p.v)).collect();
    let basis = collocation(&spline, &params);
    let setup_ms = t0.elapsed().as_secs_f64() * 1e3;
    let (n, nt) = (basis.n(), basis.nt());
    let (rows, cols, nnz) = (n.nrows, n.ncols, n.nnz());
    println!(
        "{rows} data points, {cols} control points, {nnz} weights ({:.1} per row); setup {setup_ms:.0} ms",
        nnz as f64 / rows as f64
    );
    // Bytes one step touches in the two products.
    let matrix = |m: &trispline::fit::Csr| m.nnz() * 12 + (m.nrows + 1) * 8;
    let bytes_n = matrix(n) + cols * 24 + rows * 24;
    let bytes_nt = matrix(nt) + rows * 24 + cols * 24;
    let bound_ms = (bytes_n + bytes_nt) as f64 / (bw * 1e9) * 1e3;
    println!(
        "bytes per step: N x {:.1} MB + N^T r {:.1} MB = {:.1} MB -> bound {bound_ms:.2} ms per step",
        bytes_n as f64 / 1e6,
        bytes_nt as f64 / 1e6,
        (bytes_n + bytes_nt) as f64 / 1e6
    );

    // The two products alone.
    let x = vec![DVec3::new(0.1, 0.2, 0.3); cols];
    let mut y = vec![DVec3::ZERO; rows];
    let mut z = vec![DVec3::ZERO; cols];
    let (mut tn, mut tt) = (Vec::new(), Vec::new());
    for _ in 0..9 {
        let t = Instant::now();
        basis.mul_vec3(&x, &mut y);
        tn.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        basis.mul_t_vec3(&y, &mut z);
        tt.push(t.elapsed().as_secs_f64() * 1e3);
    }
    std::hint::black_box(&z);
    let (mn, mt) = (median(&mut tn), median(&mut tt));
    println!(
        "N x: {:.2} ms min / {mn:.2} median ({:.2} GB/s); N^T r: {:.2} ms min / {mt:.2} median ({:.2} GB/s)",
        tn[0],
        bytes_n as f64 / mn / 1e6,
        tt[0],
        bytes_nt as f64 / mt / 1e6
    );

    let start = vec![DVec3::ZERO; cols];
    let problem = FitProblem {
        basis: &basis,
        data: &data,
        smoothing: 0.0,
        fairness: None,
        pia_operator: None,
        on_step: None,
    };
    println!("\n| method | step min ms | step median ms | bound ms | median / bound |");
    println!("|---|---|---|---|---|");
    for method in [Method::Cg, Method::Lspia] {
        let budget = Budget {
            max_iterations: 15,
            stall_steps: 0,
            ..Budget::default()
        };
        let out = fit(&problem, start.clone(), method, &budget).expect("fit");
        let mut per_step: Vec<f64> = out
            .steps
            .windows(2)
            .skip(1)
            .map(|w| w[1].elapsed_ms - w[0].elapsed_ms)
            .collect();
        let med = median(&mut per_step);
        println!(
            "| {method:?} | {:.2} | {med:.2} | {bound_ms:.2} | {:.2} |",
            per_step[0],
            med / bound_ms
        );
    }

    // Start for the budget runs: the control points on the surface at their own grid
    // positions (what an inverse-subdivided net roughly gives).
    let net: Vec<DVec3> = spline
        .control_coords()
        .iter()
        .map(|&(i, j)| height(i as f64, j as f64))
        .collect();
    println!("\nsteps to reach max error <= target (start: the surface sampled at the control points; cap 300 steps)");
    println!("| target | lspia | cg |\n|---|---|---|");
    for target in [1e-2, 5e-3, 2.5e-3] {
        let mut cells = Vec::new();
        for method in [Method::Lspia, Method::Cg] {
            let budget = Budget {
                tolerance: target,
                max_error: Some(target),
                max_iterations: 300,
                stall_steps: 0,
                ..Budget::default()
            };
            let t = Instant::now();
            let out = fit(&problem, net.clone(), method, &budget).expect("fit");
            let ms = t.elapsed().as_secs_f64() * 1e3;
            let last = out.steps.last().map_or(f64::NAN, |s| s.max_error);
            cells.push(if out.status == FitStatus::Met {
                format!("{} steps, {:.2} s", out.iterations, ms / 1e3)
            } else {
                format!("not met after {} (max {last:.2e})", out.iterations)
            });
        }
        println!("| {target:e} | {} |", cells.join(" | "));
    }
    println!("(pia does not apply here: K = {K} is not a power of two, and GridSpline has no inverse-subdivision update)");

    // Sparse direct solves (faer Cholesky of N^T N + s L^T L; the fairness term keeps the
    // corner controls, which barely touch the data, definite).
    println!(
        "\n| direct solve | data points | controls | time s | max error |\n|---|---|---|---|---|"
    );
    direct_row(&spline, &basis, &data);
    let cells = (0..138).flat_map(|j| (0..138).flat_map(move |i| [(i, j, false), (i, j, true)]));
    let small = GridSpline::new(cells);
    let params: Vec<SurfaceParam> = (0..138 * 2)
        .flat_map(|b| {
            (0..138 * 2).map(move |a| SurfaceParam {
                face: 0,
                u: a as f64 / 2.0,
                v: b as f64 / 2.0,
            })
        })
        .collect();
    let data: Vec<DVec3> = params.iter().map(|p| height(p.u, p.v)).collect();
    direct_row(&small, &collocation(&small, &params), &data);
}

fn height(gx: f64, gy: f64) -> DVec3 {
    let (x, y) = (gx + 0.5 * gy, 0.866 * gy);
    DVec3::new(
        x,
        y,
        2.0 * (0.3 * x).sin() * (0.2 * y).cos() + 0.01 * (3.0 * x).sin(),
    )
}

fn direct_row(spline: &GridSpline, basis: &Collocation, data: &[DVec3]) {
    let fairness = Collocation::new(umbrella_laplacian(
        spline.control_count(),
        &spline.net_triangles(),
    ));
    let problem = FitProblem {
        basis,
        data,
        smoothing: 1e-6,
        fairness: Some(&fairness),
        pia_operator: None,
        on_step: None,
    };
    let budget = Budget {
        max_iterations: 1,
        stall_steps: 0,
        ..Budget::default()
    };
    let t = Instant::now();
    match fit(
        &problem,
        vec![DVec3::ZERO; basis.ncols()],
        Method::Direct,
        &budget,
    ) {
        Ok(out) => println!(
            "| faer Cholesky | {} | {} | {:.2} | {:.2e} |",
            basis.nrows(),
            basis.ncols(),
            t.elapsed().as_secs_f64(),
            out.steps.last().map_or(f64::NAN, |s| s.max_error)
        ),
        Err(e) => println!(
            "| faer Cholesky | {} | {} | failed: {e} | |",
            basis.nrows(),
            basis.ncols()
        ),
    }
}
