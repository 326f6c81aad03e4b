//! `fit --surface dms | bpatch` and the daemon with `surface = "dms"`: the surface.json
//! kinds as the README specifies them, `curvature` on both, degree range checks, and a
//! warm start from the previous version's domain and controls.

use std::path::{Path, PathBuf};
use std::process::Command;

fn trispline(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
        .args(args)
        .output()
        .expect("runs")
}

fn sample(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/patches")
        .join(name)
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).expect("reads")).expect("json")
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap_or_default()
}

/// `fit` with `extra` flags on the dome patch, then `curvature` on its surface.json.
fn fit_dome(extra: &[&str]) -> (serde_json::Value, serde_json::Value) {
    let dir = tempfile::tempdir().expect("tmp");
    let out = dir.path().join("out");
    let input = sample("dome.obj");
    let mut args = vec!["fit", s(&input), "--out", s(&out)];
    args.extend_from_slice(extra);
    let o = trispline(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let surface = json(&out.join("surface.json"));
    let report = json(&out.join("report.json"));
    assert!(std::fs::metadata(out.join("surface.glb")).is_ok_and(|m| m.len() > 1000));
    let curv = dir.path().join("curv");
    let o = trispline(&[
        "curvature",
        s(&out.join("surface.json")),
        "--grid",
        "61",
        "--out",
        s(&curv),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let regions = json(&curv.join("regions.json"));
    assert!(
        regions.to_string().contains("convex"),
        "the dome reads as convex somewhere: {regions}"
    );
    (surface, report)
}

fn pairs(v: &serde_json::Value) -> usize {
    v.as_array().map_or(0, |a| {
        a.iter()
            .filter(|p| p.as_array().is_some_and(|c| c.len() == 2))
            .count()
    })
}

#[test]
fn fit_dms_writes_the_dms_kind_and_curvature_reads_it() {
    for degree in [2usize, 3] {
        let d = degree.to_string();
        let (surface, report) = fit_dome(&["--surface", "dms", "--dms-degree", &d]);
        assert_eq!(surface["kind"], "dms");
        assert_eq!(surface["degree"], degree);
        let vertices = pairs(&surface["domain_vertices"]);
        let triangles = surface["domain_triangles"].as_array().map_or(0, Vec::len);
        assert!(
            vertices > 3 && triangles > 1,
            "{vertices} vertices, {triangles} triangles"
        );
        let clouds = surface["knot_clouds"].as_array().expect("knot_clouds");
        assert_eq!(clouds.len(), vertices);
        assert!(clouds.iter().all(|c| pairs(c) == degree + 1));
        // The vertex is the first knot of its cloud.
        assert_eq!(clouds[0][0], surface["domain_vertices"][0]);
        let per = (degree + 1) * (degree + 2) / 2;
        assert_eq!(
            surface["control_points"].as_array().map_or(0, Vec::len),
            triangles * per
        );
        assert!(surface["trim"]["outer"]
            .as_array()
            .is_some_and(|a| a.len() > 10));
        assert_eq!(report["surface"], "dms");
        assert_eq!(report["path"], "planar");
        assert_eq!(report["domain"]["triangles"], triangles);
        // The dome spans 2.83 units.
        let rms = report["final"]["geometric_rms_error"]
            .as_f64()
            .expect("rms");
        assert!(rms < 0.01, "degree {degree}: geometric rms {rms}");
    }
}

#[test]
fn fit_bpatch_writes_the_bpatch_kind_and_curvature_reads_it() {
    let (surface, report) = fit_dome(&["--surface", "bpatch", "--bpatch-degree", "6"]);
    assert_eq!(surface["kind"], "bpatch");
    assert_eq!(report["path"], "planar");
    assert_eq!(surface["degree"], 6);
    assert_eq!(pairs(&surface["domain_triangle"]), 3);
    for seq in ["r", "s", "t"] {
        assert_eq!(pairs(&surface["knots"][seq]), 6, "{seq}");
    }
    assert_eq!(surface["knots"]["r"][0], surface["domain_triangle"][0]);
    assert_eq!(surface["control_points"].as_array().map_or(0, Vec::len), 28);
    let rms = report["final"]["geometric_rms_error"]
        .as_f64()
        .expect("rms");
    assert!(rms < 0.02, "geometric rms {rms}");
}

#[test]
fn degrees_and_spreads_out_of_range_are_refused() {
    let dir = tempfile::tempdir().expect("tmp");
    let input = sample("dome.obj");
    let out = dir.path().join("out");
    for flags in [
        ["--dms-degree", "4"],
        ["--dms-degree", "1"],
        ["--bpatch-degree", "30"],
        ["--knot-spread", "1.5"],
        ["--curvature-floor", "1.5"],
        ["--curvature-floor", "1"],
    ] {
        let o = trispline(&[
            "fit",
            s(&input),
            "--surface",
            "dms",
            flags[0],
            flags[1],
            "--out",
            s(&out),
        ]);
        assert!(!o.status.success(), "{flags:?} accepted");
        assert!(!out.join("surface.json").exists());
        if flags[0] == "--curvature-floor" {
            let stderr = String::from_utf8_lossy(&o.stderr);
            assert!(stderr.contains("needs a value in [0, 1)"), "{stderr}");
        }
    }
    // A spread out of the dms range is the bpatch kind's to take: each kind is held to its
    // own range only.
    let o = trispline(&[
        "fit",
        s(&input),
        "--surface",
        "bpatch",
        "--knot-spread",
        "1.5",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, DMS_CONFIG.replace("degree = 2", "degree = 5")).expect("write");
    let o = trispline(&[
        "watch",
        ".",
        "--out",
        s(&out),
        "--config",
        s(&cfg),
        "--once",
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("fit.dms.degree"));
}

const DMS_CONFIG: &str = r#"
[fit]
surface = "dms"
levels = 1
method = "cg"
inverse = "exact"

[fit.budget]
max_iterations = 60

[fit.dms]
degree = 2

[output]
tessellation = 32

[daemon]
settle_ms = 0
poll_interval_ms = 50
max_file_bytes = 10000000
max_vertices = 1000000
"#;

#[test]
fn the_daemon_warm_starts_a_dms_fit_from_the_previous_domain() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (inbox, out, cfg) = (
        tmp.path().join("in"),
        tmp.path().join("out"),
        tmp.path().join("dms.toml"),
    );
    std::fs::create_dir_all(&inbox).expect("mkdir");
    std::fs::write(&cfg, DMS_CONFIG).expect("config");
    let run = || {
        let o = trispline(&[
            "watch",
            s(&inbox),
            "--out",
            s(&out),
            "--config",
            s(&cfg),
            "--once",
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        json(&out.join("dome/report.json"))
    };
    std::fs::copy(sample("dome.obj"), inbox.join("dome@1.obj")).expect("copy");
    let first = run();
    assert_eq!(first["surface"], "dms");
    assert_eq!(first["warm_start"], false);
    // A new version: the same ground, every point moved up by a hundredth.
    let text = std::fs::read_to_string(sample("dome.obj")).expect("read");
    let moved: String = text
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(rest) => {
                let c: Vec<f64> = rest
                    .split_whitespace()
                    .filter_map(|x| x.parse().ok())
                    .collect();
                format!("v {} {} {}\n", c[0], c[1], c[2] + 0.01)
            }
            None => format!("{l}\n"),
        })
        .collect();
    std::fs::write(inbox.join("dome@2.obj"), moved).expect("write");
    let second = run();
    assert_eq!(second["version"], "dome@2.obj");
    assert_eq!(second["warm_start"], true, "{second}");
    assert_eq!(second["reused_controls"], second["control_points"]);
    assert_eq!(second["cold_start"], serde_json::Value::Null);
    let rms = second["final"]["geometric_rms_error"]
        .as_f64()
        .expect("rms");
    let first_rms = first["final"]["geometric_rms_error"].as_f64().expect("rms");
    assert!(rms < 1.5 * first_rms + 1e-4, "warm {rms}, cold {first_rms}");
}
