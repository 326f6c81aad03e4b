//! OBJ reader. Handwritten rather than through tobj: tobj renumbers positions per object in
//! order of first use, which loses the file's vertex order (the order `coarsen` and
//! `subdivide` promise to keep) and splits objects that share vertices. Here all groups
//! and objects share the file's one position list, polygons are fan-triangulated, and only
//! position indices are used, so UV or normal seams never split a vertex.
//!
//! Measured with tobj 4.0.5 (`single_index` + `triangulate`, `triangulate` alone, and the
//! default `LoadOptions` all alike): on a 4-vertex file whose first face is `f 2 4 3`, 3 of
//! 4 positions change index; `examples/patches/dome.obj` loses its 2 unused vertices (1256
//! -> 1254) and 1252 move; `decimated-max.obj` 5270 of 5272 move; `semi_regular/subd0..2`
//! every vertex moves (296, 1178, 4706). No option keeps the file's order.

use super::{IoError, IoErrorKind, LoadOptions};
use crate::mesh::TriMesh;
use glam::DVec3;

pub(crate) fn read_obj(bytes: &[u8], file: &str, opts: &LoadOptions) -> Result<TriMesh, IoError> {
    let text = super::text::decode(bytes, file)?;
    let err = |n: usize, kind: IoErrorKind| IoError::at(file, format!("line {n}"), kind);
    let mut positions: Vec<DVec3> = Vec::new();
    // Each face keeps its line (for errors) and the vertices read before it (negative
    // indices count back from there).
    let mut faces: Vec<(usize, i64, Vec<i64>)> = Vec::new();
    let mut fan_triangles = 0usize;
    for (n, raw) in text.lines().enumerate() {
        let n = n + 1;
        let line = raw.split('#').next().unwrap_or("");
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let mut c = [0.0; 3];
                for slot in &mut c {
                    let w = words.next().ok_or_else(|| {
                        err(
                            n,
                            IoErrorKind::malformed("vertex with fewer than 3 coordinates"),
                        )
                    })?;
                    *slot = w.parse().map_err(|_| {
                        err(n, IoErrorKind::malformed(format!("'{w}' is not a number")))
                    })?;
                }
                let p = DVec3::from_array(c);
                if !p.is_finite() {
                    return Err(err(
                        n,
                        IoErrorKind::non_finite("non-finite vertex coordinate"),
                    ));
                }
                positions.push(p);
            }
            Some("f") => {
                let mut idx = Vec::new();
                for w in words {
                    let first = w.split('/').next().unwrap_or("");
                    let i: i64 = first.parse().map_err(|_| {
                        err(n, IoErrorKind::malformed(format!("bad face index '{w}'")))
                    })?;
                    idx.push(i);
                }
                if idx.len() < 3 {
                    return Err(err(
                        n,
                        IoErrorKind::malformed(format!("face with {} vertices", idx.len())),
                    ));
                }
                fan_triangles += idx.len() - 2;
                faces.push((n, positions.len() as i64, idx));
            }
            _ => {}
        }
    }
    // Indices are resolved at the end, once the vertex count is known: the triangle
    // budget is checked before the triangles are allocated.
    let nv = positions.len() as i64;
    opts.check_vertices(positions.len(), "the OBJ file")
        .and_then(|()| opts.check_triangles(fan_triangles, positions.len(), "the OBJ file"))
        .map_err(|kind| IoError::new(file, None, kind))?;
    let mut triangles = Vec::with_capacity(fan_triangles);
    for (n, so_far, f) in &faces {
        let mut resolved = Vec::with_capacity(f.len());
        for &i in f {
            let k = if i > 0 {
                i - 1
            } else if i < 0 {
                so_far + i
            } else {
                -1
            };
            if k < 0 || k >= nv {
                return Err(err(
                    *n,
                    IoErrorKind::index_out_of_range(format!(
                        "vertex index {i} out of range (1..={nv})"
                    )),
                ));
            }
            resolved.push(k as u32);
        }
        for j in 1..resolved.len() - 1 {
            triangles.push([resolved[0], resolved[j], resolved[j + 1]]);
        }
    }
    Ok(TriMesh::new(positions, triangles))
}
