//! The JSON Schemas in `schemas/` hold for real outputs of every surface kind and layout:
//! `fit` on a scan (`loop` grid, `bezier` patches, `--domain mesh`), on a mesh with
//! subdivision connectivity (`bezier` single patch, `loop` mesh), and `bspline-fit`.

use glam::DVec3;
use std::path::Path;
use std::process::Command;
use trispline::io::writers::write_obj;
use trispline::surface::bezier::{lattice_points, lattice_triangles};
use trispline::TriMesh;

pub(crate) fn schema(name: &str) -> jsonschema::Validator {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("schemas")
        .join(name);
    let value: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).expect("schema file")).expect("json");
    jsonschema::validator_for(&value).expect("a valid schema")
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).expect("exists")).expect("json")
}

/// Every violation of `doc` against `validator`, as text.
pub(crate) fn violations(
    validator: &jsonschema::Validator,
    doc: &serde_json::Value,
) -> Vec<String> {
    validator
        .iter_errors(doc)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect()
}

/// A height-field grid of rows x cols vertices (29 cells across: no subdivision
/// connectivity, so `fit` takes the scan path).
fn scan_patch(rows: usize, cols: usize) -> TriMesh {
    let positions = (0..rows)
        .flat_map(|r| {
            (0..cols).map(move |c| {
                let (x, y) = (r as f64 * 0.01, c as f64 * 0.01);
                DVec3::new(
                    x,
                    y,
                    0.02 * (-((x - 0.12).powi(2) + (y - 0.15).powi(2)) * 40.0).exp(),
                )
            })
        })
        .collect();
    let mut triangles = Vec::new();
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let i = (r * cols + c) as u32;
            let (down, right) = (i + cols as u32, i + 1);
            triangles.push([i, down, down + 1]);
            triangles.push([i, down + 1, right]);
        }
    }
    TriMesh::new(positions, triangles)
}

/// A mesh with Loop subdivision connectivity: one lattice of 32 segments a side.
fn lattice_patch() -> TriMesh {
    let n = 32;
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

fn run(args: &[&str], input: &Path, out: &Path) {
    let o = Command::new(env!("CARGO_BIN_EXE_trispline"))
        .arg(args[0])
        .arg(input)
        .args(&args[1..])
        .arg("--out")
        .arg(out)
        .output()
        .expect("runs");
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn outputs_of_every_kind_follow_the_schemas() {
    let (surface_schema, report_schema) =
        (schema("surface.schema.json"), schema("report.schema.json"));
    let tmp = tempfile::tempdir().expect("tmp");
    let scan = tmp.path().join("scan.obj");
    write_obj(&scan, &scan_patch(25, 30)).expect("write");
    let lattice = tmp.path().join("lattice.obj");
    write_obj(&lattice, &lattice_patch()).expect("write");
    // (arguments, input, expected kind, layout and report.json's path)
    type Case<'a> = (
        &'a [&'a str],
        &'a Path,
        &'a str,
        Option<&'a str>,
        Option<&'a str>,
    );
    let cases: [Case; 6] = [
        (&["fit"], &scan, "loop", Some("grid"), Some("scan")),
        (
            &["fit", "--surface", "bezier"],
            &scan,
            "bezier",
            Some("patches"),
            Some("scan"),
        ),
        (
            &["fit", "--domain", "mesh"],
            &scan,
            "loop",
            Some("mesh"),
            Some("object"),
        ),
        (
            &["fit", "--surface", "bezier", "--levels", "2"],
            &lattice,
            "bezier",
            None,
            Some("subdivided"),
        ),
        (
            &["fit", "--levels", "2"],
            &lattice,
            "loop",
            Some("mesh"),
            Some("subdivided"),
        ),
        (
            &["bspline-fit", "--grid", "25x30", "--control", "8x9"],
            &scan,
            "bspline",
            None,
            None,
        ),
    ];
    let mut failures = Vec::new();
    for (k, (args, input, kind, layout, path)) in cases.iter().enumerate() {
        let out = tmp.path().join(format!("out{k}"));
        run(args, input, &out);
        let surface = read_json(&out.join("surface.json"));
        assert_eq!(surface["kind"], *kind, "{args:?}");
        assert_eq!(surface["layout"].as_str(), *layout, "{args:?}");
        let report = read_json(&out.join("report.json"));
        assert_eq!(report["path"].as_str(), *path, "{args:?}");
        for (name, validator, doc) in [
            ("surface.json", &surface_schema, &surface),
            ("report.json", &report_schema, &report),
        ] {
            for v in violations(validator, doc) {
                failures.push(format!("{args:?} {name}: {v}"));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");

    // The schemas are not vacuous: a broken document of each is refused.
    let mut surface = read_json(&tmp.path().join("out0/surface.json"));
    surface["cells"][0] = serde_json::json!([0, 0, 2]);
    assert!(!violations(&surface_schema, &surface).is_empty());
    let mut report = read_json(&tmp.path().join("out0/report.json"));
    report["status"] = serde_json::json!("done");
    assert!(!violations(&report_schema, &report).is_empty());
}
