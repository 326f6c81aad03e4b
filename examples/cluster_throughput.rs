//! What the cluster queue (NATS JetStream) costs and gives, against the single-process
//! daemon:
//! 1. throughput of 40k-point scans with 1, 2 and 3 worker processes;
//! 2. the work the queue adds per job on the worker, measured directly: each job carries
//!    its publish time, and the worker logs a `queue cost` line per job (publish -> receive,
//!    claim, warm-state load and store, record commit, acknowledgement), shown here as
//!    median, p95 and max; whole-fit wall times swing by hundreds of ms on a shared
//!    machine, so a difference of them cannot show a few ms;
//! 3. tiny patches whose fit takes a few ms: jobs/s of a burst, and the end-to-end latency
//!    (file renamed in -> its `fitted` event) of jobs sent one at a time.
//!
//! Run it with `cargo build --release --bin trispline`, then
//! `cargo run --release --example cluster_throughput [-- SCANS TINY]`.
//!
//! Needs `nats-server` (scripts/install_nats.sh; or $TRISPLINE_NATS_SERVER) and
//! `../shared/data/range_scans/bun000_tri.ply` (40,256 points, 1.5 MB: over the default
//! payload limit, so the workers read it from the shared folder, as big scans travel).
//! SCANS (default 8) copies of the scan are fitted as separate patches with the embedded
//! config; TINY (default 200) is the number of tiny jobs per run.

use std::io::{Read, Seek, SeekFrom};
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{binary, Res};

fn nats_server() -> Res<PathBuf> {
    let on_path = std::env::var_os("PATH").and_then(|p| {
        std::env::split_paths(&p)
            .map(|d| d.join("nats-server"))
            .find(|c| c.is_file())
    });
    let candidates = [
        std::env::var_os("TRISPLINE_NATS_SERVER").map(PathBuf::from),
        on_path,
        std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/bin/nats-server")),
    ];
    candidates
        .into_iter()
        .flatten()
        .find(|p| p.is_file())
        .ok_or_else(|| "no nats-server: run scripts/install_nats.sh".into())
}

fn is_fitted(e: &serde_json::Value) -> bool {
    matches!(e["status"].as_str(), Some("met" | "capped" | "stalled"))
}

fn fitted_events(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("events.ndjson"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(is_fitted)
        .collect()
}

fn wait_fitted(out: &Path, n: usize, limit: Duration) -> Res<()> {
    let end = Instant::now() + limit;
    while fitted_events(out).len() < n {
        if Instant::now() > end {
            let got = fitted_events(out).len();
            return Err(format!("only {got} of {n} fitted in {limit:?}").into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(())
}

/// The fast fit of the process tests: tiny patches fit in a few ms.
const TINY_FIT: &str = "[fit]\nsurface = \"bezier\"\nlevels = 1\nmethod = \"cg\"\ninverse = \"exact\"\n[fit.budget]\nmax_iterations = 20\ntolerance_rel = 1e-3\n[fit.scan]\nlattice = 6\nsmoothing = 1e-5\n[fit.components]\nmode = \"largest\"\n[output]\ntessellation = 8\n";

/// A run folder: `in/`, `out/`, and a config with `threads` fitting threads.
fn folder(fit: &str, threads: usize) -> Res<(tempfile::TempDir, PathBuf)> {
    let tmp = tempfile::tempdir()?;
    std::fs::create_dir_all(tmp.path().join("in"))?;
    std::fs::create_dir_all(tmp.path().join("stage"))?;
    let cfg = tmp.path().join("cfg.toml");
    std::fs::write(
        &cfg,
        format!("{fit}[daemon]\nsettle_ms = 0\nworkers = {threads}\n[log]\nlevel = \"warn\"\n"),
    )?;
    Ok((tmp, cfg))
}

/// A scan-like height field of `n` x `n` vertices as ASCII PLY; `seed` changes the shape.
fn tiny_patch(n: usize, seed: u32) -> Vec<u8> {
    let s = seed as f64 * 0.37;
    let mut out = format!("ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n", n * n, 2 * (n - 1) * (n - 1));
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64);
            let z = 0.15 * (3.0 * x + s).sin() * (2.0 * y - s).cos();
            out.push_str(&format!("{x:.6} {y:.6} {z:.6}\n"));
        }
    }
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i;
            out.push_str(&format!("3 {a} {} {}\n", a + 1, a + n + 1));
            out.push_str(&format!("3 {a} {} {}\n", a + n + 1, a + n));
        }
    }
    out.into_bytes()
}

/// Processes killed when the run ends, whatever happened.
struct Killed(Vec<Child>);

impl Drop for Killed {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// A nats-server on a free port and `workers` worker processes logging JSON to
/// `logs/w<k>.log`; returns the URL.
fn start_cluster(
    nats: &Path,
    bin: &Path,
    dir: &Path,
    cfg: &Path,
    workers: usize,
) -> Res<(Killed, String)> {
    let port = TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
    let mut procs = Killed(vec![Command::new(nats)
        .args(["-js", "-a", "127.0.0.1", "-p", &port.to_string(), "-sd"])
        .arg(dir.join("nats"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()?]);
    let url = format!("nats://127.0.0.1:{port}");
    let end = Instant::now() + Duration::from_secs(10);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if Instant::now() > end {
            return Err("nats-server did not start".into());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    std::fs::create_dir_all(dir.join("logs"))?;
    for k in 0..workers {
        let log = std::fs::File::create(dir.join(format!("logs/w{k}.log")))?;
        procs.0.push(
            Command::new(bin)
                .args([
                    "worker",
                    "--queue",
                    &url,
                    "--name",
                    &format!("w{k}"),
                    "--log-json",
                ])
                .arg("--out")
                .arg(dir.join("out"))
                .arg("--config")
                .arg(cfg)
                // The per-job `queue cost` lines are at info.
                .env("RUST_LOG", "info")
                .stderr(log)
                .spawn()?,
        );
    }
    // The workers connect and create the consumer before any clock starts.
    std::thread::sleep(Duration::from_millis(1500));
    Ok((procs, url))
}

/// `watch --once` over the folder's `in/`, with `--queue url` when given; returns the
/// seconds from its start to the `n`-th fitted event.
fn run_once(bin: &Path, dir: &Path, cfg: &Path, url: Option<&str>, n: usize) -> Res<f64> {
    let t = Instant::now();
    let mut cmd = Command::new(bin);
    cmd.arg("watch")
        .arg(dir.join("in"))
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--config")
        .arg(cfg)
        .arg("--once")
        .stderr(Stdio::null());
    if let Some(u) = url {
        cmd.args(["--queue", u]);
    }
    if !cmd.status()?.success() {
        return Err("watch --once failed".into());
    }
    wait_fitted(&dir.join("out"), n, Duration::from_secs(900))?;
    Ok(t.elapsed().as_secs_f64())
}

/// The workers' `queue cost` lines.
fn queue_costs(dir: &Path) -> Vec<serde_json::Value> {
    let mut all = Vec::new();
    for entry in std::fs::read_dir(dir.join("logs"))
        .into_iter()
        .flatten()
        .flatten()
    {
        let text = std::fs::read_to_string(entry.path()).unwrap_or_default();
        all.extend(
            text.lines()
                .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
                .filter(|l| l["fields"]["message"] == "queue cost")
                .map(|l| l["fields"].clone()),
        );
    }
    all
}

/// (median, p95, max) of the finite values.
fn spread(mut v: Vec<f64>) -> Option<(f64, f64, f64)> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Some((at(0.5), at(0.95), v[v.len() - 1]))
}

fn show_costs(what: &str, costs: &[serde_json::Value]) {
    println!(
        "queue work per job on the worker, {what} ({} jobs), ms:",
        costs.len()
    );
    println!("  {:<16} {:>8} {:>8} {:>8}", "", "median", "p95", "max");
    let keys = [
        ("claim_ms", "claim"),
        ("state_load_ms", "state load"),
        ("stale_check_ms", "stale check"),
        ("state_save_ms", "state store"),
        ("commit_ms", "heartbeat end"),
        ("ack_ms", "commit + ack"),
        ("completion_ms", "completion"),
        ("queue_ms", "TOTAL queue work"),
        ("wait_ms", "publish->receive"),
        // Not queue work: the writer's outputs, which the single daemon writes too, and
        // the state's encoding and shared file, done at the same time beside them.
        ("write_ms", "writer (outputs)"),
        ("state_prepare_ms", "state encoding"),
    ];
    for (key, name) in keys {
        let v = costs.iter().filter_map(|c| c[key].as_f64()).collect();
        if let Some((m, p, x)) = spread(v) {
            println!("  {name:<16} {m:>8.2} {p:>8.2} {x:>8.2}");
        }
    }
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

/// The 40k-point table; prints the queue's work per job of the 1-worker run.
fn scans_table(bin: &Path, nats: &Path, scan: &[u8], scans: usize) -> Res<()> {
    println!(
        "{:<34} {:>8} {:>9} {:>9}",
        "run", "wall s", "scans/s", "ms/scan"
    );
    let show = |name: &str, wall: f64| {
        println!(
            "{name:<34} {wall:>8.2} {:>9.2} {:>9.1}",
            scans as f64 / wall,
            1e3 * wall / scans as f64
        )
    };
    let fill = |dir: &Path| -> Res<()> {
        for k in 0..scans {
            std::fs::write(dir.join(format!("in/s{k:03}.ply")), scan)?;
        }
        Ok(())
    };
    for threads in [1, 2] {
        let (tmp, cfg) = folder("", threads)?;
        fill(tmp.path())?;
        let wall = run_once(bin, tmp.path(), &cfg, None, scans)?;
        show(&format!("single daemon, {threads} thread(s)"), wall);
    }
    let mut one = Vec::new();
    for workers in 1..=3 {
        let (tmp, cfg) = folder("", 1)?;
        fill(tmp.path())?;
        let (_procs, url) = start_cluster(nats, bin, tmp.path(), &cfg, workers)?;
        let wall = run_once(bin, tmp.path(), &cfg, Some(&url), scans)?;
        show(&format!("queue, {workers} worker process(es)"), wall);
        if workers == 1 {
            one = queue_costs(tmp.path());
        }
    }
    show_costs("40k-point scans, 1 worker", &one);
    Ok(())
}

/// Jobs/s of `n` tiny patches queued at once.
fn tiny_burst(bin: &Path, nats: &Path, n: usize) -> Res<()> {
    let fill = |dir: &Path| -> Res<()> {
        for k in 0..n {
            std::fs::write(
                dir.join(format!("in/t{k:04}.ply")),
                tiny_patch(12, k as u32),
            )?;
        }
        Ok(())
    };
    let (tmp, cfg) = folder(TINY_FIT, 1)?;
    fill(tmp.path())?;
    let wall = run_once(bin, tmp.path(), &cfg, None, n)?;
    let fit = spread(
        fitted_events(&tmp.path().join("out"))
            .iter()
            .filter_map(|e| e["timings"]["fit_ms"].as_f64())
            .collect(),
    );
    if let Some((m, _, _)) = fit {
        println!("tiny patch (12 x 12 grid): fit {m:.1} ms (median)");
    }
    println!(
        "burst of {n}: single daemon, 1 thread: {:.1} jobs/s",
        n as f64 / wall
    );
    for workers in [1, 2] {
        let (tmp, cfg) = folder(TINY_FIT, 1)?;
        fill(tmp.path())?;
        let (_procs, url) = start_cluster(nats, bin, tmp.path(), &cfg, workers)?;
        let wall = run_once(bin, tmp.path(), &cfg, Some(&url), n)?;
        println!(
            "burst of {n}: queue, {workers} worker(s):     {:.1} jobs/s",
            n as f64 / wall
        );
    }
    Ok(())
}

/// Reads the event log's new lines from `offset` on.
fn new_events(path: &Path, offset: &mut u64) -> Vec<serde_json::Value> {
    let Ok(mut f) = std::fs::File::open(path) else {
        return Vec::new();
    };
    let mut text = String::new();
    if f.seek(SeekFrom::Start(*offset)).is_err() || f.read_to_string(&mut text).is_err() {
        return Vec::new();
    }
    // Only whole lines: the writer appends each line in one write.
    let whole = text.rfind('\n').map_or(0, |i| i + 1);
    *offset += whole as u64;
    text[..whole]
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

/// End-to-end latency (renamed into the watched folder -> `fitted` event) of `n` tiny jobs
/// sent one at a time to a running daemon, `--queue url` when given; in ms, the first five
/// (warm-up) left out.
fn paced(bin: &Path, dir: &Path, cfg: &Path, url: Option<&str>, n: usize) -> Res<Vec<f64>> {
    let mut cmd = Command::new(bin);
    cmd.arg("watch")
        .arg(dir.join("in"))
        .arg("--out")
        .arg(dir.join("out"))
        .arg("--config")
        .arg(cfg)
        .stderr(Stdio::null());
    if let Some(u) = url {
        cmd.args(["--queue", u]);
    }
    let _daemon = Killed(vec![cmd.spawn()?]);
    std::thread::sleep(Duration::from_millis(1500));
    let log = dir.join("out/events.ndjson");
    let mut offset = 0;
    let mut latencies = Vec::new();
    for k in 0..n {
        // Ten patches in turn: each job after the first ten has a warm state to load.
        let name = format!("p{}@{k:04}.ply", k % 10);
        let staged = dir.join("stage").join(&name);
        std::fs::write(&staged, tiny_patch(12, k as u32))?;
        let t = Instant::now();
        std::fs::rename(&staged, dir.join("in").join(&name))?;
        let end = t + Duration::from_secs(60);
        loop {
            if new_events(&log, &mut offset)
                .iter()
                .any(|e| is_fitted(e) && e["version"] == name.as_str())
            {
                break;
            }
            if Instant::now() > end {
                return Err(format!("{name} not fitted in 60 s").into());
            }
            std::thread::sleep(Duration::from_micros(500));
        }
        if k >= 5 {
            latencies.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    Ok(latencies)
}

fn tiny_latency(bin: &Path, nats: &Path, n: usize) -> Res<()> {
    let (single_dir, cfg) = folder(TINY_FIT, 1)?;
    let single = paced(bin, single_dir.path(), &cfg, None, n)?;
    let (queue_dir, qcfg) = folder(TINY_FIT, 1)?;
    let (_procs, url) = start_cluster(nats, bin, queue_dir.path(), &qcfg, 1)?;
    let queued = paced(bin, queue_dir.path(), &qcfg, Some(&url), n)?;
    println!(
        "one at a time ({} jobs after 5 warm-up), end-to-end latency in ms:",
        single.len()
    );
    println!("  {:<22} {:>8} {:>8} {:>8}", "", "median", "p95", "max");
    let mut medians = Vec::new();
    for (name, v) in [("single daemon", single), ("queue, 1 worker", queued)] {
        if let Some((m, p, x)) = spread(v) {
            println!("  {name:<22} {m:>8.2} {p:>8.2} {x:>8.2}");
            medians.push(m);
        }
    }
    if let [s, q] = medians[..] {
        println!("  queue - single (medians): {:+.2} ms", q - s);
    }
    show_costs(
        "tiny jobs one at a time, 1 worker",
        &queue_costs(queue_dir.path()),
    );
    Ok(())
}

fn main() -> Res<()> {
    let mut args = std::env::args().skip(1);
    let scans: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(8);
    let tiny: usize = args.next().map(|a| a.parse()).transpose()?.unwrap_or(200);
    let bin = binary()?;
    let nats = nats_server()?;
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/range_scans/bun000_tri.ply");
    let scan = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!("{cores} cores; load average at start: {}", load_average());
    println!("\n== tiny patches ==");
    tiny_latency(&bin, &nats, tiny)?;
    tiny_burst(&bin, &nats, tiny)?;
    println!("load average now: {}", load_average());
    println!(
        "\n== {scans} scans of {} ({} bytes) ==",
        path.display(),
        scan.len()
    );
    if scans > 0 {
        scans_table(&bin, &nats, &scan, scans)?;
    }
    println!("load average at end: {}", load_average());
    Ok(())
}
