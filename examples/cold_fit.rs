//! The cold-fit benchmark of the real-scan issue, measured as a user meets it: a fresh
//! `trispline fit` process per run, from its start to `surface.json` in place, on a
//! 40k-vertex range scan.
//!
//!     cargo build --release --bin trispline
//!     cargo run --release --example cold_fit [-- FILE [RUNS [IDLE_S [SURFACE [DOMAIN]]]]]
//!
//! Defaults: `../shared/data/range_scans/bun000_tri.ply`, 8 runs, no idle, `loop`, the
//! domain `fit` picks (`mesh` passes `--domain mesh`: the whole-object path for a mesh the
//! dispatch would fit on its exact subdivision connectivity, such as bun_zipper
//! subdivided once by `trispline subdivide`, the 135k-vertex scan). With
//! IDLE_S > 0 every run waits that long first: on a VM that hands free memory back to its
//! host, a fit after idle pays for its fresh pages again (see `allocator::small_pages_only`),
//! so back-to-back runs alone flatter the figures.
//!
//! Per run: `surface` = process start -> `surface.json` renamed into place (polled every
//! millisecond, so late by up to 1 ms); `exit` = process start -> exit; then the report's
//! stages: `read` (read + parse), `prepare` (clean, components, holes, map, grid, initial
//! net), `fit` (first fit and correction rounds), `shown` (tessellation, GLB, report and
//! surface descriptions: the report's `wall_ms` less prepare and fit), and `rest` =
//! surface - read - wall: process start, argument parsing and the three atomic writes with
//! their fsyncs.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{binary, Res};

const COLUMNS: [&str; 7] = ["surface", "exit", "read", "prepare", "fit", "shown", "rest"];

fn run_once(bin: &Path, input: &Path, surface: &str, domain: Option<&str>) -> Res<[f64; 7]> {
    let out = tempfile::tempdir()?;
    let target = out.path().join("surface.json");
    // Into a file, not a pipe: a pipe nobody reads while the fit runs could fill and stall it.
    let log_path = out.path().join("stderr.txt");
    let log = std::fs::File::create(&log_path)?;
    let start = Instant::now();
    let mut child = Command::new(bin)
        .args(["fit", "--surface", surface])
        .args(domain.map(|d| ["--domain", d]).into_iter().flatten())
        .arg("--out")
        .arg(out.path())
        .arg(input)
        .stdout(Stdio::null())
        .stderr(log)
        .spawn()?;
    let mut at_surface = None;
    let status = loop {
        if at_surface.is_none() && target.exists() {
            at_surface = Some(start.elapsed());
        }
        if let Some(status) = child.try_wait()? {
            break status;
        }
        if start.elapsed() > Duration::from_secs(600) {
            child.kill()?;
            return Err("a fit took over 10 minutes".into());
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    let exit = start.elapsed();
    if !status.success() {
        let why = std::fs::read_to_string(&log_path).unwrap_or_default();
        return Err(format!("trispline fit failed ({status}): {why}").into());
    }
    let surface_ms = at_surface.unwrap_or(exit).as_secs_f64() * 1e3;
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.path().join("report.json"))?)?;
    let field = |k: &str| report[k].as_f64().ok_or(format!("report.json has no {k}"));
    let (read, prepare, fit, wall) = (
        field("read_ms")?,
        field("prepare_ms")?,
        field("fit_ms")?,
        field("wall_ms")?,
    );
    Ok([
        surface_ms,
        exit.as_secs_f64() * 1e3,
        read,
        prepare,
        fit,
        wall - prepare - fit,
        surface_ms - read - wall,
    ])
}

fn main() -> Res<()> {
    let mut args = std::env::args().skip(1);
    let input = args.next().map(PathBuf::from).unwrap_or_else(|| {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/range_scans/bun000_tri.ply")
    });
    let runs: usize = args.next().and_then(|a| a.parse().ok()).unwrap_or(8).max(1);
    let idle: f64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(0.0);
    let surface = args.next().unwrap_or_else(|| "loop".into());
    let domain = args.next();
    if !input.exists() {
        return Err(format!("{} missing (pass a mesh file)", input.display()).into());
    }
    let bin = binary()?;
    let domain_arg = domain.as_ref().map(|d| format!(" --domain {d}"));
    println!(
        "{}: {runs} cold `trispline fit --surface {surface}{}` processes, {idle} s idle before each (ms)",
        input.display(),
        domain_arg.unwrap_or_default()
    );
    println!("{}", COLUMNS.map(|c| format!("{c:>8}")).join(""));
    let mut rows = Vec::with_capacity(runs);
    for _ in 0..runs {
        if idle > 0.0 {
            std::thread::sleep(Duration::from_secs_f64(idle));
        }
        let row = run_once(&bin, &input, &surface, domain.as_deref())?;
        println!("{}", row.map(|v| format!("{v:8.1}")).join(""));
        rows.push(row);
    }
    let sorted: Vec<Vec<f64>> = (0..COLUMNS.len())
        .map(|c| {
            let mut v: Vec<f64> = rows.iter().map(|r| r[c]).collect();
            v.sort_by(f64::total_cmp);
            v
        })
        .collect();
    let line = |stat: &dyn Fn(&[f64]) -> f64| -> String {
        sorted.iter().map(|v| format!("{:8.1}", stat(v))).collect()
    };
    println!("{}  min", line(&|v| v[0]));
    println!(
        "{}  median",
        line(&|v| 0.5 * (v[(v.len() - 1) / 2] + v[v.len() / 2]))
    );
    Ok(())
}
