//! `trispline fit` on scans without subdivision connectivity: remeshed onto a lattice and
//! fitted; closed and higher-genus meshes refused with the reason.

use std::path::Path;
use std::process::Command;
use trispline::testdata::shared_data;

fn trispline(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn an_irregular_patch_is_remeshed_and_fitted_with_a_trim() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("out");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/patches/dome.obj");
    let o = trispline(&[
        "fit",
        input.to_str().unwrap_or_default(),
        "--surface",
        "bezier",
        "--lattice",
        "12",
        "--iterations",
        "200",
        "--out",
        out.to_str().unwrap_or_default(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).expect("report"))
            .expect("json");
    assert_eq!(report["remeshed"], true);
    assert_eq!(report["control_points"], 91);
    assert_eq!(
        report["data_points"], 1254,
        "every scan vertex is a data point; no virtual ones"
    );
    // Every stage's time, the file's read included (the benchmark reads them).
    for stage in [
        "read_ms",
        "parameterization_ms",
        "resample_ms",
        "prepare_ms",
        "fit_ms",
        "wall_ms",
    ] {
        assert!(
            report[stage].as_f64().is_some_and(|t| t > 0.0),
            "{stage}: {}",
            report[stage]
        );
    }
    // The dome spans 2.83 units; a degree-12 patch follows it to well under 1 %.
    let rms = report["final"]["geometric_rms_error"]
        .as_f64()
        .expect("rms");
    assert!(rms < 0.01, "geometric rms {rms}");
    let surface: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("surface.json")).expect("surface"))
            .expect("json");
    assert!(surface["trim"]["outer"]
        .as_array()
        .is_some_and(|a| a.len() > 10));
}

#[test]
fn closed_and_higher_genus_meshes_are_refused_by_the_grid_domain() {
    for rel in ["models/decimated-max.obj", "models/fertility.off"] {
        let Some(path) = shared_data(rel) else { return };
        let dir = tempfile::tempdir().expect("tmp");
        let out = dir.path().join("out");
        let o = trispline(&[
            "fit",
            path.to_str().unwrap_or_default(),
            "--domain",
            "grid",
            "--out",
            out.to_str().unwrap_or_default(),
        ]);
        assert_eq!(o.status.code(), Some(2), "{rel}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains("not disk-like"), "{rel}: {err}");
        assert!(!out.join("surface.json").exists());
    }
}

/// `fit input args --out out`, which must exit 2 and write no surface: its stderr.
fn refused(input: &Path, args: &[&str], out: &Path) -> String {
    let mut all = vec!["fit", input.to_str().unwrap_or_default()];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", out.to_str().unwrap_or_default()]);
    let o = trispline(&all);
    assert_eq!(o.status.code(), Some(2), "{args:?}");
    assert!(!out.join("surface.json").exists(), "{args:?}");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn flags_are_refused_where_the_config_refuses_their_values() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("out");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/patches/dome.obj");
    for (args, key) in [
        (
            &["--target-controls-pct", "0"][..],
            "fit.scan.target_controls_pct",
        ),
        (
            &["--target-controls-pct", "150"][..],
            "fit.scan.target_controls_pct",
        ),
        (
            &["--min-component-fraction", "2"][..],
            "fit.components.min_fraction",
        ),
    ] {
        let err = refused(&input, args, &out);
        assert!(
            err.contains(key) && err.contains("must be"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn absurd_resolutions_are_refused_before_allocating() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("out");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/patches/dome.obj");
    for args in [
        &["--surface", "loop", "--lattice", "100000"][..],
        &["--surface", "loop", "--levels", "12"][..],
        &["--surface", "bezier", "--levels", "14"][..],
        &["--surface", "bezier", "--lattice", "500"][..],
    ] {
        let err = refused(&input, args, &out);
        // Refused by the config's range where it has one (the grid's segments), else by
        // the pipeline's size check.
        assert!(
            err.contains("too fine") || err.contains("at most") || err.contains("must be 1..="),
            "{args:?}: {err}"
        );
    }
}
