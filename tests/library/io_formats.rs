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
