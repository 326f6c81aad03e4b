//! Operations as a process: SIGTERM with work in flight loses nothing, a config change
//! refits unchanged inputs, SIGHUP with good and bad configs, sd_notify, /metrics.

use crate::daemon_support::*;
use std::io::{Read, Write};
use std::os::unix::net::UnixDatagram;
use std::process::Stdio;
use std::time::Duration;

#[test]
fn sigterm_with_work_in_flight_loses_nothing() {
    let s = setup(&config(0, "native", "").replace("workers = 2", "workers = 1"));
    let (mut child, mut w) = s.spawn_pipe();
    let patches: Vec<String> = (0..6).map(|k| format!("rec{k}")).collect();
    for (k, p) in patches.iter().enumerate() {
        let bytes = patch_ply(40, k as u32);
        write_all(
            &mut w,
            format!(
                "{{\"patch\": \"{p}\", \"format\": \"ply\", \"bytes\": {}}}\n",
                bytes.len()
            )
            .as_bytes(),
        );
        write_all(&mut w, &bytes);
    }
    w.flush().expect("flush");
    // Stop while records are still waiting or being fitted (stdin stays open).
    assert!(wait_until(|| events(&s.out).iter().any(is_fitted)));
    signal(&child, "TERM");
    let status = wait_exit(&mut child);
    drop(w);
    assert!(status.is_some_and(|st| st.success()), "{status:?}");
    let ev = events(&s.out);
    for p in &patches {
        let fitted = ev.iter().any(|e| e["patch"] == p.as_str() && is_fitted(e));
        let spilled = ev
            .iter()
            .any(|e| e["patch"] == p.as_str() && e["status"] == "spilled");
        assert!(fitted ^ spilled, "{p}: fitted or kept, exactly one: {ev:?}");
    }
    // The next start fits what was kept in the watch folder.
    let o = s.once();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for p in &patches {
        assert!(s.out.join(p).join("surface.json").exists(), "{p}");
    }
}

#[test]
fn a_stop_bound_of_zero_keeps_the_record_in_flight() {
    let s = setup(
        &config(0, "native", "")
            .replace("workers = 2", "workers = 1")
            .replace("stop_timeout_ms = 20000", "stop_timeout_ms = 0")
            .replace("max_iterations = 20", "max_iterations = 400"),
    );
    let log = s.out.parent().expect("tmp").join("daemon.log");
    let mut child = bin()
        .args(s.args())
        .args(["--pipe", "-"])
        .env("RUST_LOG", "debug")
        .stdin(Stdio::piped())
        .stderr(std::fs::File::create(&log).expect("log"))
        .spawn()
        .expect("spawns");
    let mut w = child.stdin.take().expect("stdin");
    let bytes = patch_ply(120, 1);
    write_all(
        &mut w,
        format!(
            "{{\"patch\": \"big\", \"format\": \"ply\", \"bytes\": {}}}\n",
            bytes.len()
        )
        .as_bytes(),
    );
    write_all(&mut w, &bytes);
    w.flush().expect("flush");
    let fitting = || std::fs::read_to_string(&log).is_ok_and(|l| l.contains("fitting"));
    assert!(wait_until(fitting));
    signal(&child, "TERM");
    let status = wait_exit(&mut child);
    drop(w);
    assert!(status.is_some_and(|st| st.success()), "{status:?}");
    let ev = events(&s.out);
    let fitted = ev.iter().any(|e| e["patch"] == "big" && is_fitted(e));
    let spilled: Vec<_> = ev.iter().filter(|e| e["status"] == "spilled").collect();
    println!(
        "fitted before the stop: {fitted}; spilled: {}",
        spilled.len()
    );
    assert!(fitted || spilled.len() == 1, "{ev:?}");
    if let Some(e) = spilled.first() {
        let path = e["path"].as_str().expect("path");
        assert_eq!(std::fs::read(path).expect("spilled file"), bytes);
    }
}

#[test]
fn restart_skips_unchanged_inputs_until_the_fit_config_changes() {
    let s = setup(&config(0, "poll", ""));
    for k in 0..2 {
        std::fs::write(s.inbox.join(format!("p{k}.ply")), patch_ply(12, k)).expect("write");
    }
    let fitted = || events(&s.out).iter().filter(|e| is_fitted(e)).count();
    assert!(s.once().status.success());
    assert_eq!(fitted(), 2);
    let o = s.once();
    assert!(String::from_utf8_lossy(&o.stderr).contains("unchanged 2"));
    assert_eq!(fitted(), 2, "unchanged inputs are skipped");
    // Settle time is not part of the fit: still skipped.
    let text = std::fs::read_to_string(&s.cfg).expect("read");
    std::fs::write(&s.cfg, text.replace("settle_ms = 0", "settle_ms = 1")).expect("write");
    assert!(s.once().status.success());
    assert_eq!(fitted(), 2);
    let text = std::fs::read_to_string(&s.cfg).expect("read");
    std::fs::write(
        &s.cfg,
        text.replace("max_iterations = 20", "max_iterations = 9"),
    )
    .expect("write");
    assert!(s.once().status.success());
    assert_eq!(fitted(), 4, "a fit config change refits");
    let r = read_json(&s.out.join("p0/report.json"));
    assert_eq!(r["budget"]["max_iterations"], 9);
}

#[test]
fn sighup_applies_a_good_config_and_keeps_the_old_one_on_a_bad_one() {
    let s = setup(&config(0, "native", ""));
    let child = s.spawn(&[]);
    let iterations =
        |p: &str| read_json(&s.out.join(p).join("report.json"))["budget"]["max_iterations"].clone();
    let count = |status: &str| {
        events(&s.out)
            .iter()
            .filter(|e| e["status"] == status)
            .count()
    };
    drop_file(&s.inbox, "a.ply", &patch_ply(12, 1));
    assert!(
        wait_until(|| s.out.join("a/surface.json").exists()),
        "{}",
        s.log()
    );
    assert_eq!(iterations("a"), 20);
    let good = config(0, "native", "").replace("max_iterations = 20", "max_iterations = 7");
    std::fs::write(&s.cfg, good).expect("write");
    signal(&child, "HUP");
    assert!(wait_until(|| count("config_reloaded") >= 1), "{}", s.log());
    drop_file(&s.inbox, "b.ply", &patch_ply(12, 2));
    assert!(
        wait_until(|| s.out.join("b/surface.json").exists()),
        "{}",
        s.log()
    );
    assert_eq!(iterations("b"), 7);
    let bad = config(0, "native", "").replace("lattice = 6", "latice = 6");
    std::fs::write(&s.cfg, bad).expect("write");
    signal(&child, "HUP");
    assert!(wait_until(|| count("config_rejected") >= 1), "{}", s.log());
    let rejected = events(&s.out)
        .into_iter()
        .rfind(|e| e["status"] == "config_rejected")
        .expect("event");
    assert!(
        rejected["reason"]
            .as_str()
            .is_some_and(|r| r.contains("latice")),
        "{rejected}"
    );
    drop_file(&s.inbox, "c.ply", &patch_ply(12, 3));
    assert!(
        wait_until(|| s.out.join("c/surface.json").exists()),
        "{}",
        s.log()
    );
    assert_eq!(iterations("c"), 7, "the last good config stays");
    assert!(stop(child).is_some_and(|st| st.success()));
    assert!(s.log().contains("config reload refused"));
}

#[test]
fn systemd_notifications_follow_ready_reload_and_stop() {
    let s = setup(&config(0, "native", ""));
    let sock_path = s.out.parent().expect("tmp").join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).expect("bind");
    sock.set_read_timeout(Some(DEADLINE)).expect("timeout");
    let mut child = bin()
        .args([
            "watch",
            s.inbox.to_str().expect("utf8"),
            "--out",
            s.out.to_str().expect("utf8"),
        ])
        .env("NOTIFY_SOCKET", &sock_path)
        .stderr(Stdio::null())
        .spawn()
        .expect("spawns");
    let next = || {
        let mut buf = [0u8; 256];
        let n = sock.recv(&mut buf).expect("a notification");
        // sd-notify ends each state with a newline, as systemd accepts.
        String::from_utf8_lossy(&buf[..n]).trim_end().to_string()
    };
    assert_eq!(next(), "READY=1");
    // Without --config a reload re-applies the embedded default: the SIGHUP path alone.
    signal(&child, "HUP");
    assert_eq!(next(), "RELOADING=1");
    assert_eq!(next(), "READY=1");
    assert!(wait_until(|| events(&s.out)
        .iter()
        .any(|e| e["status"] == "config_reloaded")));
    signal(&child, "TERM");
    assert_eq!(next(), "STOPPING=1");
    assert!(wait_exit(&mut child).is_some_and(|st| st.success()));
}

fn http_get(port: u16, path: &str) -> String {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).expect("connects");
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    s.write_all(format!("GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").as_bytes())
        .expect("sends");
    let mut out = String::new();
    s.read_to_string(&mut out).expect("reads");
    out
}

#[test]
fn metrics_and_health_on_loopback() {
    // Port 0: the daemon binds a free port and logs it, so no other process can take it
    // between a probe and the start.
    let s = setup(&config(0, "native", "metrics_addr = \"127.0.0.1:0\""));
    let child = s.spawn(&[]);
    let mut port = 0u16;
    let bound = wait_until(|| {
        let log = s.log();
        let Some(at) = log.find("addr=127.0.0.1:") else {
            return false;
        };
        let digits: String = log[at + 15..]
            .chars()
            .take_while(|c| c.is_ascii_digit())
            .collect();
        port = digits.parse().unwrap_or(0);
        port != 0
    });
    assert!(bound, "{}", s.log());
    drop_file(&s.inbox, "a.ply", &patch_ply(12, 1));
    drop_file(&s.inbox, "b.ply", &patch_ply(12, 2));
    drop_file(&s.inbox, "bad.ply", CORRUPT_PLY);
    assert!(wait_until(|| events(&s.out).len() >= 3), "{}", s.log());
    let m = http_get(port, "/metrics");
    assert!(m.starts_with("HTTP/1.1 200"), "{m}");
    assert!(m.contains("trispline_patches_fitted_total 2"), "{m}");
    assert!(m.contains("trispline_patches_rejected_total 1"), "{m}");
    assert!(m.contains("trispline_fit_duration_seconds_count 2"), "{m}");
    assert!(m.contains("trispline_queue_depth 0"), "{m}");
    // Labels are kinds, never file names or reasons (one series per input otherwise): the
    // reader's own kind for a header that never ends, the same one the event carries.
    let rejected = events(&s.out)
        .into_iter()
        .find(|e| e["status"] == "rejected")
        .expect("a rejection event");
    assert_eq!(rejected["kind"], "bad_header", "{rejected}");
    assert!(
        m.contains("trispline_rejections_total{kind=\"bad_header\"} 1"),
        "{m}"
    );
    assert!(!m.contains("bad.ply"), "{m}");
    assert!(http_get(port, "/healthz").ends_with("ok\n"));
    assert!(stop(child).is_some_and(|st| st.success()));
    let refused = bin()
        .args(["watch", ".", "--out", "x", "--check-config", "--config"])
        .arg({
            let p = s.out.parent().expect("tmp").join("open.toml");
            std::fs::write(&p, config(0, "native", "metrics_addr = \"0.0.0.0:9187\""))
                .expect("write");
            p
        })
        .output()
        .expect("runs");
    assert_eq!(refused.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&refused.stderr).contains("loopback"));
}
