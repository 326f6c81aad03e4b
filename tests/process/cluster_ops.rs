//! The cluster's operations around the fits: a source that starts before its server, the
//! warm start of a result dropped as stale, the processed-file policy of queued inputs, and
//! a worker's config reload on SIGHUP.

use crate::cluster::*;
use crate::daemon_support::*;
use std::collections::HashMap;
use std::io::{Read, Write};
use std::path::Path;
use std::time::Duration;

/// The response to `GET path`, or `None` while nothing listens.
fn http_get(port: u16, path: &str) -> Option<String> {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(10))).ok()?;
    s.write_all(format!("GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").as_bytes())
        .ok()?;
    let mut out = String::new();
    s.read_to_string(&mut out).ok()?;
    Some(out)
}

#[test]
fn a_source_started_before_its_server_waits_coalesces_and_publishes_once_it_is_up() {
    let Some(bin) = nats_server() else {
        return;
    };
    let port = free_port();
    let metrics = free_port();
    let cfg = cluster_config().replace(
        "[daemon]\n",
        &format!("[daemon]\nmetrics_addr = \"127.0.0.1:{metrics}\"\n"),
    );
    let s = setup(&cfg);
    let url = format!("nats://127.0.0.1:{port}");
    let mut source = s.spawn(&["--queue", &url]);
    let mut all = Vec::new();
    for v in 1..=3u32 {
        let name = format!("a@{v:04}.ply");
        drop_file(&s.inbox, &name, &patch_ply(10, v));
        all.push(name);
    }
    drop_file(&s.inbox, "b@0001.ply", &patch_ply(10, 9));
    all.push("b@0001.ply".into());
    let unreachable = wait_until(|| {
        http_get(metrics, "/healthz")
            .is_some_and(|r| r.starts_with("HTTP/1.1 503") && r.contains("queue unreachable"))
    });
    assert!(unreachable, "{}", s.log());
    // Retrying, not gone: the versions wait in the source meanwhile.
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        source.try_wait().expect("status").is_none(),
        "the source kept running: {}",
        s.log()
    );
    assert!(s.log().contains("not reachable"), "{}", s.log());
    let server = Server::start_on(bin, port);
    // The worker reads the same file: without the source's metrics address, which is taken.
    std::fs::write(&s.cfg, cluster_config()).expect("config");
    let w = spawn_worker(&s, &server, "w1");
    assert!(
        wait_until(|| accounted(&s.out, &all)),
        "{}",
        logs(&s, &["w1"])
    );
    let newest = HashMap::from([
        ("a".to_string(), "a@0003.ply".to_string()),
        ("b".to_string(), "b@0001.ply".to_string()),
    ]);
    check_newest_fitted_last(&s.out, &newest);
    let reachable = wait_until(|| {
        http_get(metrics, "/healthz").is_some_and(|r| r.contains("ok, queue reachable"))
    });
    assert!(reachable, "{}", s.log());
    assert!(stop(source).is_some_and(|st| st.success()), "{}", s.log());
    assert!(stop(w).is_some_and(|st| st.success()));
}

#[test]
fn a_result_dropped_as_stale_leaves_its_warm_start_for_the_next_version() {
    let Some(server) = Server::start() else {
        return;
    };
    // The default fit on a 150 x 150 grid: long enough for the next version to be queued
    // while the first one fits.
    let s = setup("[daemon]\nsettle_ms = 100\nworkers = 1\n[cluster]\nack_wait_ms = 2000\n");
    let source = s.spawn(&["--queue", &server.url()]);
    let w = spawn_worker(&s, &server, "A");
    let v1 = patch_obj(150, 7);
    drop_file(&s.inbox, "ear@0001.obj", &v1);
    let fitting = wait_until(|| {
        worker_log(&s, "A")
            .lines()
            .any(|l| l.contains("fitting") && l.contains("ear@0001.obj"))
    });
    assert!(fitting, "{}", logs(&s, &["A"]));
    // Same surface, other bytes: the warm start applies to it.
    drop_file(
        &s.inbox,
        "ear@0002.obj",
        &[v1.as_slice(), b"# version 2\n"].concat(),
    );
    let about = |v: &str| {
        events(&s.out)
            .into_iter()
            .find(|e| e["version"] == v && (is_fitted(e) || e["status"] == "superseded"))
    };
    assert!(
        wait_until(|| about("ear@0001.obj").is_some() && about("ear@0002.obj").is_some()),
        "{}",
        logs(&s, &["A"])
    );
    let first = about("ear@0001.obj").expect("accounted");
    let second = about("ear@0002.obj").expect("accounted");
    assert!(is_fitted(&second), "{second}");
    if first["status"] == "superseded" {
        // Fitted, then dropped for version 2: nothing of it was written, yet version 2
        // starts from its control net, read from the bucket.
        assert_eq!(first["by"], "ear@0002.obj", "{first}");
        assert_eq!(second["warm_start"], true, "{second}");
        assert!(
            worker_log(&s, "A").contains("ear@0001.obj"),
            "{}",
            logs(&s, &["A"])
        );
    } else {
        eprintln!("version 1 was written before version 2 came; the stale path was not exercised");
    }
    assert!(stop(w).is_some_and(|st| st.success()));
    assert!(stop(source).is_some_and(|st| st.success()));
}

/// A PLY of two triangles, under the 1 KiB payload limit of the test below.
const TINY_PLY: &[u8] = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n";

#[test]
fn queued_inputs_are_moved_once_stored_in_the_stream_or_once_a_worker_finished_them() {
    let Some(server) = Server::start() else {
        return;
    };
    let cfg = cluster_config()
        .replace("[output]\n", "[output]\nprocessed = \"move\"\n")
        .replace("[cluster]\n", "[cluster]\npayload_limit = 1024\n");
    let s = setup(&cfg);
    let source = s.spawn(&["--queue", &server.url()]);
    // Small enough to travel in the message, and too big (a path job).
    let small = patch_ply(10, 1);
    assert!(small.len() > 1024, "the path job's file is over the limit");
    drop_file(&s.inbox, "tiny.ply", TINY_PLY);
    drop_file(&s.inbox, "big.ply", &small);
    let processed = |name: &str| s.out.join("processed").join(name);
    let gone = |name: &str| !s.inbox.join(name).exists();
    // No worker runs yet: the message holds the bytes, so the file goes now.
    assert!(
        wait_until(|| gone("tiny.ply") && processed("tiny.ply").exists()),
        "{}",
        s.log()
    );
    assert_eq!(
        std::fs::read(processed("tiny.ply")).expect("moved"),
        TINY_PLY
    );
    assert!(
        wait_until(|| s.log().matches("queued").count() >= 2),
        "{}",
        s.log()
    );
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        s.inbox.join("big.ply").exists(),
        "a path job's file stays until a worker has read and finished it"
    );
    let w = spawn_worker(&s, &server, "w1");
    let fitted = || {
        events(&s.out)
            .iter()
            .any(|e| is_fitted(e) && e["patch"] == "big")
    };
    assert!(
        wait_until(|| fitted() && gone("big.ply") && processed("big.ply").exists()),
        "{}",
        logs(&s, &["w1"])
    );
    assert_eq!(std::fs::read(processed("big.ply")).expect("moved"), small);
    assert!(stop(w).is_some_and(|st| st.success()));
    assert!(stop(source).is_some_and(|st| st.success()));
}

fn reloads(out: &Path, status: &str) -> usize {
    events(out)
        .iter()
        .filter(|e| e["status"] == status && e["worker"] == "h1")
        .count()
}

#[test]
fn a_worker_reloads_its_config_on_sighup_and_keeps_the_old_one_when_the_new_is_bad() {
    let Some(server) = Server::start() else {
        return;
    };
    let s = setup(&cluster_config());
    let w = spawn_worker(&s, &server, "h1");
    assert!(
        wait_until(|| worker_log(&s, "h1").contains("worker started")),
        "{}",
        logs(&s, &["h1"])
    );
    // The same file: SIGHUP alone reloads it.
    signal(&w, "HUP");
    assert!(
        wait_until(|| reloads(&s.out, "config_reloaded") == 1),
        "{}",
        logs(&s, &["h1"])
    );
    std::fs::write(&s.cfg, "[fit\nbroken").expect("config");
    signal(&w, "HUP");
    assert!(
        wait_until(|| reloads(&s.out, "config_rejected") >= 1),
        "{}",
        logs(&s, &["h1"])
    );
    // A good config without GLB outputs: the next fit follows it.
    std::fs::write(
        &s.cfg,
        cluster_config().replace("[output]\n", "[output]\nglb = false\n"),
    )
    .expect("config");
    signal(&w, "HUP");
    assert!(
        wait_until(|| reloads(&s.out, "config_reloaded") >= 2),
        "{}",
        logs(&s, &["h1"])
    );
    let source = s.spawn(&["--queue", &server.url()]);
    drop_file(&s.inbox, "p.ply", &patch_ply(10, 3));
    let fitted = || {
        events(&s.out)
            .into_iter()
            .find(|e| is_fitted(e) && e["patch"] == "p")
    };
    assert!(wait_until(|| fitted().is_some()), "{}", logs(&s, &["h1"]));
    let e = fitted().expect("fitted");
    assert_eq!(e["worker"], "h1");
    assert!(e["paths"]["glb"].is_null(), "{e}");
    assert!(s.out.join("p/surface.json").exists());
    assert!(!s.out.join("p/surface.glb").exists());
    assert!(stop(source).is_some_and(|st| st.success()), "{}", s.log());
    assert!(stop(w).is_some_and(|st| st.success()));
}
