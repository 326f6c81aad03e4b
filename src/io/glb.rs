//! Binary glTF writer: positions, optional normals and colours, u32 indices.

use super::{IoError, IoErrorKind};
use crate::mesh::TriMesh;
use glam::DVec3;
use serde_json::json;
use std::path::Path;

/// Optional per-vertex attributes for [`glb_bytes`].
#[derive(Default)]
pub struct GlbAttributes<'a> {
    /// Unit normals, one per vertex.
    pub normals: Option<&'a [DVec3]>,
    /// Linear RGBA in 0..1.
    pub colors: Option<&'a [[f32; 4]]>,
    /// Line strips written as extra LINE_STRIP primitives (region boundaries, trims).
    pub polylines: &'a [Vec<DVec3>],
}

/// One buffer view's contents, written straight into the file's binary chunk.
enum ViewData<'a> {
    /// f32 x, y, z per point.
    Vec3(&'a [DVec3]),
    /// f32 r, g, b, a per vertex.
    Rgba(&'a [[f32; 4]]),
    /// u32 per corner.
    Indices(&'a [[u32; 3]]),
}

impl ViewData<'_> {
    /// Bytes of the view; every kind is a whole number of 4-byte words, so views laid end
    /// to end stay 4-byte aligned as glTF requires.
    fn byte_len(&self) -> usize {
        match self {
            ViewData::Vec3(p) => 12 * p.len(),
            ViewData::Rgba(c) => 16 * c.len(),
            ViewData::Indices(t) => 12 * t.len(),
        }
    }

    fn write(&self, out: &mut Vec<u8>) {
        match self {
            ViewData::Vec3(pts) => {
                for p in *pts {
                    for c in [p.x as f32, p.y as f32, p.z as f32] {
                        out.extend_from_slice(&c.to_le_bytes());
                    }
                }
            }
            ViewData::Rgba(colors) => {
                for c in colors.iter().flatten() {
                    out.extend_from_slice(&c.to_le_bytes());
                }
            }
            ViewData::Indices(tris) => {
                for i in tris.iter().flatten() {
                    out.extend_from_slice(&i.to_le_bytes());
                }
            }
        }
    }
}

/// Encodes a triangle mesh as GLB. glTF stores f32: coordinates are written as given,
/// with no axis swap or scaling.
pub fn glb_bytes<'a>(mesh: &'a TriMesh, attrs: &GlbAttributes<'a>) -> Vec<u8> {
    // The views' sizes are known up front: the JSON chunk (which lists their offsets) is
    // made first and each view is then encoded once, in place in the output, instead of
    // into a buffer of its own that is copied into the binary chunk and that into the file.
    let mut data: Vec<ViewData<'a>> = Vec::new();
    let mut views = Vec::new();
    let mut bin_len = 0;
    let mut push_view = |d: ViewData<'a>, target: u32| -> usize {
        let len = d.byte_len();
        views
            .push(json!({"buffer": 0, "byteOffset": bin_len, "byteLength": len, "target": target}));
        bin_len += len;
        data.push(d);
        views.len() - 1
    };
    let mut accessors = Vec::new();
    let vec3_accessor = |view: usize, pts: &[DVec3], with_bounds: bool| {
        let mut acc =
            json!({"bufferView": view, "componentType": 5126, "count": pts.len(), "type": "VEC3"});
        if with_bounds && !pts.is_empty() {
            let (lo, hi) =
                pts.iter()
                    .fold(([f32::MAX; 3], [f32::MIN; 3]), |(mut lo, mut hi), p| {
                        for (k, c) in [p.x as f32, p.y as f32, p.z as f32].into_iter().enumerate() {
                            lo[k] = lo[k].min(c);
                            hi[k] = hi[k].max(c);
                        }
                        (lo, hi)
                    });
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        acc
    };

    let pos_view = push_view(ViewData::Vec3(&mesh.positions), 34962);
    accessors.push(vec3_accessor(pos_view, &mesh.positions, true));
    let mut attributes = json!({"POSITION": 0});
    if let Some(n) = attrs.normals.filter(|n| n.len() == mesh.positions.len()) {
        let v = push_view(ViewData::Vec3(n), 34962);
        accessors.push(vec3_accessor(v, n, false));
        attributes["NORMAL"] = json!(accessors.len() - 1);
    }
    if let Some(c) = attrs.colors.filter(|c| c.len() == mesh.positions.len()) {
        let v = push_view(ViewData::Rgba(c), 34962);
        accessors.push(
            json!({"bufferView": v, "componentType": 5126, "count": c.len(), "type": "VEC4"}),
        );
        attributes["COLOR_0"] = json!(accessors.len() - 1);
    }
    let iv = push_view(ViewData::Indices(&mesh.triangles), 34963);
    accessors.push(json!({"bufferView": iv, "componentType": 5125, "count": mesh.triangles.len() * 3, "type": "SCALAR"}));
    let mut primitives =
        vec![json!({"attributes": attributes, "indices": accessors.len() - 1, "mode": 4})];
    for line in attrs.polylines.iter().filter(|l| l.len() >= 2) {
        let v = push_view(ViewData::Vec3(line), 34962);
        accessors.push(vec3_accessor(v, line, true));
        primitives.push(json!({"attributes": {"POSITION": accessors.len() - 1}, "mode": 3}));
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "trispline"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": primitives}],
        "buffers": [{"byteLength": bin_len}],
        "bufferViews": views,
        "accessors": accessors,
    });
    let mut json_bytes = serde_json::to_vec(&doc).unwrap_or_default();
    while !json_bytes.len().is_multiple_of(4) {
        json_bytes.push(b' ');
    }
    let total = 12 + 8 + json_bytes.len() + 8 + bin_len;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(bin_len as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    for d in &data {
        d.write(&mut out);
    }
    debug_assert_eq!(out.len(), total);
    out
}

pub(crate) fn write_glb(path: &Path, mesh: &TriMesh, attrs: &GlbAttributes) -> Result<(), IoError> {
    std::fs::write(path, glb_bytes(mesh, attrs))
        .map_err(|e| IoError::new(path.display().to_string(), None, IoErrorKind::Write(e)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glb_round_trips_through_the_gltf_crate() {
        let mesh = TriMesh::new(
            vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.5)],
            vec![[0, 1, 2], [1, 3, 2]],
        );
        let colors = vec![[1.0, 0.0, 0.0, 1.0]; 4];
        let bytes = glb_bytes(
            &mesh,
            &GlbAttributes {
                colors: Some(&colors),
                ..Default::default()
            },
        );
        let (doc, buffers, _) = gltf::import_slice(&bytes).expect("valid glb");
        let prim = doc
            .meshes()
            .next()
            .and_then(|m| m.primitives().next())
            .expect("one primitive");
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        let pos: Vec<[f32; 3]> = reader.read_positions().expect("positions").collect();
        assert_eq!(pos[3], [1.0, 1.0, 0.5]);
        let idx: Vec<u32> = reader.read_indices().expect("indices").into_u32().collect();
        assert_eq!(idx, vec![0, 1, 2, 1, 3, 2]);
        assert!(reader.read_colors(0).is_some());
    }
}
