//! Object folders (`[object] folders = true`): a subfolder of the watch folder is one
//! object, every mesh in it a registered scan; one surface per object after each change.

use crate::daemon_support::{
    events, is_fitted, patch_gltf_external, read_json, setup, stop, wait_until, Setup,
};
use std::path::Path;
use std::time::Instant;
use trispline::testdata::shared_data;

const BUNNY_SCANS: [&str; 5] = ["bun000", "bun045", "bun180", "bun270", "chin"];

/// The embedded defaults, native watching, objects on; `extra` adds tables.
fn object_config(extra: &str) -> String {
    format!(
        r#"
[daemon]
settle_ms = 200
poll_interval_ms = 50
workers = 1
watcher = "native"
stop_timeout_ms = 120000

[object]
folders = true
{extra}
"#
    )
}

/// The fitted events of `object` so far.
fn fitted(out: &Path, object: &str) -> Vec<serde_json::Value> {
    events(out)
        .into_iter()
        .filter(|e| e["patch"] == object && is_fitted(e))
        .collect()
}

/// The scan ids an event says the surface was fitted to.
fn scans_of(e: &serde_json::Value) -> Vec<String> {
    e["scans"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|s| s.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default()
}

/// Copies a file in under a hidden name and renames it into place.
fn drop_copy(from: &Path, folder: &Path) {
    let name = from.file_name().expect("name");
    let part = folder.join(format!(".{}", name.to_string_lossy()));
    std::fs::copy(from, &part).expect("copy");
    std::fs::rename(&part, folder.join(name)).expect("rename");
}

/// Waits for the object's `n`-th fitted event; the update's wall time in seconds.
fn wait_fitted(s: &Setup, object: &str, n: usize) -> f64 {
    let start = Instant::now();
    let done = wait_until_long(|| fitted(&s.out, object).len() >= n);
    assert!(done, "update {n} of {object} never came: {}", s.log());
    start.elapsed().as_secs_f64()
}

/// Waits for the rejection event of the scan file `name` and returns it.
fn wait_rejection(s: &Setup, name: &str) -> serde_json::Value {
    let rejected = |e: &serde_json::Value| {
        e["status"] == "rejected" && e["input"].as_str().is_some_and(|i| i.ends_with(name))
    };
    assert!(
        wait_until_long(|| events(&s.out).iter().any(rejected)),
        "no rejection of {name}: {}",
        s.log()
    );
    events(&s.out)
        .into_iter()
        .find(rejected)
        .expect("the rejection just seen")
}

/// `wait_until` for object fits, which take seconds each on a loaded machine.
fn wait_until_long(mut cond: impl FnMut() -> bool) -> bool {
    for _ in 0..10 {
        if wait_until(&mut cond) {
            return true;
        }
    }
    false
}

/// The control points of a surface.json, flattened.
fn controls(out: &Path, object: &str) -> Vec<f64> {
    let surface = read_json(&out.join(object).join("surface.json"));
    let points = surface["control_points"]
        .as_array()
        .expect("control points");
    points
        .iter()
        .flat_map(|p| p.as_array().expect("a point").iter())
        .map(|c| c.as_f64().expect("a number"))
        .collect()
}

#[test]
fn registered_scans_dropped_one_by_one_and_a_restart_end_at_the_same_surface() {
    let Some(folder) = shared_data("range_scans/registered") else {
        return;
    };
    // Fewer controls and correction rounds than the defaults keep each update to seconds
    // (the example measures quality at the defaults).
    let config =
        object_config("[fit.scan]\ntarget_controls_pct = 3.0\n[fit.correction]\nrounds = 4\n");
    // Uninterrupted: the scans one by one, an update after each.
    let s = setup(&config);
    let bunny = s.inbox.join("bunny");
    std::fs::create_dir_all(&bunny).expect("mkdir");
    drop_copy(&folder.join("bun.conf"), &bunny);
    let daemon = s.spawn(&[]);
    for (k, id) in BUNNY_SCANS.iter().enumerate() {
        drop_copy(&folder.join(format!("{id}.ply")), &bunny);
        let secs = wait_fitted(&s, "bunny", k + 1);
        let last = fitted(&s.out, "bunny").pop().expect("an event");
        let report = read_json(&s.out.join("bunny/report.json"));
        eprintln!(
            "update {}: {secs:.1} s wall, fit {:.0} ms, {} controls, rms {:.1} um, path {}",
            k + 1,
            last["timings"]["fit_ms"],
            report["control_points"],
            report["final"]["geometric_rms_error"]
                .as_f64()
                .unwrap_or(f64::NAN)
                * 1e6,
            report["session"]["path"]
        );
        // One surface of the object, fitted to every scan so far.
        assert_eq!(scans_of(&last), BUNNY_SCANS[..=k], "{last}");
        let session = &report["session"];
        assert_eq!(session["scans"].as_array().map(Vec::len), Some(k + 1));
        assert_eq!(
            session["scan_distances"].as_array().map(Vec::len),
            Some(k + 1)
        );
        for file in session["files"].as_array().expect("files") {
            assert_eq!(file["registration"]["from"], "conf", "{file}");
        }
        for d in session["scan_distances"].as_array().expect("distances") {
            // Scan noise is 35-50 um: each scan lies on the object's surface.
            assert!(d["median"].as_f64().expect("median") < 2e-4, "{d}");
        }
        assert!(s.out.join("bunny/surface.glb").is_file());
    }
    let uninterrupted = controls(&s.out, "bunny");
    re_register_bun045(&s, &folder);
    assert!(stop(daemon).is_some_and(|c| c.success()), "{}", s.log());

    // Interrupted: two scans, a stop, a restart, the other three.
    let r = setup(&config);
    let bunny = r.inbox.join("bunny");
    std::fs::create_dir_all(&bunny).expect("mkdir");
    drop_copy(&folder.join("bun.conf"), &bunny);
    let daemon = r.spawn(&[]);
    for (k, id) in BUNNY_SCANS[..2].iter().enumerate() {
        drop_copy(&folder.join(format!("{id}.ply")), &bunny);
        wait_fitted(&r, "bunny", k + 1);
    }
    assert!(stop(daemon).is_some_and(|c| c.success()), "{}", r.log());
    let daemon = r.spawn(&[]);
    for (k, id) in BUNNY_SCANS[2..].iter().enumerate() {
        drop_copy(&folder.join(format!("{id}.ply")), &bunny);
        wait_fitted(&r, "bunny", k + 3);
    }
    let last = fitted(&r.out, "bunny").pop().expect("an event");
    assert_eq!(scans_of(&last), BUNNY_SCANS, "{last}");
    assert!(stop(daemon).is_some_and(|c| c.success()), "{}", r.log());
    let resumed = controls(&r.out, "bunny");
    assert_eq!(resumed.len(), uninterrupted.len());
    let worst = resumed
        .iter()
        .zip(&uninterrupted)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    eprintln!("restarted against uninterrupted: largest control difference {worst:.2e} m");
    assert!(worst < 1e-7, "{worst}");
}

/// bun045 re-registered 30 um along x by a sidecar `.xf` (it takes precedence over
/// `bun.conf`): the daemon's kept session refits the previous control mesh locally, as a
/// corrected registration changes no ground.
fn re_register_bun045(s: &Setup, folder: &Path) {
    let registration =
        trispline::io::registration::registration_for(&folder.join("bun045.ply"), "bun045")
            .expect("bun.conf names bun045");
    let mut matrix = registration.transform.to_row_major();
    matrix[3] += 30e-6;
    let text: String = matrix
        .chunks(4)
        .map(|row| {
            row.iter()
                .map(|x| format!("{x:e}"))
                .collect::<Vec<_>>()
                .join(" ")
                + "\n"
        })
        .collect();
    let before = fitted(&s.out, "bunny").len();
    write_in(&s.inbox.join("bunny"), "bun045.xf", &text);
    let secs = wait_fitted(s, "bunny", before + 1);
    let last = fitted(&s.out, "bunny").pop().expect("an event");
    let report = read_json(&s.out.join("bunny/report.json"));
    let session = &report["session"];
    let region = &session["updated_region"];
    eprintln!(
        "bun045 re-registered: {secs:.1} s wall, fit {:.0} ms, {} ({}), rms {:.1} um",
        last["timings"]["fit_ms"],
        region["fit"],
        region["cold_because"],
        report["final"]["geometric_rms_error"]
            .as_f64()
            .unwrap_or(f64::NAN)
            * 1e6,
    );
    assert_eq!(scans_of(&last), BUNNY_SCANS, "{last}");
    let bun045 = &session["files"][1];
    assert_eq!(bun045["registration"]["from"], "sidecar", "{bun045}");
    assert_eq!(region["fit"], "local", "{region}");
}

/// A cap of the unit sphere seen along +x, 1 cm radius, as ASCII PLY.
fn cap_ply(n: i32) -> String {
    let r = 0.01;
    let step = r / n as f64;
    let mut index = std::collections::HashMap::new();
    let mut points = Vec::new();
    for j in -n..=n {
        for i in -n..=n {
            let (y, z) = (i as f64 * step, j as f64 * step);
            if y * y + z * z > (0.9 * r) * (0.9 * r) {
                continue;
            }
            index.insert((i, j), points.len());
            points.push([(r * r - y * y - z * z).sqrt(), y, z]);
        }
    }
    let mut faces = Vec::new();
    for j in -n..n {
        for i in -n..n {
            let c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)].map(|k| index.get(&k));
            if let [Some(&a), Some(&b), Some(&c), Some(&d)] = c {
                faces.push([a, b, c]);
                faces.push([a, c, d]);
            }
        }
    }
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        points.len(),
        faces.len()
    );
    for p in &points {
        s.push_str(&format!("{} {} {}\n", p[0], p[1], p[2]));
    }
    for f in &faces {
        s.push_str(&format!("3 {} {} {}\n", f[0], f[1], f[2]));
    }
    s
}

fn write_in(folder: &Path, name: &str, text: &str) {
    let part = folder.join(format!(".{name}"));
    std::fs::write(&part, text).expect("write");
    std::fs::rename(&part, folder.join(name)).expect("rename");
}

#[test]
fn object_scans_are_registered_by_xf_refused_on_bad_conf_numbers_removed_when_deleted_and_hold_their_id(
) {
    let s = setup(&object_config(""));
    let object = s.inbox.join("ball");
    std::fs::create_dir_all(&object).expect("mkdir");
    let daemon = s.spawn(&[]);
    let cap = cap_ply(12);
    write_in(&object, "a.ply", &cap);
    wait_fitted(&s, "ball", 1);
    // The same cap given in a scanner frame turned 90 degrees: its .xf turns it back
    // about z, so it covers the ball's +y side.
    write_in(&object, "b.xf", "0 -1 0 0\n1 0 0 0\n0 0 1 0\n0 0 0 1\n");
    write_in(&object, "b.ply", &cap);
    assert!(wait_until_long(|| fitted(&s.out, "ball")
        .iter()
        .any(|e| scans_of(e) == ["a", "b"])));
    let report = read_json(&s.out.join("ball/report.json"));
    let session = &report["session"];
    assert!(
        session["view_spread_deg"]
            .as_f64()
            .is_some_and(|d| d > 60.0),
        "the .xf was applied: {session}"
    );
    let b = &session["files"][1];
    assert_eq!(b["registration"]["from"], "sidecar", "{b}");
    // A .conf that names c.ply with a bad number: c is refused, never taken as identity.
    let fits_before = fitted(&s.out, "ball").len();
    write_in(&object, "scans.conf", "bmesh c.ply 0 0 0 0 0 x 1\n");
    write_in(&object, "c.ply", &cap);
    let event = wait_rejection(&s, "c.ply");
    assert_eq!(event["kind"], "malformed", "{event}");
    assert!(
        object.join("c.ply").is_file(),
        "a refused scan stays in its folder"
    );
    let last = fitted(&s.out, "ball").pop().expect("fitted");
    assert_eq!(scans_of(&last), ["a", "b"], "{last}");
    // The surface of a and b comes out again with the refusal, from the kept session's
    // local refit over no changed point, not from a fit from scratch.
    assert!(wait_until_long(
        || fitted(&s.out, "ball").len() > fits_before
    ));
    let region = &read_json(&s.out.join("ball/report.json"))["session"]["updated_region"];
    assert_eq!(region["fit"], "local", "{region}");
    assert_eq!(region["local_refit"]["changed_points"], 0, "{region}");
    // Deleting a scan removes its points.
    let before = fitted(&s.out, "ball").len();
    std::fs::remove_file(object.join("a.ply")).expect("remove");
    assert!(wait_until_long(|| fitted(&s.out, "ball")
        .iter()
        .skip(before)
        .any(|e| scans_of(e) == ["b"])));
    let report = read_json(&s.out.join("ball/report.json"));
    assert_eq!(report["session"]["scans"].as_array().map(Vec::len), Some(1));
    // A patch file named like the object may not take the object's outputs.
    write_in(&s.inbox, "ball.ply", &cap);
    let taken = |e: &serde_json::Value| e["status"] == "rejected" && e["kind"] == "id_taken";
    assert!(
        wait_until_long(|| events(&s.out).iter().any(taken)),
        "{}",
        s.log()
    );
    assert!(
        s.inbox.join("ball.ply").is_file(),
        "not broken: left in place"
    );
    let report = read_json(&s.out.join("ball/report.json"));
    assert_eq!(report["session"]["scans"].as_array().map(Vec::len), Some(1));
    // Only the broken c left: rejected, and the last surface stays.
    std::fs::remove_file(object.join("b.ply")).expect("remove");
    let no_scans = |e: &serde_json::Value| e["status"] == "rejected" && e["kind"] == "no_scans";
    assert!(wait_until_long(|| events(&s.out).iter().any(no_scans)));
    assert!(s.out.join("ball/surface.json").is_file());
    // No scan at all: the object's outputs go.
    std::fs::remove_file(object.join("c.ply")).expect("remove");
    let removed = |e: &serde_json::Value| e["patch"] == "ball" && e["status"] == "removed";
    assert!(wait_until_long(|| events(&s.out).iter().any(removed)));
    assert!(!s.out.join("ball").exists(), "{}", s.log());
    assert!(stop(daemon).is_some_and(|c| c.success()), "{}", s.log());
}

/// `ply` (ASCII, as `cap_ply` writes it) without its faces: a point cloud.
fn without_faces(ply: &str) -> String {
    let (header, body) = ply.split_once("end_header\n").expect("a PLY header");
    let vertices: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .expect("a vertex count");
    let header = header
        .lines()
        .map(|l| {
            if l.starts_with("element face ") {
                "element face 0"
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let points: Vec<&str> = body.lines().take(vertices).collect();
    format!("{header}\nend_header\n{}\n", points.join("\n"))
}

/// Points all over a sphere of 1 cm radius as an ASCII PLY without faces: a closed cloud,
/// no view's height field.
fn sphere_cloud_ply(n: usize) -> String {
    let mut points = Vec::new();
    for i in 0..n {
        let z = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let a = i as f64 * 2.399_963_229_728_653;
        points.push(format!(
            "{} {} {}",
            0.01 * r * a.cos(),
            0.01 * r * a.sin(),
            0.01 * z
        ));
    }
    format!(
        "ply\nformat ascii 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n{}\n",
        points.join("\n")
    )
}

#[test]
fn a_point_cloud_scan_is_merged_on_its_seen_side_and_one_with_no_surface_is_rejected_alone() {
    let s = setup(&object_config(""));
    let object = s.inbox.join("ball");
    std::fs::create_dir_all(&object).expect("mkdir");
    let cap = cap_ply(12);
    write_in(&object, "a.ply", &cap);
    let daemon = s.spawn(&[]);
    wait_fitted(&s, "ball", 1);
    let alone = read_json(&s.out.join("ball/report.json"));
    // The same view as a point cloud: triangulated, turned to the side the mesh scan
    // shows there, and merged (inside out, it would cancel the mesh scan's surface).
    write_in(&object, "p.ply", &without_faces(&cap));
    // Points all around a ball: no view's height field, so no surface to merge.
    write_in(&object, "q.ply", &sphere_cloud_ply(2000));
    let event = wait_rejection(&s, "q.ply");
    assert!(wait_until_long(|| fitted(&s.out, "ball")
        .iter()
        .any(|e| scans_of(e) == ["a", "p"])));
    let reason = event["reason"].as_str().unwrap_or_default();
    assert!(reason.contains("point cloud"), "{event}");
    assert!(object.join("q.ply").is_file(), "left in its folder");
    // The update that saw q (p may have come in an update of its own before it).
    let report_with_q = || {
        let report = read_json(&s.out.join("ball/report.json"));
        let rejected = report["session"]["rejected_scans"].as_array().map(Vec::len);
        (rejected == Some(1)).then_some(report)
    };
    assert!(wait_until_long(|| report_with_q().is_some()), "{}", s.log());
    let both = report_with_q().expect("the report of the update with q");
    let ids: Vec<&str> = both["session"]["scans"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|s| s["id"].as_str())
        .collect();
    assert_eq!(ids, ["a", "p"]);
    let rms = |r: &serde_json::Value| r["final"]["rms_error"].as_f64().unwrap_or(f64::MAX);
    // The merged surface's area in cells (the cloud's triangulation is coarser, so the
    // merge cell grows with it): the same ground, not a surface cancelled or doubled.
    let area = |r: &serde_json::Value| {
        let cell = r["session"]["merge"]["cell"].as_f64().unwrap_or(0.0);
        r["session"]["merge"]["vertices"].as_f64().unwrap_or(0.0) * cell * cell
    };
    assert!(
        (area(&both) - area(&alone)).abs() <= 0.1 * area(&alone),
        "the cloud lies on the mesh scan: merged area {} against {}",
        area(&both),
        area(&alone)
    );
    assert!(
        rms(&both) < 2.0 * rms(&alone) + 1e-6,
        "{} against {}",
        rms(&both),
        rms(&alone)
    );
    assert!(stop(daemon).is_some_and(|c| c.success()), "{}", s.log());
}

#[test]
fn pipe_records_with_an_object_and_a_transform_are_scans_of_that_object() {
    let s = setup(&object_config(""));
    let (mut child, mut w) = s.spawn_pipe();
    let cap = cap_ply(12);
    let record = |w: &mut std::process::ChildStdin, extra: &str, patch: &str| {
        let header = format!(
            "{{\"object\": \"ball\", \"patch\": \"{patch}\", \"format\": \"ply\", \"bytes\": {}{extra}}}\n",
            cap.len()
        );
        crate::daemon_support::write_all(w, header.as_bytes());
        crate::daemon_support::write_all(w, cap.as_bytes());
    };
    record(&mut w, "", "a");
    record(
        &mut w,
        ", \"transform\": [0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]",
        "b",
    );
    // A scaling is no rigid motion: refused, never taken as the identity.
    record(
        &mut w,
        ", \"transform\": [2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 2, 0, 0, 0, 0, 1]",
        "c",
    );
    std::io::Write::flush(&mut w).expect("flush");
    assert!(wait_until_long(|| fitted(&s.out, "ball")
        .iter()
        .any(|e| scans_of(e) == ["a", "b"])));
    let refused = events(&s.out)
        .into_iter()
        .find(|e| e["kind"] == "record_bad_object")
        .expect("the scaled record is refused");
    assert_eq!(refused["status"], "rejected", "{refused}");
    let report = read_json(&s.out.join("ball/report.json"));
    assert!(
        report["session"]["view_spread_deg"]
            .as_f64()
            .is_some_and(|d| d > 60.0),
        "the transform was applied: {}",
        report["session"]
    );
    assert!(s.out.join(".state/objects/ball/b.xf").is_file());
    drop(w);
    let status = crate::daemon_support::wait_exit(&mut child);
    assert!(status.is_some_and(|c| c.success()));
    // A scan stored just before a stop, its fit not yet run: the next start fits it.
    std::fs::write(s.out.join(".state/objects/ball/d.ply"), &cap).expect("store a scan");
    let mut again = crate::daemon_support::bin()
        .args(s.args())
        .args(["--pipe", "-"])
        .stdin(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("spawns");
    let status = crate::daemon_support::wait_exit(&mut again);
    assert!(status.is_some_and(|c| c.success()));
    assert!(
        fitted(&s.out, "ball")
            .iter()
            .any(|e| scans_of(e) == ["a", "b", "d"]),
        "the stored scan was fitted at the restart: {:?}",
        fitted(&s.out, "ball")
            .iter()
            .map(scans_of)
            .collect::<Vec<_>>()
    );
}

/// A glTF scan in an object folder whose `.bin` is copied after it: the object waits for
/// the buffer as a patch does (said once, read again every second), then fits the scan.
/// It used to be rejected at once and the late buffer changed nothing.
#[test]
fn an_object_scan_whose_gltf_buffer_arrives_late_is_waited_for() {
    let s = setup(&object_config(""));
    let object = s.inbox.join("late");
    std::fs::create_dir_all(&object).expect("mkdir");
    let daemon = s.spawn(&[]);
    assert!(wait_until(|| s.log().contains("watching")), "{}", s.log());
    let (gltf, bin) = patch_gltf_external(30, 5, "view.bin");
    write_in(&object, "view.gltf", &gltf);
    let status = |e: &serde_json::Value, st: &str| e["patch"] == "late" && e["status"] == st;
    assert!(
        wait_until(|| events(&s.out).iter().any(|e| status(e, "incomplete"))),
        "{}",
        s.log()
    );
    std::thread::sleep(std::time::Duration::from_millis(2500));
    let part = object.join(".view.bin");
    std::fs::write(&part, &bin).expect("bin");
    std::fs::rename(&part, object.join("view.bin")).expect("rename");
    wait_fitted(&s, "late", 1);
    let all = events(&s.out);
    let waiting = all.iter().filter(|e| status(e, "incomplete")).count();
    assert_eq!(waiting, 1, "{all:?}");
    assert!(!all.iter().any(|e| status(e, "rejected")), "{all:?}");
    assert!(object.join("view.gltf").is_file());
    assert!(stop(daemon).is_some_and(|st| st.success()));
}
