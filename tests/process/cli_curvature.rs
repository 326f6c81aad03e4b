//! `trispline curvature` as a process, on every surface kind the project writes.

use std::path::Path;
use std::process::Command;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json")
}

fn run_ok(cmd: &mut Command) {
    let out = cmd.output().expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Outputs exist, counts add up, loops are closed polylines.
fn check_outputs(dir: &Path) -> serde_json::Value {
    for f in [
        "curvature.glb",
        "boundaries.json",
        "boundaries.obj",
        "boundaries.igs",
        "regions.json",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing");
    }
    let regions = json(&dir.join("regions.json"));
    let b = json(&dir.join("boundaries.json"));
    let list = b["regions"].as_array().expect("regions");
    let n = |k: &str| regions[k].as_u64().expect(k) as usize;
    assert_eq!(n("convex") + n("concave") + n("saddle"), list.len());
    for r in list {
        let loops = r["loops"].as_array().expect("loops");
        assert!(!loops.is_empty());
        for l in loops {
            let l = l.as_array().expect("loop");
            assert!(l.len() >= 4);
            assert_eq!(l.first(), l.last(), "closed loop");
        }
    }
    let glb = std::fs::read(dir.join("curvature.glb")).expect("glb");
    let (doc, _, _) = gltf::import_slice(&glb).expect("valid glb");
    let prims = doc.meshes().next().expect("mesh").primitives().count();
    let loops: usize = list
        .iter()
        .map(|r| r["loops"].as_array().map_or(0, Vec::len))
        .sum();
    assert_eq!(prims, 1 + loops, "surface + one line strip per loop");
    regions
}

#[test]
fn bspline_surface_of_sin_x_sin_y_has_the_known_regions() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (rows, cols) = (121, 41);
    let mut obj = String::new();
    for r in 0..rows {
        for c in 0..cols {
            let x = -3.0 + 6.0 * r as f64 / (rows - 1) as f64;
            let y = 0.1 + 1.3 * c as f64 / (cols - 1) as f64;
            obj.push_str(&format!("v {x} {y} {}\n", x.sin() * y.sin()));
        }
    }
    obj.push_str("f 1 2 3\n");
    let input = tmp.path().join("sinsin.obj");
    std::fs::write(&input, obj).expect("write");
    let fit = tmp.path().join("fit");
    run_ok(
        bin()
            .arg("bspline-fit")
            .arg(&input)
            .args(["--grid", "121x41", "--control", "60x20", "--out"])
            .arg(&fit),
    );
    let out = tmp.path().join("curv");
    run_ok(
        bin()
            .arg("curvature")
            .arg(fit.join("surface.json"))
            .args(["--grid", "201", "--out"])
            .arg(&out),
    );
    let r = check_outputs(&out);
    assert_eq!(
        (
            r["convex"].as_u64(),
            r["concave"].as_u64(),
            r["saddle"].as_u64()
        ),
        (Some(1), Some(1), Some(3))
    );
    assert_eq!(r["samples"], 201 * 201);
    // Colouring by curvature works as well.
    run_ok(
        bin()
            .arg("curvature")
            .arg(fit.join("surface.json"))
            .args(["--grid", "41", "--colour", "gaussian", "--out"])
            .arg(tmp.path().join("k")),
    );
}

#[test]
fn triangular_kinds_written_by_fit() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dome = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/patches/dome.obj");
    let single: &[&str] = &["--bezier-layout", "single"];
    for (kind, extra) in [("bezier", &[][..]), ("bezier", single), ("loop", &[][..])] {
        let name = format!("{kind}{}", extra.len());
        let fit = tmp.path().join(&name);
        run_ok(
            bin()
                .arg("fit")
                .arg(&dome)
                .args(["--surface", kind])
                .args(extra)
                .arg("--out")
                .arg(&fit),
        );
        let out = tmp.path().join(format!("{name}-curv"));
        run_ok(
            bin()
                .arg("curvature")
                .arg(fit.join("surface.json"))
                .args(["--grid", "61", "--out"])
                .arg(&out),
        );
        let r = check_outputs(&out);
        assert_eq!(r["surface_kind"], kind);
        let samples = r["samples"].as_u64().expect("samples");
        if extra.is_empty() {
            // A grid fit of the scan (bezier: one quartic patch per cell): every grid cell
            // of the domain sampled at least 2 x 2, about 61 across.
            assert!((1000..20_000).contains(&samples), "{samples} samples");
        } else {
            // The single patch: the triangular lattice of 61 a side.
            assert_eq!(samples, 61 * 62 / 2);
        }
        // The dome is one cap: a single convex or concave region covers nearly all of it.
        let total: u64 = ["convex", "concave", "saddle"]
            .iter()
            .map(|k| r[*k].as_u64().unwrap_or(0))
            .sum();
        assert!(total >= 1, "{r}");
    }
}

#[test]
fn malformed_surface_json_is_refused() {
    let tmp = tempfile::tempdir().expect("tmp");
    let bad = tmp.path().join("surface.json");
    std::fs::write(
        &bad,
        r#"{"schema":"trispline.surface/1","kind":"bspline","degree_u":3}"#,
    )
    .expect("write");
    let out = bin()
        .arg("curvature")
        .arg(&bad)
        .arg("--out")
        .arg(tmp.path().join("o"))
        .output()
        .expect("run");
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("degree_v"));
}

/// A coarse net subdivided twice by Loop's rules, written as OBJ: an input with
/// subdivision connectivity, so `fit --surface loop` writes the mesh layout.
fn subdivided_obj(path: &Path, positions: Vec<glam::DVec3>, faces: Vec<[u32; 3]>) {
    let coarse = trispline::TriMesh::new(positions, faces);
    let fine = trispline::mesh::loop_subdiv::subdivide(&coarse, 2).expect("manifold");
    trispline::io::writers::write_obj(path, &fine).expect("write");
}

fn fit_and_analyse(tmp: &Path, name: &str) -> (serde_json::Value, std::path::PathBuf) {
    let fit = tmp.join(format!("{name}-fit"));
    run_ok(
        bin()
            .arg("fit")
            .arg(tmp.join(format!("{name}.obj")))
            .args(["--surface", "loop", "--levels", "2", "--min-levels", "2"])
            .arg("--out")
            .arg(&fit),
    );
    let surface = json(&fit.join("surface.json"));
    assert_eq!(surface["layout"], "mesh", "{name}");
    let out = tmp.join(format!("{name}-curv"));
    run_ok(
        bin()
            .arg("curvature")
            .arg(fit.join("surface.json"))
            .args(["--grid", "40", "--out"])
            .arg(&out),
    );
    (surface, out)
}

#[test]
fn loop_mesh_layout_written_by_fit() {
    use glam::DVec3;
    let tmp = tempfile::tempdir().expect("tmp");
    // Closed: an octahedron (valence 4 everywhere), faces outwards.
    let mut faces = Vec::new();
    for i in 0..4u32 {
        faces.push([i, (i + 1) % 4, 4]);
        faces.push([(i + 1) % 4, i, 5]);
    }
    let octa = vec![
        DVec3::X,
        DVec3::Y,
        -DVec3::X,
        -DVec3::Y,
        DVec3::Z,
        -DVec3::Z,
    ];
    subdivided_obj(&tmp.path().join("octa.obj"), octa, faces);
    let (surface, out) = fit_and_analyse(tmp.path(), "octa");
    assert_eq!(surface["control_faces"].as_array().map(Vec::len), Some(8));
    for f in [
        "curvature.glb",
        "boundaries.json",
        "boundaries.obj",
        "boundaries.igs",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let r = json(&out.join("regions.json"));
    assert_eq!(r["surface_kind"], "loop");
    // The fitted limit surface of a convex net: one convex region, no boundary at all.
    assert_eq!(
        (r["convex"].as_u64(), r["saddle"].as_u64()),
        (Some(1), Some(0)),
        "{r}"
    );
    assert_eq!(r["regions"][0]["loops"], 0, "{r}");

    // Open: a hexagonal fan around a centre of valence 5 (a pentagon of 5 triangles with
    // a second ring), lifted by a saddle.
    let mut pos = vec![DVec3::ZERO];
    for ring in 1..=2 {
        for k in 0..5 {
            let a = std::f64::consts::TAU * (k as f64 + 0.5 * (ring - 1) as f64) / 5.0;
            let (x, y) = (ring as f64 * a.cos(), ring as f64 * a.sin());
            pos.push(DVec3::new(x, y, 0.3 * (x * x - y * y)));
        }
    }
    let mut faces = Vec::new();
    for k in 0..5u32 {
        let (a, b) = (1 + k, 1 + (k + 1) % 5);
        let (o, p) = (6 + k, 6 + (k + 1) % 5);
        faces.push([0, a, b]);
        faces.push([a, o, b]);
        faces.push([b, o, p]);
    }
    subdivided_obj(&tmp.path().join("fan.obj"), pos, faces);
    let (surface, out) = fit_and_analyse(tmp.path(), "fan");
    assert_eq!(surface["control_faces"].as_array().map(Vec::len), Some(15));
    let r = check_outputs(&out);
    assert!(r["saddle"].as_u64() >= Some(1), "{r}");
    let b = json(&out.join("boundaries.json"));
    assert!(
        b["param_loops_encoding"].is_string(),
        "mesh layout documents its packing"
    );
}
