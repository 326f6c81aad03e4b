//! `trispline fit` as a process: outputs, report fields, refusals with exit status 2.

use glam::DVec3;
use std::path::Path;
use std::process::Command;
use trispline::io::writers::write_obj;
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::TriMesh;

fn lattice_patch(n: usize) -> TriMesh {
    TriMesh::new(
        lattice_points(n)
            .into_iter()
            .map(|(i, j)| {
                let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                DVec3::new(
                    u + v / 2.0,
                    v * 0.866,
                    0.1 * (3.0 * u).sin() * (2.0 * v).cos(),
                )
            })
            .collect(),
        lattice_triangles(n),
    )
}

fn trispline(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
        .args(args)
        .output()
        .expect("runs")
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).expect("exists")).expect("json")
}

#[test]
fn fits_a_lattice_patch_and_writes_all_outputs() {
    let dir = tempfile::tempdir().expect("tmp");
    let input = dir.path().join("patch.obj");
    write_obj(&input, &lattice_patch(32)).expect("write");
    let out = dir.path().join("out");
    let o = trispline(&[
        "fit",
        input.to_str().unwrap_or_default(),
        "--surface",
        "bezier",
        "--levels",
        "2",
        "--out",
        out.to_str().unwrap_or_default(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = read_json(&out.join("report.json"));
    assert_eq!(report["data_points"], 561);
    assert_eq!(report["control_points"], 45);
    assert_eq!(report["degree"], 8);
    assert_eq!(report["status"], "met");
    let fin = &report["final"];
    let tol = report["tolerance"].as_f64().expect("tolerance");
    assert!(fin["max_error"].as_f64().expect("max") <= tol);
    assert!(
        fin["geometric_max_error"].as_f64().expect("geo")
            <= fin["max_error"].as_f64().expect("max") + 1e-12
    );
    assert_eq!(report["iterations"][0]["k"], 0);
    let surface = read_json(&out.join("surface.json"));
    assert_eq!(surface["schema"], "trispline.surface/1");
    assert_eq!(
        surface["control_points"].as_array().map(|a| a.len()),
        Some(45)
    );
    let glb = std::fs::read(out.join("surface.glb")).expect("glb");
    let (doc, _, _) = gltf::import_slice(&glb).expect("valid glb");
    let prim = doc
        .meshes()
        .next()
        .and_then(|m| m.primitives().next())
        .expect("primitive");
    assert!(prim.get(&gltf::Semantic::Colors(0)).is_some());
    // What the colours mean, beside them and in the report.
    let legend = std::fs::read_to_string(out.join("legend.svg")).expect("legend");
    assert!(legend.starts_with("<svg") && legend.contains("tolerance"));
    let stops = report["error_ramp"]["stops"]
        .as_array()
        .expect("ramp stops");
    assert_eq!(stops[2]["error"].as_f64(), Some(tol));
    // One line on success: status, errors, size and time.
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert_eq!(stdout.lines().count(), 1, "{stdout}");
    assert!(
        stdout.contains(": met") && stdout.contains("RMS") && stdout.contains("45 control points"),
        "{stdout}"
    );
}

#[test]
fn refuses_unsupported_inputs_with_status_2() {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("out");
    // A closed octahedron has no subdivision connectivity and is no disk to remesh.
    let (positions, faces) = trispline::testdata::octahedron();
    let oct = TriMesh::new(positions, faces);
    let closed = dir.path().join("closed.obj");
    write_obj(&closed, &oct).expect("write");
    let o = trispline(&[
        "fit",
        closed.to_str().unwrap_or_default(),
        "--domain",
        "grid",
        "--out",
        out.to_str().unwrap_or_default(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("subdivision connectivity") && err.contains("not disk-like"),
        "{err}"
    );
    // `loop` on an input with subdivision connectivity: the exact Loop limit surface of its
    // own coarse net (a 4-segment lattice after 2 levels: 15 controls, 16 faces).
    let input = dir.path().join("patch.obj");
    write_obj(&input, &lattice_patch(16)).expect("write");
    let o = trispline(&[
        "fit",
        input.to_str().unwrap_or_default(),
        "--surface",
        "loop",
        "--min-levels",
        "2",
        "--out",
        out.to_str().unwrap_or_default(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).expect("report"))
            .expect("json");
    assert!(report.get("remeshed").is_none());
    let surface: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("surface.json")).expect("surface"))
            .expect("json");
    assert_eq!(surface["kind"], "loop");
    assert_eq!(surface["layout"], "mesh");
    assert_eq!(surface["control_points"].as_array().map(Vec::len), Some(15));
    assert_eq!(surface["control_faces"].as_array().map(Vec::len), Some(16));
    std::fs::remove_dir_all(&out).expect("clean");
    // A subdivided closed mesh has connectivity but no single-triangle lattice: Bezier refuses.
    let tet = TriMesh::new(
        vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
        vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    );
    let fine = trispline::mesh::loop_subdiv::subdivide(&tet, 2).expect("manifold");
    write_obj(&input, &fine).expect("write");
    let o = trispline(&[
        "fit",
        input.to_str().unwrap_or_default(),
        "--surface",
        "bezier",
        "--out",
        out.to_str().unwrap_or_default(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("lattice"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!out.join("surface.json").exists());
    // The Loop limit surface takes the closed net as it is.
    let o = trispline(&[
        "fit",
        input.to_str().unwrap_or_default(),
        "--surface",
        "loop",
        "--min-levels",
        "2",
        "--out",
        out.to_str().unwrap_or_default(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let surface: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("surface.json")).expect("surface"))
            .expect("json");
    assert_eq!(surface["control_faces"].as_array().map(Vec::len), Some(4));
}

#[test]
fn a_missed_budget_refines_to_one_level_less() {
    let dir = tempfile::tempdir().expect("tmp");
    let input = dir.path().join("patch.obj");
    write_obj(&input, &lattice_patch(32)).expect("write");
    let out = dir.path().join("out");
    let fit = |extra: &[&str]| {
        let mut args = vec![
            "fit",
            input.to_str().unwrap_or_default(),
            "--surface",
            "bezier",
            "--levels",
            "3",
            "--tolerance",
            "1e-9",
            "--out",
            out.to_str().unwrap_or_default(),
        ];
        args.extend_from_slice(extra);
        let o = trispline(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        read_json(&out.join("report.json"))
    };
    // Degree 4 (L = 3) cannot follow sin * cos to 1e-9; degree 8, 16 and the square case
    // only get closer: with the floor at 1 the fit ends at L = 1 (degree 16), having tried
    // L = 3 and 2 first.
    let report = fit(&[]);
    assert_eq!(report["levels"], 1);
    assert_eq!(report["degree"], 16);
    let tried = report["refinement"].as_array().expect("refinement");
    let levels: Vec<_> = tried.iter().map(|t| t["levels"].as_u64()).collect();
    assert_eq!(levels, vec![Some(3), Some(2)]);
    let err = |v: &serde_json::Value| v["final"]["max_error"].as_f64().expect("max");
    assert!(err(&report) < err(&tried[1]) && err(&tried[1]) < err(&tried[0]));
    // With the floor at the starting level nothing is refined.
    let report = fit(&["--min-levels", "3"]);
    assert_eq!(report["levels"], 3);
    assert!(report.get("refinement").is_none());
}
