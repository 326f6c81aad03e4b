//! B-patch and DMS fits in the product (`fit.surface = "bpatch" | "dms"`): the tessellation
//! written into the GLB against an independent evaluation of the surface.json read back
//! (Seidel's recursion on the controls for B-patches, simplex splines evaluated directly by
//! Micchelli's recurrence for DMS), curvature of both read-back surfaces, and what a DMS
//! fit of a range scan shows.

use crate::shared_mesh;
use glam::{DVec2, DVec3};
use trispline::curvature::planar::DmsPatch;
use trispline::curvature::regions::{analyze, AnalysisOptions};
use trispline::curvature::{DerivativeSurface, Triangular};
use trispline::io::surface_json::{parse_surface_json, SurfaceDescription};
use trispline::io::{read_mesh_bytes, Format, LoadOptions};
use trispline::mesh::clean::{clean, CleanOptions};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::output::{surface_json, tessellated_glb};
use trispline::pipeline::scan::components::cleaned_components;
use trispline::pipeline::scattered::tessellate_planar;
use trispline::pipeline::worker::{fit_patch, run_input, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::surface::bpatch::de_boor;
use trispline::surface::dms::DmsSpline;
use trispline::surface::SurfaceParam;
use trispline::TriMesh;

/// A height field over [-h, h]^2 sampled on an n x n grid, split into triangles.
fn height_field(n: usize, h: f64, z: impl Fn(f64, f64) -> f64) -> TriMesh {
    let mut positions = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (
                -h + 2.0 * h * i as f64 / (n - 1) as f64,
                -h + 2.0 * h * j as f64 / (n - 1) as f64,
            );
            positions.push(DVec3::new(x, y, z(x, y)));
        }
    }
    let mut triangles = Vec::new();
    for j in 0..n as u32 - 1 {
        for i in 0..n as u32 - 1 {
            let v = j * n as u32 + i;
            triangles.push([v, v + 1, v + n as u32]);
            triangles.push([v + 1, v + n as u32 + 1, v + n as u32]);
        }
    }
    TriMesh::new(positions, triangles)
}

fn wavy() -> TriMesh {
    height_field(50, 0.05, |x, y| {
        0.01 * (40.0 * x).sin() * (30.0 * y).cos() + 0.3 * x * y
    })
}

/// Sphere of radius `SPHERE_R` seen from above: Gaussian curvature 1 / R^2 everywhere.
const SPHERE_R: f64 = 0.2;

fn cap() -> TriMesh {
    height_field(40, 0.06, |x, y| {
        (SPHERE_R * SPHERE_R - x * x - y * y).sqrt()
    })
}

fn config(kind: SurfaceKind) -> WorkerConfig {
    let mut cfg = WorkerConfig::default();
    cfg.fit.surface = kind;
    cfg.fit.bpatch.degree = 6;
    cfg.fit.budget.max_iterations = 300;
    cfg
}

/// Determinant of (b - a, c - a).
fn det(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// The simplex spline of `knots` at x, straight from its definition (degree 0: 1 / |det|
/// inside the knot triangle) and Micchelli's recurrence over the best-shaped knot triple.
/// Only for points off every knot line (the caller nudges them).
fn simplex(x: DVec2, knots: &[DVec2]) -> f64 {
    if knots.len() == 3 {
        let d = det(knots[0], knots[1], knots[2]);
        if d.abs() < 1e-300 {
            return 0.0;
        }
        let l = [
            det(x, knots[1], knots[2]) / d,
            det(knots[0], x, knots[2]) / d,
            det(knots[0], knots[1], x) / d,
        ];
        return if l.iter().all(|&v| v > 0.0) {
            1.0 / d.abs()
        } else {
            0.0
        };
    }
    let mut best = (0.0, [0, 1, 2]);
    for a in 0..knots.len() {
        for b in a + 1..knots.len() {
            for c in b + 1..knots.len() {
                let d = det(knots[a], knots[b], knots[c]).abs();
                if d > best.0 {
                    best = (d, [a, b, c]);
                }
            }
        }
    }
    let [a, b, c] = best.1;
    let d = det(knots[a], knots[b], knots[c]);
    let lambda = [
        det(x, knots[b], knots[c]) / d,
        det(knots[a], x, knots[c]) / d,
        det(knots[a], knots[b], x) / d,
    ];
    [a, b, c]
        .iter()
        .zip(lambda)
        .map(|(&drop, l)| {
            let rest: Vec<DVec2> = knots
                .iter()
                .enumerate()
                .filter(|(k, _)| *k != drop)
                .map(|(_, p)| *p)
                .collect();
            l * simplex(x, &rest)
        })
        .sum()
}

/// The DMS spline at domain point x: every basis function of every triangle from its
/// definition, N_b^I = |det(t_a,i, t_b,j, t_c,k)| M(x | t_a,0..i, t_b,0..j, t_c,0..k).
fn dms_direct(spline: &DmsSpline, controls: &[DVec3], x: DVec2) -> DVec3 {
    let n = spline.degree();
    let clouds = spline.knot_clouds();
    let mut sum = DVec3::ZERO;
    for (t, tri) in spline.triangles().iter().enumerate() {
        let [a, b, c] = tri.map(|v| &clouds[v as usize]);
        for j in 0..=n {
            for i in 0..=n - j {
                let k = n - i - j;
                let knots: Vec<DVec2> = a[..=i]
                    .iter()
                    .chain(&b[..=j])
                    .chain(&c[..=k])
                    .copied()
                    .collect();
                let weight = det(a[i], b[j], c[k]).abs() * simplex(x, &knots);
                sum += controls[spline.control_index(t, i, j)] * weight;
            }
        }
    }
    sum
}

/// Fits `mesh`, writes surface.json and the GLB as the worker does, reads both back, and
/// returns (GLB vertex, its tessellation parameter) pairs with the read-back surface.
fn written_and_read(
    mesh: &TriMesh,
    kind: SurfaceKind,
) -> (Vec<(DVec3, SurfaceParam)>, SurfaceDescription, f64) {
    let cfg = config(kind);
    let fitted = fit_patch(mesh, None, &cfg).expect("fits");
    let info = fitted.scattered.as_ref().expect("a planar fit");
    let tess = tessellate_planar(&fitted.fit, &info.coverage, 24);
    assert!(!tess.triangles.is_empty());
    let glb = tessellated_glb(&fitted.fit, &tess, fitted.budget.tolerance);
    let surface = surface_json(&fitted.fit, None, &serde_json::json!({}));
    let read = parse_surface_json(&serde_json::to_vec(&surface).expect("json"), "s.json")
        .expect("reads back");
    let shown = read_mesh_bytes(&glb, Format::Glb, "s.glb", &LoadOptions::default())
        .expect("glb reads")
        .mesh;
    // The GLB holds the tessellation's used vertices in order of first use.
    let mut used = Vec::new();
    let mut seen = vec![false; tess.positions.len()];
    for t in &tess.triangles {
        for &v in t {
            if !std::mem::replace(&mut seen[v as usize], true) {
                used.push(v as usize);
            }
        }
    }
    assert_eq!(shown.positions.len(), used.len());
    let pairs = shown
        .positions
        .iter()
        .zip(&used)
        .map(|(p, &v)| (*p, tess.params[v]))
        .collect();
    (pairs, read, fitted.fit.geometric_rms())
}

#[test]
fn the_dms_glb_is_the_surface_json_evaluated_directly() {
    let (pairs, read, rms) = written_and_read(&wavy(), SurfaceKind::Dms);
    let SurfaceDescription::Dms { spline, controls } = read else {
        panic!("surface.json is not kind dms");
    };
    assert_eq!(spline.degree(), 2);
    assert!(rms < 1e-3, "rms {rms}");
    let mut worst: f64 = 0.0;
    for (shown, p) in pairs.iter().step_by(7) {
        let corners = spline.triangles()[p.face as usize].map(|v| spline.vertices()[v as usize]);
        let x = corners[2] + (corners[0] - corners[2]) * p.u + (corners[1] - corners[2]) * p.v;
        // Off the knot lines through the lattice point (the spline is continuous).
        let centre = (corners[0] + corners[1] + corners[2]) / 3.0;
        let direct = dms_direct(&spline, &controls, x + (centre - x) * 1e-9);
        worst = worst.max((direct - *shown).length());
    }
    // f32 in the GLB: ~1e-8 at these 0.1 m coordinates.
    assert!(worst < 1e-6, "largest difference {worst}");
}

#[test]
fn the_bpatch_glb_is_the_surface_json_by_seidels_recursion() {
    let (pairs, read, rms) = written_and_read(&wavy(), SurfaceKind::Bpatch);
    let SurfaceDescription::BPatch { patch, controls } = read else {
        panic!("surface.json is not kind bpatch");
    };
    assert_eq!(patch.degree(), 6);
    assert!(rms < 5e-3, "rms {rms}");
    let mut worst: f64 = 0.0;
    for (shown, p) in &pairs {
        worst = worst.max((de_boor(&patch, &controls, p.u, p.v) - *shown).length());
    }
    assert!(worst < 1e-6, "largest difference {worst}");
}

/// Median Gaussian curvature over an analysis of `surface`.
fn median_gaussian(surface: &dyn DerivativeSurface) -> f64 {
    let a = analyze(
        surface,
        &AnalysisOptions {
            grid: 41,
            ..AnalysisOptions::default()
        },
    );
    let mut k: Vec<f64> = a.curvature.iter().flatten().map(|c| c.gaussian).collect();
    assert!(k.len() > 100, "{} samples", k.len());
    k.sort_by(f64::total_cmp);
    k[k.len() / 2]
}

#[test]
fn curvature_reads_both_kinds_back() {
    let sphere = 1.0 / (SPHERE_R * SPHERE_R);
    for kind in [SurfaceKind::Dms, SurfaceKind::Bpatch] {
        let (_, read, _) = written_and_read(&cap(), kind);
        let k = match read {
            SurfaceDescription::Dms { spline, controls } => {
                median_gaussian(&DmsPatch { spline, controls })
            }
            SurfaceDescription::BPatch { patch, controls } => median_gaussian(&Triangular {
                surface: patch,
                controls,
            }),
            other => panic!("{kind}: read back as {other:?}"),
        };
        assert!(
            (k - sphere).abs() < 0.1 * sphere,
            "{kind}: median K {k}, the sphere's {sphere}"
        );
    }
}

/// Issue 24: a DMS fit of a range scan is shown by the rule of the other kinds' GLBs
/// (`pipeline::coverage`: the mapped patch and the fitted points' footprint, rims cut
/// finer): the GLB read back covers the fitted points and stays near the data.
#[test]
fn a_dms_fit_of_a_range_scan_is_shown_where_it_was_fitted() {
    let Some(mesh) = shared_mesh("range_scans/bun045_tri.ply") else {
        return;
    };
    let mut cfg = WorkerConfig::default();
    cfg.fit.surface = SurfaceKind::Dms;
    let outputs = run_input(&mesh, None, &cfg).expect("fits");
    let out = &outputs.parts[0].outputs;
    // The fitted points: the largest piece of the cleaned input.
    let fitted = cleaned_components(&clean(&mesh, &CleanOptions::default()))
        .into_iter()
        .next()
        .expect("a piece");
    let shown = read_mesh_bytes(&out.glb, Format::Glb, "dms.glb", &LoadOptions::default())
        .expect("the GLB reads back")
        .mesh;
    let within = super::shown_surface::share_within(&shown, &fitted.positions, 1e-3);
    let data = MeshDistance::new(&mesh);
    let farthest = shown
        .positions
        .iter()
        .filter_map(|p| data.distance(*p))
        .fold(0.0f64, f64::max);
    println!(
        "bun045_tri as DMS: {:.3} % of {} fitted points within 1 mm of the GLB, farthest shown vertex {:.0} um",
        100.0 * within,
        fitted.positions.len(),
        farthest * 1e6
    );
    // Before the coverage rule: 94.8 % (the mapped patch alone lost the rims).
    assert!(within >= 0.995, "{:.3} % within 1 mm", 100.0 * within);
    assert!(
        farthest < 1.5e-3,
        "a shown vertex {farthest} m from the data"
    );
}
