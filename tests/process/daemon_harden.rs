//! The hardening points of the daemon as a process: a relative watch folder sees renamed-in
//! files; pipe path records cannot reach outside their roots; odd entries are reported once
//! and odd names get distinct, safe folders; superseded versions are recorded once across
//! starts; a record half-received at a stop is reported; a `.gltf` takes its external
//! buffer from beside it; a quarantine folder where a patch folder could live is refused.

use crate::daemon_support::*;
use std::io::Write;
use std::process::{Command, Stdio};

fn count(out: &std::path::Path, f: impl Fn(&serde_json::Value) -> bool) -> usize {
    events(out).iter().filter(|e| f(e)).count()
}

/// `trispline watch in --out out` started from the folder above, then `mv in/.x.part
/// in/a.obj`: fitted at once, with a settle time far too long for the settle fallback to
/// be what took it.
#[test]
fn a_relative_watch_folder_sees_renamed_in_files() {
    let s = setup(&config(3_000_000, "native", ""));
    let root = s.out.parent().expect("tmp").to_path_buf();
    let log = std::fs::File::create(root.join("daemon.log")).expect("log");
    let child = Daemon::from(
        bin()
            .current_dir(&root)
            .args(["watch", "in", "--out", "out", "--config", "daemon.toml"])
            .stdin(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("spawns"),
    );
    assert!(
        wait_until(|| s.log().contains("watching")),
        "started: {}",
        s.log()
    );
    std::fs::write(s.inbox.join(".x.part"), patch_obj(12, 1)).expect("write");
    let moved = Command::new("mv")
        .current_dir(&root)
        .args(["in/.x.part", "in/a.obj"])
        .status()
        .expect("mv");
    assert!(moved.success());
    assert!(
        wait_until(|| s.out.join("a/surface.json").exists()),
        "a renamed-in file is fitted: {}",
        s.log()
    );
    assert!(stop(child).is_some_and(|st| st.success()));
}

/// `../`, an absolute path elsewhere and a symlink out of the folder name a victim file:
/// each is refused with a kind, and the victim is neither moved nor deleted although the
/// processed policy is `delete`; a file inside the folder is fitted and deleted.
#[test]
fn pipe_path_records_cannot_reach_outside_the_roots() {
    // The fixture already has an [output] table: the policy goes into it.
    let s = setup(
        &config(3_000_000, "native", "")
            .replace("[output]\n", "[output]\nprocessed = \"delete\"\n"),
    );
    let root = s.out.parent().expect("tmp").to_path_buf();
    let victim = root.join("victim.obj");
    std::fs::write(&victim, patch_obj(12, 2)).expect("victim");
    let sub = s.inbox.join("sub");
    std::fs::create_dir(&sub).expect("sub");
    std::os::unix::fs::symlink(&victim, sub.join("link.obj")).expect("symlink");
    std::fs::write(sub.join("mine.obj"), patch_obj(12, 3)).expect("inside");
    let (mut child, mut w) = s.spawn_pipe();
    let records = [
        ("dotdot", format!("{}/../victim.obj", s.inbox.display())),
        ("absolute", victim.display().to_string()),
        ("symlink", sub.join("link.obj").display().to_string()),
        ("inside", sub.join("mine.obj").display().to_string()),
    ];
    for (patch, path) in &records {
        let line = serde_json::json!({"patch": patch, "path": path}).to_string();
        write_all(&mut w, format!("{line}\n").as_bytes());
    }
    drop(w);
    assert!(wait_exit(&mut child).is_some_and(|st| st.success()));
    let ev = events(&s.out);
    for patch in ["dotdot", "absolute", "symlink"] {
        let e = ev
            .iter()
            .find(|e| e["patch"] == patch)
            .unwrap_or_else(|| panic!("{patch}: {ev:?}"));
        assert_eq!(e["status"], "rejected", "{e}");
        assert_eq!(e["kind"], "path_outside_roots", "{e}");
        assert!(e["quarantined_as"].is_null(), "{e}");
    }
    assert!(victim.exists(), "the victim stays where it is");
    assert!(sub.join("link.obj").exists(), "the symlink is left too");
    assert!(s.out.join("inside/surface.json").exists());
    assert!(
        !sub.join("mine.obj").exists(),
        "the processed policy applies inside the roots"
    );
}

/// A symlink loop, symlinks to a folder and to a device, a folder and a FIFO with mesh
/// names, a non-UTF-8 name: each reported once (one event, however many scans), never
/// fitted. Names that used to collide or land on OUT's own entries get folders of their own.
#[test]
fn odd_entries_are_reported_once_and_odd_names_get_their_own_folders() {
    use std::os::unix::ffi::OsStrExt;
    let s = setup(&config(200, "poll", ""));
    let inbox = &s.inbox;
    std::os::unix::fs::symlink("loop.obj", inbox.join("loop.obj")).expect("loop");
    std::os::unix::fs::symlink(inbox.parent().expect("tmp"), inbox.join("todir.obj"))
        .expect("dir link");
    std::os::unix::fs::symlink("/dev/zero", inbox.join("zero.ply")).expect("device link");
    std::fs::create_dir(inbox.join("dir.obj")).expect("dir");
    assert!(Command::new("mkfifo")
        .arg(inbox.join("fifo.ply"))
        .status()
        .expect("mkfifo")
        .success());
    let raw = std::ffi::OsStr::from_bytes(b"bad\xffname.obj");
    std::fs::write(inbox.join(raw), patch_obj(10, 1)).expect("non-utf8");
    let names = [
        "测试.obj",
        "例子.obj",
        "quarantine.obj",
        "processed.obj",
        "events.ndjson.obj",
    ];
    for (k, n) in names.iter().enumerate() {
        std::fs::write(inbox.join(n), patch_obj(10, k as u32 + 2)).expect("write");
    }
    let child = s.spawn(&[]);
    let fitted = || count(&s.out, is_fitted);
    assert!(
        wait_until(|| fitted() == names.len()),
        "{:?} {}",
        events(&s.out),
        s.log()
    );
    // Many more scans happen while a late file is settled and fitted.
    drop_file(inbox, "late.obj", &patch_obj(10, 9));
    assert!(wait_until(|| s.out.join("late/surface.json").exists()));
    assert!(stop(child).is_some_and(|st| st.success()));
    let skipped: Vec<(String, String)> = events(&s.out)
        .iter()
        .filter(|e| e["status"] == "skipped")
        .map(|e| {
            let input = e["input"].as_str().unwrap_or("");
            let name = input.rsplit('/').next().unwrap_or("").to_string();
            (name, e["kind"].as_str().unwrap_or("").to_string())
        })
        .collect();
    let mut want = vec![
        ("loop.obj".to_string(), "symlink_loop".to_string()),
        ("todir.obj".into(), "directory".into()),
        ("zero.ply".into(), "device".into()),
        ("dir.obj".into(), "directory".into()),
        ("fifo.ply".into(), "fifo".into()),
        ("bad\u{fffd}name.obj".into(), "non_utf8_name".into()),
    ];
    let mut got = skipped.clone();
    want.sort();
    got.sort();
    assert_eq!(got, want, "each once");
    let folders: std::collections::HashSet<String> = events(&s.out)
        .iter()
        .filter(|e| is_fitted(e))
        .map(|e| e["patch"].as_str().unwrap_or("").to_string())
        .collect();
    assert_eq!(folders.len(), names.len() + 1, "{folders:?}");
    assert!(
        folders.contains("测试") && folders.contains("例子"),
        "{folders:?}"
    );
    for reserved in ["quarantine", "processed", "events.ndjson"] {
        assert!(!folders.contains(reserved), "{folders:?}");
    }
    assert!(s.out.join("events.ndjson").is_file());
    assert!(!s.out.join("quarantine/surface.json").exists());
}

/// Older versions left in the folder lose to the newest again at every start; the event
/// log says so once per version.
#[test]
fn superseded_versions_are_recorded_once_across_starts() {
    let s = setup(&config(0, "native", ""));
    for k in 0..3u32 {
        std::fs::write(s.inbox.join(format!("scan@{k}.obj")), patch_obj(10, k)).expect("write");
        // Distinct mtimes, oldest first.
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    for _ in 0..3 {
        let o = s.once();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    for k in 0..2 {
        let version = format!("scan@{k}.obj");
        let n = count(&s.out, |e| {
            e["status"] == "superseded" && e["version"] == version.as_str()
        });
        assert_eq!(n, 1, "{version}: {:?}", events(&s.out));
    }
    assert_eq!(count(&s.out, is_fitted), 1);
}

/// SIGTERM while a record's payload is still arriving: the event log says which record
/// was cut and how far it got.
#[test]
fn a_record_half_received_at_stop_is_reported() {
    let s = setup(&format!(
        "{}\n[log]\nlevel = \"debug\"\n",
        config(0, "native", "")
    ));
    let (mut child, mut w) = s.spawn_pipe();
    w.write_all(b"{\"patch\": \"cut\", \"format\": \"obj\", \"bytes\": 100000}\n")
        .expect("header");
    w.write_all(&[b'#'; 1000]).expect("part");
    w.flush().expect("flush");
    assert!(
        wait_until(|| s.log().contains("reading a record's payload")),
        "{}",
        s.log()
    );
    signal(&child, "TERM");
    assert!(wait_exit(&mut child).is_some_and(|st| st.success()));
    drop(w);
    let ev = events(&s.out);
    let cut = ev
        .iter()
        .find(|e| e["patch"] == "cut")
        .unwrap_or_else(|| panic!("{ev:?}"));
    assert_eq!(cut["status"], "rejected");
    assert_eq!(cut["kind"], "record_truncated");
    assert!(
        cut["reason"]
            .as_str()
            .is_some_and(|r| r.contains("of 100000 bytes")),
        "{cut}"
    );
}

/// A `.gltf` dropped into the folder with its buffer beside it is fitted (the buffer is
/// resolved in the watch folder); one naming a buffer outside the folder is rejected with
/// the reader's kind, and the file outside is left alone.
#[test]
fn a_gltf_with_an_external_buffer_beside_it_is_fitted() {
    let s = setup(&config(200, "native", ""));
    let child = s.spawn(&[]);
    assert!(wait_until(|| s.log().contains("watching")), "{}", s.log());
    let (gltf, bin) = patch_gltf_external(12, 3, "scan.bin");
    std::fs::write(s.inbox.join("scan.bin"), &bin).expect("bin");
    drop_file(&s.inbox, "scan.gltf", gltf.as_bytes());
    let outside = s.out.parent().expect("tmp").join("outside.bin");
    std::fs::write(&outside, &bin).expect("outside bin");
    let (escaping, _) = patch_gltf_external(12, 4, "../outside.bin");
    drop_file(&s.inbox, "escape.gltf", escaping.as_bytes());
    assert!(
        wait_until(|| s.out.join("scan/surface.json").exists()
            && count(&s.out, |e| e["status"] == "rejected") >= 1),
        "{}",
        s.log()
    );
    let rejected = events(&s.out)
        .into_iter()
        .find(|e| e["status"] == "rejected")
        .expect("the escaping gltf is rejected");
    assert_eq!(rejected["kind"], "unsupported", "{rejected}");
    assert!(outside.exists(), "the file outside the folder stays");
    assert!(stop(child).is_some_and(|st| st.success()));
}

/// The two files of a glTF copied one after the other, the `.gltf` first: it used to be
/// quarantined at once for its missing buffer, and the `.bin` arriving after it (no mesh
/// itself) changed nothing. Now it waits for the buffer, said once, and is fitted.
#[test]
fn a_gltf_whose_buffer_arrives_after_it_waits_for_it() {
    let s = setup(&config(200, "native", ""));
    let child = s.spawn(&[]);
    assert!(wait_until(|| s.log().contains("watching")), "{}", s.log());
    let (gltf, bin) = patch_gltf_external(12, 5, "late.bin");
    drop_file(&s.inbox, "late.gltf", gltf.as_bytes());
    assert!(
        wait_until(|| count(&s.out, |e| e["status"] == "incomplete") >= 1),
        "{}",
        s.log()
    );
    // Read again every second meanwhile: still one event, and nothing quarantined.
    std::thread::sleep(std::time::Duration::from_millis(2500));
    std::fs::write(s.inbox.join("late.bin"), &bin).expect("bin");
    assert!(
        wait_until(|| s.out.join("late/surface.json").exists()),
        "{}",
        s.log()
    );
    let waiting = count(&s.out, |e| e["status"] == "incomplete");
    assert_eq!(waiting, 1, "{:?}", events(&s.out));
    assert_eq!(count(&s.out, |e| e["status"] == "rejected"), 0);
    assert!(s.inbox.join("late.gltf").exists());
    assert!(stop(child).is_some_and(|st| st.success()));
}

/// `output.quarantine_dir` inside OUT under a patch's name used to be published over (or
/// filled with that patch's versions). Now the daemon refuses to start with the reason,
/// before it fits anything; under `OUT/quarantine` the folder is taken and a broken input
/// lands there.
#[test]
fn a_quarantine_dir_where_a_patch_folder_could_be_is_refused() {
    let s = setup("");
    let with_quarantine = |q: &std::path::Path| {
        let line = format!("[output]\nquarantine_dir = {:?}\n", q.display().to_string());
        let text = config(0, "poll", "").replace("[output]\n", &line);
        std::fs::write(&s.cfg, text).expect("config");
    };
    std::fs::write(s.inbox.join("bad.obj"), patch_obj(10, 1)).expect("patch");
    std::fs::write(
        s.inbox.join("broken.ply"),
        b"ply\nformat ascii 1.0\nelement vertex 99\n",
    )
    .expect("broken");
    for refused in [s.out.join("bad"), s.out.clone(), s.inbox.clone()] {
        with_quarantine(&refused);
        let run = s.once();
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{}: {stderr}", refused.display());
        assert!(stderr.contains("output.quarantine_dir"), "{stderr}");
        assert!(events(&s.out).is_empty(), "nothing fitted or quarantined");
        assert!(!s.out.join("bad").exists());
    }
    let held = s.out.join("quarantine/held");
    with_quarantine(&held);
    let run = s.once();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(s.out.join("bad/surface.json").exists());
    assert!(held.join("broken.ply").exists() && held.join("broken.ply.error.json").exists());
}
