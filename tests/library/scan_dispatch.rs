//! Where a grid surface of a scan gives way to the whole-object path (it strays from the
//! data, or misses the error budget a closer object fit meets), and how far the shown grid
//! surface may stand past the scan's rim.

use super::scan_pipeline::{height_field, loop_config, range_scan};
use trispline::mesh::distance::MeshDistance;
use trispline::pipeline::output::{tessellate, Coverage};
use trispline::pipeline::worker::{fit_patch, outputs_of, run_patch};
use trispline::pipeline::SurfaceKind;
use trispline::{DVec3, TriMesh};

/// The farthest point of `fit`'s shown grid surface (the GLB's tessellation) from `data`.
fn grid_stray(data: &TriMesh, fitted: &trispline::pipeline::worker::FittedPatch) -> f64 {
    let scan = fitted.scan.as_ref().expect("a grid fit");
    let coverage = Coverage::of(&fitted.fit, scan);
    let segments = trispline::pipeline::worker::DEFAULT_TESSELLATION;
    let shown = tessellate(&fitted.fit, segments, Some(&coverage));
    let nearest = MeshDistance::new(data);
    shown
        .triangles
        .iter()
        .flatten()
        .map(|&v| {
            nearest
                .distance(shown.positions[v as usize])
                .expect("a finite vertex")
        })
        .fold(0.0, f64::max)
}

#[test]
fn a_grid_surface_straying_from_a_small_curved_patch_gives_way_to_the_object_path() {
    // Nine bumps on a patch of 324 points: the few grid cells over them bulge off the data
    // between the points (about 9 % of the diagonal), which the data-to-surface errors
    // cannot see.
    let mesh = height_field(17, 0, |x, y| {
        let bump = |t: f64| (3.0 * std::f64::consts::PI * t).sin();
        DVec3::new(x, y, 0.3 * bump(x) * bump(y))
    });
    let diagonal = mesh.bounds_diagonal();
    let mut grid_cfg = loop_config();
    grid_cfg.fit.domain = trispline::pipeline::worker::Domain::Grid;
    let grid = fit_patch(&mesh, None, &grid_cfg).expect("the grid fit");
    let grid_shown_stray = grid_stray(&mesh, &grid);
    assert!(
        grid_shown_stray > 0.005 * diagonal,
        "the grid surface strays {:.3} % of the diagonal",
        100.0 * grid_shown_stray / diagonal
    );

    let auto = run_patch(&mesh, None, &loop_config()).expect("the default fit");
    let report = &auto.report;
    assert_eq!(report["path"], "object", "{report}");
    let reason = report["object"]["path_reason"].as_str().unwrap_or_default();
    assert!(reason.starts_with("the grid surface strays"), "{reason}");
    // Closer both ways: its farthest point from the data, and the data's from it.
    let object_stray = report["object"]["stray"]["max"].as_f64().expect("a stray");
    assert_eq!(report["stray"]["max"], report["object"]["stray"]["max"]);
    let object_max = report["final"]["geometric_max_error"]
        .as_f64()
        .expect("a max");
    let grid_max = grid.fit.geometric_max();
    assert!(
        object_stray.max(object_max) < grid_shown_stray.max(grid_max),
        "object {object_stray:.3e} / {object_max:.3e}, grid {grid_shown_stray:.3e} / {grid_max:.3e}"
    );
    // The object path was given at least the grid surface's controls.
    let controls = report["control_points"].as_u64().unwrap_or(0) as usize;
    assert!(controls >= grid.fit.controls.len(), "{controls} controls");

    // The object path fits Loop surfaces only: Bezier patches asked for stay on the grid.
    let mut bezier = loop_config();
    bezier.fit.surface = SurfaceKind::Bezier;
    let kept = fit_patch(&mesh, None, &bezier).expect("the Bezier fit");
    assert!(kept.scan.is_some() && kept.object.is_none());
    // Its stray is measured and reported all the same: past the bound, as the Loop grid's.
    let expected = grid_stray(&mesh, &kept);
    let outputs = outputs_of(kept, &bezier, std::time::Instant::now());
    let stray = &outputs.report["stray"];
    let max = stray["max"].as_f64().expect("stray.max in report.json");
    assert!((max - expected).abs() <= 1e-12 * diagonal, "{stray}");
    assert_eq!(stray["within"], false, "{stray}");
}

/// A half cylinder of radius 1, three long, sampled 40 times around and 30 times along
/// (the shape and sampling of CGAL's `cylinder.off`).
fn long_half_cylinder() -> TriMesh {
    let (along, around) = (30usize, 40usize);
    let mut positions = Vec::new();
    for j in 0..around {
        let a = std::f64::consts::PI * j as f64 / (around - 1) as f64;
        for i in 0..along {
            let x = 3.0 * i as f64 / (along - 1) as f64;
            positions.push(DVec3::new(x, a.cos(), a.sin()));
        }
    }
    let id = |i: usize, j: usize| (j * along + i) as u32;
    let mut triangles = Vec::new();
    for j in 0..around - 1 {
        for i in 0..along - 1 {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(positions, triangles)
}

#[test]
fn a_grid_surface_missing_the_error_budget_gives_way_to_a_closer_object_fit() {
    // The grid surface of this half cylinder stays within the stray bound but misses the
    // data everywhere (RMS over the tolerance, a largest error): the object path is tried
    // and its surface, closer on average and no farther both ways, is kept.
    let mesh = long_half_cylinder();
    let mut grid_cfg = loop_config();
    grid_cfg.fit.domain = trispline::pipeline::worker::Domain::Grid;
    let grid = fit_patch(&mesh, None, &grid_cfg).expect("the grid fit");
    let tolerance = grid.budget.tolerance;
    let grid_rms = grid.fit.geometric_rms();
    assert!(
        grid_rms > tolerance,
        "the grid fit's RMS {grid_rms:.3e} within the tolerance {tolerance:.3e}"
    );
    let grid_distance = grid_stray(&mesh, &grid).max(grid.fit.geometric_max());

    let auto = run_patch(&mesh, None, &loop_config()).expect("the default fit");
    let report = &auto.report;
    assert_eq!(report["path"], "object", "{report}");
    let reason = report["object"]["path_reason"].as_str().unwrap_or_default();
    assert!(
        reason.starts_with("the grid surface misses the data"),
        "{reason}"
    );
    let rms = report["final"]["geometric_rms_error"]
        .as_f64()
        .expect("an RMS");
    assert!(rms < grid_rms, "object RMS {rms:.3e}, grid {grid_rms:.3e}");
    let stray = report["stray"]["max"].as_f64().expect("a stray");
    let max = report["final"]["geometric_max_error"]
        .as_f64()
        .expect("a max");
    assert!(
        stray.max(max) <= grid_distance,
        "object {stray:.3e} / {max:.3e}, grid both ways {grid_distance:.3e}"
    );
    assert_eq!(report["stray"]["within"], true, "{}", report["stray"]);
}

#[test]
fn a_tight_tolerance_on_a_noisy_scan_does_not_fit_it_on_the_object_path_too() {
    // bun000's grid surface misses a 10 um tolerance (the scan's noise is 35-50 um) but
    // lies within a thousandth of the diagonal of it on average: no gross miss, so the
    // object path is not tried (it would take ten times the grid fit and be dropped).
    let Some(mesh) = range_scan("bun000_range_grid.ply") else {
        return;
    };
    let mut cfg = loop_config();
    cfg.fit.budget.tolerance = Some(1e-5);
    let outputs = run_patch(&mesh, None, &cfg).expect("the fit");
    let report = &outputs.report;
    assert!(report["object"].is_null(), "{}", report["object"]);
    assert!(
        report["object_path_tried"].is_null(),
        "{}",
        report["object_path_tried"]
    );
    let rms = report["final"]["geometric_rms_error"]
        .as_f64()
        .expect("an RMS");
    assert!(
        rms > 1e-5,
        "the grid surface meets the tolerance: {rms:.3e}"
    );
    assert_eq!(report["stray"]["within"], true, "{}", report["stray"]);
}

#[test]
fn a_grid_surface_is_shown_no_farther_past_the_rim_than_the_stray_bound() {
    // Half a cylinder of 484 points: its grid surface curls on past the straight rims. The
    // shown part reached a few point spacings (the hole-bridging distance) past them, 2.7 %
    // of the diagonal; it stops at the bound, and the patch stays on the grid. The budget
    // is one the grid surface meets in RMS (at the default 0.1 % of the diagonal it misses
    // it by 17 %, and the object path's surface is kept, closer to the data both ways).
    let mesh = height_field(21, 0, |x, y| {
        let a = std::f64::consts::PI * y;
        DVec3::new(x, 0.5 * a.cos(), 0.5 * a.sin())
    });
    let mut cfg = loop_config();
    cfg.fit.budget.tolerance_rel = 2e-3;
    let fitted = fit_patch(&mesh, None, &cfg).expect("the fit");
    assert!(fitted.scan.is_some(), "the grid path");
    let stray = grid_stray(&mesh, &fitted);
    let diagonal = mesh.bounds_diagonal();
    assert!(
        stray <= 0.005 * diagonal,
        "the shown surface strays {:.3} % of the diagonal",
        100.0 * stray / diagonal
    );
    // report.json says what the check measured, as it says an object's stray.
    let outputs = outputs_of(fitted, &cfg, std::time::Instant::now());
    let reported = &outputs.report["stray"];
    let max = reported["max"].as_f64().expect("stray.max in report.json");
    assert!(
        (max - stray).abs() <= 1e-9 * diagonal,
        "report.json's stray {max:.6e} against the shown surface's {stray:.6e}"
    );
    assert_eq!(reported["within"], true);
    assert_eq!(reported["limit_share"], 0.005);
}
