//! Outputs other people and tools can open: file modes under the umask, `trispline
//! export` of B-spline and triangular surface.json files to STEP.

use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
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

/// A Python that imports OpenCASCADE's bindings: $TRISPLINE_OCP_PYTHON or the virtual
/// environment scripts/install_ocp.sh makes. Required under CI.
fn ocp_python() -> Option<PathBuf> {
    let from_env = std::env::var_os("TRISPLINE_OCP_PYTHON").map(PathBuf::from);
    let cache = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .map(|c| c.join("trispline/ocp/bin/python"));
    crate::cluster::first_file(
        [from_env, cache],
        "OpenCASCADE",
        "scripts/install_ocp.sh",
        "TRISPLINE_OCP_PYTHON",
    )
}

/// Fits `input` (on the object path with `extra` flags), exports the surface, and checks
/// the report and, with OpenCASCADE, the STEP and IGES files: one B-spline face per
/// patch, in metres, equal to the patches' JSON, sewn at a tolerance of 1e-9 of the size
/// into a shell whose free boundary is `free_loops` closed wires.
fn export_object(dir: &Path, name: &str, input: &Path, extra: &[&str], free_loops: usize) {
    let p = |p: &Path| p.to_str().expect("utf-8").to_string();
    let out = dir.join(name);
    let mut args = vec!["fit".to_string(), p(input), "--out".into(), p(&out)];
    args.extend(extra.iter().map(|s| s.to_string()));
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let o = under_umask("022", &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let surface = report(&out.join("surface.json"));
    assert_eq!(surface["layout"], "mesh");
    let faces = surface["control_faces"].as_array().expect("faces").len();
    let step = dir.join(format!("x/{name}.stp"));
    let o = under_umask(
        "022",
        &[
            "export",
            &p(&out.join("surface.json")),
            "--step",
            &p(&step),
            "--iges",
            &p(&step.with_extension("igs")),
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let line = String::from_utf8_lossy(&o.stdout);
    let r = report(&step.with_file_name(format!("{name}.report.json")));
    let patches = r["patches"].as_u64().expect("patches") as usize;
    match r["corner_levels"].as_u64().expect("corner levels") {
        0 => assert_eq!(patches, faces, "{line}"),
        _ => assert!(patches > faces, "{line}"),
    }
    assert!(
        line.contains(&format!("{patches} Bezier patches")),
        "{line}"
    );
    // The default corner levels meet the fit's own RMS as the largest deviation.
    let fit_rms = surface["fit"]["rms_error"].as_f64().expect("fit rms");
    assert_eq!(r["tolerance"]["value"].as_f64(), Some(fit_rms));
    assert_eq!(r["tolerance"]["met"], true, "{r}");
    assert!(r["deviation"]["max"].as_f64().expect("max") <= fit_rms);
    let Some(python) = ocp_python() else {
        return;
    };
    for cad in [step.clone(), step.with_extension("igs")] {
        let occ = read_by_opencascade(&python, &cad, &step.with_extension("json"));
        assert_eq!(occ["faces"].as_u64(), Some(patches as u64), "{occ}");
        assert_eq!(occ["degrees"], serde_json::json!(["4x4"]), "{occ}");
        let mm = occ["mm_per_unit"].as_f64().expect("unit");
        assert!((mm - 1000.0).abs() < 1e-9, "metres read as {mm} mm: {occ}");
        let difference = occ["max_difference_from_json"]
            .as_f64()
            .expect("difference");
        assert!(difference < 1e-12 * OBJECT_SIZE, "{occ}");
        assert_eq!(
            occ["closed_free_wires"].as_u64(),
            Some(free_loops as u64),
            "{occ}"
        );
        assert_eq!(occ["open_free_wires"].as_u64(), Some(0), "{occ}");
    }
}

/// The test objects are under this across (in metres, the fits' default unit).
const OBJECT_SIZE: f64 = 3.0;

/// What scripts/occ_patchwork.py says of `cad` (STEP or IGES) and the patches' JSON (`-`:
/// none), sewn at a tolerance of 1e-9 of the objects' size.
fn read_by_opencascade(python: &Path, cad: &Path, patches: &Path) -> serde_json::Value {
    let o = Command::new(python)
        .arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scripts/occ_patchwork.py"
        ))
        .arg(cad)
        .arg(patches)
        .arg(format!("{:e}", 1e-9 * OBJECT_SIZE))
        .output()
        .expect("run python");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // OpenCASCADE's IGES reader prints a line of its own before the JSON.
    let stdout = String::from_utf8_lossy(&o.stdout);
    let last = stdout
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("");
    let occ: serde_json::Value = serde_json::from_str(last).expect("json");
    assert_eq!(occ["read"], true, "{cad:?}");
    occ
}

#[test]
fn export_writes_whole_objects_as_watertight_patchworks_that_opencascade_sews() {
    let tmp = tempfile::tempdir().expect("tmp");
    // A torus: closed, genus 1; no free boundary at all.
    let input = tmp.path().join("torus.obj");
    trispline::io::write_mesh_file(&input, &trispline::testdata::torus(32, 12)).expect("write");
    export_object(tmp.path(), "torus", &input, &[], 0);

    // An open sheet with a hole: its rim and the hole are the free boundary.
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
    export_object(tmp.path(), "holed", &input, &["--domain", "mesh"], 2);

    // An explicit split is taken as asked, and one beyond the cap is refused.
    let p = |p: &Path| p.to_str().expect("utf-8").to_string();
    let surface = tmp.path().join("torus/surface.json");
    let step = tmp.path().join("x/deep.stp");
    let o = under_umask(
        "022",
        &[
            "export",
            &p(&surface),
            "--step",
            &p(&step),
            "--depth",
            "1",
            "--corner-levels",
            "0",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r = report(&tmp.path().join("x/deep.report.json"));
    let faces = report(&surface)["control_faces"]
        .as_array()
        .expect("faces")
        .len();
    assert_eq!(
        (r["depth"].as_u64(), r["corner_levels"].as_u64()),
        (Some(1), Some(0))
    );
    assert_eq!(r["patches"].as_u64(), Some(4 * faces as u64));
    let fresh = tmp.path().join("not_made/deep.stp");
    let o = under_umask(
        "022",
        &["export", &p(&surface), "--step", &p(&fresh), "--depth", "4"],
    );
    assert!(
        !fresh.parent().expect("folder").exists(),
        "refused before making anything"
    );
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
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

#[test]
fn the_daemon_writes_surface_stp_beside_whole_objects_when_asked() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (input, out) = (tmp.path().join("in"), tmp.path().join("out"));
    std::fs::create_dir_all(&input).expect("in");
    trispline::io::write_mesh_file(
        &input.join("torus.obj"),
        &trispline::testdata::torus(32, 12),
    )
    .expect("write");
    // Fine enough for its grid surface to hold the stray bound: the 25 x 30 grid's strays
    // past it (0.70 %), and the object fit that then lies closer is written as STEP.
    write_bump_obj(&input.join("bump.obj"), 50, 60);
    let config = trispline::daemon::config::DEFAULT_CONFIG
        .replace("step = false", "step = true")
        .replace("step_units = \"m\"", "step_units = \"mm\"");
    assert!(config.contains("step = true") && config.contains("step_units = \"mm\""));
    std::fs::write(tmp.path().join("cfg.toml"), config).expect("config");
    let p = |p: &Path| p.to_str().expect("utf-8").to_string();
    let o = under_umask(
        "022",
        &[
            "watch",
            &p(&input),
            "--out",
            &p(&out),
            "--config",
            &p(&tmp.path().join("cfg.toml")),
            "--once",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The whole object: surface.stp, with the patchwork in report.json and the event.
    let r = report(&out.join("torus/report.json"));
    let cad = &r["cad"];
    assert_eq!(cad["written"], true, "{cad}");
    assert_eq!(cad["units"], "mm");
    assert_eq!(cad["tolerance"]["met"], true, "{cad}");
    let stp = out.join("torus/surface.stp");
    let text = std::fs::read_to_string(&stp).expect("surface.stp");
    assert!(text.starts_with("ISO-10303-21;") && text.contains("SI_UNIT(.MILLI.,.METRE.)"));
    assert_eq!(mode(&stp), 0o644);
    let hash = r["output_hashes"]["surface.stp"].as_str().expect("hash");
    assert_eq!(hash.len(), 16);
    let events = std::fs::read_to_string(out.join("events.ndjson")).expect("events");
    assert!(events
        .lines()
        .any(|l| l.contains("\"step\"") && l.contains("torus/surface.stp")));
    let validator = crate::schemas::schema("report.schema.json");
    assert_eq!(
        crate::schemas::violations(&validator, &r),
        Vec::<String>::new()
    );
    // The disk-like scan fits on its grid: no STEP, and report.json says why.
    let r = report(&out.join("bump/report.json"));
    assert_eq!(
        crate::schemas::violations(&validator, &r),
        Vec::<String>::new()
    );
    assert_eq!(r["cad"]["written"], false);
    assert!(r["cad"]["reason"]
        .as_str()
        .expect("reason")
        .contains("trispline export"));
    assert!(!out.join("bump/surface.stp").exists());
    let Some(python) = ocp_python() else {
        return;
    };
    let occ = read_by_opencascade(&python, &stp, Path::new("-"));
    assert_eq!(occ["faces"], cad["patches"], "{occ}");
    assert_eq!(occ["closed_free_wires"].as_u64(), Some(0), "{occ}");
    assert_eq!(occ["open_free_wires"].as_u64(), Some(0), "{occ}");
}
