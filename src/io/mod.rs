//! File formats. The only module that touches the filesystem for meshes.
#![warn(missing_docs)]

mod error;
pub mod glb;
pub(crate) mod gltf_reader;
pub mod iges;
pub mod obj;
pub mod off;
mod pcd;
pub mod ply;
pub mod polylines;
pub mod registration;
pub mod step;
pub mod stl;
pub mod surface_json;
mod text;
pub mod writers;
mod xyz;

pub use error::{IoError, IoErrorKind};

use crate::mesh::TriMesh;
use glam::DVec3;
use std::path::Path;

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
/// A mesh file format, named by its extension.
pub enum Format {
    /// Wavefront OBJ.
    Obj,
    /// glTF 2.0 JSON (buffers embedded or beside the file).
    Gltf,
    /// Binary glTF.
    Glb,
    /// PLY, ascii or binary, with Stanford range grids.
    Ply,
    /// STL, ascii or binary.
    Stl,
    /// Object File Format.
    Off,
    /// ASCII point cloud: `x y z` per line, extra columns read past.
    Xyz,
    /// ASCII point cloud with a count line first (Leica and other scanners' export).
    Pts,
    /// The Point Cloud Library's format (ascii or binary).
    Pcd,
}

impl Format {
    /// Every extension read, as the refusals of unknown ones list them.
    pub const READABLE: &'static str = "obj, gltf, glb, ply, stl, off, xyz, pts, pcd";

    pub(crate) fn from_path(path: &Path) -> Option<Format> {
        Self::from_extension(path.extension()?.to_str()?)
    }

    /// The format an extension (without its dot, any case) names.
    pub fn from_extension(ext: &str) -> Option<Format> {
        Some(match ext.to_ascii_lowercase().as_str() {
            "obj" => Format::Obj,
            "gltf" => Format::Gltf,
            "glb" => Format::Glb,
            "ply" => Format::Ply,
            "stl" => Format::Stl,
            "off" => Format::Off,
            "xyz" => Format::Xyz,
            "pts" => Format::Pts,
            "pcd" => Format::Pcd,
            _ => return None,
        })
    }
}

#[derive(Clone, Debug)]
/// Options of the mesh readers, with the budgets every declared count is checked against
/// before anything is allocated for it.
pub struct LoadOptions {
    /// Range grids: triangles with an edge longer than this multiple of the median grid
    /// spacing bridge depth jumps and are dropped.
    pub range_grid_max_edge_factor: f64,
    /// Most vertices a mesh may have (the daemon's `daemon.max_vertices`).
    pub max_vertices: usize,
    /// Largest input in bytes, external glTF buffers included (`daemon.max_file_bytes`).
    pub max_file_bytes: u64,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            range_grid_max_edge_factor: 6.0,
            // The daemon's shipped defaults (config/default.toml).
            max_vertices: 5_000_000,
            max_file_bytes: 512 << 20,
        }
    }
}

/// Triangles per vertex a mesh may have. Closed manifold meshes have about two; eight
/// leaves room for soups of duplicated faces while a strip or polygon of 10^8 indices
/// over three vertices (10^8 triangles, 1.2 GB) is refused at the 25th.
const TRIANGLES_PER_VERTEX: usize = 8;
/// Range-grid cells per vertex: Stanford scans fill one cell in two to five; sixteen
/// allows sparse scans while 10^8 empty cells over a few vertices (40 bytes per cell once
/// gridded) are refused from the header.
const GRID_CELLS_PER_VERTEX: usize = 16;
/// Small meshes and grids are never refused by the per-vertex ratios.
const SMALL_ALLOWANCE: usize = 1 << 12;

impl LoadOptions {
    /// Options with the daemon's limits (and the default range-grid edge factor).
    pub fn with_limits(max_file_bytes: u64, max_vertices: usize) -> Self {
        Self {
            max_file_bytes,
            max_vertices,
            ..Self::default()
        }
    }

    /// Most triangles a mesh of `vertices` vertices may have.
    pub(crate) fn max_triangles(&self, vertices: usize) -> usize {
        TRIANGLES_PER_VERTEX
            .saturating_mul(vertices.min(self.max_vertices))
            .saturating_add(SMALL_ALLOWANCE)
    }

    /// Most range-grid cells an image over `vertices` vertices may have.
    pub(crate) fn max_grid_cells(&self, vertices: usize) -> usize {
        GRID_CELLS_PER_VERTEX
            .saturating_mul(vertices.min(self.max_vertices))
            .saturating_add(SMALL_ALLOWANCE)
    }

    /// Refuses `vertices` above `max_vertices`.
    pub(crate) fn check_vertices(&self, vertices: usize, what: &str) -> Result<(), IoErrorKind> {
        if vertices > self.max_vertices {
            return Err(IoErrorKind::too_large(format!(
                "{what}: {vertices} vertices exceed the limit of {}",
                self.max_vertices
            )));
        }
        Ok(())
    }

    /// Refuses `triangles` above the budget of a mesh of `vertices` vertices.
    pub(crate) fn check_triangles(
        &self,
        triangles: usize,
        vertices: usize,
        what: &str,
    ) -> Result<(), IoErrorKind> {
        let max = self.max_triangles(vertices);
        if triangles > max {
            return Err(IoErrorKind::too_large(format!(
                "{what}: {triangles} triangles over {vertices} vertices exceed the budget of {max}"
            )));
        }
        Ok(())
    }

    /// Refuses an input of `bytes` bytes above `max_file_bytes`.
    pub(crate) fn check_file_bytes(&self, bytes: u64, what: &str) -> Result<(), IoErrorKind> {
        if bytes > self.max_file_bytes {
            return Err(IoErrorKind::too_large(format!(
                "{what} is {bytes} bytes, more than the limit of {}",
                self.max_file_bytes
            )));
        }
        Ok(())
    }
}

/// A raw range image: `rows x cols` cells, each holding a point or nothing.
#[derive(Clone, Debug)]
pub struct RangeGrid {
    /// Rows of the image.
    pub rows: usize,
    /// Columns of the image.
    pub cols: usize,
    /// Cell (r, c) at `r * cols + c`.
    pub points: Vec<Option<DVec3>>,
}

#[derive(Clone, Debug)]
/// A mesh or point cloud as read, with the range image it came from, if any.
pub struct Loaded {
    /// The triangles (range grids: triangulated from the image). A point cloud (`.xyz`,
    /// `.pts`, `.pcd`, a PLY or OBJ with vertices only) is a mesh without triangles: the
    /// worker triangulates it (`remesh::points`) and fits its points.
    pub mesh: TriMesh,
    /// The range image of a Stanford range-grid PLY.
    pub grid: Option<RangeGrid>,
}

impl Loaded {
    /// True for a point cloud: vertices and no triangle.
    pub fn is_point_cloud(&self) -> bool {
        self.mesh.triangles.is_empty()
    }
}

/// Reads any supported mesh file, choosing the format by extension.
pub fn read_mesh_file(path: &Path, opts: &LoadOptions) -> Result<Loaded, IoError> {
    let name = path.display().to_string();
    let format = Format::from_path(path).ok_or_else(|| {
        IoError::new(
            &name,
            None,
            IoErrorKind::UnknownExtension(
                "unknown extension (obj, gltf, glb, ply, stl, off, xyz, pts, pcd)",
            ),
        )
    })?;
    let bytes = read_limited(path, opts.max_file_bytes, "the file")
        .map_err(|kind| IoError::new(&name, None, kind))?;
    read_with_base(&bytes, format, &name, opts, path.parent())
}

/// Reads a whole file after checking its size against `max_bytes`, and never more than
/// `max_bytes` even if it grows meanwhile (a file being written, `/dev/zero`).
pub(crate) fn read_limited(
    path: &Path,
    max_bytes: u64,
    what: &str,
) -> Result<Vec<u8>, IoErrorKind> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(IoErrorKind::Open)?;
    let len = file.metadata().map_err(IoErrorKind::Open)?.len();
    if len > max_bytes {
        return Err(IoErrorKind::too_large(format!(
            "{what} is {len} bytes, more than the limit of {max_bytes}"
        )));
    }
    let mut bytes = Vec::with_capacity(len as usize);
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(IoErrorKind::Open)?;
    if bytes.len() as u64 > max_bytes {
        return Err(IoErrorKind::too_large(format!(
            "{what} grew past the limit of {max_bytes} bytes while being read"
        )));
    }
    Ok(bytes)
}

/// Reads a mesh held in memory (the pipe source); `name` is used in errors.
pub fn read_mesh_bytes(
    bytes: &[u8],
    format: Format,
    name: &str,
    opts: &LoadOptions,
) -> Result<Loaded, IoError> {
    read_with_base(bytes, format, name, opts, None)
}

/// Reads the bytes of a file that lies in `folder` (read by the caller, e.g. to hash them
/// first): a `.gltf`'s external buffers are resolved there, and only there.
pub fn read_mesh_bytes_in(
    bytes: &[u8],
    format: Format,
    name: &str,
    opts: &LoadOptions,
    folder: &Path,
) -> Result<Loaded, IoError> {
    read_with_base(bytes, format, name, opts, Some(folder))
}

/// `read_mesh_bytes` (no `base`) or `read_mesh_bytes_in` (`base`: the file's folder).
pub(crate) fn read_with_base(
    bytes: &[u8],
    format: Format,
    name: &str,
    opts: &LoadOptions,
    base: Option<&Path>,
) -> Result<Loaded, IoError> {
    if bytes.is_empty() {
        return Err(IoError::new(name, None, IoErrorKind::Empty));
    }
    opts.check_file_bytes(bytes.len() as u64, "the input")
        .map_err(|kind| IoError::new(name, None, kind))?;
    let plain = |mesh: TriMesh| Loaded { mesh, grid: None };
    let loaded = match format {
        Format::Ply => ply::read_ply(bytes, name, opts)?,
        Format::Obj => plain(obj::read_obj(bytes, name, opts)?),
        Format::Off => plain(off::read_off(bytes, name, opts)?),
        Format::Stl => plain(stl::read_stl(bytes, name)?),
        Format::Gltf | Format::Glb => plain(gltf_reader::read_gltf(bytes, name, base, opts)?),
        Format::Xyz | Format::Pts => plain(xyz::read_xyz(bytes, name, opts)?),
        Format::Pcd => plain(pcd::read_pcd(bytes, name, opts)?),
    };
    if loaded.mesh.positions.is_empty() {
        return Err(IoError::new(name, None, IoErrorKind::NoVertices));
    }
    // Readers whose counts are not declared up front (OBJ, STL) are bounded by the input
    // size while reading; the budgets still hold for what they return.
    let (v, t) = (loaded.mesh.positions.len(), loaded.mesh.triangles.len());
    opts.check_vertices(v, "the mesh")
        .and_then(|()| opts.check_triangles(t, v, "the mesh"))
        .map_err(|kind| IoError::new(name, None, kind))?;
    Ok(loaded)
}

/// Merges vertices with bit-identical coordinates (and drops none otherwise).
pub(crate) fn weld_exact(mesh: TriMesh) -> TriMesh {
    let mut map = std::collections::HashMap::with_capacity(mesh.positions.len());
    let mut positions = Vec::new();
    let remap: Vec<u32> = mesh
        .positions
        .iter()
        .map(|p| {
            let key = [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()];
            *map.entry(key).or_insert_with(|| {
                positions.push(*p);
                (positions.len() - 1) as u32
            })
        })
        .collect();
    let triangles = mesh
        .triangles
        .iter()
        .map(|t| {
            [
                remap[t[0] as usize],
                remap[t[1] as usize],
                remap[t[2] as usize],
            ]
        })
        .collect();
    TriMesh::new(positions, triangles)
}

/// Writes a mesh, choosing the format by extension (obj, ply = binary little-endian, glb).
pub fn write_mesh_file(path: &Path, mesh: &TriMesh) -> Result<(), IoError> {
    match Format::from_path(path) {
        Some(Format::Glb) => glb::write_glb(path, mesh, &glb::GlbAttributes::default()),
        Some(Format::Obj) => writers::write_obj(path, mesh),
        Some(Format::Ply) => writers::write_ply(path, mesh),
        _ => Err(IoError::new(
            path.display().to_string(),
            None,
            IoErrorKind::UnknownExtension("can write .obj, .ply or .glb only"),
        )),
    }
}

/// Temp files for outputs. `tempfile` creates 0600 by default (right for secrets, wrong for
/// results another user's viewer or CAD station must open); asking for 0666 at creation
/// lets the kernel apply the process umask exactly as for a plain `File::create`
/// (0644 under 022, 0600 under 077) without reading or changing the umask.
fn output_temp_builder() -> tempfile::Builder<'static, 'static> {
    let mut builder = tempfile::Builder::new();
    builder.prefix(".trispline-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder
}

/// Writes through a temp file in the same folder: write, fsync, rename, fsync the folder,
/// so that readers see the old complete file or the new complete one, never a partial one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    use std::io::Write;
    let name = path.display().to_string();
    let err = |e: std::io::Error| IoError::new(&name, None, IoErrorKind::Write(e));
    let dir = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = output_temp_builder().tempfile_in(dir).map_err(err)?;
    tmp.write_all(bytes).map_err(err)?;
    tmp.as_file().sync_all().map_err(err)?;
    tmp.persist(path).map_err(|e| err(e.error))?;
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    Ok(())
}

/// Several files of one folder made visible in the given order (the last one as the commit
/// marker): every temp file is written and fsynced (concurrently, so the syncs overlap),
/// then all are renamed in order and the folder is fsynced once. Each file on its own is
/// old-complete or new-complete after a crash, as with `write_atomic`, and the last one is
/// only durable together with the others because they share the folder's one fsync.
pub(crate) fn write_atomic_group(dir: &Path, files: &[(&str, &[u8])]) -> Result<(), IoError> {
    use std::io::Write;
    let err = |name: &str, e: std::io::Error| {
        IoError::new(
            dir.join(name).display().to_string(),
            None,
            IoErrorKind::Write(e),
        )
    };
    let temps: Vec<Result<tempfile::NamedTempFile, IoError>> = std::thread::scope(|scope| {
        let handles: Vec<_> = files
            .iter()
            .map(|&(name, bytes)| {
                scope.spawn(move || {
                    let mut tmp = output_temp_builder()
                        .tempfile_in(dir)
                        .map_err(|e| err(name, e))?;
                    tmp.write_all(bytes).map_err(|e| err(name, e))?;
                    tmp.as_file().sync_all().map_err(|e| err(name, e))?;
                    Ok(tmp)
                })
            })
            .collect();
        handles
            .into_iter()
            .zip(files)
            .map(|(h, (name, _))| {
                h.join().unwrap_or_else(|_| {
                    Err(err(name, std::io::Error::other("writer thread panicked")))
                })
            })
            .collect()
    });
    let mut ready = Vec::with_capacity(temps.len());
    for t in temps {
        // An error drops every temp file: nothing of this group becomes visible.
        ready.push(t?);
    }
    for (tmp, (name, _)) in ready.into_iter().zip(files) {
        tmp.persist(dir.join(name))
            .map_err(|e| err(name, e.error))?;
    }
    std::fs::File::open(dir)
        .and_then(|d| d.sync_all())
        .map_err(|e| err("", e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn kind_of(bytes: &[u8], format: Format) -> &'static str {
        match read_mesh_bytes(bytes, format, "t", &LoadOptions::default()) {
            Ok(_) => "ok",
            Err(e) => e.kind(),
        }
    }

    #[test]
    fn readers_report_a_kind_per_failure_and_keep_the_file_and_place_in_the_message() {
        let ply_header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
        let cases: [(&[u8], Format, &str); 9] = [
            (b"", Format::Off, "empty"),
            (b"OFF\n3 1 0\n0 0 0\n1 0 0\n", Format::Off, "truncated"),
            (
                b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
                Format::Off,
                "index_out_of_range",
            ),
            (b"OFF\n99999 1 0\n", Format::Off, "too_large"),
            (b"v 0 0 nan\n", Format::Obj, "non_finite"),
            (b"v 0 0 x\n", Format::Obj, "malformed"),
            (b"v 0 0 0\n\x00\x01", Format::Obj, "not_text"),
            (
                b"ply\nformat ascii 1.0\nelement vertex 1\nproperty int8x x\nend_header\n",
                Format::Ply,
                "bad_header",
            ),
            (b"{", Format::Gltf, "gltf"),
        ];
        for (bytes, format, kind) in cases {
            assert_eq!(
                kind_of(bytes, format),
                kind,
                "{}",
                String::from_utf8_lossy(bytes)
            );
        }
        let ply = format!("{ply_header}0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n");
        let e = read_mesh_bytes(
            ply.as_bytes(),
            Format::Ply,
            "scan.ply",
            &LoadOptions::default(),
        )
        .expect_err("index 5 of 3 vertices");
        assert_eq!(e.kind(), "index_out_of_range");
        assert!(
            e.to_string()
                .starts_with("scan.ply (line 13): face 0: vertex index 5"),
            "{e}"
        );
        let missing = read_mesh_file(Path::new("/nonexistent/x.ply"), &LoadOptions::default())
            .expect_err("no such file");
        assert_eq!(missing.kind(), "open");
        assert!(std::error::Error::source(&missing.kind).is_some());
        let unknown =
            read_mesh_file(Path::new("x.e57"), &LoadOptions::default()).expect_err("no reader");
        assert_eq!(unknown.kind(), "unknown_extension");
    }
}
