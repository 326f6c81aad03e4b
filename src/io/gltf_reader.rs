//! glTF 2.0 / GLB: every triangle primitive of every mesh node, with world transforms.

use super::{IoError, IoErrorKind};
use crate::mesh::TriMesh;
use glam::{DMat4, DVec3};
use std::path::Path;

const COMPRESSED: [&str; 3] = [
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
];

/// `base` is the folder for external buffers of a .gltf file (None for in-memory input).
pub(crate) fn read_gltf(bytes: &[u8], file: &str, base: Option<&Path>) -> Result<TriMesh, IoError> {
    let e = |kind: IoErrorKind| IoError::new(file, None, kind);
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|x| e(IoErrorKind::Gltf(x)))?;
    for ext in gltf.extensions_required().chain(gltf.extensions_used()) {
        if COMPRESSED.contains(&ext) {
            return Err(e(IoErrorKind::unsupported(format!(
                "compressed meshes ({ext}) are not supported; export without compression"
            ))));
        }
    }
    let mut buffers = Vec::new();
    for b in gltf.buffers() {
        let data = match b.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| e(IoErrorKind::malformed("GLB has no binary chunk")))?,
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let b64 = rest
                        .split_once(";base64,")
                        .map(|x| x.1)
                        .ok_or_else(|| e(IoErrorKind::unsupported("unsupported data URI")))?;
                    decode_base64(b64)
                        .ok_or_else(|| e(IoErrorKind::malformed("bad base64 in data URI")))?
                } else {
                    let dir = base.ok_or_else(|| {
                        e(IoErrorKind::unsupported(format!(
                            "external buffer '{uri}' cannot be resolved for streamed input"
                        )))
                    })?;
                    if uri.contains("..") || uri.starts_with('/') {
                        return Err(e(IoErrorKind::unsupported(format!(
                            "buffer URI '{uri}' leaves the file's folder"
                        ))));
                    }
                    std::fs::read(dir.join(uri)).map_err(|x| {
                        e(IoErrorKind::ExternalBuffer {
                            uri: uri.to_string(),
                            source: x,
                        })
                    })?
                }
            }
        };
        if data.len() < b.length() {
            return Err(e(IoErrorKind::count_mismatch(format!(
                "buffer {} is {} bytes, declared {}",
                b.index(),
                data.len(),
                b.length()
            ))));
        }
        buffers.push(data);
    }
    let mut mesh = TriMesh::default();
    let scenes: Vec<gltf::Scene> = gltf.scenes().collect();
    let mut stack: Vec<(gltf::Node, DMat4)> = Vec::new();
    if scenes.is_empty() {
        // No scene: take every mesh node as a root.
        stack.extend(gltf.nodes().map(|n| (n, DMat4::IDENTITY)));
    } else {
        for s in &scenes {
            stack.extend(s.nodes().map(|n| (n, DMat4::IDENTITY)));
        }
    }
    let mut visited = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visited += 1;
        if visited > 1_000_000 {
            return Err(e(IoErrorKind::malformed(
                "node hierarchy too deep or cyclic",
            )));
        }
        let m = node.transform().matrix();
        let local = DMat4::from_cols_array_2d(&m.map(|c| c.map(|x| x as f64)));
        let world = parent * local;
        if let Some(gm) = node.mesh() {
            for prim in gm.primitives() {
                use gltf::mesh::Mode;
                let mode = prim.mode();
                if !matches!(
                    mode,
                    Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan
                ) {
                    continue;
                }
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
                let pos: Vec<DVec3> = reader
                    .read_positions()
                    .ok_or_else(|| {
                        e(IoErrorKind::malformed(format!(
                            "mesh '{}' primitive without positions",
                            gm.name().unwrap_or("")
                        )))
                    })?
                    .map(|p| {
                        world.transform_point3(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64))
                    })
                    .collect();
                if pos.iter().any(|p| !p.is_finite()) {
                    return Err(e(IoErrorKind::non_finite("non-finite vertex coordinate")));
                }
                let idx: Vec<u32> = match reader.read_indices() {
                    Some(i) => i.into_u32().collect(),
                    None => (0..pos.len() as u32).collect(),
                };
                if idx.iter().any(|&i| i as usize >= pos.len()) {
                    return Err(e(IoErrorKind::index_out_of_range(
                        "index out of range in a primitive",
                    )));
                }
                let off = mesh.positions.len() as u32;
                let flip = world.determinant() < 0.0;
                let mut push = |a: u32, b: u32, c: u32| {
                    let t = if flip { [a, c, b] } else { [a, b, c] };
                    mesh.triangles.push([t[0] + off, t[1] + off, t[2] + off]);
                };
                match mode {
                    Mode::Triangles => idx.chunks_exact(3).for_each(|t| push(t[0], t[1], t[2])),
                    Mode::TriangleStrip => {
                        for k in 0..idx.len().saturating_sub(2) {
                            if k % 2 == 0 {
                                push(idx[k], idx[k + 1], idx[k + 2]);
                            } else {
                                push(idx[k + 1], idx[k], idx[k + 2]);
                            }
                        }
                    }
                    _ => {
                        for k in 1..idx.len().saturating_sub(1) {
                            push(idx[0], idx[k], idx[k + 1]);
                        }
                    }
                }
                mesh.positions.extend(pos);
            }
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    Ok(mesh)
}

fn decode_base64(s: &str) -> Option<Vec<u8>> {
    let val = |c: u8| -> Option<u32> {
        Some(match c {
            b'A'..=b'Z' => (c - b'A') as u32,
            b'a'..=b'z' => (c - b'a' + 26) as u32,
            b'0'..=b'9' => (c - b'0' + 52) as u32,
            b'+' | b'-' => 62,
            b'/' | b'_' => 63,
            _ => return None,
        })
    };
    let clean: Vec<u8> = s
        .bytes()
        .filter(|&c| c != b'=' && !c.is_ascii_whitespace())
        .collect();
    let mut out = Vec::with_capacity(clean.len() * 3 / 4);
    for chunk in clean.chunks(4) {
        let mut acc = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            acc |= val(c)? << (18 - 6 * i);
        }
        let bytes = acc.to_be_bytes();
        out.extend_from_slice(&bytes[1..chunk.len()]);
    }
    Some(out)
}
