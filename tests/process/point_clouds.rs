//! Point clouds as a user hands them in: `trispline fit cloud.xyz`, `inspect`, a whole
//! object's cloud refused with the reason, and the daemon fitting a `.pcd` dropped in its
//! folder and one sent through the pipe.

use crate::daemon_support::*;

/// A scan-like height field sampled as a jittered `n` x `n` cloud (in metres, a 6 cm
/// square), with a hole, as (x, y, z) triples.
fn cloud(n: usize) -> Vec<[f64; 3]> {
    let mut pts = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (ci, cj) = (i as f64 - n as f64 / 2.0, j as f64 - n as f64 / 2.0);
            if ci.abs() < 3.0 && cj.abs() < 4.0 {
                continue;
            }
            let jitter = ((i * 31 + j * 17) % 13) as f64 / 13.0 - 0.5;
            let (x, y) = (
                0.06 * (i as f64 + 0.3 * jitter) / n as f64,
                0.06 * (j as f64 - 0.3 * jitter) / n as f64,
            );
            pts.push([x, y, 0.01 * (40.0 * x).sin() * (30.0 * y).cos()]);
        }
    }
    pts
}

fn xyz_bytes(pts: &[[f64; 3]]) -> Vec<u8> {
    pts.iter()
        .map(|p| format!("{} {} {} 128 128 128\n", p[0], p[1], p[2]))
        .collect::<String>()
        .into_bytes()
}

fn pcd_bytes(pts: &[[f64; 3]]) -> Vec<u8> {
    let mut b = format!(
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH {}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {}\nDATA binary\n",
        pts.len(),
        pts.len()
    )
    .into_bytes();
    for p in pts {
        for c in p {
            b.extend_from_slice(&(*c as f32).to_le_bytes());
        }
    }
    b
}

fn sphere(n: usize) -> Vec<[f64; 3]> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = golden * i as f64;
            [0.05 * r * phi.cos(), 0.05 * y, 0.05 * r * phi.sin()]
        })
        .collect()
}

#[test]
fn fit_and_inspect_take_an_xyz_cloud_and_fit_a_whole_objects_cloud() {
    let dir = tempfile::tempdir().expect("tmp");
    let pts = cloud(40);
    let input = dir.path().join("cloud.xyz");
    std::fs::write(&input, xyz_bytes(&pts)).expect("write");
    let out = dir.path().join("out");
    let o = bin()
        .args(["fit", input.to_str().unwrap_or_default(), "--out"])
        .arg(&out)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = read_json(&out.join("report.json"));
    assert_eq!(report["point_cloud"]["points"], pts.len());
    assert_eq!(report["point_cloud"]["left_out_points"], 0);
    assert_eq!(report["data_points"], pts.len(), "every point is data");
    let rms = report["final"]["geometric_rms_error"]
        .as_f64()
        .expect("rms");
    assert!(rms < 1e-4, "rms {rms}");
    assert!(out.join("surface.glb").exists());

    let o = bin()
        .args(["inspect", input.to_str().unwrap_or_default()])
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stats: serde_json::Value = serde_json::from_slice(&o.stdout).expect("json");
    assert_eq!(stats["point_cloud"]["triangulated_points"], pts.len());

    // A whole object's cloud: reconstructed and fitted as a closed object.
    let ball = dir.path().join("ball.xyz");
    std::fs::write(&ball, xyz_bytes(&sphere(3000))).expect("write");
    let o = bin()
        .args(["fit", ball.to_str().unwrap_or_default(), "--out"])
        .arg(dir.path().join("ball"))
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = read_json(&dir.path().join("ball/report.json"));
    assert_eq!(report["point_cloud"]["route"], "reconstruction", "{report}");
    assert_eq!(report["path"], "object");
    assert!(dir.path().join("ball/surface.glb").exists());
}

#[test]
fn the_daemon_fits_pcd_clouds_from_its_folder_and_its_pipe() {
    let s = setup(&config(200, "native", ""));
    let pts = cloud(30);
    drop_file(&s.inbox, "cloud.pcd", &pcd_bytes(&pts));
    drop_file(&s.inbox, "ball.pcd", &pcd_bytes(&sphere(2000)));
    let (child, mut w) = s.spawn_pipe();
    let payload = pcd_bytes(&cloud(24));
    write_all(
        &mut w,
        format!(
            "{{\"patch\": \"piped\", \"format\": \"pcd\", \"bytes\": {}}}\n",
            payload.len()
        )
        .as_bytes(),
    );
    write_all(&mut w, &payload);
    let done = || {
        s.out.join("cloud/surface.json").exists()
            && s.out.join("piped/surface.json").exists()
            && events(&s.out).iter().any(|e| e["patch"] == "ball")
    };
    let finished = wait_until(done);
    let stopped = stop(child);
    drop(w);
    assert!(stopped.is_some_and(|st| st.success()), "{stopped:?}");
    assert!(finished, "{:?}", events(&s.out));
    let report = read_json(&s.out.join("cloud/report.json"));
    assert_eq!(report["point_cloud"]["points"], pts.len());
    // A whole object's cloud is reconstructed and fitted, not rejected.
    let ball = events(&s.out)
        .into_iter()
        .find(|e| e["patch"] == "ball")
        .expect("ball event");
    assert_ne!(ball["status"], "rejected", "{ball}");
    let report = read_json(&s.out.join("ball/report.json"));
    assert_eq!(report["point_cloud"]["route"], "reconstruction", "{report}");
    assert!(report["point_cloud"]["points_to_surface"]["rms"]
        .as_f64()
        .is_some());
}
