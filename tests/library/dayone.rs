//! What a scanning team meets on day one: pieces left out are reported, and a previous
//! version too different from the new one cannot blow the warm start up.

use trispline::pipeline::scan::ColdStart;
use trispline::pipeline::worker::{fit_patch, run_patch, FitConfig, FittedPatch, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::{DVec3, TriMesh};

/// A scan-like patch: an (n+1)^2 grid over [0, 1]^2 (about 1 mm spacing at n = 99 in a
/// 0.1 m patch; odd n, so that it has no subdivision connectivity) lifted into a gentle bump with a little deterministic roughness.
fn scan_patch(n: usize) -> TriMesh {
    let mut positions = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (i as f64 / n as f64, j as f64 / n as f64);
            let rough = 2e-5 * ((i * 7919 + j * 104_729) % 17) as f64 / 17.0;
            let z = 0.02 * (-((x - 0.5).powi(2) + (y - 0.4).powi(2)) * 6.0).exp() + rough;
            positions.push(DVec3::new(0.1 * x, 0.1 * y, z));
        }
    }
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in 0..n {
            triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
            triangles.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(positions, triangles)
}

/// `mesh` without the faces touching a vertex `keep` refuses.
fn without(mesh: &TriMesh, keep: impl Fn(usize) -> bool) -> TriMesh {
    TriMesh::new(
        mesh.positions.clone(),
        mesh.triangles
            .iter()
            .copied()
            .filter(|t| t.iter().all(|&v| keep(v as usize)))
            .collect(),
    )
}

fn loop_config() -> WorkerConfig {
    WorkerConfig {
        fit: FitConfig {
            surface: SurfaceKind::Loop,
            ..FitConfig::default()
        },
        ..WorkerConfig::default()
    }
}

fn scan_of(f: &FittedPatch) -> &trispline::pipeline::scan::ScanFit {
    f.scan.as_ref().expect("a scan fit")
}

#[test]
fn pieces_left_out_are_counted_with_their_share() {
    let n = 61;
    let mesh = scan_patch(n);
    // A band of columns removed: a 45-column piece and a 15-column one remain.
    let gap = |v: usize| (45..=46).contains(&(v % (n + 1)));
    let split = without(&mesh, |v| !gap(v));
    let fitted = fit_patch(&split, None, &loop_config()).expect("fits");
    let scan = scan_of(&fitted);
    let dropped = scan.preparation.dropped;
    assert_eq!(scan.preparation.components, 2);
    assert_eq!(dropped.pieces, 1);
    // Columns 47..=61 of 62 rows.
    assert_eq!(dropped.vertices, 15 * (n + 1));
    assert_eq!(dropped.largest, dropped.vertices);
    let total = dropped.vertices + scan.preparation.kept_vertices;
    assert!((dropped.share - dropped.vertices as f64 / total as f64).abs() < 1e-12);
    assert_eq!(scan.preparation.kept_vertices, fitted.fit.data.len());

    let whole = fit_patch(&mesh, None, &loop_config()).expect("fits");
    assert_eq!(scan_of(&whole).preparation.dropped.pieces, 0);
    assert_eq!(scan_of(&whole).preparation.dropped.share, 0.0);
}

/// The control budget a warm fit may not exceed: the target share of the data with the
/// warm start's slack (1.25x), plus rounding.
fn within_budget(f: &FittedPatch) -> bool {
    let target = 0.05 * f.fit.data.len() as f64;
    (f.fit.controls.len() as f64) <= 1.25 * target.round() + 1.0
}

#[test]
fn versions_too_different_start_cold_and_stay_within_the_budget() {
    // The budget as a contract: no fit past it to hold the stray bound (a fragmented
    // version's object-path fit may otherwise spend several times the budget on that).
    let mut cfg = loop_config();
    cfg.fit.scan.stray_budget_steps = 0;
    let mesh = scan_patch(99);
    let first = run_patch(&mesh, None, &cfg).expect("first version");

    // The same surface rescanned (fresh roughness): warm, and it reuses the controls.
    let mut rescan = mesh.clone();
    for (k, p) in rescan.positions.iter_mut().enumerate() {
        p.z += 5e-6 * ((k * 31) % 7) as f64 / 7.0;
    }
    let again = fit_patch(&rescan, Some(&first.warm), &cfg).expect("rescan");
    assert_eq!(scan_of(&again).cold_start, None);
    assert!(again.fit.warm_start);
    assert!(scan_of(&again).reused_controls > 0);

    // A fifth of the vertices gone at random (deterministic hash): a piece full of holes
    // with fragments around it.
    let gone = |v: usize| (v.wrapping_mul(2_654_435_761) >> 7).is_multiple_of(5);
    let fragmented = without(&mesh, |v| !gone(v));
    let f = fit_patch(&fragmented, Some(&first.warm), &cfg).expect("fragmented");
    let s = scan_of(&f);
    assert!(
        s.preparation.components > 1,
        "{} pieces",
        s.preparation.components
    );
    // The largest piece keeps most of the points on the same ground: whether it starts
    // warm or cold, its controls stay within the budget and near a cold fit's.
    let cold = fit_patch(&fragmented, None, &cfg).expect("fragmented, cold");
    assert!(within_budget(&f), "{} controls", f.fit.controls.len());
    assert!(
        f.fit.controls.len() as f64 <= 1.25 * cold.fit.controls.len() as f64,
        "warm {} vs cold {} controls",
        f.fit.controls.len(),
        cold.fit.controls.len()
    );

    // Half of it cut away.
    let cut = without(&mesh, |v| v % 100 < 50);
    let f = fit_patch(&cut, Some(&first.warm), &cfg).expect("cut");
    assert!(
        matches!(scan_of(&f).cold_start, Some(ColdStart::Pieces { .. })),
        "{:?}",
        scan_of(&f).cold_start
    );
    assert!(within_budget(&f), "{} controls", f.fit.controls.len());

    // Moved by a tenth of its bounding-box diagonal.
    let shift = 0.1 * mesh.bounds_diagonal() * DVec3::new(1.0, 1.0, 0.0).normalize();
    let mut moved = mesh.clone();
    for p in &mut moved.positions {
        *p += shift;
    }
    let f = fit_patch(&moved, Some(&first.warm), &cfg).expect("moved");
    let reason = scan_of(&f).cold_start.expect("starts cold");
    assert!(matches!(reason, ColdStart::Shift { .. }), "{reason:?}");
    assert!(reason.to_string().starts_with("frame:"), "{reason}");
    assert!(within_budget(&f), "{} controls", f.fit.controls.len());

    // Turned by 45 degrees about the x axis.
    let (sin, cos) = 45f64.to_radians().sin_cos();
    let mut turned = mesh.clone();
    for p in &mut turned.positions {
        *p = DVec3::new(p.x, cos * p.y - sin * p.z, sin * p.y + cos * p.z);
    }
    let f = fit_patch(&turned, Some(&first.warm), &cfg).expect("turned");
    assert!(
        matches!(scan_of(&f).cold_start, Some(ColdStart::Frame { .. })),
        "{:?}",
        scan_of(&f).cold_start
    );
}

/// Whatever the previous state, a warm grid has at most the budget's slack of controls:
/// a previous version fitted on a far finer grid (a tenth of the spacing) is refused for
/// the budget even when nothing else changed.
#[test]
fn a_previous_grid_far_finer_than_the_budget_is_refused() {
    let mesh = scan_patch(61);
    let mut fine = loop_config();
    fine.fit.scan.target_controls_pct = 40.0;
    let first = run_patch(&mesh, None, &fine).expect("fine first version");
    let cfg = loop_config();
    let f = fit_patch(&mesh, Some(&first.warm), &cfg).expect("second version");
    let reason = scan_of(&f).cold_start.expect("starts cold");
    assert!(matches!(reason, ColdStart::Budget { .. }), "{reason:?}");
    assert!(within_budget(&f), "{} controls", f.fit.controls.len());
}
