//! What a scanning team relies on (issue 21): files taken only when complete, however long
//! the writer pauses; valid but unsupported inputs left in place with a reason; partial
//! config files; subfolders; log lines that say what is going on; restarts that refit only
//! what a config change affects.

use crate::daemon_support::*;
use std::io::Write;
use std::path::Path;
use std::time::Duration;
use trispline::daemon::state::content_hash;

/// Writes `bytes` through one handle in `pieces`, pausing `pause` between pieces with the
/// file held open: a scanner flushing in bursts, a slow network copy.
fn write_with_pauses(path: &Path, bytes: &[u8], pieces: usize, pause: Duration) {
    let mut f = std::fs::File::create(path).expect("create");
    let mut chunks = bytes.chunks(bytes.len().div_ceil(pieces)).peekable();
    while let Some(chunk) = chunks.next() {
        f.write_all(chunk).expect("write");
        f.flush().expect("flush");
        if chunks.peek().is_some() {
            std::thread::sleep(pause);
        }
    }
}

fn with_output(config: &str, keys: &str) -> String {
    config.replace("[output]\n", &format!("[output]\n{keys}\n"))
}

/// Three pauses of 1.5 s with a settle time of 300 ms: native mode waits for the close, poll
/// mode sees the writer's open descriptor in /proc. Each file is fitted once, from its
/// complete bytes, and nothing is quarantined.
#[test]
fn writers_pausing_longer_than_the_settle_time_are_fitted_once_and_whole() {
    let runs: Vec<_> = ["native", "poll"]
        .into_iter()
        .map(|watcher| {
            std::thread::spawn(move || {
                let s = setup(&config(300, watcher, ""));
                let child = s.spawn(&[]);
                let bytes = patch_ply(16, 21);
                assert!(
                    wait_until(|| s.log().contains("watching")),
                    "{watcher}: {}",
                    s.log()
                );
                write_with_pauses(
                    &s.inbox.join("burst.ply"),
                    &bytes,
                    4,
                    Duration::from_millis(1500),
                );
                assert!(
                    wait_until(|| s.out.join("burst/surface.json").exists()),
                    "{watcher}: {}",
                    s.log()
                );
                assert!(stop(child).is_some_and(|st| st.success()));
                (watcher, s, bytes)
            })
        })
        .collect();
    for run in runs {
        let (watcher, s, bytes) = run.join().expect("run");
        let ev = events(&s.out);
        let fitted: Vec<_> = ev.iter().filter(|e| is_fitted(e)).collect();
        assert_eq!(fitted.len(), 1, "{watcher}: {ev:?}");
        let report = read_json(&s.out.join("burst/report.json"));
        assert_eq!(
            report["input_hash"],
            format!("{:016x}", content_hash(&bytes)),
            "{watcher}: read before it was complete"
        );
        assert!(
            !ev.iter().any(|e| e["status"] == "rejected"),
            "{watcher}: {ev:?}"
        );
        assert!(!s.out.join("quarantine").exists(), "{watcher}");
        assert!(s.inbox.join("burst.ply").exists(), "{watcher}");
    }
}

/// A valid mesh the pipeline refuses (too small to fit) stays where it is, rejected with
/// its kind and reason; a broken file still goes to quarantine; `daemon.unsupported =
/// "quarantine"` moves the valid one too.
#[test]
fn unsupported_valid_inputs_stay_in_place_with_a_reason() {
    for policy in ["keep", "quarantine"] {
        let s = setup(&config(0, "poll", &format!("unsupported = \"{policy}\"\n")));
        std::fs::write(s.inbox.join("tiny.ply"), patch_ply(5, 1)).expect("write");
        std::fs::write(s.inbox.join("broken.ply"), CORRUPT_PLY).expect("write");
        std::fs::write(s.inbox.join("good.ply"), patch_ply(12, 2)).expect("write");
        let o = s.once();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let ev = events(&s.out);
        let tiny = ev
            .iter()
            .find(|e| e["patch"] == "tiny")
            .expect("an event for tiny");
        assert_eq!(tiny["status"], "rejected", "{tiny}");
        let kind = tiny["kind"].as_str().unwrap_or("");
        assert!(
            ["too_few_vertices", "no_component"].contains(&kind),
            "{tiny}"
        );
        assert!(tiny["reason"].as_str().is_some_and(|r| !r.is_empty()));
        let q = s.out.join("quarantine");
        if policy == "keep" {
            assert!(s.inbox.join("tiny.ply").exists(), "left in place");
            assert!(tiny["kept_in_place"].is_string(), "{tiny}");
            assert!(tiny["quarantined_as"].is_null(), "{tiny}");
            assert!(!q.join("tiny.ply").exists());
        } else {
            assert!(!s.inbox.join("tiny.ply").exists());
            assert!(q.join("tiny.ply").exists(), "quarantined as asked");
        }
        assert!(
            q.join("broken.ply").exists(),
            "{policy}: broken files still go"
        );
        assert!(s.out.join("good/surface.json").exists());
        let log = String::from_utf8_lossy(&o.stderr);
        assert!(log.contains("kept_in_place"), "{log}");
        // The next start does not reject (nor report) the same file again.
        let again = s.once();
        assert!(again.status.success());
        let tiny_events = events(&s.out)
            .iter()
            .filter(|e| e["patch"] == "tiny")
            .count();
        assert_eq!(tiny_events, 1, "{policy}");
    }
}

/// A config file with only the keys it changes runs, merged over the embedded default;
/// an unknown key in it is refused with its name.
#[test]
fn a_partial_config_file_is_merged_over_the_defaults() {
    let partial = "[fit]\nsurface = \"bezier\"\nlevels = 1\n\n[fit.budget]\nmax_iterations = 7\n\n[fit.scan]\nlattice = 6\n\n[daemon]\nsettle_ms = 0\nworkers = 2\n";
    let s = setup(partial);
    let printed = bin()
        .args(s.args())
        .arg("--print-config")
        .output()
        .expect("runs");
    assert!(printed.status.success(), "{printed:?}");
    let text = String::from_utf8_lossy(&printed.stdout);
    assert!(text.contains("max_iterations = 7"), "{text}");
    assert!(text.contains("max_file_bytes = 536870912"), "{text}");
    std::fs::write(s.inbox.join("p.ply"), patch_ply(12, 3)).expect("write");
    let o = s.once();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = read_json(&s.out.join("p/report.json"));
    assert_eq!(report["budget"]["max_iterations"], 7);
    std::fs::write(&s.cfg, "[fit.budget]\nmax_iteratons = 7\n").expect("write");
    let bad = bin()
        .args(s.args())
        .arg("--check-config")
        .output()
        .expect("runs");
    assert_eq!(bad.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("max_iteratons"), "{err}");
}

/// `--recursive`: files in subfolders are patches named by their relative path, with
/// outputs under OUT/<sub>/<name>; a folder moved in whole while the daemon runs is seen.
/// Without it, a subfolder is reported as skipped.
#[test]
fn recursive_watch_takes_subfolders_as_patches() {
    let s = setup(&config(200, "native", ""));
    std::fs::create_dir_all(s.inbox.join("left/deep")).expect("mkdir");
    std::fs::write(s.inbox.join("top.ply"), patch_ply(12, 1)).expect("write");
    std::fs::write(s.inbox.join("left/ear@2.ply"), patch_ply(12, 2)).expect("write");
    std::fs::write(s.inbox.join("left/deep/ear.ply"), patch_ply(12, 3)).expect("write");
    let flat = s.once();
    assert!(flat.status.success());
    let ev = events(&s.out);
    assert_eq!(ev.iter().filter(|e| is_fitted(e)).count(), 1, "{ev:?}");
    assert!(ev
        .iter()
        .any(|e| e["status"] == "skipped" && e["kind"] == "directory"));
    let child = s.spawn(&["--recursive"]);
    for p in ["left/ear", "left/deep/ear"] {
        assert!(
            wait_until(|| s.out.join(p).join("surface.json").exists()),
            "{p}: {}",
            s.log()
        );
    }
    // A folder prepared elsewhere and renamed in raises one event for itself only.
    let staged = s._tmp.path().join("staged");
    std::fs::create_dir_all(&staged).expect("mkdir");
    std::fs::write(staged.join("chin.obj"), patch_obj(12, 4)).expect("write");
    std::fs::rename(&staged, s.inbox.join("right")).expect("rename in");
    assert!(
        wait_until(|| s.out.join("right/chin/surface.json").exists()),
        "{}",
        s.log()
    );
    assert!(stop(child).is_some_and(|st| st.success()));
    let ev = events(&s.out);
    for id in ["left/ear", "left/deep/ear", "right/chin"] {
        let fits: Vec<_> = ev
            .iter()
            .filter(|e| e["patch"] == id && is_fitted(e))
            .collect();
        assert_eq!(fits.len(), 1, "{id}: {ev:?}");
        let report = read_json(&s.out.join(id).join("report.json"));
        assert_eq!(report["patch"], id);
    }
    assert!(s.out.join("top/surface.json").exists());
}

/// A `fitting` line per job with its size, a `fitted` line with errors and controls, and
/// statuses spelled as in the events.
#[test]
fn log_lines_say_what_is_fitted_and_how_well() {
    let s = setup(&config(0, "poll", ""));
    std::fs::write(s.inbox.join("ear@0007.ply"), patch_ply(12, 5)).expect("write");
    let o = s.once();
    assert!(o.status.success());
    let log = String::from_utf8_lossy(&o.stderr);
    let fitting = log
        .lines()
        .find(|l| l.contains(" fitting"))
        .unwrap_or_else(|| panic!("no fitting line: {log}"));
    assert!(
        fitting.contains("patch=ear")
            && fitting.contains("version=ear@0007.ply")
            && fitting.contains("vertices=144"),
        "{fitting}"
    );
    let fitted = log
        .lines()
        .find(|l| l.contains(" fitted"))
        .unwrap_or_else(|| panic!("no fitted line: {log}"));
    for key in ["rms=", "max=", "controls=", "status="] {
        assert!(fitted.contains(key), "{key}: {fitted}");
    }
    let event = events(&s.out)
        .into_iter()
        .find(is_fitted)
        .expect("fitted event");
    let status = event["status"].as_str().expect("status");
    assert!(
        fitted.contains(&format!("status=\"{status}\""))
            || fitted.contains(&format!("status={status}")),
        "{fitted}"
    );
    assert!(!log.contains("Met") && !log.contains("Stalled") && !log.contains("Capped"));
}

/// Output-only settings do not refit unchanged inputs at the next start; an output newly
/// asked for does (only a fit can make it).
#[test]
fn output_settings_refit_only_what_lacks_an_output() {
    let s = setup(&with_output(&config(0, "poll", ""), "glb = false"));
    std::fs::write(s.inbox.join("p.ply"), patch_ply(12, 6)).expect("write");
    let fitted = || events(&s.out).iter().filter(|e| is_fitted(e)).count();
    assert!(s.once().status.success());
    assert_eq!(fitted(), 1);
    assert!(!s.out.join("p/surface.glb").exists());
    let text = std::fs::read_to_string(&s.cfg).expect("read");
    let retessellated = text.replace("tessellation = 8", "tessellation = 12");
    let relogged = format!("{retessellated}\n[log]\nlevel = \"debug\"\n");
    std::fs::write(&s.cfg, &relogged).expect("write");
    let o = s.once();
    assert!(String::from_utf8_lossy(&o.stderr).contains("unchanged 1"));
    assert_eq!(fitted(), 1, "tessellation and log level refit nothing");
    std::fs::write(&s.cfg, relogged.replace("glb = false", "glb = true")).expect("write");
    assert!(s.once().status.success());
    assert_eq!(fitted(), 2, "a GLB now asked for is made");
    assert!(s.out.join("p/surface.glb").exists());
}

/// Under systemd with `WatchdogSec=`, the scheduler loop sends `WATCHDOG=1` keep-alives
/// after `READY=1`; `STOPPING=1` still comes at a stop.
#[test]
fn the_systemd_watchdog_gets_keep_alives() {
    use std::os::unix::net::UnixDatagram;
    let s = setup(&config(0, "native", ""));
    let sock_path = s.out.parent().expect("tmp").join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).expect("bind");
    sock.set_read_timeout(Some(DEADLINE)).expect("timeout");
    // systemd names the watched process in WATCHDOG_PID: the shell's pid, kept by exec.
    let command = format!(
        "WATCHDOG_PID=$$ exec '{}' {}",
        env!("CARGO_BIN_EXE_trispline"),
        s.args()
            .iter()
            .map(|a| format!("'{a}'"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    let mut child = std::process::Command::new("sh")
        .args(["-c", &command])
        .env("NOTIFY_SOCKET", &sock_path)
        .env("WATCHDOG_USEC", "200000")
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("spawns");
    let next = || {
        let mut buf = [0u8; 256];
        let n = sock.recv(&mut buf).expect("a notification");
        String::from_utf8_lossy(&buf[..n]).trim_end().to_string()
    };
    assert_eq!(next(), "READY=1");
    let keep_alives = (0..3).filter(|_| next() == "WATCHDOG=1").count();
    assert_eq!(keep_alives, 3);
    signal(&child, "TERM");
    let mut stopping = false;
    for _ in 0..20 {
        let m = next();
        if m == "STOPPING=1" {
            stopping = true;
            break;
        }
        assert_eq!(m, "WATCHDOG=1");
    }
    assert!(stopping);
    assert!(wait_exit(&mut child).is_some_and(|st| st.success()));
}

/// A pipe path record's relative path is taken in the watch folder; `bad/../x.ply` with no
/// folder `bad` is refused naming `bad` (the kernel resolves `..` after it), not the file,
/// and an id like `bad/../x` is made safe, never a path.
#[test]
fn pipe_paths_are_relative_to_the_watch_folder_and_refusals_name_the_cause() {
    let s = setup(&config(0, "native", ""));
    std::fs::write(s.inbox.join("x.ply"), patch_ply(12, 8)).expect("write");
    let (mut child, mut w) = s.spawn_pipe();
    write_all(
        &mut w,
        b"{\"patch\": \"rel\", \"path\": \"x.ply\"}\n{\"patch\": \"bad/../x\", \"path\": \"bad/../x.ply\"}\n",
    );
    drop(w);
    assert!(wait_exit(&mut child).is_some_and(|st| st.success()));
    let ev = events(&s.out);
    assert!(
        ev.iter().any(|e| e["patch"] == "rel" && is_fitted(e)),
        "{ev:?}"
    );
    let bad = ev
        .iter()
        .find(|e| e["status"] == "rejected")
        .expect("the record naming bad/ is refused");
    assert_eq!(bad["kind"], "path_unreadable", "{bad}");
    let reason = bad["reason"].as_str().unwrap_or("");
    assert!(
        reason.starts_with("bad/../x.ply: ") && reason.contains("/bad does not exist"),
        "{reason}"
    );
    let id = bad["patch"].as_str().unwrap_or("");
    assert!(
        !id.contains('/') && id.starts_with("bad_.._x~"),
        "a safe id: {id}"
    );
    assert!(s.inbox.join("x.ply").exists(), "nothing moved");
}
