//! STL (ascii and binary) through stl_io; coincident corners are welded on exact equality
//! because binary STL repeats every vertex per facet.

use super::{IoError, IoErrorKind};
use crate::mesh::TriMesh;
use glam::DVec3;

pub(crate) fn read_stl(bytes: &[u8], file: &str) -> Result<TriMesh, IoError> {
    // A binary STL states its facet count, and its size follows from it. That decides,
    // not the first bytes: many CAD exporters begin a binary file's free 80-byte header
    // with "solid", which stl_io takes for ascii and then fails to parse.
    if let Some(facets) = binary_facets(bytes) {
        return read_binary(bytes, facets, file);
    }
    let Some(ascii) = ascii_text(bytes) else {
        let Some(declared) = declared_facets(bytes) else {
            return Err(IoError::new(
                file,
                None,
                IoErrorKind::truncated(format!(
                    "neither ascii nor binary STL: {} bytes, shorter than a binary header",
                    bytes.len()
                )),
            ));
        };
        return Err(IoError::at(
            file,
            "byte 80",
            IoErrorKind::count_mismatch(format!(
                "binary STL declares {declared} facets but has {} bytes",
                bytes.len()
            )),
        ));
    };
    let mut cursor = std::io::Cursor::new(ascii.as_ref());
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

/// Bytes of a binary STL: the 80-byte header, the facet count, then per facet its normal,
/// three corners (f32 each) and a 2-byte attribute.
const BINARY_HEADER_BYTES: usize = 84;
const BINARY_FACET_BYTES: usize = 50;

/// The facet count a binary STL header states, if `bytes` are long enough to hold one.
fn declared_facets(bytes: &[u8]) -> Option<usize> {
    match bytes.get(80..BINARY_HEADER_BYTES)? {
        &[a, b, c, d] => Some(u32::from_le_bytes([a, b, c, d]) as usize),
        _ => None,
    }
}

/// The facet count of a binary STL whose size matches it, if `bytes` is one.
fn binary_facets(bytes: &[u8]) -> Option<usize> {
    let n = declared_facets(bytes)?;
    let size = n
        .checked_mul(BINARY_FACET_BYTES)?
        .checked_add(BINARY_HEADER_BYTES)?;
    (size == bytes.len()).then_some(n)
}

/// A binary STL's facets, read here because stl_io has no binary-only entry point: its
/// reader probes for ascii first (see `read_stl`).
fn read_binary(bytes: &[u8], facets: usize, file: &str) -> Result<TriMesh, IoError> {
    let mut positions = Vec::with_capacity(3 * facets);
    let body = &bytes[BINARY_HEADER_BYTES..];
    for (f, facet) in body.chunks_exact(BINARY_FACET_BYTES).enumerate() {
        // The stored normal (the first 12 bytes) is ignored: the winding decides.
        for corner in facet[12..48].chunks_exact(12) {
            let c = |k: usize| {
                f32::from_le_bytes([corner[k], corner[k + 1], corner[k + 2], corner[k + 3]])
            };
            let p = DVec3::new(c(0) as f64, c(4) as f64, c(8) as f64);
            if !p.is_finite() {
                return Err(IoError::at(
                    file,
                    format!("facet {f}"),
                    IoErrorKind::non_finite("non-finite coordinate"),
                ));
            }
            positions.push(p);
        }
    }
    let triangles = (0..facets as u32)
        .map(|f| [3 * f, 3 * f + 1, 3 * f + 2])
        .collect();
    Ok(super::weld_exact(TriMesh::new(positions, triangles)))
}

/// The bytes of an ascii STL as stl_io reads them, if `bytes` is one: its first line
/// must be `solid <name>` there, while exporters also write a bare `solid`, a tab after
/// it, leading blanks or capitals; such a first line is replaced by one stl_io reads.
/// `None` for bytes that are no ascii STL.
fn ascii_text(bytes: &[u8]) -> Option<std::borrow::Cow<'_, [u8]>> {
    let line_end = bytes
        .iter()
        .position(|&b| b == b'\n')
        .unwrap_or(bytes.len());
    let first = bytes[..line_end].trim_ascii_start();
    let solid = first.get(..5)?.eq_ignore_ascii_case(b"solid");
    if !solid || first.get(5).is_some_and(|b| !b.is_ascii_whitespace()) {
        return None;
    }
    // A binary file that begins with "solid" but does not match its facet count (a
    // truncated one) holds NUL bytes in its floats and attributes; text never does.
    if bytes.contains(&0) {
        return None;
    }
    if bytes.starts_with(b"solid ") {
        return Some(std::borrow::Cow::Borrowed(bytes));
    }
    let rest = bytes.get(line_end..).unwrap_or_default();
    Some(std::borrow::Cow::Owned(
        [b"solid stl".as_slice(), rest].concat(),
    ))
}
