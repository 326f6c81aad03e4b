//! `loop` on inputs with subdivision connectivity: the exact Loop limit surface of the
//! input's own coarse net (extraordinary vertices, boundaries) is fitted, not a remeshed
//! lattice. Known nets are recovered from their own limit surface; the elephant fits.

use crate::shared_mesh;
use trispline::fit::{Budget, FitStatus, Method};
use trispline::mesh::detect::Hierarchy;
use trispline::mesh::distance::MeshDistance;
use trispline::mesh::inverse::{coarsen, InverseMethod};
use trispline::mesh::loop_subdiv::subdivide;
use trispline::mesh::topology::Topology;
use trispline::pipeline::output::tessellate;
use trispline::pipeline::subdivided::fit_subdivided;
use trispline::pipeline::worker::{fit_patch, outputs_of, run_patch, FitConfig, WorkerConfig};
use trispline::pipeline::{FitOptions, SurfaceKind};
use trispline::surface::loop_limit::LoopLimitSurface;
use trispline::surface::{SurfaceParam, TriSurface};
use trispline::{DVec3, TriMesh};

/// An open disc around a valence-5 centre, with a second ring whose vertices have valence
/// 4 to 7 and boundary vertices with two to four faces: extraordinary everywhere.
fn irregular_disc() -> TriMesh {
    let mut positions = vec![DVec3::new(0.0, 0.0, 0.3)];
    let ring = 5;
    for k in 0..ring {
        let a = std::f64::consts::TAU * k as f64 / ring as f64;
        positions.push(DVec3::new(a.cos(), a.sin(), 0.1 * (3.0 * a).sin()));
    }
    let outer = 12;
    for k in 0..outer {
        let a = std::f64::consts::TAU * (k as f64 + 0.3) / outer as f64;
        positions.push(DVec3::new(
            2.1 * a.cos(),
            2.0 * a.sin(),
            -0.2 * (2.0 * a).cos(),
        ));
    }
    let mut triangles = Vec::new();
    for k in 0..ring as u32 {
        triangles.push([0, 1 + k, 1 + (k + 1) % ring as u32]);
    }
    // Stitch the inner ring (5) to the outer ring (12) by angle.
    let angle = |p: DVec3| p.y.atan2(p.x).rem_euclid(std::f64::consts::TAU);
    let (mut i, mut o) = (0usize, 0usize);
    let inner_id = |i: usize| 1 + (i % ring) as u32;
    let outer_id = |o: usize| 1 + ring as u32 + (o % outer) as u32;
    let inner_angle = |i: usize| angle(positions[inner_id(i) as usize]) + (i / ring) as f64 * 7.0;
    let outer_angle = |o: usize| angle(positions[outer_id(o) as usize]) + (o / outer) as f64 * 7.0;
    while i < ring || o < outer {
        let advance_inner = o >= outer || (i < ring && inner_angle(i + 1) < outer_angle(o + 1));
        if advance_inner {
            triangles.push([inner_id(i), outer_id(o), inner_id(i + 1)]);
            i += 1;
        } else {
            triangles.push([inner_id(i), outer_id(o), outer_id(o + 1)]);
            o += 1;
        }
    }
    TriMesh::new(positions, triangles)
}

/// The fine mesh of `net` subdivided `levels` times with every vertex moved onto the net's
/// limit surface, and the coarse faces the pipeline will find.
fn limit_samples(net: &TriMesh, levels: usize) -> TriMesh {
    let fine = subdivide(net, levels).expect("subdivides");
    let topo = Topology::from_mesh(&fine).expect("manifold");
    let (hierarchy, _) = Hierarchy::detect(&topo, levels);
    assert_eq!(hierarchy.depth(), levels);
    let coarse = coarsen(&fine, levels, InverseMethod::Exact).expect("coarsens");
    // Coarse vertices come in the order of the even vertices, which is the net's order.
    assert_eq!(coarse.mesh.positions.len(), net.positions.len());
    let surface =
        LoopLimitSurface::new(net.positions.len(), &coarse.mesh.triangles).expect("surface");
    let positions = hierarchy
        .fine_vertex_params(&topo)
        .into_iter()
        .map(|(face, u, v)| {
            surface
                .evaluate(&net.positions, SurfaceParam { face, u, v })
                .position
        })
        .collect();
    TriMesh::new(positions, fine.triangles)
}

fn options(method: Method, levels: usize) -> FitOptions<'static> {
    FitOptions {
        surface: SurfaceKind::Loop,
        levels,
        method,
        inverse: InverseMethod::Exact,
        budget: Budget {
            tolerance: 1e-9,
            max_error: Some(1e-9),
            max_iterations: 2000,
            // Run to convergence: these tests compare with the direct solve.
            stall_steps: 0,
            ..Budget::default()
        },
        on_step: None,
    }
}

/// The largest distance between corresponding points of `a` and `b`.
fn farthest_apart(a: &[DVec3], b: &[DVec3]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f64::max)
}

#[test]
fn a_known_irregular_net_is_recovered_from_its_limit_surface() {
    let net = irregular_disc();
    let data = limit_samples(&net, 2);
    for method in [Method::Cg, Method::Direct, Method::Pia] {
        let fit = fit_subdivided(&data, &options(method, 2), None).expect("fits");
        assert_eq!(fit.controls.len(), net.positions.len());
        let worst = farthest_apart(&fit.controls, &net.positions);
        let last = fit.outcome.steps.last().expect("steps");
        eprintln!(
            "{method:?}: {} steps, max error {:.2e}, controls off by {worst:.2e}",
            fit.outcome.iterations, last.max_error
        );
        assert_eq!(fit.outcome.status, FitStatus::Met, "{method:?}");
        assert!(worst < 1e-6, "{method:?}: controls off by {worst}");
        assert!(fit.geometric_max() < 1e-8, "{method:?}");
    }
}

#[test]
fn at_level_zero_the_input_is_its_own_net() {
    // Each input vertex sits at a corner of one of its faces: the net whose limit points
    // the input's vertices are is recovered. Every vertex used to land nowhere (RMS about
    // the radius on a unit icosphere).
    let net = irregular_disc();
    let data = limit_samples(&net, 0);
    let fit = fit_subdivided(&data, &options(Method::Direct, 0), None).expect("fits");
    assert_eq!(fit.controls.len(), net.positions.len());
    let worst = farthest_apart(&fit.controls, &net.positions);
    assert_eq!(fit.outcome.status, FitStatus::Met);
    assert!(worst < 1e-6, "controls off by {worst}");
    assert!(fit.geometric_max() < 1e-8);
}

#[test]
fn the_exact_path_writes_the_control_faces_and_warm_starts() {
    let net = irregular_disc();
    let mut data = limit_samples(&net, 2);
    // Some noise so that the fit has work to do.
    for (k, p) in data.positions.iter_mut().enumerate() {
        p.z += 0.002 * ((k * 7919 % 101) as f64 / 101.0 - 0.5);
    }
    let cfg = WorkerConfig {
        fit: FitConfig {
            surface: SurfaceKind::Loop,
            levels: 2,
            min_levels: 2,
            ..FitConfig::default()
        },
        tessellation: 8,
    };
    let first = run_patch(&data, None, &cfg).expect("fits");
    assert_eq!(first.surface["kind"], "loop");
    assert_eq!(first.surface["layout"], "mesh");
    let faces = first.surface["control_faces"].as_array().expect("faces");
    assert_eq!(faces.len(), net.triangles.len());
    assert_eq!(
        first.surface["control_points"].as_array().map(Vec::len),
        Some(net.positions.len())
    );
    assert_eq!(first.report["warm_start"], false);
    assert!(first.report.get("remeshed").is_none());
    // GLB: every face tessellated (at least 4 x 4).
    assert!(first.glb.len() > net.triangles.len() * 15 * 24);
    // A new version of the same patch starts from the previous controls.
    let second = run_patch(&data, Some(&first.warm), &cfg).expect("fits");
    assert_eq!(second.report["warm_start"], true);
    let steps = |r: &serde_json::Value| r["iterations"].as_array().map_or(0, Vec::len);
    assert!(steps(&second.report) <= steps(&first.report));
}

/// A sphere sampled as coarsely as CGAL's `sphere.off` (an icosahedron split twice, 162
/// vertices on the sphere) keeps the exact path, and report.json says how far its surface
/// strays from the data's facets, which sag below the sphere the surface follows: the
/// figure of the tessellation the GLB shows.
#[test]
fn the_exact_path_reports_how_far_its_surface_strays() {
    let (positions, triangles) = trispline::testdata::icosahedron();
    let fine = subdivide(&TriMesh::new(positions, triangles), 2).expect("subdivides");
    let data = TriMesh::new(
        fine.positions.iter().map(|p| p.normalize()).collect(),
        fine.triangles,
    );
    let cfg = WorkerConfig {
        fit: FitConfig {
            surface: SurfaceKind::Loop,
            ..FitConfig::default()
        },
        ..WorkerConfig::default()
    };
    let fitted = fit_patch(&data, None, &cfg).expect("fits");
    assert!(
        fitted.scan.is_none() && fitted.object.is_none(),
        "the exact path"
    );
    // Independently: every vertex of the whole tessellation the GLB shows, to the data's
    // facets.
    let shown = tessellate(&fitted.fit, cfg.tessellation, None);
    let nearest = MeshDistance::new(&data);
    let farthest = shown
        .positions
        .iter()
        .map(|&p| nearest.distance(p).expect("a finite vertex"))
        .fold(0.0, f64::max);
    let outputs = outputs_of(fitted, &cfg, std::time::Instant::now());
    let stray = &outputs.report["stray"];
    let max = stray["max"].as_f64().expect("stray.max in report.json");
    assert!(
        (max - farthest).abs() <= 1e-12,
        "report.json {max:.6e}, the GLB's vertices {farthest:.6e}"
    );
    let share = max / data.bounds_diagonal();
    assert!(
        (stray["share_of_diagonal"].as_f64().unwrap_or(f64::NAN) - share).abs() < 1e-12,
        "{stray}"
    );
    // The facets sag about half a percent of the diagonal below the sphere: the surface
    // stands near the bound, on whichever side the report says.
    assert!((0.002..0.01).contains(&share), "{share:.4}");
    assert_eq!(stray["within"], share <= 0.005, "{stray}");
}

/// The semi-regular elephant (subd2 = two exact 1-to-4 splits of subd0): fitted on its own
/// coarse net, which has extraordinary vertices all over.
#[test]
fn elephant_fits_on_its_own_coarse_net() {
    let Some(mesh) = shared_mesh("semi_regular/subd2.obj") else {
        return;
    };
    let diag = mesh.bounds_diagonal();
    for (levels, bound) in [(1usize, 2e-3), (2, 4e-3)] {
        let fit = fit_subdivided(&mesh, &options(Method::Cg, levels), None).expect("fits");
        let direct = fit_subdivided(&mesh, &options(Method::Direct, levels), None).expect("fits");
        let rms = |f: &trispline::pipeline::PatchFit| {
            f.outcome.steps.last().map_or(f64::MAX, |s| s.rms_error)
        };
        eprintln!(
            "elephant L={levels}: {} data, {} controls, cg rms {:.3e} ({} steps), direct rms {:.3e}, geometric rms {:.3e} (diag {diag:.3})",
            fit.data.len(),
            fit.controls.len(),
            rms(&fit),
            fit.outcome.iterations,
            rms(&direct),
            fit.geometric_rms()
        );
        // CG reaches the least-squares optimum.
        assert!(rms(&fit) <= rms(&direct) * (1.0 + 1e-6));
        assert!(fit.geometric_rms() < bound * diag, "L={levels}");
    }
}
