//! PLY reader (ascii, binary little- and big-endian): vertices, polygon faces, triangle
//! strips and Stanford raw range grids. Handwritten so that every error can name a line or
//! byte offset and no declared count is trusted before it is checked against the file size.

mod body;
mod header;
mod range_grid;

use super::{IoError, IoErrorKind, LoadOptions, Loaded, RangeGrid};
use crate::mesh::TriMesh;
use body::{read_count, Body};
use glam::DVec3;
use header::{parse_header, Element, Encoding, Header, Property};
use range_grid::triangulate_range_grid;

/// Reads a PLY file held in memory; `file` names it in errors.
pub(crate) fn read_ply(bytes: &[u8], file: &str, opts: &LoadOptions) -> Result<Loaded, IoError> {
    let header = parse_header(bytes, file)?;
    let mut body = Body {
        bytes,
        pos: header.body_offset,
        encoding: header.encoding,
        line: header.body_first_line,
        file,
    };
    let mut positions: Vec<DVec3> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut grid_cells: Option<Vec<Option<u32>>> = None;
    for e in &header.elements {
        check_room(&body, e)?;
        match e.name.as_str() {
            "vertex" => {
                opts.check_vertices(positions.len().saturating_add(e.count), "element 'vertex'")
                    .map_err(|kind| body.error(kind))?;
                read_vertices(&mut body, e, &mut positions)?
            }
            "face" | "tristrips" | "range_grid" => {
                let cells = (e.name == "range_grid").then(|| grid_cells.insert(Vec::new()));
                read_index_lists(&mut body, e, positions.len(), opts, &mut triangles, cells)?
            }
            _ => skip_element(&mut body, e)?,
        }
    }
    let grid = match grid_cells {
        Some(cells) => {
            let grid = range_grid(&header, &cells, &positions, file)?;
            triangles.extend(triangulate_range_grid(
                &grid,
                &cells,
                opts.range_grid_max_edge_factor,
            ));
            Some(grid)
        }
        None => None,
    };
    Ok(Loaded {
        mesh: TriMesh::new(positions, triangles),
        grid,
    })
}

/// Refuses a declared element count the rest of the file cannot hold, before anything is
/// allocated for it.
fn check_room(body: &Body, e: &Element) -> Result<(), IoError> {
    let min = body.min_element_bytes(e);
    if e.count > body.remaining() / min {
        return Err(body.error(IoErrorKind::too_large(format!(
            "element '{}' declares {} entries but only {} bytes remain",
            e.name,
            e.count,
            body.remaining()
        ))));
    }
    Ok(())
}

/// The `vertex` element: x, y, z of every entry (other properties are read past).
fn read_vertices(body: &mut Body, e: &Element, positions: &mut Vec<DVec3>) -> Result<(), IoError> {
    let idx = |n: &str| {
        e.props
            .iter()
            .position(|p| matches!(p, Property::Scalar(s, _) if s == n))
    };
    let (ix, iy, iz) = match (idx("x"), idx("y"), idx("z")) {
        (Some(x), Some(y), Some(z)) => (x, y, z),
        _ => return Err(body.error(IoErrorKind::bad_header("vertex element lacks x, y or z"))),
    };
    positions.reserve(e.count);
    if body.encoding == Encoding::Little && body.fast_vertices(e, [ix, iy, iz], positions) {
        return Ok(());
    }
    let mut vals = vec![0.0; e.props.len()];
    for v in 0..e.count {
        for (k, p) in e.props.iter().enumerate() {
            match p {
                Property::Scalar(_, t) => vals[k] = body.read(*t)?,
                Property::List(_, c, t) => {
                    let n = read_count(body, *c)?;
                    for _ in 0..n {
                        body.read(*t)?;
                    }
                }
            }
        }
        let p = DVec3::new(vals[ix], vals[iy], vals[iz]);
        if !p.is_finite() {
            return Err(body.error(IoErrorKind::non_finite(format!(
                "vertex {v} has a non-finite coordinate"
            ))));
        }
        positions.push(p);
    }
    Ok(())
}

/// An element whose `vertex_indices` list gives connectivity: `face` (polygons, fanned),
/// `tristrips` (strips split at negative indices) or `range_grid` (one vertex or none per
/// cell, pushed to `grid_cells`). Lists are consumed value by value, never collected: a
/// list can be as long as the file.
fn read_index_lists(
    body: &mut Body,
    e: &Element,
    vertex_count: usize,
    opts: &LoadOptions,
    triangles: &mut Vec<[u32; 3]>,
    grid_cells: Option<&mut Vec<Option<u32>>>,
) -> Result<(), IoError> {
    let target = e
        .props
        .iter()
        .position(|p| matches!(p, Property::List(n, _, _) if n == "vertex_indices" || n == "vertex_index"))
        .ok_or_else(|| {
            body.error(IoErrorKind::bad_header(format!(
                "element '{}' has no vertex_indices list",
                e.name
            )))
        })?;
    // Declared counts that size allocations are checked before anything is reserved: a
    // face gives at least one triangle, a grid entry is one cell.
    let declared = match (e.name.as_str(), &grid_cells) {
        ("face", _) => opts.check_triangles(e.count, vertex_count, "element 'face'"),
        (_, Some(_)) => {
            let max = opts.max_grid_cells(vertex_count);
            if e.count > max {
                Err(IoErrorKind::too_large(format!(
                    "range_grid declares {} cells over {vertex_count} vertices, more than the budget of {max}",
                    e.count
                )))
            } else {
                Ok(())
            }
        }
        _ => Ok(()),
    };
    declared.map_err(|kind| body.error(kind))?;
    if e.name == "face"
        && body.encoding == Encoding::Little
        && body.fast_triangles(e, vertex_count, triangles)
    {
        return Ok(());
    }
    let connectivity = match e.name.as_str() {
        "face" => Connectivity::Face,
        "tristrips" => Connectivity::Strip,
        _ => Connectivity::Grid,
    };
    let mut sink = IndexSink {
        element: &e.name,
        connectivity,
        vertex_count,
        max_triangles: opts.max_triangles(vertex_count),
        triangles,
        grid_cells,
        item: 0,
        seen: 0,
        run: 0,
        first: 0,
        last: [0; 2],
        cell: None,
    };
    if let Some(g) = sink.grid_cells.as_mut() {
        g.reserve(e.count);
    }
    for item in 0..e.count {
        sink.start(item);
        read_target_list(body, e, target, &mut sink)?;
        sink.finish(body)?;
    }
    Ok(())
}

#[derive(Clone, Copy, PartialEq)]
enum Connectivity {
    Face,
    Strip,
    Grid,
}

/// Turns the indices of one list at a time into triangles or a grid cell as they are
/// read, holding only the indices a fan or strip still needs.
struct IndexSink<'a> {
    element: &'a str,
    connectivity: Connectivity,
    vertex_count: usize,
    max_triangles: usize,
    triangles: &'a mut Vec<[u32; 3]>,
    grid_cells: Option<&'a mut Vec<Option<u32>>>,
    /// The entry being read, and how many of its indices were seen.
    item: usize,
    seen: usize,
    /// Strips: indices since the last restart (negative index).
    run: usize,
    /// Faces: the fan's apex.
    first: u32,
    /// The two indices before the current one.
    last: [u32; 2],
    cell: Option<u32>,
}

impl IndexSink<'_> {
    fn start(&mut self, item: usize) {
        self.item = item;
        self.seen = 0;
        self.run = 0;
        self.cell = None;
    }

    fn index(&self, x: f64, body: &Body) -> Result<u32, IoError> {
        if x >= 0.0 && x.fract() == 0.0 && (x as usize) < self.vertex_count {
            Ok(x as u32)
        } else {
            Err(body.error(IoErrorKind::index_out_of_range(format!(
                "{} {}: vertex index {x} out of range (0..{})",
                self.element, self.item, self.vertex_count
            ))))
        }
    }

    fn push(&mut self, t: [u32; 3], body: &Body) -> Result<(), IoError> {
        if self.triangles.len() >= self.max_triangles {
            return Err(body.error(IoErrorKind::too_large(format!(
                "{} {}: more than {} triangles over {} vertices",
                self.element, self.item, self.max_triangles, self.vertex_count
            ))));
        }
        self.triangles.push(t);
        Ok(())
    }

    fn value(&mut self, x: f64, body: &Body) -> Result<(), IoError> {
        let seen = self.seen;
        self.seen += 1;
        match self.connectivity {
            Connectivity::Face => {
                let i = self.index(x, body)?;
                match seen {
                    0 => self.first = i,
                    1 => {}
                    _ => self.push([self.first, self.last[1], i], body)?,
                }
                self.last = [self.last[1], i];
            }
            Connectivity::Strip => {
                if x < 0.0 {
                    self.run = 0;
                    return Ok(());
                }
                let c = self.index(x, body)?;
                let [a, b] = self.last;
                // Strips alternate winding; degenerate joins are dropped.
                if self.run >= 2 && a != b && b != c && a != c {
                    let t = if self.run.is_multiple_of(2) {
                        [a, b, c]
                    } else {
                        [b, a, c]
                    };
                    self.push(t, body)?;
                }
                self.run += 1;
                self.last = [b, c];
            }
            Connectivity::Grid => {
                if seen == 0 {
                    self.cell = Some(self.index(x, body)?);
                }
            }
        }
        Ok(())
    }

    fn finish(&mut self, body: &Body) -> Result<(), IoError> {
        match self.connectivity {
            Connectivity::Face if self.seen < 3 => Err(body.error(IoErrorKind::malformed(
                format!("face {} has {} vertices", self.item, self.seen),
            ))),
            Connectivity::Grid => {
                if let Some(g) = self.grid_cells.as_mut() {
                    g.push(self.cell);
                }
                Ok(())
            }
            _ => Ok(()),
        }
    }
}

/// One entry of an index-list element: the values of property `target` go to `sink`,
/// every other property is read past.
fn read_target_list(
    body: &mut Body,
    e: &Element,
    target: usize,
    sink: &mut IndexSink,
) -> Result<(), IoError> {
    for (k, p) in e.props.iter().enumerate() {
        match p {
            Property::Scalar(_, t) => {
                body.read(*t)?;
            }
            Property::List(_, c, t) => {
                let n = read_count(body, *c)?;
                for _ in 0..n {
                    let x = body.read(*t)?;
                    if k == target {
                        sink.value(x, body)?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Any other element: read past, value by value (its size is not known in advance).
fn skip_element(body: &mut Body, e: &Element) -> Result<(), IoError> {
    for _ in 0..e.count {
        for p in &e.props {
            match p {
                Property::Scalar(_, t) => {
                    body.read(*t)?;
                }
                Property::List(_, c, t) => {
                    let n = read_count(body, *c)?;
                    for _ in 0..n {
                        body.read(*t)?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// The range image: the cells' vertices laid out as `obj_info num_cols x num_rows`.
fn range_grid(
    header: &Header,
    cells: &[Option<u32>],
    positions: &[DVec3],
    file: &str,
) -> Result<RangeGrid, IoError> {
    let (cols, rows) = match (header.num_cols, header.num_rows) {
        (Some(c), Some(r)) if c.checked_mul(r) == Some(cells.len()) => (c, r),
        _ => {
            return Err(IoError::new(
                file,
                None,
                IoErrorKind::count_mismatch(format!(
                    "range_grid has {} cells but obj_info num_cols x num_rows does not match",
                    cells.len()
                )),
            ))
        }
    };
    let points = cells
        .iter()
        .map(|c| c.map(|i| positions[i as usize]))
        .collect();
    Ok(RangeGrid { rows, cols, points })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A binary little-endian file: three float vertices (one possibly not finite) and
    /// faces given as index lists.
    fn binary(z2: f32, faces: &[&[i32]]) -> Vec<u8> {
        let mut b = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
            faces.len()
        )
        .into_bytes();
        for p in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, z2],
            [0.0, 1.0, 0.0],
        ] {
            for c in p {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        for f in faces {
            b.push(f.len() as u8);
            for i in *f {
                b.extend_from_slice(&i.to_le_bytes());
            }
        }
        b
    }

    #[test]
    fn fixed_layout_reading_matches_the_general_reader_and_leaves_it_the_odd_cases() {
        let opts = LoadOptions::default();
        let tris = read_ply(&binary(0.5, &[&[0, 1, 2], &[0, 2, 3]]), "t.ply", &opts)
            .expect("plain triangles");
        assert_eq!(tris.mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(tris.mesh.positions[2], DVec3::new(1.0, 1.0, 0.5));
        // A quad is fanned by the general reader, after the fixed layout gave up.
        let quad =
            read_ply(&binary(0.5, &[&[0, 1, 2], &[0, 1, 2, 3]]), "q.ply", &opts).expect("a quad");
        assert_eq!(quad.mesh.triangles, vec![[0, 1, 2], [0, 1, 2], [0, 2, 3]]);
        // Errors name the place the general reader finds them at.
        let e = read_ply(&binary(0.5, &[&[0, 1, 2], &[0, 9, 2]]), "r.ply", &opts)
            .expect_err("index out of range");
        assert!(
            e.to_string()
                .contains("face 1: vertex index 9 out of range"),
            "{e}"
        );
        let e = read_ply(&binary(f32::NAN, &[&[0, 1, 2]]), "n.ply", &opts).expect_err("not finite");
        assert!(
            e.to_string()
                .contains("vertex 2 has a non-finite coordinate"),
            "{e}"
        );
    }
}
