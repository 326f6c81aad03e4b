//! Point clouds in: the `.xyz` / `.pts` / `.pcd` readers and vertices-only PLY, their
//! typed refusals, and a real scan's points fitted through the scan path as well as its mesh.

use crate::shared_mesh;
use std::path::Path;
use trispline::io::{read_mesh_bytes, read_mesh_file, Format, LoadOptions};
use trispline::pipeline::worker::{run_input, FitConfig, WorkerConfig};
use trispline::pipeline::SurfaceKind;
use trispline::{DVec3, TriMesh};

fn read(bytes: &[u8], format: Format) -> Result<TriMesh, String> {
    read_mesh_bytes(bytes, format, "cloud", &LoadOptions::default())
        .map(|l| l.mesh)
        .map_err(|e| e.kind().to_string())
}

fn pcd_header(fields: &str, size: &str, ty: &str, width: usize, height: usize) -> String {
    format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {ty}\nCOUNT {}\nWIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {}\n",
        vec!["1"; fields.split(' ').count()].join(" "),
        width * height
    )
}

/// Binary PCD of points with an f32 normal z and a u8 label beside them.
fn binary_pcd(points: &[DVec3]) -> Vec<u8> {
    let mut b = pcd_header(
        "x y z normal_z label",
        "4 4 4 4 1",
        "F F F F U",
        points.len(),
        1,
    )
    .into_bytes();
    b.extend_from_slice(b"DATA binary\n");
    for p in points {
        for c in [p.x as f32, p.y as f32, p.z as f32, 1.0] {
            b.extend_from_slice(&c.to_le_bytes());
        }
        b.push(7);
    }
    b
}

/// `.xyz` with three extra columns (normals), the way Open3D and CloudCompare write them.
fn xyz_text(points: &[DVec3]) -> String {
    points
        .iter()
        .map(|p| format!("{} {} {} 0 0 1\n", p.x, p.y, p.z))
        .collect()
}

fn square() -> Vec<DVec3> {
    vec![
        DVec3::ZERO,
        DVec3::X,
        DVec3::new(0.0, 1.0, 0.5),
        DVec3::new(1.0, 1.0, 0.25),
    ]
}

#[test]
fn point_cloud_formats_read_the_same_points() {
    let pts = square();
    let plain: String = pts
        .iter()
        .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
        .collect();
    let with_normals = xyz_text(&pts);
    let with_count = format!("{}\n{}", pts.len(), with_normals);
    let ascii_pcd = format!(
        "{}DATA ascii\n{}",
        pcd_header("x y z rgb", "4 4 4 4", "F F F U", 2, 2),
        pts.iter()
            .map(|p| format!("{} {} {} 4278190080\n", p.x, p.y, p.z))
            .collect::<String>()
    );
    let ply = format!(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nend_header\n{}",
        pts.iter()
            .map(|p| format!("{} {} {} 0\n", p.x, p.y, p.z))
            .collect::<String>()
    );
    let binary = binary_pcd(&pts);
    let cases: [(&[u8], Format); 6] = [
        (plain.as_bytes(), Format::Xyz),
        (with_normals.as_bytes(), Format::Xyz),
        (with_count.as_bytes(), Format::Pts),
        (ascii_pcd.as_bytes(), Format::Pcd),
        (&binary, Format::Pcd),
        (ply.as_bytes(), Format::Ply),
    ];
    for (k, (bytes, format)) in cases.into_iter().enumerate() {
        let loaded = read_mesh_bytes(bytes, format, "c", &LoadOptions::default())
            .unwrap_or_else(|e| panic!("case {k}: {e}"));
        assert!(loaded.is_point_cloud(), "case {k}");
        assert_eq!(loaded.mesh.positions, pts, "case {k}");
    }
    // PCL's missing points of an organized cloud (NaN in x, y and z) are skipped.
    let organized = format!(
        "{}DATA ascii\n0 0 0\nnan nan nan\nNaN NaN NaN\n1 1 1\n",
        pcd_header("x y z", "4 4 4", "F F F", 2, 2)
    );
    assert_eq!(
        read(organized.as_bytes(), Format::Pcd).expect("organized"),
        TriMesh::new(vec![DVec3::ZERO, DVec3::ONE], Vec::new())
    );
}

#[test]
fn malformed_point_clouds_get_typed_errors() {
    let pts = square();
    let mut truncated_pcd = binary_pcd(&pts);
    truncated_pcd.truncate(truncated_pcd.len() - 3);
    let head = pcd_header("x y z", "4 4 4", "F F F", 2, 1);
    let cases: Vec<(Vec<u8>, Format, &str)> = vec![
        (b"1 2 3\n4 5\n".to_vec(), Format::Xyz, "malformed"),
        (b"1 2 3\n4 5 x\n".to_vec(), Format::Xyz, "malformed"),
        (b"1 2 3\n4 nan 6\n".to_vec(), Format::Xyz, "non_finite"),
        (b"1 2 inf\n".to_vec(), Format::Xyz, "non_finite"),
        (b"# only a comment\n".to_vec(), Format::Xyz, "empty"),
        (b"1 2 3\n\x00\x00\n".to_vec(), Format::Xyz, "not_text"),
        (b"3\n1 2 3\n4 5 6\n".to_vec(), Format::Pts, "truncated"),
        (b"1\n1 2 3\n4 5 6\n".to_vec(), Format::Pts, "count_mismatch"),
        (
            b"18446744073709551616\n1 2 3\n".to_vec(),
            Format::Pts,
            "too_large",
        ),
        (truncated_pcd, Format::Pcd, "truncated"),
        (
            format!("{head}DATA ascii\n1 2 3\n").into_bytes(),
            Format::Pcd,
            "truncated",
        ),
        (
            format!("{head}DATA ascii\n1 2 3\n4 5 6\n7 8 9\n").into_bytes(),
            Format::Pcd,
            "count_mismatch",
        ),
        (
            format!("{head}DATA ascii\n1 2 3\n4 nan 6\n").into_bytes(),
            Format::Pcd,
            "non_finite",
        ),
        (
            head.replace("POINTS 2", "POINTS 3")
                .into_bytes()
                .into_iter()
                .chain(*b"DATA ascii\n1 2 3\n")
                .collect(),
            Format::Pcd,
            "count_mismatch",
        ),
        (
            head.replace("WIDTH 2", "WIDTH 1000")
                .replace("POINTS 2", "POINTS 1000")
                .into_bytes()
                .into_iter()
                .chain(*b"DATA binary\n")
                .collect(),
            Format::Pcd,
            "truncated",
        ),
        (
            head.replace("SIZE 4 4 4", "SIZE 4 4")
                .into_bytes()
                .into_iter()
                .chain(*b"DATA ascii\n")
                .collect(),
            Format::Pcd,
            "bad_header",
        ),
        (
            head.replace("FIELDS x y z", "FIELDS x y w")
                .into_bytes()
                .into_iter()
                .chain(*b"DATA ascii\n1 2 3\n4 5 6\n")
                .collect(),
            Format::Pcd,
            "bad_header",
        ),
        (
            format!("{head}DATA binary_compressed\n\x01\x00").into_bytes(),
            Format::Pcd,
            "unsupported",
        ),
        (
            b"VERSION 0.7\nFIELDS x y z\n".to_vec(),
            Format::Pcd,
            "bad_header",
        ),
    ];
    for (bytes, format, kind) in &cases {
        assert_eq!(
            read(bytes, *format).err().as_deref(),
            Some(*kind),
            "{}",
            String::from_utf8_lossy(bytes)
        );
    }
    // Budgets hold before allocating: a declared count over max_vertices is refused.
    let small = LoadOptions::with_limits(1 << 20, 10);
    let many = format!(
        "{}DATA binary\n",
        pcd_header("x y z", "4 4 4", "F F F", 11, 1)
    );
    let e = read_mesh_bytes(many.as_bytes(), Format::Pcd, "big.pcd", &small).expect_err("budget");
    assert_eq!(e.kind(), "too_large");
    assert!(e.to_string().starts_with("big.pcd (line "), "{e}");
    let e = read_mesh_bytes(b"11\n0 0 0\n", Format::Pts, "big.pts", &small).expect_err("budget");
    assert_eq!(e.kind(), "too_large");
    // The messages name the file and the line.
    let e = read_mesh_bytes(b"1 2 3\n4 5 x\n", Format::Xyz, "scan.xyz", &small).expect_err("x");
    assert_eq!(e.to_string(), "scan.xyz (line 2): 'x' is not a number");
}

fn loop_config() -> WorkerConfig {
    WorkerConfig {
        fit: FitConfig {
            surface: SurfaceKind::Loop,
            ..FitConfig::default()
        },
        ..WorkerConfig::default()
    }
}

fn rms_and_controls(report: &serde_json::Value) -> (f64, usize, usize) {
    (
        report["final"]["geometric_rms_error"]
            .as_f64()
            .expect("rms"),
        report["control_points"].as_u64().expect("controls") as usize,
        report["data_points"].as_u64().expect("points") as usize,
    )
}

/// A range scan's vertices, written as .xyz and as binary .pcd, read back as clouds and
/// fitted: the scan goals hold (RMS <= 75 um with <= 5 % controls) and the fit is as good
/// as the mesh's within 15 %.
#[test]
fn a_range_scan_as_a_point_cloud_meets_the_scan_goals_like_its_mesh() {
    let Some(mesh) = shared_mesh("range_scans/bun045_tri.ply") else {
        return;
    };
    let dir = tempfile::tempdir().expect("temp dir");
    let (xyz, pcd) = (dir.path().join("bun045.xyz"), dir.path().join("bun045.pcd"));
    std::fs::write(&xyz, xyz_text(&mesh.positions)).expect("xyz");
    std::fs::write(&pcd, binary_pcd(&mesh.positions)).expect("pcd");
    let read_cloud = |p: &Path| {
        let loaded = read_mesh_file(p, &LoadOptions::default()).expect("cloud reads");
        assert!(loaded.is_point_cloud());
        loaded.mesh
    };
    let cloud = read_cloud(&pcd);
    assert_eq!(cloud.positions, mesh.positions);
    assert_eq!(read_cloud(&xyz).positions, mesh.positions);

    let cfg = loop_config();
    let from_cloud = run_input(&cloud, None, &cfg).expect("the cloud fits");
    let from_mesh = run_input(&mesh, None, &cfg).expect("the mesh fits");
    let report = &from_cloud.parts[0].outputs.report;
    let (rms, controls, points) = rms_and_controls(report);
    let (mesh_rms, mesh_controls, mesh_points) =
        rms_and_controls(&from_mesh.parts[0].outputs.report);
    let stats = &report["point_cloud"];
    println!(
        "bun045 as a cloud: {points} of {} points fitted, {controls} controls, RMS {:.1} um; as a mesh: {mesh_points} points, {mesh_controls} controls, RMS {:.1} um; triangulation {stats}",
        mesh.positions.len(),
        rms * 1e6,
        mesh_rms * 1e6
    );
    assert!(rms <= 75e-6, "cloud RMS {:.1} um", rms * 1e6);
    assert!(
        20 * controls <= points,
        "{controls} controls, {points} points"
    );
    assert!(
        rms <= 1.15 * mesh_rms,
        "cloud {:.1} um vs mesh {:.1} um",
        rms * 1e6,
        mesh_rms * 1e6
    );
    // The points themselves are the data: all but a few strays (bun045: 666 of 40097, the
    // rims' sparse grazing samples) and the pieces the largest-component fit leaves out
    // are fitted (bun045: 38284 points against 39454 from the mesh).
    assert_eq!(stats["points"], mesh.positions.len());
    let left_out = stats["left_out_points"].as_u64().expect("count") as usize;
    assert!(50 * left_out <= mesh.positions.len(), "{left_out} left out");
    assert!(
        points as f64 >= 0.95 * mesh_points as f64,
        "{points} fitted vs {mesh_points}"
    );
}

/// A whole object's cloud (no height field over any plane) is reconstructed (oriented
/// normals, the scans' merge) and fitted as a closed object; its own points are measured
/// against the surface. `fit.domain = "mesh"` sends a height-field cloud the same way.
#[test]
fn closed_clouds_are_reconstructed_and_fitted_as_whole_objects() {
    let mut sphere = Vec::new();
    let n = 3000;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..n {
        let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - y * y).sqrt();
        let phi = golden * i as f64;
        sphere.push(DVec3::new(r * phi.cos(), y, r * phi.sin()));
    }
    let cloud = TriMesh::new(sphere, Vec::new());
    let fitted = run_input(&cloud, None, &loop_config()).expect("a sphere is reconstructed");
    let report = &fitted.parts[0].outputs.report;
    assert_eq!(report["path"], "object", "{report}");
    assert_eq!(report["point_cloud"]["route"], "reconstruction");
    assert_eq!(report["point_cloud"]["points"], n);
    assert_eq!(report["topology"]["control"]["genus"], 0);
    assert_eq!(report["topology"]["control"]["boundary_loops"], 0);
    let measured = &report["point_cloud"]["points_to_surface"];
    assert_eq!(measured["points"], n, "{report}");
    // The points' spacing is about 0.065: the surface lies within a small share of it.
    let rms = measured["rms"].as_f64().expect("rms");
    assert!(rms < 2e-3, "cloud to surface rms {rms}");

    let mut cfg = loop_config();
    cfg.fit.domain = trispline::pipeline::worker::Domain::Mesh;
    let wavy: Vec<DVec3> = (0..40 * 40)
        .map(|k| {
            let (x, y) = ((k % 40) as f64 / 39.0, (k / 40) as f64 / 39.0);
            DVec3::new(x, y, 0.1 * (3.0 * x).sin() * (2.0 * y).cos())
        })
        .collect();
    let patch = TriMesh::new(wavy, Vec::new());
    let fitted = run_input(&patch, None, &cfg).expect("a reconstructed patch");
    let report = &fitted.parts[0].outputs.report;
    assert_eq!(report["point_cloud"]["route"], "reconstruction");
    assert_eq!(report["path"], "object");
    let plain = run_input(&patch, None, &loop_config()).expect("a height field");
    assert_eq!(
        plain.parts[0].outputs.report["point_cloud"]["route"],
        "height_field"
    );
}

/// Stanford's bunny (bun_zipper, VRIP's reconstruction: 35,947 vertices, 5 holes in its
/// base) as a cloud of its vertices: reconstructed and fitted as one whole object, its
/// points as near the surface as the mesh's own fit leaves them, within the merge's
/// smoothing (measured: median 54 um, RMS 105 um, 1,343 controls; from the mesh: RMS 62
/// um, 1,709 controls).
#[test]
fn the_bunny_as_a_cloud_of_its_vertices_becomes_one_surface_near_its_points() {
    let Some(mesh) = shared_mesh("models/bun_zipper.ply") else {
        return;
    };
    let cloud = TriMesh::new(mesh.positions.clone(), Vec::new());
    let fitted = run_input(&cloud, None, &loop_config()).expect("the bunny's cloud");
    let report = &fitted.parts[0].outputs.report;
    assert_eq!(report["path"], "object", "{report}");
    assert_eq!(report["point_cloud"]["route"], "reconstruction");
    assert_eq!(report["topology"]["control"]["genus"], 0, "{report}");
    // The five holes of the base stay open; the merge adds at most a few pinholes.
    let holes = report["topology"]["control"]["boundary_loops"]
        .as_u64()
        .expect("loops");
    assert!((5..=12).contains(&holes), "{holes} boundary loops");
    // The budget counts the cloud's points (5 %), not the merged vertices.
    let controls = report["control_points"].as_u64().expect("controls") as f64;
    let points = mesh.positions.len() as f64;
    assert!(
        controls > 0.025 * points && controls <= 0.05 * points,
        "{controls}"
    );
    let measured = &report["point_cloud"]["points_to_surface"];
    assert_eq!(measured["points"], mesh.positions.len());
    let (median, rms) = (
        measured["median"].as_f64().expect("median"),
        measured["rms"].as_f64().expect("rms"),
    );
    // Scan noise is 35-50 um; the mesh's own fit reaches 62 um RMS.
    assert!(median < 80e-6, "median {median}");
    assert!(rms < 150e-6, "rms {rms}");
}
