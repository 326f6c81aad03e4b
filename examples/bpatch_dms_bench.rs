//! Speed of the B-patch and DMS kinds (issue 24): the paper's B-patch case (91 points,
//! degree 3) and DMS case (453 points, degree 2) fitted end to end (collocation assembly
//! included), a 40k-point DMS fit of degree 2, basis evaluations per second, and the steps
//! CG / LSPIA / PIA need on a B-patch against the Bezier patch of the same degree (the same
//! polynomials: knots change only the conditioning). Cases: `examples/bpatch_dms/cases.rs`.
//!
//! Also: one DMS triangle's basis (degree 2 and 3) by the recurrence at every point against
//! its kept polynomial pieces, and the product path (`pipeline::worker::fit_patch`, DMS
//! degree 2) on the 40k-point range scan bun045_tri when the shared data is there.
//!
//! Times are min / median of repeated runs (the machine is shared).
//!
//! Run: cargo run --release --example bpatch_dms_bench [-- --scan-only]

#[path = "bpatch_dms/cases.rs"]
mod cases;

use cases::{lattice_domain, BPatchCase, DmsCase};
use glam::DVec3;
use std::time::Instant;
use trispline::fit::{Budget, FitStatus, Method};
use trispline::scattered_fit::{fit_scattered, InitialNet, ScatteredOptions};
use trispline::surface::bezier::BezierTriangle;
use trispline::surface::dms::PlanarSurface;
use trispline::surface::{BasisDerivRows, SurfaceParam, TriSurface};

fn min_median(mut times: Vec<f64>) -> (f64, f64) {
    times.sort_by(f64::total_cmp);
    (times[0], times[times.len() / 2])
}

fn time_runs(runs: usize, mut f: impl FnMut()) -> (f64, f64) {
    min_median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

fn options(method: Method, iterations: usize, initial: InitialNet) -> ScatteredOptions {
    ScatteredOptions {
        method,
        budget: Budget {
            tolerance: 0.002,
            max_iterations: iterations,
            stall_steps: 0,
            ..Budget::default()
        },
        initial,
        ..ScatteredOptions::default()
    }
}

fn fit_times(
    label: &str,
    surface: &dyn PlanarSurface,
    params: &[SurfaceParam],
    data: &[DVec3],
    initial: &InitialNet,
    runs: usize,
) {
    for (method, iterations) in [
        (Method::Direct, 1),
        (Method::Cg, 10),
        (Method::Lspia, 10),
        (Method::Pia, 10),
    ] {
        let opts = options(method, iterations, initial.clone());
        let mut last = None;
        let (min, median) = time_runs(runs, || {
            last = Some(fit_scattered(surface, params, data, &opts, None).expect("fit"));
        });
        let Some(out) = last else { continue };
        let s = out.rounds[0].steps.last().expect("steps");
        println!(
            "{label} {method:?} ({} steps): {min:.2} ms min, {median:.2} ms median (assembly {:.2} ms, solve {:.2} ms); rms {:.2e}, max {:.2e}",
            out.rounds[0].iterations, out.assembly_ms, out.solve_ms, s.rms_error, s.max_error
        );
    }
}

fn evaluations_per_second(label: &str, surface: &dyn TriSurface, params: &[SurfaceParam]) {
    let mut row = Vec::new();
    let mut rows = BasisDerivRows::default();
    let reps = (200_000 / params.len()).max(1);
    let t = Instant::now();
    let mut acc = 0.0;
    for _ in 0..reps {
        for p in params {
            surface.basis_row(*p, &mut row);
            acc += row.len() as f64;
        }
    }
    let value_rate = (reps * params.len()) as f64 / t.elapsed().as_secs_f64();
    let t = Instant::now();
    for _ in 0..reps {
        for p in params {
            surface.basis_rows_with_derivatives(*p, &mut rows);
            acc += rows.indices.len() as f64;
        }
    }
    let deriv_rate = (reps * params.len()) as f64 / t.elapsed().as_secs_f64();
    std::hint::black_box(acc);
    println!(
        "{label}: {:.2} M basis rows/s (values), {:.2} M/s (with derivatives) on one thread; {:.2} us / {:.2} us per point",
        value_rate / 1e6,
        deriv_rate / 1e6,
        1e6 / value_rate,
        1e6 / deriv_rate
    );
}

/// Steps each method needs until the RMS error is within `rel` of the least-squares
/// optimum `optimum`.
fn steps_to(
    surface: &dyn PlanarSurface,
    case: &BPatchCase,
    start: &[DVec3],
    pia: Option<trispline::fit::engine::PiaOperator>,
    optimum: f64,
    rel: f64,
) -> String {
    let mut cells = Vec::new();
    for method in [Method::Cg, Method::Lspia, Method::Pia] {
        let opts = ScatteredOptions {
            method,
            budget: Budget {
                tolerance: 0.002,
                rms_error: Some(optimum * (1.0 + rel)),
                max_iterations: 20_000,
                stall_steps: 0,
                ..Budget::default()
            },
            initial: InitialNet::Given(start.to_vec()),
            ..ScatteredOptions::default()
        };
        let out = fit_scattered(surface, &case.params, &case.data, &opts, pia).expect("fit");
        let r = &out.rounds[0];
        cells.push(match r.status {
            FitStatus::Met => format!("{}", r.iterations),
            status => format!(
                "{status:?} after {} (rms {:.4e})",
                r.iterations,
                r.steps.last().map_or(f64::NAN, |s| s.rms_error)
            ),
        });
    }
    cells.join(" | ")
}

fn optimum_rms(surface: &dyn PlanarSurface, case: &BPatchCase) -> f64 {
    let opts = options(Method::Direct, 1, InitialNet::Affine);
    let out = fit_scattered(surface, &case.params, &case.data, &opts, None).expect("fit");
    out.rounds[0].steps.last().expect("steps").rms_error
}

fn conditioning_table() {
    println!("\nSteps until the RMS error is within a factor (1 + rel) of the least-squares optimum, 91-point case, Bezier vs B-patch (same start surface; PIA = inverse Loop of the residuals, in each kind's controls: it converges to the interpolation-like fixed point of inverse subdivision, not to the least-squares fit)");
    println!("| surface | optimum rms | rel | cg | lspia | pia |\n|---|---|---|---|---|---|");
    let bezier_case = BPatchCase::new(0.0);
    let bezier = BezierAsPlanar(BezierTriangle::new(3), bezier_case.patch.clone());
    let bezier_pia = |r: &[DVec3]| bezier_case.inverse.apply(r);
    for rel in [1e-2, 1e-4, 1e-8] {
        let optimum = optimum_rms(&bezier, &bezier_case);
        let row = steps_to(
            &bezier,
            &bezier_case,
            &bezier_case.bezier_net,
            Some(&bezier_pia),
            optimum,
            rel,
        );
        println!("| bezier | {optimum:.6e} | {rel:e} | {row} |");
        for spread in [0.5, 1.0, 2.0] {
            let case = BPatchCase::new(spread);
            let optimum = optimum_rms(&case.patch, &case);
            let pia = |r: &[DVec3]| case.pia_update(r);
            let row = steps_to(&case.patch, &case, &case.start, Some(&pia), optimum, rel);
            println!("| bpatch spread {spread} | {optimum:.6e} | {rel:e} | {row} |");
        }
    }
}

/// The Bezier patch over the B-patch's domain (a B-patch with corner knots gives the
/// domain geometry; evaluation is the Bezier kind's own).
struct BezierAsPlanar(BezierTriangle, trispline::surface::bpatch::BPatch);

impl TriSurface for BezierAsPlanar {
    fn control_count(&self) -> usize {
        self.0.control_count()
    }
    fn domain_face_count(&self) -> usize {
        1
    }
    fn basis_row(&self, p: SurfaceParam, out: &mut Vec<(u32, f64)>) {
        self.0.basis_row(p, out)
    }
    fn basis_rows_with_derivatives(&self, p: SurfaceParam, out: &mut BasisDerivRows) {
        self.0.basis_rows_with_derivatives(p, out)
    }
    fn step(&self, p: SurfaceParam, du: f64, dv: f64) -> SurfaceParam {
        self.0.step(p, du, dv)
    }
}

impl PlanarSurface for BezierAsPlanar {
    fn domain_point(&self, p: SurfaceParam) -> glam::DVec2 {
        self.1.domain_point(p)
    }
    fn locate(&self, x: glam::DVec2) -> Option<SurfaceParam> {
        self.1.locate(x)
    }
    fn greville_sites(&self) -> Vec<glam::DVec2> {
        self.1.greville_sites()
    }
    fn control_net_edges(&self) -> Vec<[u32; 2]> {
        self.1.control_net_edges()
    }
}

/// One DMS domain triangle's family (knot clouds as the perturbed rule puts them, roots as
/// `DmsSpline` builds them) at `count` points: microseconds per point by the recurrence
/// and by the kept pieces (the second pass, once every cell met is converted).
fn recurrence_against_pieces(degree: usize, count: usize) {
    use glam::DVec2;
    use trispline::surface::bezier::lattice_points;
    use trispline::surface::simplex_spline::{det2, SimplexFamily};
    let corners = [
        DVec2::new(0.0, 0.0),
        DVec2::new(1.0, 0.0),
        DVec2::new(0.5, 0.866),
    ];
    let clouds: Vec<Vec<DVec2>> = corners
        .iter()
        .enumerate()
        .map(|(v, &c)| {
            (0..=degree)
                .map(|i| {
                    let phi = 0.5 + 2.4 * (i + 3 * v) as f64;
                    c + DVec2::new(phi.cos(), phi.sin()) * (0.6 * i as f64 / degree as f64)
                })
                .collect()
        })
        .collect();
    let pool: Vec<DVec2> = clouds.iter().flatten().copied().collect();
    let bits = |first: usize, n: usize| -> u16 { (((1u32 << n) - 1) as u16) << first };
    let roots: Vec<(u16, f64)> = lattice_points(degree)
        .into_iter()
        .map(|(i, j)| {
            let k = degree - i - j;
            let mask = bits(0, i + 1) | bits(degree + 1, j + 1) | bits(2 * (degree + 1), k + 1);
            (mask, det2(clouds[0][i], clouds[1][j], clouds[2][k]).abs())
        })
        .collect();
    let family = SimplexFamily::compile(&pool, &roots).expect("valid knots");
    let points: Vec<DVec2> = cases::scattered_uv(count)
        .into_iter()
        .map(|(u, v)| cases::plane(u, v))
        .collect();
    let (mut scratch, mut out) = (Vec::new(), Vec::new());
    let mut per_point = |cached: bool| {
        let t = Instant::now();
        for x in &points {
            if cached {
                family.evaluate_cached::<true>(*x, DVec2::ZERO, &mut scratch, &mut out);
            } else {
                family.evaluate::<true>(*x, DVec2::ZERO, &mut scratch, &mut out);
            }
            std::hint::black_box(&out);
        }
        t.elapsed().as_secs_f64() * 1e6 / count as f64
    };
    let recurrence = per_point(false);
    let first = per_point(true);
    let kept = per_point(true);
    println!(
        "one DMS triangle, degree {degree} ({} nodes): {recurrence:.3} us per point by the recurrence, {first:.3} us converting pieces ({} cells), {kept:.3} us from the kept pieces ({:.1}x)",
        family.node_count(),
        family.piece_count(),
        recurrence / kept
    );
}

/// `fit_patch` on bun045_tri as DMS of degree 2 (the worker's defaults otherwise).
fn product_scan() {
    use trispline::io::{read_mesh_file, LoadOptions};
    use trispline::pipeline::worker::{fit_patch, WorkerConfig};
    use trispline::pipeline::SurfaceKind;
    let Some(file) = trispline::testdata::shared_data("range_scans/bun045_tri.ply") else {
        println!("bun045_tri.ply not found: product path skipped");
        return;
    };
    let mesh = match read_mesh_file(&file, &LoadOptions::default()) {
        Ok(l) => l.mesh,
        Err(e) => {
            println!("{}: {e}", file.display());
            return;
        }
    };
    for degree in [2, 3] {
        let mut cfg = WorkerConfig::default();
        cfg.fit.surface = SurfaceKind::Dms;
        cfg.fit.dms.degree = degree;
        let mut last = None;
        let (min, median) = time_runs(3, || last = Some(fit_patch(&mesh, None, &cfg)));
        match last {
            Some(Ok(f)) => {
                let rounds = f
                    .scattered
                    .as_ref()
                    .map_or(0, |i| i.correction_rms.len().saturating_sub(1));
                println!(
                    "bun045_tri as DMS degree {degree} (fit_patch): {min:.0} ms min, {median:.0} ms median; last run: prepare {:.0} ms, fit {:.0} ms ({rounds} rounds); {} points, {} controls, rms {:.1} um",
                    f.fit.prepare_ms,
                    f.fit.fit_ms,
                    f.fit.data.len(),
                    f.fit.controls.len(),
                    f.fit.geometric_rms() * 1e6
                );
            }
            Some(Err(e)) => println!("bun045_tri as DMS degree {degree}: {e}"),
            None => {}
        }
    }
}

fn main() {
    if std::env::args().any(|a| a == "--scan-only") {
        product_scan();
        return;
    }
    let bp = BPatchCase::new(0.5);
    println!(
        "B-patch: degree 3, {} points, {} controls (outward knots, spread 0.5)",
        bp.data.len(),
        bp.patch.control_count()
    );
    fit_times(
        "bpatch",
        &bp.patch,
        &bp.params,
        &bp.data,
        &InitialNet::Given(bp.start.clone()),
        200,
    );

    let dms = DmsCase::paper();
    println!(
        "\nDMS: degree 2, {} points, {} domain triangles, {} controls, {} recurrence nodes",
        dms.data.len(),
        dms.spline.domain_face_count(),
        dms.spline.control_count(),
        dms.spline.node_count()
    );
    fit_times(
        "dms",
        &dms.spline,
        &dms.params,
        &dms.data,
        &InitialNet::Affine,
        50,
    );

    let big = DmsCase::new(lattice_domain(24), 2, 40_000);
    println!(
        "\nDMS: degree 2, {} points, {} domain triangles, {} controls",
        big.data.len(),
        big.spline.domain_face_count(),
        big.spline.control_count()
    );
    let t = Instant::now();
    let _ = cases::DmsCase::new(lattice_domain(24), 2, 10);
    println!(
        "spline construction (knots, recurrence compilation, grids): {:.2} ms",
        t.elapsed().as_secs_f64() * 1e3
    );
    fit_times(
        "dms 40k",
        &big.spline,
        &big.params,
        &big.data,
        &InitialNet::Affine,
        5,
    );
    let corrected = ScatteredOptions {
        correction_rounds: 2,
        ..options(Method::Direct, 1, InitialNet::Affine)
    };
    let mut last = None;
    let (min, median) = time_runs(3, || {
        last = Some(
            fit_scattered(&big.spline, &big.params, &big.data, &corrected, None).expect("fit"),
        );
    });
    if let Some(out) = last {
        println!(
            "dms 40k direct + 2 foot-point rounds: {min:.1} ms min, {median:.1} ms median (last run: assembly {:.1} ms, solves {:.1} ms, foot points {:.1} ms)",
            out.assembly_ms, out.solve_ms, out.correction_ms
        );
    }

    println!();
    evaluations_per_second("bpatch degree 3", &bp.patch, &bp.params);
    evaluations_per_second("dms degree 2 (453-point case)", &dms.spline, &dms.params);
    let dms3 = DmsCase::new(cases::paper_domain(), 3, 453);
    evaluations_per_second("dms degree 3 (453-point case)", &dms3.spline, &dms3.params);
    evaluations_per_second(
        "dms degree 2 (24-lattice domain)",
        &big.spline,
        &big.params[..20_000],
    );

    println!();
    recurrence_against_pieces(2, 20_000);
    recurrence_against_pieces(3, 20_000);
    println!();
    product_scan();

    conditioning_table();
}
