//! A stable-toolchain mutation fuzzer for every reader (the cargo-fuzz targets in `fuzz/`
//! need nightly and libFuzzer): seeded with the inputs of `fuzz/src/targets.rs` (plus any
//! files given on the command line), it mutates them (bit flips, byte sets, inserted
//! "interesting" numbers, deletions, duplications, splices, truncations), runs each
//! reader under `catch_unwind`, and saves every input that panics.
//!
//! ```text
//! cargo run --release --example reader_fuzz -- [--runs N] [--seed S] [--target NAME]...
//!     [--artifacts DIR] [SEED_FILE...]
//! cargo run --release --example reader_fuzz -- --write-seeds DIR
//! ```
//! `--write-seeds` writes the seed inputs to `DIR/<target>/` and exits: the starting corpus
//! for the cargo-fuzz targets, so libFuzzer and this fuzzer start from the same inputs.
//! Deterministic for a given seed. Prints executions, crashes and distinct outcomes per
//! target; exits 1 if anything panicked.

#[path = "../fuzz/src/targets.rs"]
mod targets;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

/// The last panic's message, recorded by a silent hook (a fuzzer prints crashes once, at
/// the end, not a backtrace per execution).
static LAST_PANIC: Mutex<String> = Mutex::new(String::new());

const MAX_INPUT: usize = 64 << 10;
const MAX_CORPUS: usize = 512;
const INTERESTING: [&[u8]; 16] = [
    b"0",
    b"-1",
    b"1",
    b"3",
    b"255",
    b"65536",
    b"2147483647",
    b"4294967296",
    b"-2147483648",
    b"99999999999",
    b"1e30",
    b"nan",
    b"inf",
    b"\xff\xff\xff\xff",
    b"\x00\x00\x00\x80",
    b"\xff\xff\xff\x7f",
];

struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        // xorshift64*
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn mutate(rng: &mut Rng, input: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut out = input.to_vec();
    for _ in 0..1 + rng.below(4) {
        let len = out.len();
        let at = rng.below(len + 1);
        match rng.below(9) {
            0 if len > 0 => {
                let i = rng.below(len);
                out[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                out[i] = rng.next() as u8;
            }
            2 => {
                let word = INTERESTING[rng.below(INTERESTING.len())];
                // Replace a run of digits when there is one at `at`, else insert.
                let end = (at..len).find(|&k| !out[k].is_ascii_digit()).unwrap_or(len);
                out.splice(at..end, word.iter().copied());
            }
            3 if len > 0 => {
                let n = 1 + rng.below(16.min(len));
                let from = rng.below(len - n + 1);
                out.drain(from..from + n);
            }
            4 if len > 0 => {
                let n = 1 + rng.below(64.min(len));
                let from = rng.below(len - n + 1);
                let chunk = out[from..from + n].to_vec();
                out.splice(at..at, chunk);
            }
            5 => {
                let other = &corpus[rng.below(corpus.len())];
                let from = rng.below(other.len() + 1);
                out.truncate(at);
                out.extend_from_slice(&other[from..]);
            }
            6 => out.truncate(at),
            7 => {
                let n = 1 + rng.below(8);
                out.splice(at..at, (0..n).map(|_| rng.next() as u8));
            }
            _ if len >= 4 => {
                let i = rng.below(len - 3);
                let v = [0u32, 1, 3, u32::MAX, 1 << 31, 1 << 16, 1 << 24][rng.below(7)];
                out[i..i + 4].copy_from_slice(&v.to_le_bytes());
            }
            _ => out.push(rng.next() as u8),
        }
    }
    out.truncate(MAX_INPUT);
    out
}

struct Report {
    target: &'static str,
    executions: u64,
    crashes: Vec<(PathBuf, String)>,
    outcomes: usize,
    seconds: f64,
}

fn fuzz_target(
    target: &'static str,
    runs: u64,
    seed: u64,
    extra: &[Vec<u8>],
    artifacts: &Path,
) -> Report {
    let mut corpus = targets::seeds(target);
    corpus.extend(extra.iter().cloned());
    if corpus.is_empty() {
        corpus.push(Vec::new());
    }
    let mut rng = Rng(seed ^ (target.len() as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let mut outcomes = HashSet::new();
    let mut crash_hashes = HashSet::new();
    let mut crashes = Vec::new();
    let start = Instant::now();
    let exec = |input: &[u8], outcomes: &mut HashSet<String>| -> Option<String> {
        match std::panic::catch_unwind(|| targets::run(target, input)) {
            Ok(r) => {
                outcomes.insert(match r {
                    Ok(()) => "ok".to_string(),
                    Err(kind) => kind,
                });
                None
            }
            Err(_) => Some(LAST_PANIC.lock().map(|m| m.clone()).unwrap_or_default()),
        }
    };
    let mut executions = 0;
    while executions < runs {
        let input = if (executions as usize) < corpus.len() {
            corpus[executions as usize].clone()
        } else {
            let parent = &corpus[rng.below(corpus.len())];
            mutate(&mut rng, parent, &corpus)
        };
        executions += 1;
        let known = outcomes.len();
        if let Some(message) = exec(&input, &mut outcomes) {
            let hash = fnv(&input);
            if crash_hashes.insert(hash) {
                let dir = artifacts.join(target);
                let path = dir.join(format!("crash-{hash:016x}"));
                if std::fs::create_dir_all(&dir)
                    .and_then(|()| std::fs::write(&path, &input))
                    .is_err()
                {
                    eprintln!("cannot save {}", path.display());
                }
                crashes.push((path, message));
            }
        } else if outcomes.len() > known && corpus.len() < MAX_CORPUS {
            // A new outcome (a new error kind, or first success) marks a new path through
            // the reader: worth mutating further.
            corpus.push(input);
        } else if rng.below(4096) == 0 && corpus.len() < MAX_CORPUS {
            corpus.push(input);
        }
    }
    Report {
        target,
        executions,
        crashes,
        outcomes: outcomes.len(),
        seconds: start.elapsed().as_secs_f64(),
    }
}

fn fnv(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

fn target_of(path: &Path) -> Option<&'static str> {
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    let name = path.file_name()?.to_str()?;
    Some(match ext.as_str() {
        "json" if name.contains("surface") => "surface_json",
        "toml" => "daemon_config",
        other => targets::TARGETS.into_iter().find(|t| *t == other)?,
    })
}

/// Writes every target's seeds as `dir/<target>/seed-<i>`; returns how many.
fn write_seeds(dir: &Path) -> std::io::Result<usize> {
    let mut count = 0;
    for target in targets::TARGETS {
        let folder = dir.join(target);
        std::fs::create_dir_all(&folder)?;
        for (i, seed) in targets::seeds(target).iter().enumerate() {
            std::fs::write(folder.join(format!("seed-{i}")), seed)?;
            count += 1;
        }
    }
    Ok(count)
}

fn main() {
    let mut runs = 1_000_000u64;
    let mut seed = 0x5eed_u64;
    let mut chosen: Vec<&'static str> = Vec::new();
    let mut artifacts = PathBuf::from("fuzz/artifacts");
    let mut files = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().unwrap_or_default();
        match a.as_str() {
            "--runs" => runs = value().parse().unwrap_or(runs),
            "--seed" => seed = value().parse().unwrap_or(seed),
            "--artifacts" => artifacts = PathBuf::from(value()),
            "--write-seeds" => {
                let dir = PathBuf::from(value());
                match write_seeds(&dir) {
                    Ok(count) => println!("{count} seeds written under {}", dir.display()),
                    Err(e) => {
                        eprintln!("cannot write seeds under {}: {e}", dir.display());
                        std::process::exit(1);
                    }
                }
                return;
            }
            "--target" => {
                let t = value();
                match targets::TARGETS.into_iter().find(|x| *x == t) {
                    Some(t) => chosen.push(t),
                    None => eprintln!("unknown target {t}; targets: {:?}", targets::TARGETS),
                }
            }
            _ => files.push(PathBuf::from(a)),
        }
    }
    if chosen.is_empty() {
        chosen = targets::TARGETS.to_vec();
    }
    std::panic::set_hook(Box::new(|info| {
        if let Ok(mut m) = LAST_PANIC.lock() {
            *m = info.to_string();
        }
    }));
    println!("target          executions  crashes  outcomes  seconds");
    let mut failed = false;
    for target in chosen {
        let extra: Vec<Vec<u8>> = files
            .iter()
            .filter(|f| target_of(f) == Some(target))
            .filter_map(|f| std::fs::read(f).ok())
            .filter(|b| b.len() <= MAX_INPUT)
            .collect();
        let r = fuzz_target(target, runs, seed, &extra, &artifacts);
        println!(
            "{:<15} {:>10} {:>8} {:>9} {:>8.1}",
            r.target,
            r.executions,
            r.crashes.len(),
            r.outcomes,
            r.seconds
        );
        for (path, message) in &r.crashes {
            failed = true;
            println!(
                "  crash {}: {}",
                path.display(),
                message.lines().next().unwrap_or("")
            );
        }
    }
    if failed {
        std::process::exit(1);
    }
}
