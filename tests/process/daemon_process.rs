//! The daemon as a process: --once over a folder with versions and a corrupt file, restart
//! skipping unchanged inputs, warm start of a new version, config errors, SIGTERM.

use crate::daemon_support::events;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const FAST_CONFIG: &str = r#"
[fit]
surface = "bezier"
levels = 1
method = "cg"
inverse = "exact"

[fit.budget]
max_iterations = 30
tolerance_rel = 1e-3

[fit.scan]
lattice = 8
smoothing = 1e-5

[output]
tessellation = 16

[daemon]
settle_ms = 0
poll_interval_ms = 50
max_file_bytes = 10000000
max_vertices = 1000000
"#;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
}

fn fitted_events(out: &Path) -> usize {
    events(out)
        .iter()
        .filter(|e| matches!(e["status"].as_str(), Some("met" | "capped" | "stalled")))
        .count()
}

fn sample(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/patches")
        .join(name)
}

#[test]
fn once_fits_versions_quarantines_and_warm_starts() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (inbox, out, cfg) = (
        tmp.path().join("in"),
        tmp.path().join("out"),
        tmp.path().join("fast.toml"),
    );
    std::fs::create_dir_all(&inbox).expect("mkdir");
    std::fs::write(&cfg, FAST_CONFIG).expect("config");
    std::fs::copy(sample("dome.obj"), inbox.join("dome@1.obj")).expect("copy");
    std::fs::copy(sample("dome.obj"), inbox.join("dome@2.obj")).expect("copy");
    std::fs::copy(sample("ripple.off"), inbox.join("ripple.off")).expect("copy");
    std::fs::write(
        inbox.join("broken.ply"),
        b"ply\nformat ascii 1.0\nelement vertex 99\n",
    )
    .expect("write");
    std::fs::write(inbox.join(".hidden.obj"), b"v 0 0 0\n").expect("write");
    std::fs::write(inbox.join("upload.obj.part"), b"v 0 0 0\n").expect("write");
    let run = || {
        bin()
            .args([
                "watch",
                inbox.to_str().unwrap_or_default(),
                "--out",
                out.to_str().unwrap_or_default(),
                "--config",
                cfg.to_str().unwrap_or_default(),
                "--once",
            ])
            .output()
            .expect("runs")
    };
    let o = run();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for patch in ["dome", "ripple"] {
        let s: serde_json::Value = serde_json::from_slice(
            &std::fs::read(out.join(patch).join("surface.json")).expect("surface"),
        )
        .expect("json");
        assert_eq!(s["schema"], "trispline.surface/1");
        assert!(out.join(patch).join("surface.glb").exists());
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("dome/report.json")).expect("report"))
            .expect("json");
    assert_eq!(
        report["version"], "dome@2.obj",
        "the newest version is fitted"
    );
    assert_eq!(report["warm_start"], false);
    let ev = events(&out);
    assert!(ev.iter().any(|e| e["status"] == "superseded"
        && e["input"]
            .as_str()
            .is_some_and(|i| i.ends_with("dome@1.obj"))));
    assert!(ev
        .iter()
        .any(|e| e["status"] == "rejected" && e["patch"] == "broken"));
    assert!(
        out.join("quarantine/broken.ply").exists()
            && out.join("quarantine/broken.ply.error.json").exists()
    );
    assert!(!inbox.join("broken.ply").exists());
    assert!(
        inbox.join("dome@1.obj").exists(),
        "superseded inputs are never deleted"
    );
    assert_eq!(fitted_events(&out), 2);
    // Restart: unchanged inputs are skipped by content hash.
    let o = run();
    assert!(o.status.success());
    assert_eq!(
        fitted_events(&out),
        2,
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // A new version of a known patch starts from the previous control net.
    let mut text = std::fs::read_to_string(sample("dome.obj")).expect("read");
    text.push_str("# version 3\n");
    std::fs::write(inbox.join("dome@3.obj"), text).expect("write");
    let o = run();
    assert!(o.status.success());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("dome/report.json")).expect("report"))
            .expect("json");
    assert_eq!(report["version"], "dome@3.obj");
    assert_eq!(report["warm_start"], true);
}

#[test]
fn config_errors_name_the_key_and_exit_2() {
    let tmp = tempfile::tempdir().expect("tmp");
    let cfg = tmp.path().join("bad.toml");
    std::fs::write(&cfg, FAST_CONFIG.replace("lattice = 8", "latice = 8")).expect("write");
    let o = bin()
        .args([
            "watch",
            ".",
            "--out",
            "x",
            "--config",
            cfg.to_str().unwrap_or_default(),
            "--check-config",
        ])
        .output()
        .expect("runs");
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("latice") && err.contains("line"), "{err}");
    let o = bin()
        .args(["watch", ".", "--out", "x", "--print-config"])
        .output()
        .expect("runs");
    assert!(o.status.success() && String::from_utf8_lossy(&o.stdout).contains("[fit]"));
}

#[test]
fn sigterm_stops_the_daemon_gracefully() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (inbox, out, cfg) = (
        tmp.path().join("in"),
        tmp.path().join("out"),
        tmp.path().join("fast.toml"),
    );
    std::fs::create_dir_all(&inbox).expect("mkdir");
    std::fs::write(&cfg, FAST_CONFIG).expect("config");
    let mut child = bin()
        .args([
            "watch",
            inbox.to_str().unwrap_or_default(),
            "--out",
            out.to_str().unwrap_or_default(),
            "--config",
            cfg.to_str().unwrap_or_default(),
        ])
        .stderr(Stdio::null())
        .spawn()
        .expect("spawns");
    // A file dropped while it runs is fitted: written under a .part name (ignored), then
    // renamed into place, as uploaders do. (With settle_ms = 0 a file copied in place could
    // be read while still empty.)
    std::fs::copy(
        sample("saddle@0001.ply"),
        inbox.join("saddle@0001.ply.part"),
    )
    .expect("copy");
    std::fs::rename(
        inbox.join("saddle@0001.ply.part"),
        inbox.join("saddle@0001.ply"),
    )
    .expect("rename");
    let deadline = Instant::now() + Duration::from_secs(60);
    while !out.join("saddle/surface.json").exists() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(out.join("saddle/surface.json").exists());
    let pid = child.id().to_string();
    Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill");
    let deadline = Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break Some(s);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            break None;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(
        status.is_some_and(|s| s.success()),
        "exit status {status:?}"
    );
}

/// A closed UV sphere of `around` x `rings` quads (poles fanned), as OBJ.
fn coarse_sphere_obj(around: usize, rings: usize) -> String {
    let mut obj = String::from("v 0 0 1\n");
    for j in 1..rings {
        let theta = std::f64::consts::PI * j as f64 / rings as f64;
        for i in 0..around {
            let phi = std::f64::consts::TAU * i as f64 / around as f64;
            let (s, c) = (theta.sin(), theta.cos());
            obj += &format!("v {} {} {}\n", s * phi.cos(), s * phi.sin(), c);
        }
    }
    obj += "v 0 0 -1\n";
    // 1-based: the north pole is 1, ring j's vertex i is 2 + (j - 1) * around + i.
    let at = |j: usize, i: usize| 2 + (j - 1) * around + i % around;
    let south = 2 + (rings - 1) * around;
    for i in 0..around {
        obj += &format!("f 1 {} {}\n", at(1, i), at(1, i + 1));
        obj += &format!("f {} {south} {}\n", at(rings - 1, i), at(rings - 1, i + 1));
        for j in 1..rings - 1 {
            let (a, b, c, d) = (at(j, i), at(j + 1, i), at(j + 1, i + 1), at(j, i + 1));
            obj += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
        }
    }
    obj
}

#[test]
fn an_event_says_when_a_whole_object_strays_past_its_bound_or_pieces_are_left_out() {
    let tmp = tempfile::tempdir().expect("tmp");
    let (inbox, out, cfg) = (
        tmp.path().join("in"),
        tmp.path().join("out"),
        tmp.path().join("defaults.toml"),
    );
    std::fs::create_dir_all(&inbox).expect("mkdir");
    // The embedded defaults (a Loop surface at 5 % of the points), read without delay, and
    // no faceted surface: its last resort would hold the coarse sphere within the bound.
    let config = "[daemon]\nsettle_ms = 0\npoll_interval_ms = 50\n[fit]\nfaceted = false\n";
    std::fs::write(&cfg, config).expect("config");
    // 146 points: 8 controls, which stray some 1.6 % of the diagonal from the facets.
    std::fs::write(inbox.join("coarse.obj"), coarse_sphere_obj(16, 10)).expect("write");
    // 1,298 points of the same sphere: its 39 controls hold it within the bound.
    std::fs::write(inbox.join("fine.obj"), coarse_sphere_obj(48, 28)).expect("write");
    // Two tori apart, of 384 and 240 vertices: the default policy fits the larger.
    let mut pair = trispline::testdata::torus(32, 12);
    let small = trispline::testdata::torus(24, 10);
    let offset = pair.positions.len() as u32;
    pair.positions
        .extend(small.positions.iter().map(|p| *p + glam::DVec3::X * 4.0));
    pair.triangles
        .extend(small.triangles.iter().map(|t| t.map(|v| v + offset)));
    trispline::io::write_mesh_file(&inbox.join("pair.obj"), &pair).expect("write");
    let done = bin()
        .args(["watch", &inbox.display().to_string(), "--out"])
        .arg(&out)
        .arg("--config")
        .arg(&cfg)
        .arg("--once")
        .output()
        .expect("runs");
    assert!(
        done.status.success(),
        "{}",
        String::from_utf8_lossy(&done.stderr)
    );
    let all = events(&out);
    let of = |patch: &str| {
        all.iter()
            .find(|e| e["patch"] == patch)
            .unwrap_or_else(|| panic!("no event for {patch}: {all:?}"))
    };
    let coarse = of("coarse");
    assert_eq!(coarse["path"], "object", "{coarse}");
    assert_eq!(coarse["stray"]["within"], false, "{coarse}");
    let share = coarse["stray"]["share_of_diagonal"]
        .as_f64()
        .expect("share");
    let limit = coarse["stray"]["limit_share"].as_f64().expect("limit");
    assert!(share > limit, "{coarse}");
    let fine = of("fine");
    assert!(
        fine["status"].is_string() && fine.get("stray").is_none() && fine.get("dropped").is_none(),
        "{fine}"
    );
    // Pieces left out are said there too.
    let pair = of("pair");
    assert_eq!(pair["dropped"]["pieces"], 1, "{pair}");
    assert_eq!(pair["dropped"]["vertices"], 240, "{pair}");
}
