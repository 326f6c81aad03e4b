//! The pipe source as a process: stdin with path and inline records and malformed ones in
//! between (framing kept, bad bytes quarantined), and a FIFO reopened after each writer.

use crate::daemon_support::*;
use std::io::Write;
use std::process::{Command, Stdio};

const GARBAGE: &[u8] = b"ply\nformat ascii 1.0\nelement vertex 99\n\x00\x01\n\n";

fn inline(w: &mut impl Write, patch: &str, format: &str, bytes: &[u8]) {
    write_all(
        w,
        format!(
            "{{\"patch\": \"{patch}\", \"format\": \"{format}\", \"bytes\": {}}}\n",
            bytes.len()
        )
        .as_bytes(),
    );
    write_all(w, bytes);
}

#[test]
fn stdin_records_of_both_kinds_with_malformed_ones_between() {
    let s = setup(
        &config(0, "native", "").replace("max_file_bytes = 10000000", "max_file_bytes = 200000"),
    );
    let outside = s.out.parent().expect("tmp").join("elsewhere.obj");
    std::fs::write(&outside, patch_obj(12, 1)).expect("write");
    // Path records reach only files under the pipe roots: here the folder above the inbox.
    let roots = format!("pipe_roots = [{:?}]", s.out.parent().expect("tmp"));
    std::fs::write(
        &s.cfg,
        config(0, "native", &roots).replace("max_file_bytes = 10000000", "max_file_bytes = 200000"),
    )
    .expect("config");
    let mut child = bin()
        .args(s.args())
        .args(["--pipe", "-"])
        .stdin(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawns");
    let mut w = child.stdin.take().expect("stdin");
    write_all(
        &mut w,
        format!(
            "{{\"patch\": \"frompath\", \"path\": \"{}\"}}\n",
            outside.display()
        )
        .as_bytes(),
    );
    inline(&mut w, "inline_ply", "ply", &patch_ply(12, 2));
    write_all(&mut w, b"this is not json\n");
    // A valid header whose bytes are not a mesh: consumed, quarantined, framing kept.
    inline(&mut w, "garbage", "ply", GARBAGE);
    // Bad format, but the length is known: skipped exactly.
    inline(
        &mut w,
        "weird",
        "e57",
        b"{\"patch\": \"fake\", \"path\": \"/nonexistent\"}\n",
    );
    // Over the size limit: refused without holding it, streamed to quarantine.
    inline(&mut w, "huge", "ply", &vec![b'\n'; 300_000]);
    write_all(&mut w, b"{\"patch\": \"nopath\"}\n");
    write_all(&mut w, b"\n");
    inline(&mut w, "inline_obj", "obj", &patch_obj(12, 3));
    // Truncated: the stream ends inside the payload.
    write_all(
        &mut w,
        b"{\"patch\": \"cut\", \"format\": \"obj\", \"bytes\": 5000}\nv 0 0 0\n",
    );
    drop(w);
    let status = wait_exit(&mut child);
    let mut err = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut e, &mut err);
    }
    assert!(
        status.is_some_and(|st| st.success()),
        "stdin EOF ends the daemon: {status:?} {err}"
    );
    for p in ["frompath", "inline_ply", "inline_obj"] {
        assert!(s.out.join(p).join("surface.json").exists(), "{p}: {err}");
    }
    let ev = events(&s.out);
    let rejected: Vec<_> = ev.iter().filter(|e| e["status"] == "rejected").collect();
    let reason = |patch: &str| {
        rejected
            .iter()
            .find(|e| e["patch"] == patch)
            .and_then(|e| e["reason"].as_str())
            .unwrap_or_else(|| panic!("{patch} rejected: {rejected:?}"))
            .to_string()
    };
    assert!(reason("weird").contains("format"));
    assert!(reason("huge").contains("max_file_bytes"));
    assert!(reason("nopath").contains("path"));
    assert!(reason("cut").contains("ended after"));
    assert!(
        reason("garbage").contains("pipe:stdin#4"),
        "{}",
        reason("garbage")
    );
    assert!(rejected
        .iter()
        .any(|e| e["reason"].as_str().is_some_and(|r| r.contains("not JSON"))));
    assert_eq!(rejected.len(), 6, "{rejected:?}");
    assert_eq!(ev.iter().filter(|e| is_fitted(e)).count(), 3);
    // Nothing lost: every bad payload is in quarantine, byte for byte.
    let q: Vec<String> = std::fs::read_dir(s.out.join("quarantine"))
        .expect("quarantine")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().to_string())
        .collect();
    let size_of = |prefix: &str| {
        let name = q
            .iter()
            .find(|n| n.starts_with(prefix) && !n.ends_with(".error.json"))
            .unwrap_or_else(|| panic!("{prefix} in {q:?}"));
        std::fs::metadata(s.out.join("quarantine").join(name))
            .expect("meta")
            .len()
    };
    assert_eq!(size_of("huge@"), 300_000);
    assert_eq!(size_of("garbage@"), GARBAGE.len() as u64);
    assert_eq!(size_of("cut@"), 8);
    assert!(outside.exists(), "a fitted path input is left in place");
}

#[test]
fn a_fifo_is_reopened_after_each_writer() {
    let s = setup(&config(0, "native", ""));
    let fifo = s.out.parent().expect("tmp").join("feed");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo");
    assert!(made.success());
    let child = s.spawn(&["--pipe", fifo.to_str().expect("utf8")]);
    for (k, patch) in ["first", "second", "third"].iter().enumerate() {
        // Opening for writing waits until the daemon has the FIFO open for reading.
        let mut w = std::fs::OpenOptions::new()
            .write(true)
            .open(&fifo)
            .expect("open fifo");
        inline(&mut w, patch, "ply", &patch_ply(12, k as u32));
        drop(w);
        assert!(
            wait_until(|| s.out.join(patch).join("surface.json").exists()),
            "{patch}: {}",
            s.log()
        );
    }
    assert!(stop(child).is_some_and(|st| st.success()), "{}", s.log());
    assert_eq!(events(&s.out).iter().filter(|e| is_fitted(e)).count(), 3);
}
