//! One entry point per reader for the fuzzers (cargo-fuzz targets, the stable mutation
//! fuzzer `examples/reader_fuzz.rs`) and the regression test that replays their corpus.
//! Every entry must return (a value or a typed error) for any bytes: a panic is a bug.

use trispline::daemon::config::DaemonConfig;
use trispline::io::surface_json::parse_surface_json;
use trispline::io::{read_mesh_bytes, Format, LoadOptions};

/// The readers under test, by target name.
pub const TARGETS: [&str; 11] = [
    "ply",
    "obj",
    "off",
    "stl",
    "gltf",
    "glb",
    "xyz",
    "pts",
    "pcd",
    "surface_json",
    "daemon_config",
];

/// Budgets small enough that a fuzzer cannot spend its memory on one legitimate but
/// large input, large enough for every seed.
fn options() -> LoadOptions {
    LoadOptions::with_limits(16 << 20, 200_000)
}

/// Runs one reader on `data`: `Ok(())` when it read the input, `Err(kind)` with the
/// typed error's stable name when it refused it. Unknown target names are refused.
/// What the glTF reader says when its `catch_unwind` net caught a panic of the `gltf` crate.
const GLTF_PANIC_NET: &str = "the glTF reader failed";
/// The outcome `run` reports for an input that needed that net: a finding, not a typed error.
pub const READER_PANICKED: &str = "reader_panicked";

pub fn run(target: &str, data: &[u8]) -> Result<(), String> {
    let format = match target {
        "ply" => Format::Ply,
        "obj" => Format::Obj,
        "off" => Format::Off,
        "stl" => Format::Stl,
        "gltf" => Format::Gltf,
        "glb" => Format::Glb,
        "xyz" => Format::Xyz,
        "pts" => Format::Pts,
        "pcd" => Format::Pcd,
        "surface_json" => {
            return parse_surface_json(data, "fuzz.json")
                .map(|_| ())
                .map_err(|e| e.kind().to_string())
        }
        "daemon_config" => {
            let text = std::str::from_utf8(data).map_err(|_| "not_text".to_string())?;
            return DaemonConfig::parse(text, "fuzz.toml")
                .map(|_| ())
                .map_err(|e| {
                    // The message without its line and column numbers: one outcome per
                    // kind of complaint.
                    format!("config: {e}")
                        .chars()
                        .filter(|c| !c.is_ascii_digit())
                        .take(60)
                        .collect()
                });
        }
        other => return Err(format!("unknown target {other}")),
    };
    read_mesh_bytes(data, format, "fuzz.bin", &options())
        .map(|_| ())
        .map_err(|e| {
            // The glTF reader's last-resort net turns a panic inside the `gltf` crate into
            // an error; the replay test must still see that the net was needed.
            if e.to_string().contains(GLTF_PANIC_NET) {
                READER_PANICKED.to_string()
            } else {
                e.kind().to_string()
            }
        })
}

/// Small valid (and a few hostile) inputs per target, made in code: the fuzzers start
/// from them and the regression test replays them.
pub fn seeds(target: &str) -> Vec<Vec<u8>> {
    match target {
        "ply" => ply_seeds(),
        "obj" => vec![
            trispline::io::writers::obj_bytes(&sample()),
            b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nvt 0 0\nf 1/1/1 2/1/1 3/1/1 4/1/1\nf -1 -2 -3\n".to_vec(),
        ],
        "off" => vec![
            b"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0.3\n3 0 1 2\n4 1 3 2 0\n".to_vec(),
            b"COFF 3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n3 0 1 2\n"
                .to_vec(),
        ],
        "stl" => vec![stl_binary(), stl_ascii()],
        "gltf" => gltf_seeds(),
        "glb" => vec![trispline::io::glb::glb_bytes(
            &sample(),
            &trispline::io::glb::GlbAttributes::default(),
        )],
        "xyz" => vec![
            b"# x y z nx ny nz\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0.5 0 0 1\n1,1,0.3\n".to_vec(),
            b"0.5\t0.25\t1e-3\t200\n-1;2;3\n".to_vec(),
        ],
        "pts" => vec![
            b"4\n0 0 0 -1200 255 0 0\n1 0 0 -1100 0 255 0\n0 1 0 -1000 0 0 255\n1 1 0.3 -900 9 9 9\n"
                .to_vec(),
            b"99999999999\n0 0 0\n".to_vec(),
        ],
        "pcd" => pcd_seeds(),
        "surface_json" => surface_seeds(),
        "daemon_config" => vec![
            include_bytes!("../../config/default.toml").to_vec(),
            b"[fit]\nsurface = \"loop\"\nlevels = 1\nmethod = \"cg\"\ninverse = \"exact\"\n[daemon]\nsettle_ms = 0\npoll_interval_ms = 50\nmax_file_bytes = 100\nmax_vertices = 100\n".to_vec(),
        ],
        _ => Vec::new(),
    }
}

fn sample() -> trispline::TriMesh {
    use glam::DVec3;
    trispline::TriMesh::new(
        vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.3)],
        vec![[0, 1, 2], [1, 3, 2]],
    )
}

const PLY_XYZ: &str = "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n";

fn ply_seeds() -> Vec<Vec<u8>> {
    let ascii_body = "0 0 0\n1 0 0\n0 1 0\n1 1 0.3\n";
    let grid = format!(
        "ply\nformat ascii 1.0\nobj_info num_cols 2\nobj_info num_rows 3\n{PLY_XYZ}element range_grid 6\nproperty list uchar int vertex_indices\nend_header\n{ascii_body}1 0\n1 1\n1 2\n1 3\n0\n0\n"
    );
    let strips = format!(
        "ply\nformat ascii 1.0\n{PLY_XYZ}element tristrips 1\nproperty list int int vertex_indices\nend_header\n{ascii_body}6 0 1 2 -1 1 3\n"
    );
    let faces = format!(
        "ply\nformat ascii 1.0\n{PLY_XYZ}property uchar red\nelement face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\nelement other 1\nproperty list uchar float stuff\nend_header\n0 0 0 1\n1 0 0 1\n0 1 0 1\n1 1 0.3 1\n3 0 1 2 7\n4 0 1 3 2 7\n2 1.5 2.5\n"
    );
    let mut big_endian = format!(
        "ply\nformat binary_big_endian 1.0\n{PLY_XYZ}element face 1\nproperty list uchar uint vertex_indices\nend_header\n"
    )
    .into_bytes();
    for c in [
        0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.3,
    ] {
        big_endian.extend_from_slice(&c.to_be_bytes());
    }
    big_endian.push(3);
    for i in [0u32, 1, 2] {
        big_endian.extend_from_slice(&i.to_be_bytes());
    }
    // The issue's reproducers, in miniature: a grid declaring 2^32 x 2^32 cells, a strip
    // far longer than its three vertices can make triangles for.
    let huge_grid = format!(
        "ply\nformat ascii 1.0\nobj_info num_cols 4294967296\nobj_info num_rows 4294967296\n{PLY_XYZ}element range_grid 1\nproperty list uchar int vertex_indices\nend_header\n{ascii_body}1 0\n"
    );
    let mut long_strip = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement tristrips 1\nproperty list int uchar vertex_indices\nend_header\n".to_string().into_bytes();
    for c in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        long_strip.extend_from_slice(&c.to_le_bytes());
    }
    long_strip.extend_from_slice(&30_000i32.to_le_bytes());
    long_strip.extend((0..30_000).map(|k| (k % 3) as u8));
    vec![
        trispline::io::writers::ply_bytes(&sample()),
        grid.into_bytes(),
        strips.into_bytes(),
        faces.into_bytes(),
        big_endian,
        huge_grid.into_bytes(),
        long_strip,
    ]
}

fn stl_binary() -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&2u32.to_le_bytes());
    for tri in [
        [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        [1.0, 0.0, 0.0, 1.0, 1.0, 0.3, 0.0, 1.0, 0.0],
    ] {
        b.extend_from_slice(&[0u8; 12]);
        for c in tri {
            b.extend_from_slice(&c.to_le_bytes());
        }
        b.extend_from_slice(&[0u8; 2]);
    }
    b
}

fn stl_ascii() -> Vec<u8> {
    b"solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n".to_vec()
}

fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let mut acc = [0u8; 3];
        acc[..chunk.len()].copy_from_slice(chunk);
        let n = u32::from_be_bytes([0, acc[0], acc[1], acc[2]]);
        for k in 0..=chunk.len() {
            out.push(ALPHABET[(n >> (18 - 6 * k) & 63) as usize] as char);
        }
        for _ in chunk.len()..3 {
            out.push('=');
        }
    }
    out
}

/// A .gltf with its buffer in a data URI: three positions and one u16 triangle, plus
/// variants with the accessor mistakes the `gltf` crate does not survive on its own.
fn gltf_seeds() -> Vec<Vec<u8>> {
    let mut buffer = Vec::new();
    for c in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        buffer.extend_from_slice(&c.to_le_bytes());
    }
    for i in [0u16, 1, 2, 0] {
        buffer.extend_from_slice(&i.to_le_bytes());
    }
    let uri = base64(&buffer);
    let doc = |index_type: u32, index_accessor: u32, stride: &str| {
        format!(
            r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0,"children":[1]}},{{"mesh":0,"translation":[1,0,0]}}],
"meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"indices":{index_accessor}}}]}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},{{"bufferView":1,"componentType":{index_type},"count":3,"type":"SCALAR"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36{stride}}},{{"buffer":0,"byteOffset":36,"byteLength":8}}],
"buffers":[{{"byteLength":44,"uri":"data:application/octet-stream;base64,{uri}"}}]}}"#
        )
        .into_bytes()
    };
    vec![
        doc(5123, 1, ""),
        // Float indices: `unreachable!` inside gltf 1.4's read_indices.
        doc(5126, 1, ""),
        // An accessor index that does not exist.
        doc(5123, 7, ""),
        // A stride shorter than a position.
        doc(5123, 1, r#","byteStride":4"#),
        // An external buffer: refused for in-memory input.
        br#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":2147483648,"uri":"big.bin"}]}"#
            .to_vec(),
    ]
}

fn surface_seeds() -> Vec<Vec<u8>> {
    vec![
        br#"{"schema":"trispline.surface/1","kind":"bezier","degree":1,"control_points":[[0,0,0],[1,0,0],[0,1,0]]}"#.to_vec(),
        br#"{"schema":"trispline.surface/1","kind":"loop","domain_segments":1,"control_points":[]}"#.to_vec(),
        br#"{"schema":"trispline.surface/1","kind":"loop","layout":"mesh","control_points":[[0,0,0],[1,0,0],[0,1,0],[0,0,1]],"control_faces":[[0,2,1],[0,1,3],[1,2,3],[0,3,2]]}"#.to_vec(),
        br#"{"schema":"trispline.surface/1","kind":"bspline","degree_u":1,"degree_v":1,"knots_u":[0,0,1,1],"knots_v":[0,0,1,1],"control_grid":[2,2],"control_points":[[0,0,0],[0,1,0],[1,0,0],[1,1,1]]}"#.to_vec(),
        br#"{"schema":"trispline.surface/1","kind":"loop","layout":"grid","cells":[[0,0,0],[0,0,1]],"control_coords":[[0,0]],"control_points":[[0,0,0]]}"#.to_vec(),
        // The issue's span reproducer: two cells 2^39 apart.
        br#"{"schema":"trispline.surface/1","kind":"loop","layout":"grid","cells":[[0,0,0],[549755813887,549755813887,0]],"control_coords":[],"control_points":[]}"#.to_vec(),
    ]
}

const PCD_HEAD: &str = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 2\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 2\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 4\n";

fn pcd_seeds() -> Vec<Vec<u8>> {
    let ascii = format!("{PCD_HEAD}DATA ascii\n0 0 0 1\n1 0 0 2\nnan nan nan 0\n1 1 0.3 4\n");
    let mut binary = format!("{PCD_HEAD}DATA binary\n").into_bytes();
    for (p, i) in [
        ([0.0f32, 0.0, 0.0], 1u16),
        ([1.0, 0.0, 0.0], 2),
        ([0.0, 1.0, 0.0], 3),
        ([1.0, 1.0, 0.3], 4),
    ] {
        for c in p {
            binary.extend_from_slice(&c.to_le_bytes());
        }
        binary.extend_from_slice(&i.to_le_bytes());
    }
    // A count no file could hold, and the compressed encoding (refused as unsupported).
    let huge = PCD_HEAD
        .replace("WIDTH 2\nHEIGHT 2", "WIDTH 4294967296\nHEIGHT 4294967296")
        .replace("POINTS 4", "POINTS 0")
        + "DATA binary\n";
    let compressed = format!("{PCD_HEAD}DATA binary_compressed\n\x08\x00\x00\x00");
    vec![
        ascii.into_bytes(),
        binary,
        huge.into_bytes(),
        compressed.into_bytes(),
    ]
}
