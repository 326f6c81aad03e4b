//! The folder source as a process: files dropped whole, renamed in, written slowly, held
//! open; native and poll watching; bursts; quick versions; corrupt files; processed policy.

use crate::daemon_support::*;
use std::io::Write;
use std::time::Duration;
use trispline::daemon::state::content_hash;

fn fitted_for(out: &std::path::Path, patch: &str) -> Vec<serde_json::Value> {
    events(out)
        .into_iter()
        .filter(|e| e["patch"] == patch && is_fitted(e))
        .collect()
}

/// Writes `bytes` through one handle in `pieces`, pausing between them, the way a slow
/// network copy does. The pauses are a tenth of the tests' settle time, so that a loaded
/// machine stretching a sleep does not make the file look complete.
fn write_slowly(path: &std::path::Path, bytes: &[u8], pieces: usize, pause: Duration) {
    let mut f = std::fs::File::create(path).expect("create");
    for chunk in bytes.chunks(bytes.len().div_ceil(pieces)) {
        f.write_all(chunk).expect("write");
        f.flush().expect("flush");
        std::thread::sleep(pause);
    }
}

fn assert_fitted_complete(s: &Setup, patch: &str, bytes: &[u8]) {
    let report = read_json(&s.out.join(patch).join("report.json"));
    assert_eq!(
        report["input_hash"],
        format!("{:016x}", content_hash(bytes)),
        "{patch} was read before it was complete"
    );
    assert_eq!(fitted_for(&s.out, patch).len(), 1, "{patch}: one fit");
}

#[test]
fn native_reads_files_only_when_complete() {
    let s = setup(&config(1000, "native", ""));
    let child = s.spawn(&[]);
    let whole = patch_ply(14, 1);
    std::fs::write(s.inbox.join("whole.ply"), &whole).expect("write");
    let renamed = patch_obj(14, 2);
    let part = s.inbox.join("renamed.obj.part");
    std::fs::write(&part, &renamed[..renamed.len() / 2]).expect("write half");
    std::thread::sleep(Duration::from_millis(100));
    let mut f = std::fs::OpenOptions::new()
        .append(true)
        .open(&part)
        .expect("open");
    f.write_all(&renamed[renamed.len() / 2..])
        .expect("write rest");
    drop(f);
    std::fs::rename(&part, s.inbox.join("renamed.obj")).expect("rename");
    let slow = patch_ply(14, 3);
    write_slowly(
        &s.inbox.join("slow.ply"),
        &slow,
        5,
        Duration::from_millis(100),
    );
    // A writer that keeps the file open past the settle time: taken on its close.
    let held = patch_ply(14, 4);
    let mut h = std::fs::File::create(s.inbox.join("held.ply")).expect("create");
    h.write_all(&held).expect("write");
    h.flush().expect("flush");
    drop(h);
    assert!(
        wait_until(|| s.out.join("held/surface.json").exists()),
        "a file held open is fitted once closed: {}",
        s.log()
    );
    for p in ["whole", "renamed", "slow"] {
        assert!(
            wait_until(|| s.out.join(p).join("surface.json").exists()),
            "{p}: {}",
            s.log()
        );
    }
    assert!(stop(child).is_some_and(|st| st.success()));
    assert_fitted_complete(&s, "whole", &whole);
    assert_fitted_complete(&s, "renamed", &renamed);
    assert_fitted_complete(&s, "slow", &slow);
    assert_fitted_complete(&s, "held", &held);
    assert!(!events(&s.out).iter().any(|e| e["status"] == "rejected"));
}

#[test]
fn poll_watcher_waits_for_the_settle_time() {
    let s = setup(&config(1000, "poll", ""));
    let child = s.spawn(&[]);
    let slow = patch_ply(14, 5);
    write_slowly(
        &s.inbox.join("slow.ply"),
        &slow,
        5,
        Duration::from_millis(100),
    );
    let renamed = patch_ply(14, 6);
    drop_file(&s.inbox, "renamed.ply", &renamed);
    for p in ["slow", "renamed"] {
        assert!(
            wait_until(|| s.out.join(p).join("surface.json").exists()),
            "{p}: {}",
            s.log()
        );
    }
    assert!(stop(child).is_some_and(|st| st.success()));
    assert_fitted_complete(&s, "slow", &slow);
    assert_fitted_complete(&s, "renamed", &renamed);
}

#[test]
fn a_burst_of_50_patches_is_fitted_once_each() {
    let s = setup(&config(300, "native", ""));
    let child = s.spawn(&[]);
    for k in 0..50 {
        drop_file(&s.inbox, &format!("p{k:02}.ply"), &patch_ply(10, k));
    }
    assert!(
        wait_until(|| events(&s.out).iter().filter(|e| is_fitted(e)).count() >= 50),
        "{}",
        s.log()
    );
    assert!(stop(child).is_some_and(|st| st.success()));
    let ev = events(&s.out);
    for k in 0..50 {
        let id = format!("p{k:02}");
        assert_eq!(ev.iter().filter(|e| e["patch"] == id).count(), 1, "{id}");
        assert!(s.out.join(&id).join("surface.json").exists());
        assert!(
            s.inbox.join(format!("{id}.ply")).exists(),
            "inputs are left"
        );
    }
    assert_eq!(ev.len(), 50);
}

#[test]
fn quick_versions_fit_only_the_newest_and_lose_nothing() {
    let s = setup(&config(300, "native", ""));
    let child = s.spawn(&[]);
    let names: Vec<String> = (1..=10).map(|k| format!("ear@{k:04}.ply")).collect();
    let versions: Vec<Vec<u8>> = (1..=10).map(|k| patch_ply(40, 100 + k)).collect();
    for (n, b) in names.iter().zip(&versions) {
        std::fs::write(s.inbox.join(format!("{n}.part")), b).expect("write");
    }
    for n in &names {
        std::fs::rename(s.inbox.join(format!("{n}.part")), s.inbox.join(n)).expect("rename");
    }
    let accounted = || {
        let ev = events(&s.out);
        names
            .iter()
            .all(|n| ev.iter().any(|e| e["version"] == n.as_str()))
    };
    assert!(wait_until(accounted), "{}", s.log());
    assert!(stop(child).is_some_and(|st| st.success()));
    let ev = events(&s.out);
    for n in &names {
        assert_eq!(
            ev.iter().filter(|e| e["version"] == n.as_str()).count(),
            1,
            "one event for {n}"
        );
        assert!(s.inbox.join(n).exists(), "{n} is never deleted");
    }
    let fitted = fitted_for(&s.out, "ear");
    assert_eq!(fitted.len(), 1, "{fitted:?}");
    assert_eq!(fitted[0]["version"], "ear@0010.ply");
    let superseded: Vec<_> = ev.iter().filter(|e| e["status"] == "superseded").collect();
    assert_eq!(superseded.len(), 9);
    assert_fitted_complete(&s, "ear", &versions[9]);
}

#[test]
fn corrupt_files_are_quarantined_and_the_daemon_keeps_going() {
    let s = setup(&config(200, "native", ""));
    let child = s.spawn(&[]);
    for k in 0..3 {
        drop_file(&s.inbox, &format!("good{k}.ply"), &patch_ply(12, k));
    }
    drop_file(&s.inbox, "broken.ply", CORRUPT_PLY);
    drop_file(&s.inbox, "empty.obj", b"");
    drop_file(&s.inbox, "@@.ply", &patch_ply(12, 9));
    drop_file(&s.inbox, "good3.ply", &patch_ply(12, 3));
    let done = || {
        let ev = events(&s.out);
        ev.iter().filter(|e| is_fitted(e)).count() >= 4
            && ev.iter().filter(|e| e["status"] == "rejected").count() >= 3
    };
    assert!(wait_until(done), "{}", s.log());
    // Still alive: a later good file is fitted too; a second bad file of the same name
    // does not overwrite the first in quarantine.
    drop_file(&s.inbox, "late.ply", &patch_ply(12, 7));
    drop_file(&s.inbox, "broken.ply", b"ply\nsecond broken file\n");
    assert!(
        wait_until(|| s.out.join("late/surface.json").exists()),
        "{}",
        s.log()
    );
    assert!(
        wait_until(|| s.out.join("quarantine/broken~1.ply.error.json").exists()),
        "{}",
        s.log()
    );
    assert!(stop(child).is_some_and(|st| st.success()));
    let q = s.out.join("quarantine");
    for name in ["broken.ply", "empty.obj", "@@.ply"] {
        assert!(q.join(name).exists(), "{name} kept in quarantine");
        let note = read_json(&q.join(format!("{name}.error.json")));
        assert!(note["reason"].as_str().is_some_and(|r| !r.is_empty()));
        assert!(!s.inbox.join(name).exists());
    }
    assert_eq!(
        std::fs::read(q.join("broken.ply")).expect("first"),
        CORRUPT_PLY
    );
    assert_eq!(
        std::fs::read(q.join("broken~1.ply")).expect("second"),
        b"ply\nsecond broken file\n"
    );
    let ev = events(&s.out);
    let broken = ev
        .iter()
        .find(|e| e["patch"] == "broken")
        .expect("broken has an event");
    assert_eq!(broken["status"], "rejected");
    assert!(broken["reason"]
        .as_str()
        .is_some_and(|r| r.contains("broken.ply")));
}

#[test]
fn processed_policy_moves_or_deletes_only_fitted_inputs() {
    for policy in ["move", "delete"] {
        let text = config(0, "native", "").replace(
            "[output]\n",
            &format!("[output]\nprocessed = \"{policy}\"\n"),
        );
        let s = setup(&text);
        std::fs::write(s.inbox.join("a@1.ply"), patch_ply(10, 1)).expect("write");
        std::fs::write(s.inbox.join("a@2.ply"), patch_ply(10, 2)).expect("write");
        std::fs::write(s.inbox.join("bad.ply"), CORRUPT_PLY).expect("write");
        let o = s.once();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert!(
            !s.inbox.join("a@2.ply").exists(),
            "{policy}: fitted input handled"
        );
        assert_eq!(
            s.out.join("processed/a@2.ply").exists(),
            policy == "move",
            "{policy}"
        );
        assert!(
            s.inbox.join("a@1.ply").exists(),
            "{policy}: superseded left"
        );
        assert!(s.out.join("quarantine/bad.ply").exists(), "{policy}");
        assert!(s.out.join("a/surface.json").exists());
    }
}
