//! Resource limits that hold and readers that never panic (issue 22, points 3 and 4):
//! the amplification reproducers are refused with `too_large` before anything is
//! allocated for their declared counts, and their peak memory, measured in a child
//! process, stays within twice that of a legitimate file of the same size. The fuzzers'
//! seed corpus and every saved crash input are replayed through all readers.

#[path = "../../fuzz/src/targets.rs"]
mod targets;

use std::path::{Path, PathBuf};
use std::process::Command;
use trispline::io::surface_json::read_surface_json;
use trispline::io::{read_mesh_bytes, read_mesh_file, Format, LoadOptions};

/// Amplification files are 10 MB (the issue's are 100 MB): the budgets do not depend on
/// the file size, so the ratio checked is the same.
const CASE_BYTES: usize = 10 << 20;
/// Set in the child process: which file to read and how.
const CHILD_CASE: &str = "TRISPLINE_IO_LIMITS_CASE";
const PEAK_TAG: &str = "IO_LIMITS_PEAK_KB";

fn xyz_header(format: &str, vertices: usize) -> String {
    format!("ply\nformat {format} 1.0\nelement vertex {vertices}\nproperty float x\nproperty float y\nproperty float z\n")
}

fn push_f32s(out: &mut Vec<u8>, values: &[f32]) {
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// Three vertices and one triangle strip of one-byte indices filling the file: 10^7
/// triangles (10^8 in the issue) if nothing stops it.
fn strip_ply() -> Vec<u8> {
    let mut b = xyz_header("binary_little_endian", 3).into_bytes();
    b.extend_from_slice(
        b"element tristrips 1\nproperty list int uchar vertex_indices\nend_header\n",
    );
    push_f32s(&mut b, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let n = CASE_BYTES - b.len() - 4;
    b.extend_from_slice(&(n as i32).to_le_bytes());
    b.extend((0..n).map(|k| (k % 3) as u8));
    b
}

/// Three vertices and 10^7 empty range-grid cells (one byte each).
fn empty_grid_ply() -> Vec<u8> {
    let cells = CASE_BYTES - 400;
    let mut b = format!(
        "ply\nformat binary_little_endian 1.0\nobj_info num_cols {cells}\nobj_info num_rows 1\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement range_grid {cells}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    .into_bytes();
    push_f32s(&mut b, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    b.resize(b.len() + cells, 0);
    b
}

/// A legitimate binary PLY of about the same size: a height field, two triangles per
/// grid square, the layout scanners write.
fn legitimate_ply() -> Vec<u8> {
    let side = 520usize;
    let mut b = xyz_header("binary_little_endian", side * side).into_bytes();
    let faces = 2 * (side - 1) * (side - 1);
    b.extend_from_slice(
        format!("element face {faces}\nproperty list uchar int vertex_indices\nend_header\n")
            .as_bytes(),
    );
    for r in 0..side {
        for c in 0..side {
            let (x, y) = (c as f32 * 0.01, r as f32 * 0.01);
            push_f32s(&mut b, &[x, y, (x * 3.0).sin() * (y * 2.0).cos()]);
        }
    }
    for r in 0..side - 1 {
        for c in 0..side - 1 {
            let a = (r * side + c) as i32;
            for t in [
                [a, a + 1, a + side as i32 + 1],
                [a, a + side as i32 + 1, a + side as i32],
            ] {
                b.push(3);
                for i in t {
                    b.extend_from_slice(&i.to_le_bytes());
                }
            }
        }
    }
    b
}

/// 152 bytes whose two cells lie 2^39 grid steps apart (the dense tables of the grid
/// surface would take ~10^24 bytes).
fn spanning_surface_json() -> Vec<u8> {
    br#"{"schema":"trispline.surface/1","kind":"loop","layout":"grid","cells":[[0,0,0],[549755813887,549755813887,0]],"control_coords":[],"control_points":[]}"#.to_vec()
}

/// A legitimate surface.json of about the same size: one linear Bezier triangle.
fn legitimate_surface_json() -> Vec<u8> {
    br#"{"schema":"trispline.surface/1","kind":"bezier","degree":1,"control_points":[[0,0,0],[1,0,0],[0,1,0]]}"#.to_vec()
}

/// A .gltf naming `uri` as a buffer of `length` bytes holding three positions and a
/// triangle of u16 indices at its start.
fn gltf_with_external_buffer(uri: &str, length: u64) -> String {
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":1}}]}}],"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},{{"bufferView":1,"componentType":5123,"count":3,"type":"SCALAR"}}],"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":6}}],"buffers":[{{"byteLength":{length},"uri":"{uri}"}}]}}"#
    )
}

fn external_buffer_bytes() -> Vec<u8> {
    let mut b = Vec::new();
    push_f32s(&mut b, &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    for i in [0u16, 1, 2, 0] {
        b.extend_from_slice(&i.to_le_bytes());
    }
    b
}

/// The amplification cases as files in `dir`: (name, path, reader).
fn write_cases(dir: &Path) -> Vec<(&'static str, PathBuf, &'static str)> {
    let write = |name: &str, bytes: &[u8]| {
        let p = dir.join(name);
        std::fs::write(&p, bytes).expect("temp file");
        p
    };
    // 2 GiB, sparse: takes no disk, and reading it would take 2 GiB of memory.
    let big = std::fs::File::create(dir.join("big.bin")).expect("temp file");
    big.set_len(2 << 30).expect("sparse file");
    vec![
        ("strip", write("strip.ply", &strip_ply()), "mesh"),
        ("empty_grid", write("grid.ply", &empty_grid_ply()), "mesh"),
        (
            "legitimate_ply",
            write("legit.ply", &legitimate_ply()),
            "mesh",
        ),
        (
            "cell_span",
            write("span.surface.json", &spanning_surface_json()),
            "surface",
        ),
        (
            "legitimate_surface",
            write("legit.surface.json", &legitimate_surface_json()),
            "surface",
        ),
        (
            "gltf_2gib_buffer",
            write(
                "big.gltf",
                gltf_with_external_buffer("big.bin", 2 << 30).as_bytes(),
            ),
            "mesh",
        ),
    ]
}

/// Reads one case as `trispline inspect` and `trispline curvature` do: the outcome kind.
fn read_case(path: &Path, reader: &str) -> String {
    let opts = LoadOptions::default();
    let outcome = match reader {
        "surface" => read_surface_json(path).map(|_| ()),
        _ => read_mesh_file(path, &opts).map(|_| ()),
    };
    match outcome {
        Ok(()) => "ok".into(),
        Err(e) => e.kind().into(),
    }
}

fn peak_rss_kb() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// In-process: every amplification case is refused as too large, the legitimate ones
/// read. Also the child process's entry point for the peak-memory test, which reruns
/// this test alone with `CHILD_CASE` naming one file.
#[test]
fn amplification_inputs_are_refused_as_too_large() {
    if let Ok(case) = std::env::var(CHILD_CASE) {
        let (reader, path) = case.split_once(':').expect("reader:path");
        let outcome = read_case(Path::new(path), reader);
        // On a line of its own: the harness prints the test name before it.
        println!("\n{PEAK_TAG} {} {outcome}", peak_rss_kb());
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    for (name, path, reader) in write_cases(dir.path()) {
        let want = if name.starts_with("legitimate") {
            "ok"
        } else {
            "too_large"
        };
        assert_eq!(read_case(&path, reader), want, "{name}");
    }
}

/// Peak RSS of reading each case in a fresh process (this test binary, running only the
/// test above): the refused files take at most twice what the legitimate file of the
/// same size takes, and far under 1 GB.
#[test]
fn amplification_inputs_peak_memory_stays_near_a_legitimate_file() {
    let dir = tempfile::tempdir().expect("temp dir");
    let exe = std::env::current_exe().expect("test binary");
    let mut peaks = std::collections::HashMap::new();
    for (name, path, reader) in write_cases(dir.path()) {
        let out = Command::new(&exe)
            .args([
                "io_limits::amplification_inputs_are_refused_as_too_large",
                "--exact",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(CHILD_CASE, format!("{reader}:{}", path.display()))
            .output()
            .expect("child test process");
        let stdout = String::from_utf8_lossy(&out.stdout);
        let line = stdout
            .lines()
            .find_map(|l| l.split_once(PEAK_TAG).map(|(_, rest)| rest))
            .unwrap_or_else(|| panic!("{name}: no measurement in {stdout}"));
        let mut words = line.split_whitespace();
        let peak: u64 = words.next().and_then(|w| w.parse().ok()).expect("peak");
        println!(
            "{name}: peak RSS {peak} kB, outcome {}",
            words.next().unwrap_or("")
        );
        peaks.insert(name, peak);
    }
    for (case, legit) in [
        ("strip", "legitimate_ply"),
        ("empty_grid", "legitimate_ply"),
        ("gltf_2gib_buffer", "legitimate_surface"),
        ("cell_span", "legitimate_surface"),
    ] {
        let (p, l) = (peaks[case], peaks[legit]);
        assert!(p > 0 && l > 0, "VmHWM unavailable");
        assert!(p <= 2 * l, "{case}: {p} kB against {l} kB for {legit}");
        assert!(p < 1 << 20, "{case}: {p} kB");
    }
}

#[test]
fn io_range_grid_dimensions_of_2_pow_32_are_an_error_not_a_panic() {
    let body = "0 0 0\n1 0 0\n0 1 0\n";
    for (cols, rows, cells) in [
        ("4294967296", "4294967296", 1),
        ("4294967296", "0", 0),
        ("0", "4294967296", 0),
        ("18446744073709551615", "2", 2),
    ] {
        let mut text = format!("ply\nformat ascii 1.0\nobj_info num_cols {cols}\nobj_info num_rows {rows}\n{}element range_grid {cells}\nproperty list uchar int vertex_indices\nend_header\n{body}", xyz_header("ascii", 3).trim_start_matches("ply\nformat ascii 1.0\n"));
        text.push_str(&"1 0\n".repeat(cells));
        let r = std::panic::catch_unwind(|| {
            read_mesh_bytes(
                text.as_bytes(),
                Format::Ply,
                "grid.ply",
                &LoadOptions::default(),
            )
        })
        .unwrap_or_else(|_| panic!("{cols} x {rows}: panicked"));
        match r {
            Ok(l) => assert!(l.mesh.triangles.is_empty(), "{cols} x {rows}"),
            Err(e) => assert_eq!(e.kind(), "count_mismatch", "{cols} x {rows}: {e}"),
        }
    }
}

#[test]
fn io_gltf_accessor_mistakes_are_typed_errors() {
    // Seeds 1..=3 of the glTF corpus: float indices (an `unreachable!` in the gltf crate),
    // an accessor that does not exist, a stride shorter than a position.
    let seeds = targets::seeds("gltf");
    assert_eq!(targets::run("gltf", &seeds[0]), Ok(()));
    for (k, seed) in seeds[1..4].iter().enumerate() {
        let r = std::panic::catch_unwind(|| targets::run("gltf", seed))
            .unwrap_or_else(|_| panic!("seed {}: panicked", k + 1));
        let kind = r.expect_err("refused");
        assert!(
            kind == "malformed" || kind == "gltf",
            "seed {}: {kind}",
            k + 1
        );
    }
}

#[test]
fn io_gltf_external_buffers_load_from_beside_the_file_and_nowhere_else() {
    let root = tempfile::tempdir().expect("temp dir");
    let dir = root.path().join("scans");
    std::fs::create_dir(&dir).expect("dir");
    let data = external_buffer_bytes();
    std::fs::write(dir.join("mesh.bin"), &data).expect("buffer");
    std::fs::write(root.path().join("outside.bin"), &data).expect("buffer");
    let opts = LoadOptions::default();
    let read = |uri: &str, length: u64| {
        let gltf = dir.join("scene.gltf");
        std::fs::write(&gltf, gltf_with_external_buffer(uri, length)).expect("gltf");
        read_mesh_file(&gltf, &opts)
    };
    let loaded = read("mesh.bin", data.len() as u64).expect("buffer beside the file");
    assert_eq!(loaded.mesh.triangles, vec![[0, 1, 2]]);
    let outside = root.path().join("outside.bin");
    #[cfg(unix)]
    std::os::unix::fs::symlink(&outside, dir.join("link.bin")).expect("symlink");
    for uri in [
        "../outside.bin",
        outside.to_str().expect("utf-8 path"),
        "link.bin",
    ] {
        let e = read(uri, data.len() as u64).expect_err(uri);
        assert_eq!(e.kind(), "unsupported", "{uri}: {e}");
        assert!(e.to_string().contains("folder"), "{uri}: {e}");
    }
    let missing = read("missing.bin", 44).expect_err("no such buffer");
    assert_eq!(missing.kind(), "external_buffer", "{missing}");
    let short = read("mesh.bin", 1000).expect_err("declared longer than the file");
    assert_eq!(short.kind(), "count_mismatch", "{short}");
    // Streamed input has no folder: a clear refusal, not a lookup in the working folder.
    let streamed = read_mesh_bytes(
        gltf_with_external_buffer("mesh.bin", 44).as_bytes(),
        Format::Gltf,
        "pipe",
        &opts,
    )
    .expect_err("no folder");
    assert!(streamed.to_string().contains("embed"), "{streamed}");
}

#[test]
fn io_declared_counts_beyond_the_vertex_budget_are_refused_before_reading() {
    let small = LoadOptions::with_limits(1 << 20, 100);
    let off = "OFF\n200 1 0\n".to_string() + &"0 0 0\n".repeat(200) + "3 0 1 2\n";
    let e = read_mesh_bytes(off.as_bytes(), Format::Off, "big.off", &small).expect_err("200 > 100");
    assert_eq!(e.kind(), "too_large", "{e}");
    let ply = xyz_header("ascii", 200) + "end_header\n" + &"0 0 0\n".repeat(200);
    let e = read_mesh_bytes(ply.as_bytes(), Format::Ply, "big.ply", &small).expect_err("200 > 100");
    assert_eq!(e.kind(), "too_large", "{e}");
    // One polygon of 30,000 corners over three vertices: refused before its fan is built.
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf".to_string() + &" 1 2 3".repeat(10_000) + "\n";
    let e = read_mesh_bytes(
        obj.as_bytes(),
        Format::Obj,
        "fan.obj",
        &LoadOptions::default(),
    )
    .expect_err("29,998 triangles over 3 vertices");
    assert_eq!(e.kind(), "too_large", "{e}");
    let tiny_files = LoadOptions::with_limits(10, 100);
    let e = read_mesh_bytes(off.as_bytes(), Format::Off, "big.off", &tiny_files)
        .expect_err("over max_file_bytes");
    assert_eq!(e.kind(), "too_large", "{e}");
}

/// Every seed of every fuzz target and every saved crash input (`fuzz/corpus/<target>/`)
/// through its reader and through all the others: a value or a typed error, never a panic.
#[test]
fn io_fuzz_corpus_and_crash_inputs_never_panic() {
    let corpus = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus");
    let mut inputs: Vec<Vec<u8>> = targets::TARGETS
        .iter()
        .flat_map(|t| targets::seeds(t))
        .collect();
    let seeded = inputs.len();
    for t in targets::TARGETS {
        if let Ok(entries) = std::fs::read_dir(corpus.join(t)) {
            for entry in entries.flatten() {
                inputs.push(std::fs::read(entry.path()).expect("corpus file"));
            }
        }
    }
    assert!(seeded >= 20, "{seeded} seeds");
    for (k, input) in inputs.iter().enumerate() {
        for t in targets::TARGETS {
            let r = std::panic::catch_unwind(|| targets::run(t, input));
            assert!(r.is_ok(), "input {k} panicked in the {t} reader");
            assert_ne!(
                r.ok().and_then(Result::err).as_deref(),
                Some(targets::READER_PANICKED),
                "input {k}: the {t} reader needed its panic net"
            );
        }
    }
}
