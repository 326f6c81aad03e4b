//! glTF 2.0 / GLB: every triangle primitive of every mesh node, with world transforms.

use super::{IoError, IoErrorKind, LoadOptions};
use crate::mesh::TriMesh;
use glam::{DMat4, DVec3};
use std::panic::AssertUnwindSafe;
use std::path::Path;

const COMPRESSED: [&str; 3] = [
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
];

/// `base` is the folder for external buffers of a .gltf file (None for in-memory input).
///
/// The `gltf` crate's readers panic on some inconsistent files (an index accessor of a
/// float type, strides shorter than an element); every accessor read is validated first,
/// and a panic that still escapes the crate is caught and reported as a malformed file.
pub(crate) fn read_gltf(
    bytes: &[u8],
    file: &str,
    base: Option<&Path>,
    opts: &LoadOptions,
) -> Result<TriMesh, IoError> {
    let e = |kind: IoErrorKind| IoError::new(file, None, kind);
    let read = std::panic::catch_unwind(AssertUnwindSafe(|| {
        let gltf = parse_validated(bytes)?;
        let buffers = load_buffers(&gltf, base, opts, bytes.len() as u64)?;
        collect_mesh(&gltf, &buffers, opts)
    }));
    match read {
        Ok(result) => result.map_err(e),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            Err(e(IoErrorKind::malformed(format!(
                "inconsistent glTF (the glTF reader failed: {what})"
            ))))
        }
    }
}

/// Parses and validates the document. The `gltf` crate's own validation indexes
/// `accessors` with a primitive's POSITION index unchecked (gltf-json 1.4.1, mesh.rs:151),
/// so attribute, index and morph-target accessor indices are bounds-checked first.
fn parse_validated(bytes: &[u8]) -> Result<gltf::Gltf, IoErrorKind> {
    check_glb_header(bytes)?;
    let unvalidated = gltf::Gltf::from_slice_without_validation(bytes)
        .map_err(|e| version_one(bytes).unwrap_or(IoErrorKind::Gltf(e)))?;
    let mut json = unvalidated.document.into_json();
    // Before the validation, which a compressed primitive fails (its accessors have no
    // buffer view) with a message that does not name the compression.
    for ext in json.extensions_required.iter().chain(&json.extensions_used) {
        if COMPRESSED.contains(&ext.as_str()) {
            return Err(IoErrorKind::unsupported(format!(
                "compressed meshes ({ext}) are not supported; export without compression"
            )));
        }
    }
    let accessors = json.accessors.len();
    for (m, mesh) in json.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            let targets = primitive
                .targets
                .iter()
                .flatten()
                .flat_map(|t| [t.positions, t.normals, t.tangents].into_iter().flatten());
            let referenced = primitive
                .attributes
                .values()
                .copied()
                .chain(primitive.indices)
                .chain(targets);
            for index in referenced {
                if index.value() >= accessors {
                    return Err(IoErrorKind::malformed(format!(
                        "mesh {m} primitive {p} names accessor {} of {accessors}",
                        index.value()
                    )));
                }
            }
        }
    }
    supply_position_bounds(&mut json);
    let document = gltf::Document::from_json(json).map_err(IoErrorKind::Gltf)?;
    Ok(gltf::Gltf {
        document,
        blob: unvalidated.blob,
    })
}

/// Gives every POSITION accessor without a valid `min` and `max` a placeholder pair. The
/// specification requires both, so the `gltf` crate refuses a document without them; but
/// they only bound the data, some exporters leave them out (assimp's test models have such
/// files), viewers read such files, and this reader never looks at them: it takes the
/// positions themselves (non-finite ones are refused there).
fn supply_position_bounds(json: &mut gltf::json::Root) {
    let positions: Vec<usize> = json
        .meshes
        .iter()
        .flat_map(|m| &m.primitives)
        .filter_map(|p| {
            p.attributes.get(&gltf::json::validation::Checked::Valid(
                gltf::json::mesh::Semantic::Positions,
            ))
        })
        .map(|a| a.value())
        .collect();
    let valid = |bound: &Option<gltf::json::Value>| {
        bound
            .as_ref()
            .is_some_and(|b| serde_json::from_value::<[f32; 3]>(b.clone()).is_ok())
    };
    for index in positions {
        if let Some(accessor) = json.accessors.get_mut(index) {
            if !valid(&accessor.min) || !valid(&accessor.max) {
                accessor.min = Some(serde_json::json!([0.0, 0.0, 0.0]));
                accessor.max = Some(serde_json::json!([0.0, 0.0, 0.0]));
            }
        }
    }
}

/// Why a document the `gltf` crate cannot parse is refused, when it is glTF 1.0 (a GLB of
/// version 1, or JSON whose `asset.version` is "1.0"): its schema differs throughout (maps
/// of objects where 2.0 has arrays), and the crate's message ("invalid type: map,
/// expected a sequence") does not say so.
fn version_one(bytes: &[u8]) -> Option<IoErrorKind> {
    let unsupported = || {
        IoErrorKind::unsupported(
            "glTF 1.0 is not supported (glTF 2.0 only); convert the file to glTF 2.0",
        )
    };
    if bytes.starts_with(b"glTF") {
        return (bytes.get(4..8)? == 1u32.to_le_bytes()).then(unsupported);
    }
    // Only `asset.version` is kept: every other field is skipped unallocated, so a large
    // embedded document costs a scan, not a second copy as a JSON tree.
    #[derive(serde::Deserialize)]
    struct Head {
        asset: Asset,
    }
    #[derive(serde::Deserialize)]
    struct Asset {
        // A string by the specification; early 1.0 exporters (collada2gltf) wrote 1.
        version: serde_json::Value,
    }
    let head: Head = serde_json::from_slice(bytes).ok()?;
    let one = match &head.asset.version {
        serde_json::Value::String(v) => v.starts_with("1.") || v == "1",
        serde_json::Value::Number(v) => v.as_f64().is_some_and(|v| v < 2.0),
        _ => false,
    };
    one.then(unsupported)
}

/// The `gltf` crate subtracts the 12-byte header from the GLB's declared total length
/// unchecked (gltf 1.4.1, binary.rs:252): a declared length under 12 is refused here.
fn check_glb_header(bytes: &[u8]) -> Result<(), IoErrorKind> {
    const HEADER_BYTES: u32 = 12;
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    let Some(length) = bytes.get(8..12) else {
        return Err(IoErrorKind::malformed(
            "GLB header is shorter than 12 bytes",
        ));
    };
    let declared = u32::from_le_bytes([length[0], length[1], length[2], length[3]]);
    if declared < HEADER_BYTES {
        return Err(IoErrorKind::malformed(format!(
            "GLB header declares a total length of {declared} bytes, less than the header itself"
        )));
    }
    Ok(())
}

/// The data of every buffer, external ones read from beside the file. The input and its
/// external buffers share one `max_file_bytes` budget; sizes are checked before reading,
/// and no more than the declared length is ever read.
fn load_buffers(
    gltf: &gltf::Gltf,
    base: Option<&Path>,
    opts: &LoadOptions,
    input_bytes: u64,
) -> Result<Vec<Vec<u8>>, IoErrorKind> {
    let mut budget = opts.max_file_bytes.saturating_sub(input_bytes);
    let mut buffers = Vec::new();
    for b in gltf.buffers() {
        let declared = b.length() as u64;
        let data = match b.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| IoErrorKind::malformed("GLB has no binary chunk"))?,
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let b64 = rest
                        .split_once(";base64,")
                        .map(|x| x.1)
                        .ok_or_else(|| IoErrorKind::unsupported("unsupported data URI"))?;
                    decode_base64(b64)
                        .ok_or_else(|| IoErrorKind::malformed("bad base64 in data URI"))?
                } else {
                    if declared > budget {
                        return Err(IoErrorKind::too_large(format!(
                            "buffer {} declares {declared} bytes; {budget} remain of the {}-byte input limit",
                            b.index(),
                            opts.max_file_bytes
                        )));
                    }
                    let data = read_external(base, uri, declared)?;
                    budget -= data.len() as u64;
                    data
                }
            }
        };
        if (data.len() as u64) < declared {
            return Err(IoErrorKind::count_mismatch(format!(
                "buffer {} is {} bytes, declared {declared}",
                b.index(),
                data.len(),
            )));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// An external buffer: a relative path inside the .gltf's folder (no `..`, no absolute
/// path, no symlink leading out), of which the first `declared` bytes are read.
fn read_external(base: Option<&Path>, uri: &str, declared: u64) -> Result<Vec<u8>, IoErrorKind> {
    use std::io::Read;
    use std::path::Component;
    let dir = base.ok_or_else(|| {
        IoErrorKind::unsupported(format!(
            "external buffer '{uri}' cannot be resolved for streamed input; embed it (.glb or a data URI)"
        ))
    })?;
    let dir = if dir.as_os_str().is_empty() {
        Path::new(".")
    } else {
        dir
    };
    let relative = Path::new(uri);
    let confined = !uri.contains('\\')
        && !uri.contains(':')
        && relative
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    let outside = || {
        IoErrorKind::unsupported(format!(
            "buffer URI '{uri}' leaves the .gltf file's folder; external buffers must sit beside it"
        ))
    };
    if !confined {
        return Err(outside());
    }
    let external = |source: std::io::Error| IoErrorKind::ExternalBuffer {
        uri: uri.to_string(),
        source,
    };
    let path = dir.join(relative);
    let (real_dir, real_path) = (
        dir.canonicalize().map_err(external)?,
        path.canonicalize().map_err(external)?,
    );
    if !real_path.starts_with(&real_dir) {
        return Err(outside());
    }
    let f = std::fs::File::open(&real_path).map_err(external)?;
    let len = f.metadata().map_err(external)?.len();
    if !f.metadata().map_err(external)?.is_file() {
        return Err(external(std::io::Error::other("not a regular file")));
    }
    if len < declared {
        return Err(IoErrorKind::count_mismatch(format!(
            "buffer '{uri}' is {len} bytes, declared {declared}"
        )));
    }
    let mut data = Vec::with_capacity(declared as usize);
    f.take(declared).read_to_end(&mut data).map_err(external)?;
    Ok(data)
}

/// Every triangle primitive of every mesh node, with world transforms, within the
/// vertex and triangle budgets (a mesh instanced by many nodes is copied per node).
fn collect_mesh(
    gltf: &gltf::Gltf,
    buffers: &[Vec<u8>],
    opts: &LoadOptions,
) -> Result<TriMesh, IoErrorKind> {
    let mut found = Primitives::default();
    let scenes: Vec<gltf::Scene> = gltf.scenes().collect();
    let roots: Vec<Vec<gltf::Node>> = if scenes.is_empty() {
        // No scene: take every node as a root of one implicit scene.
        vec![gltf.nodes().collect()]
    } else {
        scenes.iter().map(|s| s.nodes().collect()).collect()
    };
    // glTF requires the node hierarchy to be disjoint strict trees. A node met twice in one
    // scene is a cycle or a shared child: refused, since following it would repeat the
    // subtree without end (or exponentially). Scenes may share nodes; a node an earlier
    // scene already placed is skipped so the merged mesh does not hold it twice.
    let mut placed_by: Vec<Option<usize>> = vec![None; gltf.nodes().len()];
    for (scene, scene_roots) in roots.into_iter().enumerate() {
        let mut stack: Vec<(gltf::Node, DMat4)> = scene_roots
            .into_iter()
            .map(|n| (n, DMat4::IDENTITY))
            .collect();
        while let Some((node, parent)) = stack.pop() {
            match placed_by.get(node.index()).copied().flatten() {
                Some(s) if s == scene => {
                    return Err(IoErrorKind::malformed(format!(
                        "node {} is reached twice: the node hierarchy has a cycle or a shared child",
                        node.index()
                    )));
                }
                Some(_) => continue,
                None => {}
            }
            if let Some(slot) = placed_by.get_mut(node.index()) {
                *slot = Some(scene);
            }
            let m = node.transform().matrix();
            let local = DMat4::from_cols_array_2d(&m.map(|c| c.map(|x| x as f64)));
            let world = parent * local;
            if let Some(gm) = node.mesh() {
                for prim in gm.primitives() {
                    add_primitive(
                        &mut found,
                        &prim,
                        gm.name().unwrap_or(""),
                        world,
                        buffers,
                        opts,
                    )?;
                }
            }
            stack.extend(node.children().map(|c| (c, world)));
        }
    }
    found.into_mesh()
}

/// What the scene's primitives hold: triangles, points, and how many line primitives.
#[derive(Default)]
struct Primitives {
    mesh: TriMesh,
    points: Vec<DVec3>,
    lines: usize,
}

impl Primitives {
    /// The triangles; a scene of points only is a point cloud (a mesh without triangles,
    /// as a PLY of vertices only), and one of lines only has nothing to fit.
    fn into_mesh(self) -> Result<TriMesh, IoErrorKind> {
        if !self.mesh.triangles.is_empty() {
            if !self.points.is_empty() {
                tracing::warn!(
                    points = self.points.len(),
                    "glTF point primitives beside triangles are not fitted"
                );
            }
            return Ok(self.mesh);
        }
        if !self.points.is_empty() {
            return Ok(TriMesh::new(self.points, Vec::new()));
        }
        if self.lines > 0 {
            return Err(IoErrorKind::unsupported(format!(
                "the scene holds {} line primitive(s) (LINES, LINE_LOOP, LINE_STRIP) and no \
                 triangles or points: no surface to fit",
                self.lines
            )));
        }
        Ok(self.mesh)
    }
}

fn add_primitive(
    found: &mut Primitives,
    prim: &gltf::Primitive,
    mesh_name: &str,
    world: DMat4,
    buffers: &[Vec<u8>],
    opts: &LoadOptions,
) -> Result<(), IoErrorKind> {
    use gltf::accessor::{DataType, Dimensions};
    use gltf::mesh::Mode;
    let mode = prim.mode();
    if matches!(mode, Mode::Lines | Mode::LineLoop | Mode::LineStrip) {
        found.lines += 1;
        return Ok(());
    }
    let (mesh, points) = (&mut found.mesh, &mut found.points);
    let positions = prim.get(&gltf::Semantic::Positions).ok_or_else(|| {
        IoErrorKind::malformed(format!("mesh '{mesh_name}' primitive without positions"))
    })?;
    check_accessor(
        &positions,
        buffers,
        &[DataType::F32],
        Dimensions::Vec3,
        "POSITION",
    )?;
    let vertex_total = (mesh.positions.len() + points.len()).saturating_add(positions.count());
    opts.check_vertices(vertex_total, "the glTF scene")?;
    let index_count = match prim.indices() {
        Some(a) => {
            let types = [DataType::U8, DataType::U16, DataType::U32];
            check_accessor(&a, buffers, &types, Dimensions::Scalar, "indices")?;
            a.count()
        }
        None => positions.count(),
    };
    let new_triangles = match mode {
        Mode::Points => 0,
        Mode::Triangles => index_count / 3,
        _ => index_count.saturating_sub(2),
    };
    opts.check_triangles(
        mesh.triangles.len().saturating_add(new_triangles),
        vertex_total,
        "the glTF scene",
    )?;
    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
    let pos: Vec<DVec3> = reader
        .read_positions()
        .ok_or_else(|| {
            IoErrorKind::malformed(format!("mesh '{mesh_name}' primitive without positions"))
        })?
        .map(|p| world.transform_point3(DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)))
        .collect();
    if pos.iter().any(|p| !p.is_finite()) {
        return Err(IoErrorKind::non_finite("non-finite vertex coordinate"));
    }
    let idx: Vec<u32> = match reader.read_indices() {
        Some(i) => i.into_u32().collect(),
        None => (0..pos.len() as u32).collect(),
    };
    if idx.iter().any(|&i| i as usize >= pos.len()) {
        return Err(IoErrorKind::index_out_of_range(
            "index out of range in a primitive",
        ));
    }
    if mode == Mode::Points {
        points.extend(idx.iter().map(|&i| pos[i as usize]));
        return Ok(());
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
    Ok(())
}

/// What the `gltf` crate's accessor iterator assumes without checking: a buffer view, an
/// element type it can decode, a stride no shorter than an element, and every element
/// inside the view and the view inside its buffer.
fn check_accessor(
    a: &gltf::Accessor,
    buffers: &[Vec<u8>],
    types: &[gltf::accessor::DataType],
    dimensions: gltf::accessor::Dimensions,
    what: &str,
) -> Result<(), IoErrorKind> {
    let bad = |why: String| IoErrorKind::malformed(format!("{what} accessor {}: {why}", a.index()));
    if a.sparse().is_some() {
        return Err(IoErrorKind::unsupported(format!(
            "{what} accessor {}: sparse accessors are not supported",
            a.index()
        )));
    }
    if !types.contains(&a.data_type()) || a.dimensions() != dimensions {
        return Err(bad(format!(
            "type {:?} {:?} is not allowed here",
            a.data_type(),
            a.dimensions()
        )));
    }
    let view = a.view().ok_or_else(|| bad("no buffer view".into()))?;
    let size = a.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(bad(format!(
            "stride {stride} is shorter than an element ({size} bytes)"
        )));
    }
    let buffer_len = buffers.get(view.buffer().index()).map_or(0, Vec::len);
    let view_end = view.offset().checked_add(view.length());
    if view_end.is_none_or(|end| end > buffer_len) {
        return Err(bad("buffer view runs past its buffer".into()));
    }
    // glTF requires count >= 1, and the `gltf` crate's readers compute `count - 1`
    // unchecked (gltf 1.4.1, accessor/util.rs:384).
    if a.count() == 0 {
        return Err(bad("count 0 (glTF requires at least one element)".into()));
    }
    let end = (a.count() - 1)
        .checked_mul(stride)
        .and_then(|x| x.checked_add(size))
        .and_then(|x| x.checked_add(a.offset()));
    if end.is_none_or(|end| end > view.length()) {
        return Err(bad(format!(
            "{} elements run past the buffer view",
            a.count()
        )));
    }
    Ok(())
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
