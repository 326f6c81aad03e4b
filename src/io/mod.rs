//! File formats. The only module that touches the filesystem for meshes.

pub mod glb;

use crate::mesh::TriMesh;
use glam::DVec3;
use std::path::Path;

/// A reader or writer failure, always naming the file and, where known, where in it.
#[derive(Debug, thiserror::Error)]
#[error("{file}{}: {reason}", location.as_ref().map(|l| format!(" ({l})")).unwrap_or_default())]
pub struct IoError {
    pub file: String,
    /// "line 12", "byte 4096", "element face 17": whatever the reader knows.
    pub location: Option<String>,
    pub reason: String,
}

impl IoError {
    pub fn new(
        file: impl Into<String>,
        location: Option<String>,
        reason: impl Into<String>,
    ) -> Self {
        Self {
            file: file.into(),
            location,
            reason: reason.into(),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    Obj,
    Gltf,
    Glb,
    Ply,
    Stl,
    Off,
}

impl Format {
    pub fn from_path(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "obj" => Format::Obj,
            "gltf" => Format::Gltf,
            "glb" => Format::Glb,
            "ply" => Format::Ply,
            "stl" => Format::Stl,
            "off" => Format::Off,
            _ => return None,
        })
    }
}

#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// Range grids: triangles with an edge longer than this multiple of the median grid
    /// spacing bridge depth jumps and are dropped.
    pub range_grid_max_edge_factor: f64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            range_grid_max_edge_factor: 6.0,
        }
    }
}

/// A raw range image: `rows x cols` cells, each holding a point or nothing.
#[derive(Clone, Debug)]
pub struct RangeGrid {
    pub rows: usize,
    pub cols: usize,
    pub points: Vec<Option<DVec3>>,
}

#[derive(Clone, Debug)]
pub struct Loaded {
    pub mesh: TriMesh,
    pub grid: Option<RangeGrid>,
}

/// Reads any supported mesh file, choosing the format by extension.
pub fn read_mesh_file(path: &Path, opts: &LoadOptions) -> Result<Loaded, IoError> {
    let _ = opts;
    Err(IoError::new(
        path.display().to_string(),
        None,
        "readers not built yet",
    ))
}

/// Reads a mesh held in memory (the pipe source); `name` is used in errors.
pub fn read_mesh_bytes(
    bytes: &[u8],
    format: Format,
    name: &str,
    opts: &LoadOptions,
) -> Result<Loaded, IoError> {
    let _ = (bytes, format, opts);
    Err(IoError::new(name, None, "readers not built yet"))
}

/// Writes a mesh, choosing the format by extension (obj, ply = binary little-endian, glb).
pub fn write_mesh_file(path: &Path, mesh: &TriMesh) -> Result<(), IoError> {
    match Format::from_path(path) {
        Some(Format::Glb) => glb::write_glb(path, mesh, &glb::GlbAttributes::default()),
        _ => Err(IoError::new(path.display().to_string(), None, "writer not built yet")),
    }
}
