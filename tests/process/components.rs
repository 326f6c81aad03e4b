//! The component policy: `largest` fits one surface and says what it left out, `all` one
//! per component big enough, ids suffixed, each warm-started from the previous version's
//! piece in the same place; scans and whole objects, through the library, the CLI, the
//! daemon and on a Stanford scan.

use crate::daemon_support::*;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::pipeline::scan::components::ComponentMode;
use trispline::pipeline::worker::{run_input, ComponentsConfig, FitConfig, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::testdata::{shared_data, torus};
use trispline::{DVec3, TriMesh};

/// An n x n height field shifted by `offset`, appended to `mesh`.
fn add_sheet(mesh: &mut TriMesh, n: usize, offset: DVec3, seed: f64) {
    let base = mesh.positions.len() as u32;
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
            let z = 0.1 * (3.0 * x + seed).sin() * (2.0 * y).cos();
            mesh.positions.push(offset + DVec3::new(x, y, z));
        }
    }
    let id = |i: usize, j: usize| base + (j * n + i) as u32;
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            mesh.triangles.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
            mesh.triangles
                .push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
}

/// Two sheets (30^2 and 24^2 vertices) and a 4^2-vertex sliver.
fn three_pieces(seed: f64) -> TriMesh {
    let mut mesh = TriMesh::default();
    add_sheet(&mut mesh, 30, DVec3::ZERO, seed);
    add_sheet(&mut mesh, 24, DVec3::new(3.0, 0.0, 0.0), seed);
    add_sheet(&mut mesh, 4, DVec3::new(0.0, 3.0, 0.0), seed);
    mesh
}

fn worker(mode: ComponentMode) -> WorkerConfig {
    WorkerConfig {
        fit: FitConfig {
            surface: SurfaceKind::Loop,
            components: ComponentsConfig {
                mode,
                min_vertices: 100,
                ..ComponentsConfig::default()
            },
            ..FitConfig::default()
        },
        tessellation: 16,
    }
}

#[test]
fn all_fits_every_big_component_and_largest_only_the_largest() {
    let mesh = three_pieces(0.0);
    let all = run_input(&mesh, None, &worker(ComponentMode::All)).expect("fits");
    let suffixes: Vec<&str> = all.parts.iter().map(|p| p.suffix.as_str()).collect();
    assert_eq!(suffixes, vec![".c0", ".c1"]);
    assert!(all.failed.is_empty());
    let points: Vec<u64> = all
        .parts
        .iter()
        .map(|p| p.outputs.report["data_points"].as_u64().unwrap_or(0))
        .collect();
    assert_eq!(points, vec![900, 576]);
    let c1 = &all.parts[1].outputs.report["component"];
    assert_eq!(c1["index"], 1);
    assert_eq!(c1["total"], 3);
    assert_eq!(c1["dropped_vertices"], serde_json::json!([16]));
    for p in &all.parts {
        let rms = p.outputs.report["final"]["geometric_rms_error"]
            .as_f64()
            .unwrap_or(f64::MAX);
        assert!(rms < 1e-3, "{}: rms {rms}", p.suffix);
    }
    assert_eq!(all.warm.parts.len(), 2);

    let largest = run_input(&mesh, None, &worker(ComponentMode::Largest)).expect("fits");
    assert_eq!(largest.parts.len(), 1);
    assert_eq!(largest.parts[0].suffix, "");
    assert_eq!(largest.parts[0].outputs.report["data_points"], 900);
    assert_eq!(largest.parts[0].outputs.report["components"], 3);
}

/// Two tori apart (384 and 240 vertices; closed, so each goes the object path) and the
/// smaller one's vertex count.
fn two_tori() -> (TriMesh, usize) {
    let a = torus(32, 12);
    let mut b = torus(24, 10);
    for p in &mut b.positions {
        *p += DVec3::new(4.0, 0.0, 0.0);
    }
    let offset = a.positions.len() as u32;
    let mut both = a;
    both.positions.extend(&b.positions);
    both.triangles
        .extend(b.triangles.iter().map(|t| t.map(|v| v + offset)));
    (both, b.positions.len())
}

fn objects(mode: ComponentMode) -> WorkerConfig {
    let mut cfg = worker(mode);
    cfg.fit.scan.target_controls_pct = 10.0;
    cfg
}

#[test]
fn all_fits_each_whole_object() {
    let (both, _) = two_tori();
    let out = run_input(&both, None, &objects(ComponentMode::All)).expect("fits");
    assert_eq!(out.parts.len(), 2);
    for part in &out.parts {
        assert_eq!(part.outputs.report["path"], "object");
        assert_eq!(part.outputs.report["topology"]["control"]["genus"], 1);
        assert_eq!(part.outputs.report["dropped"]["pieces"], 0);
    }
}

#[test]
fn largest_says_which_whole_objects_it_left_out() {
    let (both, smaller) = two_tori();
    let out = run_input(&both, None, &objects(ComponentMode::Largest)).expect("fits");
    assert_eq!(out.parts.len(), 1);
    let report = &out.parts[0].outputs.report;
    assert_eq!(report["path"], "object");
    assert_eq!(report["data_points"], 384);
    let dropped = &report["dropped"];
    assert_eq!(dropped["pieces"], 1);
    assert_eq!(dropped["vertices"], smaller);
    assert_eq!(dropped["largest"], smaller);
    let share = dropped["share"].as_f64().unwrap_or(0.0);
    assert!((share - 240.0 / 624.0).abs() < 1e-12, "share {share}");
    let alone = run_input(&torus(32, 12), None, &objects(ComponentMode::Largest)).expect("fits");
    assert_eq!(alone.parts[0].outputs.report["dropped"]["pieces"], 0);

    // `trispline fit`'s line says it too, with the remedy.
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("two_tori.obj");
    trispline::io::write_mesh_file(&input, &both).expect("write");
    let out = tmp.path().join("out");
    let run = bin()
        .args(["fit", &input.display().to_string()])
        .args([
            "--target-controls-pct",
            "10",
            "--out",
            &out.display().to_string(),
        ])
        .output()
        .expect("runs");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        stdout.contains("1 piece not fitted (240 vertices, 38.5 %; --components all"),
        "{stdout}"
    );
}

#[test]
fn a_new_version_warm_starts_each_component_from_the_piece_in_the_same_place() {
    let first = run_input(&three_pieces(0.0), None, &worker(ComponentMode::All)).expect("v1");
    // The next version: the second sheet grows past the first, so the order by size swaps;
    // matching by place must still pair the pieces.
    let mut v2 = TriMesh::default();
    add_sheet(&mut v2, 30, DVec3::ZERO, 0.05);
    add_sheet(&mut v2, 31, DVec3::new(3.0, 0.0, 0.0), 0.05);
    let second = run_input(&v2, Some(&first.warm), &worker(ComponentMode::All)).expect("v2");
    assert_eq!(second.parts.len(), 2);
    for p in &second.parts {
        assert_eq!(p.outputs.report["warm_start"], true, "{}", p.suffix);
    }
    // c0 is now the 31^2 sheet at x = 3: its warm start came from v1's c1.
    let centroid_x = second.warm.parts[0].centroid.x;
    assert!((centroid_x - 3.5).abs() < 1e-9, "{centroid_x}");
    // A piece that moved far away starts cold.
    let mut moved = TriMesh::default();
    add_sheet(&mut moved, 30, DVec3::new(0.0, -10.0, 0.0), 0.0);
    let cold = run_input(&moved, Some(&first.warm), &worker(ComponentMode::All)).expect("v3");
    assert_eq!(cold.parts[0].outputs.report["warm_start"], false);
}

#[test]
fn components_under_the_vertex_floor_are_refused_with_the_reason() {
    let mut mesh = TriMesh::default();
    add_sheet(&mut mesh, 8, DVec3::ZERO, 0.0);
    for mode in [ComponentMode::All, ComponentMode::Largest] {
        let err = match run_input(&mesh, None, &worker(mode)) {
            Ok(_) => panic!("{mode:?}: a 64-vertex patch passed a floor of 100"),
            Err(e) => e.to_string(),
        };
        assert!(
            err.contains("fit.components.min_vertices"),
            "{mode:?}: {err}"
        );
    }
}

#[test]
fn the_cli_writes_one_folder_per_component_and_a_listing() {
    let tmp = tempfile::tempdir().expect("tmp");
    let input = tmp.path().join("pieces.obj");
    trispline::io::write_mesh_file(&input, &three_pieces(0.0)).expect("write");
    let out = tmp.path().join("out");
    let status = bin()
        .args(["fit", &input.display().to_string(), "--surface", "loop"])
        .args(["--components", "all", "--min-component-vertices", "100"])
        .args(["--tessellation", "8", "--out", &out.display().to_string()])
        .output()
        .expect("runs");
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
    for c in ["c0", "c1"] {
        for f in ["surface.json", "surface.glb", "report.json"] {
            assert!(out.join(c).join(f).exists(), "{c}/{f}");
        }
    }
    assert!(!out.join("c2").exists());
    let listing = read_json(&out.join("components.json"));
    assert_eq!(listing["fitted"].as_array().map(Vec::len), Some(2));
}

#[test]
fn the_daemon_writes_suffixed_patches_and_keeps_one_state_per_input() {
    let cfg =
        config(0, "native", "").replace("mode = \"largest\"", "mode = \"all\"\nmin_vertices = 100");
    let s = setup(&cfg);
    let tmp = tempfile::tempdir().expect("tmp");
    let obj = tmp.path().join("pieces.obj");
    trispline::io::write_mesh_file(&obj, &three_pieces(0.0)).expect("write");
    drop_file(&s.inbox, "scan.obj", &std::fs::read(&obj).expect("read"));
    let run = s.once();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for id in ["scan.c0", "scan.c1"] {
        let report = read_json(&s.out.join(id).join("report.json"));
        assert_eq!(report["patch"], id);
        assert!(s.out.join(id).join("surface.json").exists());
    }
    let fitted: Vec<String> = events(&s.out)
        .into_iter()
        .filter(is_fitted)
        .filter_map(|e| e["patch"].as_str().map(String::from))
        .collect();
    assert_eq!(fitted, vec!["scan.c0", "scan.c1"]);
    // Run again: the input is unchanged, so nothing is refitted.
    let again = s.once();
    assert!(again.status.success());
    assert_eq!(events(&s.out).into_iter().filter(is_fitted).count(), 2);
}

/// A patch named like a component (`scan.c0`), fitted whole under `largest`, then the
/// policy turned to `all` with a split input `scan` beside it: component 0 of `scan` used to
/// take the patch's folder (`OUT/scan.c0` fitted from two inputs). Now every id is fitted
/// from one input only: the patch is marked `~<hash>`, component 0 keeps `scan.c0`.
#[test]
fn a_patch_named_like_a_component_gets_a_folder_of_its_own() {
    let largest = config(0, "native", "");
    let all = largest.replace("mode = \"largest\"", "mode = \"all\"\nmin_vertices = 100");
    let s = setup(&largest);
    let tmp = tempfile::tempdir().expect("tmp");
    let pieces = tmp.path().join("pieces.obj");
    trispline::io::write_mesh_file(&pieces, &three_pieces(0.0)).expect("write");
    let mut lone = TriMesh::default();
    add_sheet(&mut lone, 20, DVec3::new(0.0, 0.0, 5.0), 1.0);
    let single = tmp.path().join("single.obj");
    trispline::io::write_mesh_file(&single, &lone).expect("write");
    drop_file(
        &s.inbox,
        "scan.c0.obj",
        &std::fs::read(&single).expect("read"),
    );
    let run = s.once();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    std::fs::write(&s.cfg, &all).expect("config");
    drop_file(&s.inbox, "scan.obj", &std::fs::read(&pieces).expect("read"));
    let run = s.once();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let fitted: Vec<(String, String)> = events(&s.out)
        .into_iter()
        .filter(is_fitted)
        .map(|e| {
            let input = e["input"].as_str().unwrap_or("");
            let name = input.rsplit('/').next().unwrap_or("").to_string();
            (e["patch"].as_str().unwrap_or("").to_string(), name)
        })
        .collect();
    let mut input_of = std::collections::HashMap::new();
    for (patch, input) in &fitted {
        let first = input_of.entry(patch.as_str()).or_insert(input.as_str());
        assert_eq!(
            *first,
            input.as_str(),
            "{patch} fitted from two inputs: {fitted:?}"
        );
    }
    assert_eq!(input_of.get("scan.c0"), Some(&"scan.obj"), "{fitted:?}");
    assert_eq!(input_of.get("scan.c1"), Some(&"scan.obj"), "{fitted:?}");
    let own: Vec<&&str> = input_of
        .iter()
        .filter(|(_, i)| **i == "scan.c0.obj")
        .map(|(p, _)| p)
        .collect();
    assert_eq!(own.len(), 2, "whole, then as its one component: {fitted:?}");
    for patch in own {
        assert!(patch.starts_with("scan.c0~"), "{patch}");
        assert_eq!(
            read_json(&s.out.join(patch).join("report.json"))["patch"],
            **patch
        );
    }
    assert_eq!(
        read_json(&s.out.join("scan.c0/report.json"))["component"]["vertices"],
        900,
        "component 0 of scan is its 30^2 sheet"
    );
}

/// bun045 has 12 pieces: the policy keeps those over the thresholds and fits each.
#[test]
fn stanford_scan_all_components() {
    let Some(path) = shared_data("range_scans/bun045_tri.ply") else {
        return;
    };
    let mesh = read_mesh_file(&path, &LoadOptions::default())
        .expect("reads")
        .mesh;
    let mut cfg = worker(ComponentMode::All);
    cfg.tessellation = 32;
    // Its two side pieces have ~300 vertices, under 1 % of the main one: a fraction of
    // 0.5 % keeps them.
    cfg.fit.components.min_vertices = 200;
    cfg.fit.components.min_fraction = 0.005;
    let out = run_input(&mesh, None, &cfg).expect("fits");
    let c0 = &out.parts[0].outputs.report["component"];
    eprintln!(
        "bun045: {} components, kept {}, dropped {:?}, failed {:?}",
        c0["total"], c0["kept"], c0["dropped_vertices"], out.failed
    );
    for p in &out.parts {
        let r = &p.outputs.report;
        eprintln!(
            "  {}: {} points, {} controls, geometric rms {:.1} um max {:.1} um, {}",
            p.suffix,
            r["data_points"],
            r["control_points"],
            r["final"]["geometric_rms_error"].as_f64().unwrap_or(0.0) * 1e6,
            r["final"]["geometric_max_error"].as_f64().unwrap_or(0.0) * 1e6,
            r["status"]
        );
        assert!(
            r["final"]["geometric_rms_error"].as_f64().unwrap_or(1.0) < 2e-4,
            "{}",
            p.suffix
        );
    }
    assert_eq!(c0["total"], 12);
    assert_eq!(c0["kept"], 3);
    assert_eq!(
        out.parts.len() + out.failed.len(),
        c0["kept"].as_u64().unwrap_or(0) as usize
    );
    assert!(
        out.parts[0].outputs.report["data_points"]
            .as_u64()
            .unwrap_or(0)
            > 30_000
    );
}
