//! Whole objects that grow: a new version covering more than the previous one extended
//! over its new ground from the previous control mesh, and the versions that are fitted
//! whole instead (old ground moved under most controls, or far off the previous surface).

use crate::object_pipeline::{config, controls_kept, geometric_error};
use glam::DVec3;
use trispline::pipeline::worker::{run_patch, Domain, PatchOutputs, WorkerConfig};
use trispline::testdata::torus;
use trispline::TriMesh;

/// The part of a torus from `torus(_, m)` before its `rows`-th ring: a tube with two rims.
fn torus_section(torus: &TriMesh, m: usize, rows: usize) -> TriMesh {
    let kept: Vec<[u32; 3]> = torus
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| (v as usize) / m < rows))
        .copied()
        .collect();
    TriMesh::new(torus.positions[..rows * m].to_vec(), kept)
}

#[test]
fn an_object_that_grows_is_extended_over_its_new_ground() {
    let full = torus(240, 80);
    let cfg = config(Domain::Mesh, 5.0);
    let first = run_patch(&torus_section(&full, 80, 150), None, &cfg).expect("fits");
    let grown = torus_section(&full, 80, 190);
    let second = run_patch(&grown, Some(&first.warm), &cfg).expect("fits warm");
    let cold = run_patch(&grown, None, &cfg).expect("fits cold");
    let r = &second.report;
    assert_eq!(r["object"]["warm"]["used"], true, "{}", r["object"]["warm"]);
    let local = &r["object"]["local"];
    let count = |k: &str| local[k].as_u64().unwrap_or(0) as usize;
    // The 40 new rings hold 3,200 points; the rest of the tube is old ground.
    assert!(count("new_ground_points") >= 3000, "{local}");
    let m = first.warm.controls.len();
    let n = second.warm.controls.len();
    assert!(
        n > m && count("added_controls") >= n - m,
        "{local}: {m} -> {n}"
    );
    // The previous controls far from the new ground kept their positions exactly.
    let kept = controls_kept(&first.warm.controls, &second.warm.controls);
    assert!(2 * kept > m, "{kept} of {m} previous controls kept");
    let [[warm_rms, warm_max], [cold_rms, cold_max]] =
        [r, &cold.report].map(|o| ["rms", "max"].map(|k| geometric_error(o, k)));
    eprintln!(
        "extended rms {warm_rms:.3e} max {warm_max:.3e}, cold rms {cold_rms:.3e} max {cold_max:.3e}, controls {m} -> {n} (cold {})",
        cold.warm.controls.len()
    );
    assert!(
        warm_rms <= 1.5 * cold_rms,
        "extended {warm_rms} vs cold {cold_rms}"
    );
    assert!(
        warm_max <= 2.0 * cold_max,
        "extended {warm_max} vs cold {cold_max}"
    );
}

/// A torus section of 150 of 240 rings fitted, then the section grown to 190 rings with
/// the old rings `pushed` moved out from the axis by `share` of its diagonal, fitted from
/// the first fit: the grown section, that fit, and the configuration of both.
fn grown_after_a_push(
    pushed: std::ops::Range<usize>,
    share: f64,
) -> (TriMesh, PatchOutputs, WorkerConfig) {
    let full = torus(240, 80);
    let cfg = config(Domain::Mesh, 5.0);
    let first = run_patch(&torus_section(&full, 80, 150), None, &cfg).expect("fits");
    let mut grown = torus_section(&full, 80, 190);
    let push = share * grown.bounds_diagonal();
    for p in &mut grown.positions[pushed.start * 80..pushed.end * 80] {
        *p += DVec3::new(p.x, p.y, 0.0).normalize_or_zero() * push;
    }
    let second = run_patch(&grown, Some(&first.warm), &cfg).expect("fits");
    (grown, second, cfg)
}

/// New ground beside old ground that moved everywhere (a new view averaged into the whole
/// object): the extension would free most of the previous controls, so the object is
/// fitted whole, the same fit as from scratch, and the report says why.
#[test]
fn new_ground_beside_old_ground_that_moved_everywhere_is_fitted_whole() {
    // Every old ring pushed out by 0.2 % of the diagonal: far past the previous RMS, well
    // within a local change's 1 %.
    let (grown, second, cfg) = grown_after_a_push(0..150, 0.002);
    let warm = &second.report["object"]["warm"];
    assert_eq!(warm["used"], false, "{warm}");
    let why = warm["cold_because"].as_str().unwrap_or_default();
    assert!(
        why.contains("previous controls") && why.contains("not a local change"),
        "{why}"
    );
    // What the refused attempt cost is reported beside the fit's own stages.
    assert!(warm["tried_ms"].as_f64().is_some_and(|t| t > 0.0), "{warm}");
    let cold = run_patch(&grown, None, &cfg).expect("fits cold");
    assert_eq!(
        geometric_error(&second.report, "rms"),
        geometric_error(&cold.report, "rms")
    );
    assert_eq!(second.warm.controls, cold.warm.controls);
}

#[test]
fn new_ground_with_old_ground_far_off_its_surface_is_fitted_whole() {
    // Old ground far from either rim pushed out by 3 % of the diagonal: more than a local
    // change.
    let (_, second, _) = grown_after_a_push(100..110, 0.03);
    let warm = &second.report["object"]["warm"];
    assert_eq!(warm["used"], false, "{warm}");
    let why = warm["cold_because"].as_str().unwrap_or_default();
    assert!(
        why.contains("points lie up to") && why.contains("over its inner faces"),
        "{why}"
    );
}
