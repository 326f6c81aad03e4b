//! inspect, subdivide and coarsen as processes.

use glam::DVec3;
use std::process::Command;
use trispline::io::writers::write_obj;
use trispline::io::{read_mesh_file, LoadOptions};
use trispline::TriMesh;

fn trispline(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
        .args(args)
        .output()
        .expect("runs")
}

#[test]
fn a_subdivision_past_the_face_limit_is_refused_before_any_work() {
    let dir = tempfile::tempdir().expect("tmp");
    let tetra = TriMesh::new(
        vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z],
        vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    );
    let (c, f) = (dir.path().join("c.obj"), dir.path().join("f.ply"));
    write_obj(&c, &tetra).expect("write");
    let s = |p: &std::path::Path| p.to_str().unwrap_or_default().to_string();
    // 4 faces x 4^13 = 268M faces: over the limit; 4^64 overflows.
    for levels in ["13", "64"] {
        let o = trispline(&["subdivide", &s(&c), "--levels", levels, "-o", &s(&f)]);
        assert_eq!(o.status.code(), Some(2), "{levels}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("over the limit") && err.contains("lower --levels"),
            "{err}"
        );
        assert!(!f.exists());
    }
    // Under it, a subdivision goes ahead.
    let o = trispline(&["subdivide", &s(&c), "--levels", "3", "-o", &s(&f)]);
    assert!(o.status.success());
}

#[test]
fn subdivide_then_coarsen_round_trips_and_inspect_reports_depth() {
    let dir = tempfile::tempdir().expect("tmp");
    let coarse = TriMesh::new(
        vec![
            DVec3::new(0.1, 0.0, 0.2),
            DVec3::X,
            DVec3::Y,
            DVec3::new(0.3, 0.2, 1.0),
        ],
        vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
    );
    let (c, f, back) = (
        dir.path().join("c.obj"),
        dir.path().join("f.ply"),
        dir.path().join("back.obj"),
    );
    write_obj(&c, &coarse).expect("write");
    let s = |p: &std::path::Path| p.to_str().unwrap_or_default().to_string();
    assert!(
        trispline(&["subdivide", &s(&c), "--levels", "2", "-o", &s(&f)])
            .status
            .success()
    );
    let o = trispline(&["inspect", &s(&f)]);
    assert!(o.status.success());
    let stats: serde_json::Value = serde_json::from_slice(&o.stdout).expect("one JSON object");
    for key in [
        "vertices",
        "faces",
        "components",
        "boundary_loops",
        "non_manifold_edges",
        "non_manifold_vertices",
        "duplicate_faces",
        "degenerate_faces",
        "euler_characteristic",
        "closed",
        "subdivision_depth",
    ] {
        assert!(stats.get(key).is_some(), "missing {key}");
    }
    assert_eq!(stats["faces"], 64);
    assert_eq!(stats["subdivision_depth"], 2);
    assert_eq!(stats["closed"], true);
    assert_eq!(stats["euler_characteristic"], 2);
    for method in ["exact", "lsq"] {
        assert!(trispline(&[
            "coarsen",
            &s(&f),
            "--levels",
            "2",
            "--method",
            method,
            "-o",
            &s(&back)
        ])
        .status
        .success());
        let m = read_mesh_file(&back, &LoadOptions::default())
            .expect("reads")
            .mesh;
        let err = m
            .positions
            .iter()
            .zip(&coarse.positions)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f64::max);
        assert!(err < 1e-12, "{method}: {err}");
    }
    // Depth 3 does not exist: exit status 2 and the reason.
    let o = trispline(&["coarsen", &s(&f), "--levels", "3", "-o", &s(&back)]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("level 3"));
}
