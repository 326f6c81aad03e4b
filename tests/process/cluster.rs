//! The cluster: a real nats-server with JetStream on a random loopback port, one
//! `watch --queue` source and `worker --queue` processes sharing one OUT. The server comes
//! from scripts/install_nats.sh (`.ci/run` calls it); these tests skip without one only
//! outside CI.

use crate::daemon_support::*;
use std::collections::HashMap;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The server binary: $TRISPLINE_NATS_SERVER, `nats-server` on PATH, or pip's --user bin.
pub(crate) fn nats_server() -> Option<PathBuf> {
    let from_env = std::env::var_os("TRISPLINE_NATS_SERVER").map(PathBuf::from);
    let on_path = std::env::var_os("PATH").and_then(|p| {
        std::env::split_paths(&p)
            .map(|d| d.join("nats-server"))
            .find(|c| c.is_file())
    });
    let user = std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/bin/nats-server"));
    first_file(
        [from_env, on_path, user],
        "nats-server",
        "scripts/install_nats.sh",
        "TRISPLINE_NATS_SERVER",
    )
}

/// The first of `candidates` that is a file. None is an error under CI (where the
/// installer `script` has run) and a skip elsewhere, said on stderr.
pub(crate) fn first_file<const N: usize>(
    candidates: [Option<PathBuf>; N],
    what: &str,
    script: &str,
    variable: &str,
) -> Option<PathBuf> {
    let found = candidates.into_iter().flatten().find(|c| c.is_file());
    let required = std::env::var("TRISPLINE_REQUIRE_DATA").is_ok_and(|v| v == "1")
        || std::env::var("CI").is_ok_and(|v| v == "true");
    if found.is_none() {
        assert!(!required, "no {what} (run {script} or set {variable})");
        eprintln!("skipped: no {what} ({script} installs it)");
    }
    found
}

/// A loopback port free a moment ago.
pub(crate) fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port()
}

/// The server's log, appended across restarts.
fn log_file(store: &Path) -> std::fs::File {
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(store.join("server.log"))
        .expect("server log")
}

pub(crate) struct Server {
    bin: PathBuf,
    port: u16,
    store: tempfile::TempDir,
    child: Child,
}

impl Server {
    pub(crate) fn start() -> Option<Server> {
        let bin = nats_server()?;
        Some(Self::start_on(bin, free_port()))
    }

    /// A server on `port` (a source may already be waiting for it there).
    pub(crate) fn start_on(bin: PathBuf, port: u16) -> Server {
        let store = tempfile::tempdir().expect("tmp");
        let child = Self::spawn(&bin, port, store.path());
        Server {
            bin,
            port,
            store,
            child,
        }
    }

    fn spawn(bin: &Path, port: u16, store: &Path) -> Child {
        let child = Command::new(bin)
            .args(["-js", "-a", "127.0.0.1", "-p", &port.to_string(), "-sd"])
            .arg(store)
            .stdout(Stdio::null())
            .stderr(log_file(store))
            .spawn()
            .expect("nats-server starts");
        let up = wait_until(|| std::net::TcpStream::connect(("127.0.0.1", port)).is_ok());
        assert!(up, "nats-server listens on {port}");
        child
    }

    fn log(&self) -> String {
        std::fs::read_to_string(self.store.path().join("server.log")).unwrap_or_default()
    }

    pub(crate) fn url(&self) -> String {
        format!("nats://127.0.0.1:{}", self.port)
    }

    /// Stops the server and starts it again on the same port and store.
    fn restart(&mut self, down_for: Duration) {
        signal(&self.child, "TERM");
        assert!(wait_exit(&mut self.child).is_some(), "nats-server stops");
        std::thread::sleep(down_for);
        self.child = Self::spawn(&self.bin, self.port, self.store.path());
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Fast fits and a short ack wait, so that a dead worker's job moves on in seconds.
pub(crate) fn cluster_config() -> String {
    format!(
        "{}\n[cluster]\nack_wait_ms = 2000\nmax_deliveries = 2\n",
        config(200, "native", "")
    )
}

pub(crate) fn spawn_worker(s: &Setup, server: &Server, name: &str) -> Daemon {
    let log = std::fs::File::create(s._tmp.path().join(format!("{name}.log"))).expect("log");
    Daemon(
        bin()
            .args(["worker", "--queue", &server.url(), "--name", name])
            .arg("--out")
            .arg(&s.out)
            .arg("--config")
            .arg(&s.cfg)
            .stdin(Stdio::null())
            .stderr(log)
            .spawn()
            .expect("worker starts"),
    )
}

pub(crate) fn worker_log(s: &Setup, name: &str) -> String {
    std::fs::read_to_string(s._tmp.path().join(format!("{name}.log"))).unwrap_or_default()
}

pub(crate) fn logs(s: &Setup, names: &[&str]) -> String {
    let mut all = format!("--- source\n{}", s.log());
    for n in names {
        all.push_str(&format!("\n--- {n}\n{}", worker_log(s, n)));
    }
    all
}

/// Every version of `names` has an event saying what became of it.
pub(crate) fn accounted(out: &Path, names: &[String]) -> bool {
    let ev = events(out);
    names.iter().all(|n| {
        ev.iter().any(|e| {
            let this = e["version"] == n.as_str()
                || e["input"].as_str().is_some_and(|i| i.ends_with(n.as_str()));
            this && (is_fitted(e)
                || matches!(e["status"].as_str(), Some("superseded" | "rejected")))
        })
    })
}

/// For each patch, the versions fitted in log order rise and end at `newest`.
pub(crate) fn check_newest_fitted_last(out: &Path, newest: &HashMap<String, String>) {
    let ev = events(out);
    for (patch, last) in newest {
        let fitted: Vec<&str> = ev
            .iter()
            .filter(|e| is_fitted(e) && e["patch"] == patch.as_str())
            .filter_map(|e| e["version"].as_str())
            .collect();
        assert_eq!(fitted.last(), Some(&last.as_str()), "{patch}: {fitted:?}");
        // Delivery is at least once: a fit whose acknowledgement was lost (the server away)
        // may be written again, but never after a newer version.
        assert!(
            fitted.windows(2).all(|w| w[0] <= w[1]),
            "{patch}: {fitted:?}"
        );
        let report = read_json(&out.join(patch).join("report.json"));
        assert_eq!(report["version"], last.as_str(), "{patch}");
    }
}

#[test]
fn a_burst_of_100_versions_on_3_workers_fits_each_patch_newest_last_and_loses_none() {
    let Some(server) = Server::start() else {
        return;
    };
    let s = setup(&cluster_config());
    let names = ["w1", "w2", "w3"];
    let workers: Vec<Daemon> = names.iter().map(|n| spawn_worker(&s, &server, n)).collect();
    let source = s.spawn(&["--queue", &server.url()]);
    let mut all = Vec::new();
    let mut newest = HashMap::new();
    for v in 1..=10u32 {
        for p in 0..10u32 {
            let name = format!("p{p}@{v:04}.ply");
            drop_file(&s.inbox, &name, &patch_ply(10, 100 * p + v));
            newest.insert(format!("p{p}"), name.clone());
            all.push(name);
        }
    }
    assert!(
        wait_until(|| accounted(&s.out, &all)),
        "{}",
        logs(&s, &names)
    );
    // Nothing still in flight is about to write an older version over the newest.
    std::thread::sleep(Duration::from_millis(500));
    check_newest_fitted_last(&s.out, &newest);
    let ev = events(&s.out);
    let fitted_by: std::collections::HashSet<&str> = ev
        .iter()
        .filter(|e| is_fitted(e))
        .filter_map(|e| e["worker"].as_str())
        .collect();
    assert!(!fitted_by.is_empty(), "worker names are in the events");
    for n in &all {
        let about: Vec<_> = ev.iter().filter(|e| e["version"] == n.as_str()).collect();
        assert!(!about.is_empty(), "{n} accounted for");
    }
    assert!(stop(source).is_some_and(|st| st.success()), "{}", s.log());
    for w in workers {
        assert!(stop(w).is_some_and(|st| st.success()));
    }
}

#[test]
fn a_warm_start_crosses_workers() {
    let Some(server) = Server::start() else {
        return;
    };
    let s = setup(&cluster_config());
    let source = s.spawn(&["--queue", &server.url()]);
    let a = spawn_worker(&s, &server, "A");
    // The second version is the same surface with other bytes: a warm start applies (the
    // patch is big enough for the scan path to reuse its controls, as in one process).
    let v1 = patch_obj(40, 1);
    drop_file(&s.inbox, "ear@0001.obj", &v1);
    let fitted = |v: &str| {
        events(&s.out)
            .into_iter()
            .find(|e| is_fitted(e) && e["version"] == v)
    };
    assert!(
        wait_until(|| fitted("ear@0001.obj").is_some()),
        "{}",
        logs(&s, &["A"])
    );
    assert!(stop(a).is_some_and(|st| st.success()));
    let first = fitted("ear@0001.obj").expect("fitted");
    assert_eq!(
        (first["worker"].as_str(), first["warm_start"].as_bool()),
        (Some("A"), Some(false))
    );
    let b = spawn_worker(&s, &server, "B");
    let v2 = [v1.as_slice(), b"# version 2\n"].concat();
    drop_file(&s.inbox, "ear@0002.obj", &v2);
    assert!(
        wait_until(|| fitted("ear@0002.obj").is_some()),
        "{}",
        logs(&s, &["A", "B"])
    );
    let second = fitted("ear@0002.obj").expect("fitted");
    assert_eq!(second["worker"], "B");
    assert_eq!(
        second["warm_start"], true,
        "B starts from A's fit: {second}"
    );
    assert!(stop(b).is_some_and(|st| st.success()));
    assert!(stop(source).is_some_and(|st| st.success()));
}

/// Starts a worker, waits until it is fitting `version`, and kills it with SIGKILL;
/// true when the kill came before the worker finished.
fn kill_mid_fit(s: &Setup, server: &Server, name: &str, version: &str) -> bool {
    let mut w = spawn_worker(s, server, name);
    let started = wait_until(|| {
        worker_log(s, name)
            .lines()
            .any(|l| l.contains("fitting") && l.contains(version))
    });
    let _ = w.kill();
    let _ = w.wait();
    assert!(started, "{}", logs(s, &[name]));
    !events(&s.out)
        .iter()
        .any(|e| is_fitted(e) && e["version"] == version)
}

#[test]
fn a_job_whose_worker_is_killed_completes_on_another_and_poison_is_quarantined() {
    let Some(server) = Server::start() else {
        return;
    };
    // A slower fit (a 150 x 150 grid on the default Loop surface), so that a kill lands
    // inside it.
    let s = setup(
        "[daemon]\nsettle_ms = 200\nworkers = 1\n[cluster]\nack_wait_ms = 2000\nmax_deliveries = 2\n",
    );
    let source = s.spawn(&["--queue", &server.url()]);
    let big = patch_ply(150, 7);
    drop_file(&s.inbox, "big@0001.ply", &big);
    let killed = kill_mid_fit(&s, &server, "K1", "big@0001.ply");
    let b = spawn_worker(&s, &server, "B");
    let done = || {
        events(&s.out)
            .into_iter()
            .find(|e| is_fitted(e) && e["version"] == "big@0001.ply")
    };
    assert!(
        wait_until(|| done().is_some()),
        "{}",
        logs(&s, &["K1", "B"])
    );
    if killed {
        assert_eq!(done().expect("fitted")["worker"], "B", "the job moved on");
    } else {
        eprintln!("K1 finished before the kill; the redelivery was not exercised");
    }
    assert!(stop(b).is_some_and(|st| st.success()));
    // A version whose worker dies every time: after max_deliveries = 2 starts it is
    // quarantined, not tried forever.
    drop_file(&s.inbox, "big@0002.ply", &patch_ply(150, 8));
    let k2 = kill_mid_fit(&s, &server, "K2", "big@0002.ply");
    let k3 = kill_mid_fit(&s, &server, "K3", "big@0002.ply");
    let c = spawn_worker(&s, &server, "C");
    let poison = || {
        events(&s.out)
            .into_iter()
            .find(|e| e["status"] == "rejected" && e["kind"] == "poison")
    };
    if k2 && k3 {
        assert!(
            wait_until(|| poison().is_some()),
            "{}",
            logs(&s, &["K2", "K3", "C"])
        );
        let e = poison().expect("poison");
        assert_eq!(e["patch"], "big");
        let kept = e["quarantined_as"]
            .as_str()
            .map(PathBuf::from)
            .expect("kept");
        assert_eq!(
            std::fs::read(kept).expect("quarantined bytes"),
            patch_ply(150, 8)
        );
    } else {
        eprintln!("a kill came after the fit finished; the poison path was not exercised");
    }
    assert!(stop(c).is_some_and(|st| st.success()));
    assert!(stop(source).is_some_and(|st| st.success()));
}

#[test]
fn a_server_restart_mid_run_is_ridden_out() {
    let Some(mut server) = Server::start() else {
        return;
    };
    let s = setup(&cluster_config());
    let names = ["r1", "r2"];
    let workers: Vec<Daemon> = names.iter().map(|n| spawn_worker(&s, &server, n)).collect();
    let source = s.spawn(&["--queue", &server.url()]);
    let mut all = Vec::new();
    let mut newest = HashMap::new();
    let mut drop_round = |v: u32| {
        for p in 0..6u32 {
            let name = format!("q{p}@{v:04}.ply");
            drop_file(&s.inbox, &name, &patch_ply(10, 50 * p + v));
            newest.insert(format!("q{p}"), name.clone());
            all.push(name);
        }
    };
    drop_round(1);
    // Mid-run: the first round is through (everyone is connected), the second in flight.
    let first: Vec<String> = (0..6).map(|p| format!("q{p}@0001.ply")).collect();
    assert!(
        wait_until(|| accounted(&s.out, &first)),
        "{}",
        logs(&s, &names)
    );
    drop_round(2);
    let t = Instant::now();
    server.restart(Duration::from_millis(1500));
    drop_round(3);
    assert!(
        wait_until(|| accounted(&s.out, &all)),
        "{}\n--- server\n{}",
        logs(&s, &names),
        server.log()
    );
    eprintln!(
        "run completed {:.1} s after the restart began",
        t.elapsed().as_secs_f64()
    );
    std::thread::sleep(Duration::from_millis(500));
    check_newest_fitted_last(&s.out, &newest);
    assert!(stop(source).is_some_and(|st| st.success()), "{}", s.log());
    for w in workers {
        assert!(stop(w).is_some_and(|st| st.success()));
    }
}
