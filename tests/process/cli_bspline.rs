//! `trispline bspline-fit` as a process: outputs, report fields, errors.

use std::path::Path;
use std::process::Command;
use trispline::io::surface_json::{read_surface_json, SurfaceDescription};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
}

/// An OBJ whose vertices are a rows x cols grid (row-major) of a smooth bump, triangulated.
fn write_grid_obj(path: &Path, rows: usize, cols: usize) {
    let mut s = String::new();
    for r in 0..rows {
        for c in 0..cols {
            let (x, y) = (r as f64 * 0.5, c as f64 * 0.5);
            let z = 2.0 * (-((x - 5.0).powi(2) + (y - 6.0).powi(2)) / 8.0).exp();
            s.push_str(&format!("v {x} {y} {z}\n"));
        }
    }
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let i = r * cols + c + 1;
            s.push_str(&format!(
                "f {} {} {}\nf {} {} {}\n",
                i,
                i + cols,
                i + cols + 1,
                i,
                i + cols + 1,
                i + 1
            ));
        }
    }
    std::fs::write(path, s).expect("write obj");
}

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("report.json")).expect("report")).expect("json")
}

#[test]
fn grid_fit_writes_the_four_outputs() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("grid.obj");
    write_grid_obj(&input, 25, 30);
    let out = tmp.path().join("out");
    let st = bin()
        .arg("bspline-fit")
        .arg(&input)
        .args([
            "--grid",
            "25x30",
            "--control",
            "10x12",
            "--degree",
            "3,2",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("run");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    for f in ["surface.json", "surface.igs", "surface.glb", "report.json"] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let r = report(&out);
    assert_eq!(r["control_points"], 120);
    assert_eq!(r["control_grid"], serde_json::json!([10, 12]));
    let max = r["max_error"].as_f64().expect("max_error");
    let rms = r["rms_error"].as_f64().expect("rms_error");
    assert!(max > 0.0 && max < 0.05 && rms <= max, "{max} {rms}");
    assert!(r["wall_ms"].as_f64().is_some_and(|t| t > 0.0));
    match read_surface_json(&out.join("surface.json")).expect("surface.json") {
        SurfaceDescription::BSpline(s) => {
            assert_eq!(s.degrees(), (3, 2));
            assert_eq!(s.counts(), (10, 12));
        }
        other => panic!("kind {other:?}"),
    }
    let glb = std::fs::read(out.join("surface.glb")).expect("glb");
    let (doc, _, _) = gltf::import_slice(&glb).expect("valid glb");
    assert_eq!(doc.meshes().count(), 1);
    let igs = std::fs::read_to_string(out.join("surface.igs")).expect("igs");
    assert!(igs.lines().all(|l| l.len() == 80));
}

#[test]
fn tolerance_grows_the_net_until_it_holds() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("grid.obj");
    write_grid_obj(&input, 30, 30);
    for (tol, method) in [("1e-3", "lsq"), ("1e-4", "two-pass")] {
        let out = tmp.path().join(format!("out{tol}"));
        let st = bin()
            .arg("bspline-fit")
            .arg(&input)
            .args([
                "--grid",
                "30x30",
                "--control",
                "30x30",
                "--tolerance",
                tol,
                "--method",
                method,
                "--out",
            ])
            .arg(&out)
            .output()
            .expect("run");
        assert!(
            st.status.success(),
            "{}",
            String::from_utf8_lossy(&st.stderr)
        );
        let r = report(&out);
        let t: f64 = tol.parse().expect("f64");
        assert!(r["max_error"].as_f64().expect("max") <= t);
        assert_eq!(r["within_tolerance"], true);
        assert!(
            r["control_points"].as_u64().expect("n") < 900,
            "{}",
            r["control_points"]
        );
    }
}

#[test]
fn scattered_fit_of_a_mesh() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("grid.obj");
    write_grid_obj(&input, 40, 35);
    let out = tmp.path().join("out");
    let st = bin()
        .arg("bspline-fit")
        .arg(&input)
        .args([
            "--scattered",
            "--control",
            "12x12",
            "--degree",
            "3,3",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("run");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let r = report(&out);
    assert_eq!(r["points"], 1400);
    // A 12 x 12 grid fit of the same points reaches 0.063 max, 0.0085 RMS (narrow bump).
    assert!(
        r["max_error"].as_f64().expect("max") < 0.07,
        "{}",
        r["max_error"]
    );
    assert!(
        r["rms_error"].as_f64().expect("rms") < 0.0085,
        "{}",
        r["rms_error"]
    );
}

#[test]
fn a_closed_surface_is_refused_by_the_one_patch_fit() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("torus.obj");
    trispline::io::write_mesh_file(&input, &trispline::testdata::torus(32, 12)).expect("write");
    let out = tmp.path().join("out");
    let st = bin()
        .arg("bspline-fit")
        .arg(&input)
        .args(["--scattered", "--control", "8x8", "--out"])
        .arg(&out)
        .output()
        .expect("run");
    assert_eq!(st.status.code(), Some(2));
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(
        err.contains("genus 1, 0 boundary loops) has no planar parameters"),
        "{err}"
    );
    assert!(!out.join("surface.json").exists());
}

#[test]
fn bad_arguments_fail_with_a_reason() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("grid.obj");
    write_grid_obj(&input, 10, 10);
    let cases: [&[&str]; 4] = [
        &["--grid", "9x10", "--control", "5x5"],
        &["--grid", "10x10", "--control", "12x12"],
        &["--control", "5x5"],
        &["--grid", "10x10", "--control", "5x5", "--degree", "0,3"],
    ];
    for args in cases {
        let st = bin()
            .arg("bspline-fit")
            .arg(&input)
            .args(args)
            .arg("--out")
            .arg(tmp.path().join("o"))
            .output()
            .expect("run");
        assert!(!st.status.success(), "{args:?} succeeded");
        assert!(!st.stderr.is_empty(), "{args:?}: no message");
    }
    assert!(!tmp.path().join("o/surface.json").exists());
}

#[test]
fn bunny_window_of_the_range_grid() {
    let Some(ply) = trispline::testdata::shared_data("range_scans/bun000_range_grid.ply") else {
        return;
    };
    let tmp = tempfile::tempdir().expect("tmp");
    let out = tmp.path().join("out");
    let st = bin()
        .arg("bspline-fit")
        .arg(&ply)
        .args([
            "--grid",
            "30x30",
            "--window",
            "98,192",
            "--control",
            "12x12",
            "--degree",
            "3,3",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("run");
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let r = report(&out);
    // Metres: the fit is within 1 mm at the data parameters on this window.
    assert!(
        r["max_error"].as_f64().expect("max") < 1e-3,
        "{}",
        r["max_error"]
    );
    // The whole grid has holes: a grid fit of it is refused with the reason.
    let st = bin()
        .arg("bspline-fit")
        .arg(&ply)
        .args(["--grid", "400x512", "--control", "12x12", "--out"])
        .arg(tmp.path().join("whole"))
        .output()
        .expect("run");
    assert!(!st.status.success());
    assert!(String::from_utf8_lossy(&st.stderr).contains("no range data"));
}
