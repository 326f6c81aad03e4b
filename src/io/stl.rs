//! STL (ascii and binary) through stl_io; coincident corners are welded on exact equality
//! because binary STL repeats every vertex per facet.

use super::{IoError, IoErrorKind};
use crate::mesh::TriMesh;
use glam::DVec3;

pub(crate) fn read_stl(bytes: &[u8], file: &str) -> Result<TriMesh, IoError> {
    // A binary STL states its facet count; check it before stl_io allocates for it.
    if bytes.len() >= 84 && !bytes.starts_with(b"solid") {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        if 84 + n * 50 != bytes.len() {
            return Err(IoError::at(
                file,
                "byte 80",
                IoErrorKind::count_mismatch(format!(
                    "binary STL declares {n} facets but has {} bytes",
                    bytes.len()
                )),
            ));
        }
    }
    let mut cursor = std::io::Cursor::new(bytes);
    let indexed =
        stl_io::read_stl(&mut cursor).map_err(|e| IoError::new(file, None, IoErrorKind::Stl(e)))?;
    let positions: Vec<DVec3> = indexed
        .vertices
        .iter()
        .map(|v| DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(IoError::at(
            file,
            format!("vertex {i}"),
            IoErrorKind::non_finite("non-finite coordinate"),
        ));
    }
    let n = positions.len();
    let mut triangles = Vec::with_capacity(indexed.faces.len());
    for (f, t) in indexed.faces.iter().enumerate() {
        if t.vertices.iter().any(|&i| i >= n) {
            return Err(IoError::at(
                file,
                format!("facet {f}"),
                IoErrorKind::index_out_of_range("vertex index out of range"),
            ));
        }
        triangles.push([
            t.vertices[0] as u32,
            t.vertices[1] as u32,
            t.vertices[2] as u32,
        ]);
    }
    Ok(super::weld_exact(TriMesh::new(positions, triangles)))
}
