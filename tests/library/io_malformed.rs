//! Malformed inputs give errors naming the file, never a panic or a huge allocation.

use glam::DVec3;
use trispline::io::glb::{glb_bytes, GlbAttributes};
use trispline::io::writers::{obj_bytes, ply_bytes};
use trispline::io::{read_mesh_bytes, Format, LoadOptions};
use trispline::TriMesh;

fn sample() -> TriMesh {
    TriMesh::new(
        vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.3)],
        vec![[0, 1, 2], [1, 3, 2]],
    )
}

fn must_fail(bytes: &[u8], format: Format, what: &str) {
    let r = std::panic::catch_unwind(|| {
        read_mesh_bytes(bytes, format, "input.bin", &LoadOptions::default())
    });
    match r {
        Err(_) => panic!("{what}: reader panicked"),
        Ok(Ok(m)) => panic!("{what}: accepted ({} vertices)", m.mesh.positions.len()),
        Ok(Err(e)) => assert!(
            e.to_string().contains("input.bin"),
            "{what}: error does not name the file: {e}"
        ),
    }
}

fn must_not_panic(bytes: &[u8], format: Format, what: &str) {
    let r = std::panic::catch_unwind(|| {
        read_mesh_bytes(bytes, format, "input.bin", &LoadOptions::default())
    });
    assert!(r.is_ok(), "{what}: reader panicked");
}

fn off_text() -> String {
    "OFF\n# comment\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0.3\n3 0 1 2\n3 1 3 2\n".to_string()
}

fn stl_binary() -> Vec<u8> {
    let m = sample();
    let mut out = vec![0u8; 80];
    out.extend_from_slice(&(m.triangles.len() as u32).to_le_bytes());
    for t in &m.triangles {
        out.extend_from_slice(&[0u8; 12]);
        for &i in t {
            let p = m.positions[i as usize];
            for c in [p.x, p.y, p.z] {
                out.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

#[test]
fn valid_samples_read_back() {
    let m = sample();
    for (bytes, fmt) in [
        (ply_bytes(&m), Format::Ply),
        (obj_bytes(&m), Format::Obj),
        (off_text().into_bytes(), Format::Off),
        (stl_binary(), Format::Stl),
        (glb_bytes(&m, &GlbAttributes::default()), Format::Glb),
    ] {
        let r = read_mesh_bytes(&bytes, fmt, "ok", &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{fmt:?}: {e}"));
        assert_eq!(r.mesh.positions.len(), 4, "{fmt:?}");
        assert_eq!(r.mesh.triangles.len(), 2, "{fmt:?}");
    }
    // Full precision round trip for OBJ and PLY.
    let mut precise = m.clone();
    precise.positions[3] = DVec3::new(0.1 + 1e-17, 1.0 / 3.0, std::f64::consts::PI);
    for (bytes, fmt) in [
        (ply_bytes(&precise), Format::Ply),
        (obj_bytes(&precise), Format::Obj),
    ] {
        let r = read_mesh_bytes(&bytes, fmt, "ok", &LoadOptions::default()).expect("valid");
        assert_eq!(r.mesh, precise, "{fmt:?}");
    }
}

#[test]
fn truncations_at_every_cut_point_never_panic() {
    let m = sample();
    for (bytes, fmt) in [
        (ply_bytes(&m), Format::Ply),
        (obj_bytes(&m), Format::Obj),
        (off_text().into_bytes(), Format::Off),
        (stl_binary(), Format::Stl),
        (glb_bytes(&m, &GlbAttributes::default()), Format::Glb),
    ] {
        for cut in 0..bytes.len() {
            must_not_panic(&bytes[..cut], fmt, &format!("{fmt:?} cut at {cut}"));
        }
    }
    // Binary PLY and STL cut inside the body must be errors, not short meshes.
    let ply = ply_bytes(&m);
    for cut in [ply.len() - 1, ply.len() - 13, ply.len() - 40] {
        must_fail(&ply[..cut], Format::Ply, &format!("ply cut at {cut}"));
    }
    let stl = stl_binary();
    must_fail(&stl[..stl.len() - 10], Format::Stl, "stl truncated");
}

#[test]
fn bad_contents_are_errors() {
    must_fail(b"", Format::Ply, "empty ply");
    must_fail(b"", Format::Off, "empty off");
    must_fail(b"", Format::Obj, "empty obj");
    must_fail(b"ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n", Format::Ply, "huge vertex count");
    must_fail(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 99999999\nproperty list uchar int vertex_indices\nend_header\n", Format::Ply, "huge face count");
    must_fail(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", Format::Ply, "index out of range");
    must_fail(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\nnan 0 0\n0 1 0\n", Format::Ply, "NaN");
    must_fail(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n200 0 1 2\n", Format::Ply, "list longer than file");
    must_fail(
        b"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 9 2\n",
        Format::Off,
        "off index out of range",
    );
    must_fail(
        b"OFF\n999999999 2 0\n0 0 0\n",
        Format::Off,
        "off huge count",
    );
    must_fail(
        b"OFF\n3 1 0\n0 0 0\ninf 0 0\n0 1 0\n3 0 1 2\n",
        Format::Off,
        "off inf",
    );
    must_fail(
        b"v 0 0 0\nv 1 0 0\nf 1 2 9\n",
        Format::Obj,
        "obj index out of range",
    );
    let mut stl = stl_binary();
    stl[80..84].copy_from_slice(&u32::MAX.to_le_bytes());
    must_fail(&stl, Format::Stl, "stl huge facet count");
    must_fail(
        b"glTF\x02\0\0\0\x10\0\0\0garbage!",
        Format::Glb,
        "glb garbage",
    );
    let draco = br#"{"asset":{"version":"2.0"},"extensionsRequired":["KHR_draco_mesh_compression"],"extensionsUsed":["KHR_draco_mesh_compression"]}"#;
    let r = read_mesh_bytes(draco, Format::Gltf, "input.bin", &LoadOptions::default());
    assert!(r
        .err()
        .is_some_and(|e| e.to_string().contains("KHR_draco_mesh_compression")));
}

#[test]
fn random_garbage_never_panics() {
    let mut state = 0x1234_5678_9abc_def0u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let prefixes: [&[u8]; 5] = [b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nelement face 3\nproperty list uchar int vertex_indices\nend_header\n", b"OFF\n", b"solid x\n", b"glTF", b"v 1 2 3\n"];
    for round in 0..400 {
        let len = (next() % 300) as usize;
        let mut bytes = prefixes[round % prefixes.len()].to_vec();
        bytes.extend((0..len).map(|_| next() as u8));
        for fmt in [
            Format::Ply,
            Format::Off,
            Format::Stl,
            Format::Glb,
            Format::Obj,
        ] {
            must_not_panic(&bytes, fmt, &format!("garbage round {round} as {fmt:?}"));
        }
    }
}

#[test]
fn ply_variants_read() {
    // Big-endian binary with float coordinates and a tristrip with a restart.
    let mut be = b"ply\nformat binary_big_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\nelement tristrips 1\nproperty list int int vertex_indices\nend_header\n".to_vec();
    for p in [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [1.0, 1.0, 0.0],
        [2.0, 1.0, 0.0],
    ] {
        for c in p {
            be.extend_from_slice(&c.to_be_bytes());
        }
    }
    for i in [6i32, 0, 1, 2, 3, -1, 1, 4] {
        be.extend_from_slice(&i.to_be_bytes());
    }
    // The run after -1 has only two indices: no triangle from it.
    let r = read_mesh_bytes(&be, Format::Ply, "be", &LoadOptions::default()).expect("big endian");
    assert_eq!(r.mesh.triangles, vec![[0, 1, 2], [2, 1, 3]]);
    // vertex_index instead of vertex_indices, quads fan-triangulated.
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    let r = read_mesh_bytes(ascii, Format::Ply, "quad", &LoadOptions::default()).expect("ascii");
    assert_eq!(r.mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
}

#[test]
fn range_grid_cuts_depth_jumps_and_uses_shorter_diagonals() {
    // A 3x3 grid of points; the right column sits 10 units deeper (a depth jump).
    let mut text = String::from("ply\nformat ascii 1.0\nobj_info num_cols 3\nobj_info num_rows 3\nelement vertex 9\nproperty float x\nproperty float y\nproperty float z\nelement range_grid 9\nproperty list uchar int vertex_indices\nend_header\n");
    for r in 0..3 {
        for c in 0..3 {
            let z = if c == 2 { 10.0 } else { 0.0 };
            // Stretch the first cell so that its (r,c+1)-(r+1,c) diagonal is the shorter one.
            let x = if r == 1 && c == 0 { 0.6 } else { c as f64 };
            text.push_str(&format!("{x} {r} {z}\n"));
        }
    }
    for i in 0..9 {
        text.push_str(&format!("1 {i}\n"));
    }
    let r = read_mesh_bytes(
        text.as_bytes(),
        Format::Ply,
        "grid",
        &LoadOptions::default(),
    )
    .expect("grid");
    let g = r.grid.expect("grid kept");
    assert_eq!((g.rows, g.cols), (3, 3));
    // Only the two left cells survive (2 triangles each); the first uses diagonal 1-3.
    assert_eq!(r.mesh.triangles.len(), 4);
    assert!(r
        .mesh
        .triangles
        .iter()
        .take(2)
        .all(|t| t.contains(&1) && t.contains(&3)));
}
