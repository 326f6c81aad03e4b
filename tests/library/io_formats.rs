//! Format details: glTF node transforms and data URIs, ascii STL welding, OFF variants,
//! OBJ groups, seams and negative indices, GLB writer output read back by the gltf crate.

use trispline::io::{read_mesh_bytes, Format, LoadOptions};

fn read(bytes: &[u8], format: Format) -> trispline::TriMesh {
    read_mesh_bytes(bytes, format, "sample", &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .mesh
}

fn base64(data: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in data.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[test]
fn gltf_applies_node_transforms_down_the_hierarchy() {
    let mut bin = Vec::new();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        for c in v {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    // Parent translates by (10, 0, 0); child scales by 2 and holds the mesh.
    let doc = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"translation":[10,0,0],"children":[1]}},{{"scale":[2,2,2],"mesh":0}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"mode":4}}]}}],
        "buffers":[{{"byteLength":36,"uri":"{uri}"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
    );
    let m = read(doc.as_bytes(), Format::Gltf);
    assert_eq!(m.triangles, vec![[0, 1, 2]]);
    assert_eq!(m.positions[1], glam::DVec3::new(12.0, 0.0, 0.0));
    assert_eq!(m.positions[2], glam::DVec3::new(10.0, 2.0, 0.0));
}

#[test]
fn ascii_stl_welds_shared_corners() {
    let text = "solid two\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid two\n";
    let m = read(text.as_bytes(), Format::Stl);
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.triangles.len(), 2);
}

#[test]
fn off_variants_and_obj_details() {
    let coff = "COFF\n# coloured\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n0 1 0 0 0 255 255\n1 1 0 9 9 9 255\n3 0 1 2\n4 0 1 3 2\n";
    let m = read(coff.as_bytes(), Format::Off);
    assert_eq!(m.positions.len(), 4);
    assert_eq!(m.triangles.len(), 3, "a quad fans into two triangles");
    let noff = "NOFF 3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n";
    assert_eq!(
        read(noff.as_bytes(), Format::Off).triangles,
        vec![[0, 1, 2]]
    );
    // Two groups sharing vertices through the global list, UV/normal indices ignored,
    // a negative (relative) index.
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvn 0 0 1\ng a\nf 1/1/1 2/1/1 3/1/1\ng b\nf 2//1 4//1 -2//1\n";
    let m = read(obj.as_bytes(), Format::Obj);
    assert_eq!(m.positions.len(), 4, "no vertex split at groups or seams");
    assert_eq!(m.triangles, vec![[0, 1, 2], [1, 3, 2]]);
}

#[test]
fn off_keywords_as_geomview_defines_them() {
    let triangle = "0 0 0 0.1 0.2\n1 0 0 0.3 0.4\n0 1 0 0.5 0.6\n3 0 1 2\n";
    // The keyword is optional (Geomview: "recommended but optional, as many existing
    // files lack this keyword"); ST, C and N only add columns after the position; nOFF
    // names the dimension first, on its line or the next.
    for head in [
        "3 1 0\n",
        "# no keyword\n3 1 0\n",
        "STCNOFF\n3 1 0\n",
        "STOFF 3 1 0\n",
        "nOFF 3\n3 1 0\n",
        "nOFF\n3 3 1 0\n",
    ] {
        let m = read(format!("{head}{triangle}").as_bytes(), Format::Off);
        assert_eq!(m.triangles, vec![[0, 1, 2]], "{head:?}");
        assert_eq!(m.positions[2], glam::DVec3::new(0.0, 1.0, 0.0), "{head:?}");
    }
    let refused = |head: &str| {
        read_mesh_bytes(
            format!("{head}{triangle}").as_bytes(),
            Format::Off,
            "v.off",
            &LoadOptions::default(),
        )
        .expect_err(head)
    };
    // Variants whose vertices are not points in space, or not text: named, not misread.
    for (head, says) in [
        ("4OFF\n3 1 0\n", "fourth coordinate"),
        ("4nOFF 3\n3 1 0\n", "fourth coordinate"),
        ("nOFF 4\n3 1 0\n", "dimension 4"),
        ("OFF BINARY\n", "binary OFF"),
    ] {
        let e = refused(head);
        assert_eq!(e.kind(), "unsupported", "{head:?}: {e}");
        assert!(e.to_string().contains(says), "{head:?}: {e}");
    }
    for head in ["NOFFX\n3 1 0\n", "nnOFF 3\n3 1 0\n", "appearance { }\n"] {
        let e = refused(head);
        assert_eq!(e.kind(), "bad_header", "{head:?}: {e}");
    }
}

/// Two facets of the unit square, as `ascii_stl_welds_shared_corners` has them.
const SQUARE_FACETS: &str = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid\n";

#[test]
fn stl_first_lines_as_exporters_write_them() {
    // A bare `solid`, a tab, leading blanks and capitals: all ascii, none of which stl_io
    // takes on its own (it wants "solid " and read the tab as a binary file).
    for first in [
        "solid",
        "solid\tpart",
        "  solid part",
        "SOLID PART",
        "solid\r",
    ] {
        let m = read(format!("{first}\n{SQUARE_FACETS}").as_bytes(), Format::Stl);
        assert_eq!((m.positions.len(), m.triangles.len()), (4, 2), "{first:?}");
    }
}

#[test]
fn a_binary_stl_whose_header_begins_with_solid_is_read_as_binary() {
    let mut bytes = b"solid part exported by a CAD tool".to_vec();
    bytes.resize(80, b' ');
    bytes.extend_from_slice(&2u32.to_le_bytes());
    let square = [
        [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
    ];
    for facet in square {
        bytes.extend([0.0f32, 0.0, 1.0].iter().flat_map(|c| c.to_le_bytes()));
        bytes.extend(facet.iter().flatten().flat_map(|c| c.to_le_bytes()));
        bytes.extend_from_slice(&[0, 0]);
    }
    let m = read(&bytes, Format::Stl);
    assert_eq!(m.positions.len(), 4, "corners welded");
    assert_eq!(m.triangles, vec![[0, 1, 2], [1, 3, 2]]);
    // One byte short: neither a binary STL of its count nor ascii.
    let e = read_mesh_bytes(
        &bytes[..bytes.len() - 1],
        Format::Stl,
        "part.stl",
        &LoadOptions::default(),
    )
    .expect_err("truncated");
    assert!(e.to_string().contains("declares 2 facets"), "{e}");
}

#[test]
fn text_formats_take_marks_other_encodings_and_free_header_lines() {
    // A UTF-8 byte-order mark before the first vertex used to hide that vertex.
    let m = read(
        b"\xEF\xBB\xBFv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        Format::Obj,
    );
    assert_eq!(m.positions.len(), 3);
    // UTF-16 (with its mark), as Windows tools write it.
    let utf16: Vec<u8> = [0xFE, 0xFF]
        .into_iter()
        .chain(
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
                .encode_utf16()
                .flat_map(|u| u.to_be_bytes()),
        )
        .collect();
    assert_eq!(read(&utf16, Format::Obj).triangles, vec![[0, 1, 2]]);
    // A Latin-1 material name.
    let latin1 = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl Terraind\xE6k\nf 1 2 3\n";
    assert_eq!(read(latin1, Format::Obj).triangles.len(), 1);
    assert_eq!(
        read(
            b"\xEF\xBB\xBFOFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
            Format::Off
        )
        .triangles
        .len(),
        1
    );
    // A count line after a comment whose bytes grew in the decoding (each stray byte is a
    // 3-byte U+FFFD): the bytes left are counted in the text.
    let xyz = read(
        b"# \xE6\xE6\xE6\xE6\xE6\xE6\n2\n0 0 0\n1 0 0\n",
        Format::Xyz,
    );
    assert_eq!(xyz.positions.len(), 2);
    // A PLY header line without a keyword (Blender 2.4x's "Created by" line) is free text;
    // a known keyword in a broken form is still an error.
    let ply = |extra: &str| {
        format!("ply\nformat ascii 1.0\n{extra}\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    };
    let m = read(
        ply("Created by Blender3D 247 - www.blender.org, source file:").as_bytes(),
        Format::Ply,
    );
    assert_eq!(m.triangles.len(), 1);
    let e = read_mesh_bytes(
        ply("element vertex").as_bytes(),
        Format::Ply,
        "x.ply",
        &LoadOptions::default(),
    )
    .expect_err("an element line without a count");
    assert_eq!(e.kind(), "bad_header");
}

/// A glTF document of one primitive in `mode` over three points.
fn gltf_of_mode(mode: u32) -> String {
    let bin: Vec<u8> = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    let uri = format!("data:application/octet-stream;base64,{}", base64(&bin));
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"translation":[0,0,5],"mesh":0}}],
        "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"mode":{mode}}}]}}],
        "buffers":[{{"byteLength":36,"uri":"{uri}"}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}}]}}"#
    )
}

#[test]
fn gltf_positions_without_bounds_are_read_from_the_data() {
    // `min` and `max` are required of POSITION, but some exporters leave them out; they
    // only bound the data, which the reader takes as it is.
    let full = gltf_of_mode(4);
    let without = full.replace(r#","min":[0,0,0],"max":[1,1,0]"#, "");
    let nulls = full.replace("[0,0,0]", "[null,null,null]");
    for doc in [&without, &nulls] {
        assert_ne!(doc, &full);
        let m = read(doc.as_bytes(), Format::Gltf);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert_eq!(m.positions[1], glam::DVec3::new(1.0, 0.0, 5.0));
    }
}

#[test]
fn gltf_points_are_a_cloud_lines_and_version_one_are_named() {
    let cloud = read_mesh_bytes(
        gltf_of_mode(0).as_bytes(),
        Format::Gltf,
        "p.gltf",
        &LoadOptions::default(),
    )
    .expect("points");
    assert!(cloud.is_point_cloud());
    assert_eq!(
        cloud.mesh.positions[1],
        glam::DVec3::new(1.0, 0.0, 5.0),
        "node transform applied"
    );
    for mode in [1, 2, 3] {
        let e = read_mesh_bytes(
            gltf_of_mode(mode).as_bytes(),
            Format::Gltf,
            "l.gltf",
            &LoadOptions::default(),
        )
        .expect_err("lines only");
        assert_eq!(e.kind(), "unsupported");
        assert!(e.to_string().contains("line primitive"), "{e}");
    }
    let v1 = r#"{"asset":{"version":"1.0"},"meshes":{"m":{"primitives":[]}}}"#;
    let e = read_mesh_bytes(
        v1.as_bytes(),
        Format::Gltf,
        "old.gltf",
        &LoadOptions::default(),
    )
    .expect_err("glTF 1.0");
    assert!(e.to_string().contains("glTF 1.0 is not supported"), "{e}");
    let numbered = r#"{"asset":{"version":1},"meshes":{"m":{"primitives":[]}}}"#;
    let e = read_mesh_bytes(
        numbered.as_bytes(),
        Format::Gltf,
        "old.gltf",
        &LoadOptions::default(),
    )
    .expect_err("collada2gltf's glTF 1.0");
    assert!(e.to_string().contains("glTF 1.0 is not supported"), "{e}");
    let mut glb = b"glTF".to_vec();
    glb.extend(1u32.to_le_bytes());
    glb.extend(20u32.to_le_bytes());
    glb.extend(b"\x00\x00\x00\x00\x00\x00\x00\x00");
    let e =
        read_mesh_bytes(&glb, Format::Glb, "old.glb", &LoadOptions::default()).expect_err("GLB 1");
    assert!(e.to_string().contains("glTF 1.0 is not supported"), "{e}");
}

#[test]
fn a_draco_primitive_is_named_not_reported_as_missing_data() {
    let doc = r#"{"asset":{"version":"2.0"},"extensionsUsed":["KHR_draco_mesh_compression"],
        "extensionsRequired":["KHR_draco_mesh_compression"],
        "meshes":[{"primitives":[{"attributes":{"POSITION":0},"extensions":{"KHR_draco_mesh_compression":{"bufferView":0,"attributes":{"POSITION":0}}}}]}],
        "accessors":[{"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}]}"#;
    let e = read_mesh_bytes(
        doc.as_bytes(),
        Format::Gltf,
        "d.gltf",
        &LoadOptions::default(),
    )
    .expect_err("draco");
    assert!(e.to_string().contains("KHR_draco_mesh_compression"), "{e}");
}
