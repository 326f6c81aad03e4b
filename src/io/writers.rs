//! OBJ and binary PLY writers (full f64 precision in both).

use super::{IoError, IoErrorKind};
use crate::mesh::TriMesh;
use std::io::Write;
use std::path::Path;

/// The mesh as OBJ text.
pub fn obj_bytes(mesh: &TriMesh) -> Vec<u8> {
    let mut out = Vec::with_capacity(mesh.positions.len() * 60 + mesh.triangles.len() * 24);
    out.extend_from_slice(b"# written by trispline\n");
    for p in &mesh.positions {
        // `{:?}` prints the shortest string that reads back to the same f64.
        let _ = writeln!(out, "v {:?} {:?} {:?}", p.x, p.y, p.z);
    }
    for t in &mesh.triangles {
        let _ = writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    out
}

/// The mesh as binary little-endian PLY.
pub fn ply_bytes(mesh: &TriMesh) -> Vec<u8> {
    let mut out = Vec::with_capacity(256 + mesh.positions.len() * 24 + mesh.triangles.len() * 13);
    let _ = write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment written by trispline\nelement vertex {}\nproperty double x\nproperty double y\nproperty double z\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangles.len()
    );
    for p in &mesh.positions {
        for c in [p.x, p.y, p.z] {
            out.extend_from_slice(&c.to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    out
}

fn write(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    std::fs::write(path, bytes)
        .map_err(|e| IoError::new(path.display().to_string(), None, IoErrorKind::Write(e)))
}

/// Writes the mesh as OBJ.
pub fn write_obj(path: &Path, mesh: &TriMesh) -> Result<(), IoError> {
    write(path, &obj_bytes(mesh))
}

pub(crate) fn write_ply(path: &Path, mesh: &TriMesh) -> Result<(), IoError> {
    write(path, &ply_bytes(mesh))
}
