//! Shared by the daemon process tests: the binary, small generated scan-like patches, a
//! fast config, and polling helpers with deadlines that only fail on real hangs.
#![allow(dead_code)]

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::time::{Duration, Instant};

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_trispline"))
}

/// Generous: only a hung daemon takes this long on a loaded 2-core machine.
pub const DEADLINE: Duration = Duration::from_secs(60);

pub fn config(settle_ms: u64, watcher: &str, extra_daemon: &str) -> String {
    format!(
        r#"
[fit]
surface = "bezier"
levels = 1
method = "cg"
inverse = "exact"

[fit.budget]
max_iterations = 20
tolerance_rel = 1e-3

[fit.scan]
lattice = 6
smoothing = 1e-5

[fit.components]
mode = "largest"

[output]
tessellation = 8

[daemon]
settle_ms = {settle_ms}
poll_interval_ms = 50
max_file_bytes = 10000000
max_vertices = 1000000
workers = 2
watcher = "{watcher}"
stop_timeout_ms = 20000
{extra_daemon}
"#
    )
}

/// A scan-like height field over an irregular grid of `n` x `n` vertices, as ASCII PLY;
/// `seed` changes the shape, so versions differ in content.
pub fn patch_ply(n: usize, seed: u32) -> Vec<u8> {
    let (v, f) = height_field(n, seed);
    let mut s = format!(
        "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        v.len(),
        f.len()
    );
    for p in &v {
        s.push_str(&format!("{} {} {}\n", p[0], p[1], p[2]));
    }
    for t in &f {
        s.push_str(&format!("3 {} {} {}\n", t[0], t[1], t[2]));
    }
    s.into_bytes()
}

/// The same height field as a `.gltf` whose positions and indices live in the external
/// buffer `bin_name` (returned second: the bytes to write beside it).
pub fn patch_gltf_external(n: usize, seed: u32, bin_name: &str) -> (String, Vec<u8>) {
    let (v, f) = height_field(n, seed);
    let mut bin = Vec::new();
    let (mut lo, mut hi) = ([f32::MAX; 3], [f32::MIN; 3]);
    for p in &v {
        for k in 0..3 {
            let c = p[k] as f32;
            lo[k] = lo[k].min(c);
            hi[k] = hi[k].max(c);
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let positions_len = bin.len();
    for t in &f {
        for &i in t {
            bin.extend_from_slice(&(i as u32).to_le_bytes());
        }
    }
    let gltf = format!(
        r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":{nv},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},{{"bufferView":1,"componentType":5125,"count":{ni},"type":"SCALAR"}}],"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{positions_len}}},{{"buffer":0,"byteOffset":{positions_len},"byteLength":{il}}}],"buffers":[{{"byteLength":{bl},"uri":"{bin_name}"}}]}}"#,
        lo[0],
        lo[1],
        lo[2],
        hi[0],
        hi[1],
        hi[2],
        nv = v.len(),
        ni = 3 * f.len(),
        il = bin.len() - positions_len,
        bl = bin.len(),
    );
    (gltf, bin)
}

pub fn patch_obj(n: usize, seed: u32) -> Vec<u8> {
    let (v, f) = height_field(n, seed);
    let mut s = String::from("# generated height field\n");
    for p in &v {
        s.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for t in &f {
        s.push_str(&format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1));
    }
    s.into_bytes()
}

fn height_field(n: usize, seed: u32) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let s = seed as f64 * 0.37;
    let mut v = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            // Jittered like a real scan's sampling, deterministic per (i, j, seed).
            let h = ((i * 7919 + j * 104_729 + seed as usize * 31) % 1000) as f64 / 1000.0;
            let x = (i as f64 + 0.2 * (h - 0.5)) / (n - 1) as f64;
            let y = (j as f64 + 0.2 * (0.5 - h)) / (n - 1) as f64;
            let z = 0.15 * (3.0 * x + s).sin() * (2.0 * y - s).cos() + 0.05 * x * y;
            v.push([x, y, z]);
        }
    }
    let mut f = Vec::with_capacity(2 * (n - 1) * (n - 1));
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = j * n + i;
            let (b, c, d) = (a + 1, a + n, a + n + 1);
            if (i + j) % 2 == 0 {
                f.push([a, b, d]);
                f.push([a, d, c]);
            } else {
                f.push([a, b, c]);
                f.push([b, d, c]);
            }
        }
    }
    (v, f)
}

pub const CORRUPT_PLY: &[u8] = b"ply\nformat ascii 1.0\nelement vertex 99\n";

/// Writes under a `.part` name (ignored) and renames into place, as uploaders do.
pub fn drop_file(dir: &Path, name: &str, bytes: &[u8]) {
    let part = dir.join(format!("{name}.part"));
    std::fs::write(&part, bytes).expect("write part");
    std::fs::rename(&part, dir.join(name)).expect("rename");
}

/// The event log's whole lines. The daemon may be appending a line while the log is
/// read: what follows the last newline is that line in part, not an event yet.
pub fn events(out: &Path) -> Vec<serde_json::Value> {
    let log = std::fs::read_to_string(out.join("events.ndjson")).unwrap_or_default();
    let whole = log.rfind('\n').map_or("", |end| &log[..end]);
    whole
        .lines()
        .map(|l| serde_json::from_str(l).expect("event lines are JSON"))
        .collect()
}

pub fn is_fitted(e: &serde_json::Value) -> bool {
    matches!(e["status"].as_str(), Some("met" | "capped" | "stalled"))
}

pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).expect("read")).expect("json")
}

/// Polls until `cond` holds; false after the deadline.
pub fn wait_until(mut cond: impl FnMut() -> bool) -> bool {
    let deadline = Instant::now() + DEADLINE;
    while Instant::now() < deadline {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    cond()
}

pub struct Setup {
    pub _tmp: tempfile::TempDir,
    pub inbox: PathBuf,
    pub out: PathBuf,
    pub cfg: PathBuf,
}

pub fn setup(config_text: &str) -> Setup {
    let tmp = tempfile::tempdir().expect("tmp");
    let (inbox, out, cfg) = (
        tmp.path().join("in"),
        tmp.path().join("out"),
        tmp.path().join("daemon.toml"),
    );
    std::fs::create_dir_all(&inbox).expect("mkdir");
    std::fs::write(&cfg, config_text).expect("config");
    Setup {
        _tmp: tmp,
        inbox,
        out,
        cfg,
    }
}

impl Setup {
    pub fn args(&self) -> Vec<String> {
        vec![
            "watch".into(),
            self.inbox.display().to_string(),
            "--out".into(),
            self.out.display().to_string(),
            "--config".into(),
            self.cfg.display().to_string(),
        ]
    }

    pub fn spawn(&self, extra: &[&str]) -> Daemon {
        let log = std::fs::File::create(self._tmp.path().join("daemon.log")).expect("log file");
        Daemon(
            bin()
                .args(self.args())
                .args(extra)
                .stdin(Stdio::null())
                .stderr(log)
                .spawn()
                .expect("spawns"),
        )
    }

    /// A daemon reading records from its standard input (`--pipe -`), and that input;
    /// its log goes where `spawn`'s does.
    pub fn spawn_pipe(&self) -> (Daemon, ChildStdin) {
        let log = std::fs::File::create(self._tmp.path().join("daemon.log")).expect("log file");
        let mut child = Daemon(
            bin()
                .args(self.args())
                .args(["--pipe", "-"])
                .stdin(Stdio::piped())
                .stderr(log)
                .spawn()
                .expect("spawns"),
        );
        let input = child.stdin.take().expect("stdin");
        (child, input)
    }

    pub fn log(&self) -> String {
        std::fs::read_to_string(self._tmp.path().join("daemon.log")).unwrap_or_default()
    }

    pub fn once(&self) -> std::process::Output {
        bin()
            .args(self.args())
            .arg("--once")
            .output()
            .expect("runs")
    }
}

/// A process a test started, killed when the test lets go of it without having stopped
/// it: a failed assertion must not leave a daemon or worker running after the tests.
pub struct Daemon(pub Child);

impl std::ops::Deref for Daemon {
    type Target = Child;
    fn deref(&self) -> &Child {
        &self.0
    }
}

impl std::ops::DerefMut for Daemon {
    fn deref_mut(&mut self) -> &mut Child {
        &mut self.0
    }
}

impl From<Child> for Daemon {
    fn from(child: Child) -> Self {
        Daemon(child)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        if let Ok(None) = self.0.try_wait() {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
}

pub fn signal(child: &Child, sig: &str) {
    let ok = Command::new("kill")
        .args([&format!("-{sig}"), &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(ok.success());
}

/// Waits for the process to exit; kills it and returns None on a hang.
pub fn wait_exit(child: &mut Child) -> Option<std::process::ExitStatus> {
    let deadline = Instant::now() + DEADLINE;
    loop {
        if let Ok(Some(s)) = child.try_wait() {
            return Some(s);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

pub fn stop(child: impl Into<Daemon>) -> Option<std::process::ExitStatus> {
    let mut child = child.into();
    signal(&child, "TERM");
    wait_exit(&mut child)
}

pub fn write_all(w: &mut impl Write, bytes: &[u8]) {
    w.write_all(bytes).expect("write");
}
