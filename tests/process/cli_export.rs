//! Outputs other people and tools can open: file modes under the umask, `trispline
//! export` of B-spline and triangular surface.json files to STEP.

use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::Command;

/// A rows x cols grid of a smooth bump (metres, 1.2 m x 1.45 m), as OBJ.
fn write_bump_obj(path: &Path, rows: usize, cols: usize) {
    let mut s = String::new();
    for r in 0..rows {
        for c in 0..cols {
            let (x, y) = (r as f64 * 0.05, c as f64 * 0.05);
            let z = 0.2 * (-((x - 0.5).powi(2) + (y - 0.6).powi(2)) / 0.08).exp();
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

/// Runs the binary under a umask through the shell (the umask is per process).
fn under_umask(umask: &str, args: &[&str]) -> std::process::Output {
    let mut cmd = format!("umask {umask}; exec '{}'", env!("CARGO_BIN_EXE_trispline"));
    for a in args {
        cmd.push_str(&format!(" '{a}'"));
    }
    Command::new("sh")
        .args(["-c", &cmd])
        .output()
        .expect("run sh")
}

fn mode(p: &Path) -> u32 {
    std::fs::metadata(p)
        .expect("output exists")
        .permissions()
        .mode()
        & 0o777
}

#[test]
fn outputs_honour_the_umask() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("grid.obj");
    write_bump_obj(&input, 25, 30);
    let input = input.to_str().expect("utf-8 path");
    for (umask, expected) in [("022", 0o644), ("077", 0o600), ("002", 0o664)] {
        let out = tmp.path().join(format!("out{umask}"));
        let o = under_umask(
            umask,
            &[
                "bspline-fit",
                input,
                "--grid",
                "25x30",
                "--control",
                "8x8",
                "--out",
                out.to_str().expect("utf-8"),
            ],
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        for f in [
            "surface.json",
            "surface.igs",
            "surface.stp",
            "surface.glb",
            "report.json",
        ] {
            assert_eq!(mode(&out.join(f)), expected, "{f} under umask {umask}");
        }
    }
}

#[test]
fn bspline_fit_warns_when_the_declared_unit_makes_the_data_implausible() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("grid.obj");
    write_bump_obj(&input, 25, 30);
    let input = input.to_str().expect("utf-8 path");
    let out = tmp.path().join("out");
    let out = out.to_str().expect("utf-8");
    let run = |units: &str| {
        under_umask(
            "022",
            &[
                "bspline-fit",
                input,
                "--grid",
                "25x30",
                "--control",
                "8x8",
                "--units",
                units,
                "--out",
                out,
            ],
        )
    };
    let metres = run("m");
    assert!(metres.status.success());
    assert!(!String::from_utf8_lossy(&metres.stderr).contains("warning"));
    let mm = run("mm");
    assert!(mm.status.success());
    let err = String::from_utf8_lossy(&mm.stderr);
    assert!(
        err.contains("warning") && err.contains("--units m"),
        "{err}"
    );
    let stp = std::fs::read_to_string(Path::new(out).join("surface.stp")).expect("stp");
    assert!(stp.contains("SI_UNIT(.MILLI.,.METRE.)"));
}

fn report(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).expect("report")).expect("json")
}

#[test]
fn export_refuses_a_whole_object_one_b_spline_patch_cannot_take_but_not_a_holed_sheet() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("torus.obj");
    trispline::io::write_mesh_file(&input, &trispline::testdata::torus(32, 12)).expect("write");
    let out = tmp.path().join("fit");
    let p = |p: &Path| p.to_str().expect("utf-8").to_string();
    let o = under_umask("022", &["fit", &p(&input), "--out", &p(&out)]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let surface = report(&out.join("surface.json"));
    assert_eq!(surface["layout"], "mesh");
    let step = tmp.path().join("x/torus.stp");
    let o = under_umask(
        "022",
        &["export", &p(&out.join("surface.json")), "--step", &p(&step)],
    );
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("genus 1, 0 boundary loops) is closed or has handles"),
        "{err}"
    );
    assert!(!step.exists());

    // An open sheet with a hole, fitted on the same path, still exports.
    let mut sheet = trispline::testdata::height_grid(20, |x, y| 0.1 * (3.0 * x).sin() * y);
    let hole = |t: &[u32; 3]| {
        t.iter().all(|&v| {
            let (i, j) = (v % 21, v / 21);
            (7..=12).contains(&i) && (7..=12).contains(&j)
        })
    };
    sheet.triangles.retain(|t| !hole(t));
    let input = tmp.path().join("holed.obj");
    trispline::io::write_mesh_file(&input, &sheet).expect("write");
    let out = tmp.path().join("holed");
    let o = under_umask(
        "022",
        &["fit", &p(&input), "--domain", "mesh", "--out", &p(&out)],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        report(&out.join("report.json"))["topology"]["control"]["boundary_loops"],
        2
    );
    let step = tmp.path().join("x/holed.stp");
    let o = under_umask(
        "022",
        &["export", &p(&out.join("surface.json")), "--step", &p(&step)],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(step.exists());
}

#[test]
fn export_writes_a_bspline_as_is_and_converts_a_triangular_fit_with_its_deviation() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("grid.obj");
    write_bump_obj(&input, 25, 30);
    let input = input.to_str().expect("utf-8 path");
    let p = |name: &str| tmp.path().join(name).to_str().expect("utf-8").to_string();
    let o = under_umask(
        "022",
        &[
            "bspline-fit",
            input,
            "--grid",
            "25x30",
            "--control",
            "8x8",
            "--out",
            &p("bs"),
        ],
    );
    assert!(o.status.success());
    let o = under_umask(
        "022",
        &["fit", input, "--surface", "bezier", "--out", &p("tri")],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let o = under_umask(
        "022",
        &["export", &p("bs/surface.json"), "--step", &p("x/bs.stp")],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = report(&tmp.path().join("x/bs.report.json"));
    assert_eq!(r["input_kind"], "bspline");
    assert!(r["deviation"].is_null());
    // The B-spline written is the input's, control for control.
    let a: serde_json::Value = report(&tmp.path().join("bs/surface.json"));
    let b: serde_json::Value = report(&tmp.path().join("x/bs.json"));
    assert_eq!(a["control_points"], b["control_points"]);
    assert_eq!(a["knots_u"], b["knots_u"]);

    let o = under_umask(
        "022",
        &[
            "export",
            &p("tri/surface.json"),
            "--step",
            &p("x/tri.stp"),
            "--iges",
            &p("x/tri.igs"),
            "--control",
            "16x16",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("deviation"));
    let r = report(&tmp.path().join("x/tri.report.json"));
    assert_eq!(r["input_kind"], "triangular");
    assert_eq!(r["control_grid"], serde_json::json!([16, 16]));
    let max = r["deviation"]["max"].as_f64().expect("max deviation");
    let rms = r["deviation"]["rms"].as_f64().expect("rms deviation");
    // A 0.2 m bump over 1.45 m: the conversion follows it to a fraction of a millimetre.
    assert!(
        rms > 0.0 && rms <= max && max < 1e-3,
        "max {max}, rms {rms}"
    );
    assert!(r["deviation"]["samples"].as_u64().expect("samples") > 200);
    for f in ["x/tri.stp", "x/tri.igs", "x/tri.json", "x/tri.report.json"] {
        assert_eq!(mode(&tmp.path().join(f)), 0o644, "{f}");
    }
    let stp = std::fs::read_to_string(tmp.path().join("x/tri.stp")).expect("stp");
    assert_eq!(stp.matches("B_SPLINE_SURFACE_WITH_KNOTS(").count(), 1);
}
