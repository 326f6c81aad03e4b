//! OBJ through tobj: all groups and objects merged, polygons triangulated, and only the
//! position indices used, so UV or normal seams never split a vertex.

use super::IoError;
use crate::mesh::TriMesh;
use glam::DVec3;

pub fn read_obj(bytes: &[u8], file: &str) -> Result<TriMesh, IoError> {
    let opts = tobj::LoadOptions {
        single_index: false,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let mut reader = std::io::BufReader::new(bytes);
    let (models, _) = tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed))
        .map_err(|e| IoError::new(file, None, format!("OBJ parse error: {e}")))?;
    // tobj gives each model its own position array; models that share positions in the file
    // are therefore re-indexed into one array.
    let mut mesh = TriMesh::default();
    for m in &models {
        let off = mesh.positions.len() as u32;
        let p = &m.mesh.positions;
        if p.len() % 3 != 0 {
            return Err(IoError::new(file, None, format!("object '{}' has a partial vertex", m.name)));
        }
        for c in p.chunks_exact(3) {
            let v = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
            if !v.is_finite() {
                return Err(IoError::new(file, Some(format!("object '{}'", m.name)), "non-finite vertex coordinate"));
            }
            mesh.positions.push(v);
        }
        let n = (p.len() / 3) as u32;
        for (f, t) in m.mesh.indices.chunks(3).enumerate() {
            if t.len() < 3 || t.iter().any(|&i| i >= n) {
                return Err(IoError::new(file, Some(format!("object '{}' face {f}", m.name)), "vertex index out of range"));
            }
            mesh.triangles.push([t[0] + off, t[1] + off, t[2] + off]);
        }
    }
    // tobj re-indexes positions per object, so vertices shared by two objects arrive twice;
    // welding exact duplicates keeps such objects connected. A single object is left as is.
    Ok(if models.len() > 1 { super::weld_exact(mesh) } else { mesh })
}
