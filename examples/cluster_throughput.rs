//! Throughput of 40k-point scans through the cluster queue (NATS JetStream) with 1, 2 and 3
//! worker processes, against the single-process daemon, and the queue's cost per job.
//!
//!     cargo build --release --bin trispline
//!     cargo run --release --example cluster_throughput [-- SCANS]
//!
//! Needs `nats-server` (scripts/install_nats.sh; or $TRISPLINE_NATS_SERVER) and
//! `../shared/data/range_scans/bun000_tri.ply` (40,256 points, 1.5 MB: over the default
//! payload limit, so the workers read it from the shared folder, as big scans travel). Each
//! run fits SCANS copies as separate patches (default 12) with the embedded fit config.
//! Wall time runs from the start of the source (`watch --once`) to the last `fitted` event.

use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{binary, Res};

fn nats_server() -> Res<PathBuf> {
    let candidates = [
        std::env::var_os("TRISPLINE_NATS_SERVER").map(PathBuf::from),
        std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/bin/nats-server")),
        Some(PathBuf::from("/usr/sbin/nats-server")),
        Some(PathBuf::from("/usr/bin/nats-server")),
    ];
    candidates
        .into_iter()
        .flatten()
        .find(|p| p.is_file())
        .ok_or_else(|| "no nats-server: run scripts/install_nats.sh".into())
}

fn fitted_events(out: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(out.join("events.ndjson"))
        .unwrap_or_default()
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|e| matches!(e["status"].as_str(), Some("met" | "capped" | "stalled")))
        .collect()
}

fn wait_fitted(out: &Path, n: usize, limit: Duration) -> Res<()> {
    let end = Instant::now() + limit;
    while fitted_events(out).len() < n {
        if Instant::now() > end {
            return Err(format!(
                "only {} of {n} fitted in {limit:?}",
                fitted_events(out).len()
            )
            .into());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    Ok(())
}

/// A fresh run folder with SCANS copies of the scan in `in/`.
fn prepare(scan: &[u8], scans: usize, threads: usize) -> Res<(tempfile::TempDir, PathBuf)> {
    let tmp = tempfile::tempdir()?;
    std::fs::create_dir_all(tmp.path().join("in"))?;
    for k in 0..scans {
        std::fs::write(tmp.path().join(format!("in/s{k:03}.ply")), scan)?;
    }
    let cfg = tmp.path().join("cfg.toml");
    std::fs::write(
        &cfg,
        format!("[daemon]\nsettle_ms = 0\nworkers = {threads}\n[log]\nlevel = \"warn\"\n"),
    )?;
    Ok((tmp, cfg))
}

fn mean(events: &[serde_json::Value], key: &str) -> f64 {
    let v: Vec<f64> = events
        .iter()
        .filter_map(|e| e["timings"][key].as_f64())
        .collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

struct Run {
    wall_s: f64,
    fit_ms: f64,
    read_parse_write_ms: f64,
}

fn summarise(out: &Path, wall_s: f64) -> Run {
    let ev = fitted_events(out);
    Run {
        wall_s,
        fit_ms: mean(&ev, "fit_ms"),
        read_parse_write_ms: mean(&ev, "read_ms") + mean(&ev, "parse_ms") + mean(&ev, "write_ms"),
    }
}

fn single(bin: &Path, scan: &[u8], scans: usize, threads: usize) -> Res<Run> {
    let (tmp, cfg) = prepare(scan, scans, threads)?;
    let out = tmp.path().join("out");
    let t = Instant::now();
    let st = Command::new(bin)
        .arg("watch")
        .arg(tmp.path().join("in"))
        .arg("--out")
        .arg(&out)
        .arg("--config")
        .arg(&cfg)
        .arg("--once")
        .stderr(Stdio::null())
        .status()?;
    if !st.success() {
        return Err("the single daemon failed".into());
    }
    wait_fitted(&out, scans, Duration::from_secs(5))?;
    Ok(summarise(&out, t.elapsed().as_secs_f64()))
}

struct Killed(Vec<Child>);

impl Drop for Killed {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn cluster(bin: &Path, nats: &Path, scan: &[u8], scans: usize, workers: usize) -> Res<Run> {
    let (tmp, cfg) = prepare(scan, scans, 1)?;
    let out = tmp.path().join("out");
    let port = TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
    let store = tmp.path().join("nats");
    let mut procs = Killed(vec![Command::new(nats)
        .args(["-js", "-a", "127.0.0.1", "-p", &port.to_string(), "-sd"])
        .arg(&store)
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
    for k in 0..workers {
        procs.0.push(
            Command::new(bin)
                .args(["worker", "--queue", &url, "--name", &format!("w{k}")])
                .arg("--out")
                .arg(&out)
                .arg("--config")
                .arg(&cfg)
                .stderr(Stdio::null())
                .spawn()?,
        );
    }
    // The workers connect and create the consumer before the clock starts.
    std::thread::sleep(Duration::from_millis(1500));
    let t = Instant::now();
    let st = Command::new(bin)
        .arg("watch")
        .arg(tmp.path().join("in"))
        .arg("--out")
        .arg(&out)
        .arg("--config")
        .arg(&cfg)
        .args(["--once", "--queue", &url])
        .stderr(Stdio::null())
        .status()?;
    if !st.success() {
        return Err("the source failed".into());
    }
    wait_fitted(&out, scans, Duration::from_secs(600))?;
    Ok(summarise(&out, t.elapsed().as_secs_f64()))
}

fn main() -> Res<()> {
    let scans: usize = std::env::args()
        .nth(1)
        .map(|a| a.parse())
        .transpose()?
        .unwrap_or(12);
    let bin = binary()?;
    let nats = nats_server()?;
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/range_scans/bun000_tri.ply");
    let scan = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "{scans} scans of {} ({} bytes), {cores} cores",
        path.display(),
        scan.len()
    );
    println!(
        "{:<34} {:>8} {:>9} {:>9} {:>9} {:>14}",
        "run", "wall s", "scans/s", "ms/scan", "fit ms", "read+parse+write ms"
    );
    let show = |name: &str, r: &Run| {
        println!(
            "{name:<34} {:>8.2} {:>9.2} {:>9.1} {:>9.1} {:>14.1}",
            r.wall_s,
            scans as f64 / r.wall_s,
            1e3 * r.wall_s / scans as f64,
            r.fit_ms,
            r.read_parse_write_ms
        );
    };
    let mut baseline = None;
    for threads in [1, 2] {
        let r = single(&bin, &scan, scans, threads)?;
        show(&format!("single daemon, {threads} worker thread(s)"), &r);
        if threads == 1 {
            baseline = Some(r.wall_s);
        }
    }
    let mut one = None;
    for workers in 1..=3 {
        let r = cluster(&bin, &nats, &scan, scans, workers)?;
        show(&format!("queue, {workers} worker process(es)"), &r);
        if workers == 1 {
            one = Some(r.wall_s);
        }
    }
    if let (Some(b), Some(c)) = (baseline, one) {
        println!(
            "queue cost per job (1 worker process against 1 worker thread): {:+.1} ms",
            1e3 * (c - b) / scans as f64
        );
    }
    Ok(())
}
