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
            "vertex" => read_vertices(&mut body, e, &mut positions)?,
            "face" | "tristrips" | "range_grid" => {
                let cells = (e.name == "range_grid").then(|| grid_cells.insert(Vec::new()));
                read_index_lists(&mut body, e, positions.len(), &mut triangles, cells)?
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
/// cell, pushed to `grid_cells`).
fn read_index_lists(
    body: &mut Body,
    e: &Element,
    vertex_count: usize,
    triangles: &mut Vec<[u32; 3]>,
    mut grid_cells: Option<&mut Vec<Option<u32>>>,
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
    if let Some(g) = grid_cells.as_mut() {
        g.reserve(e.count);
    }
    if e.name == "face"
        && body.encoding == Encoding::Little
        && body.fast_triangles(e, vertex_count, triangles)
    {
        return Ok(());
    }
    let mut list = Vec::new();
    for item in 0..e.count {
        read_target_list(body, e, target, &mut list)?;
        let check = |x: f64, body: &Body| -> Result<u32, IoError> {
            if x >= 0.0 && x.fract() == 0.0 && (x as usize) < vertex_count {
                Ok(x as u32)
            } else {
                Err(body.error(IoErrorKind::index_out_of_range(format!(
                    "{} {item}: vertex index {x} out of range (0..{vertex_count})",
                    e.name,
                ))))
            }
        };
        match e.name.as_str() {
            "face" => {
                if list.len() < 3 {
                    return Err(body.error(IoErrorKind::malformed(format!(
                        "face {item} has {} vertices",
                        list.len()
                    ))));
                }
                let first = check(list[0], body)?;
                for w in 1..list.len() - 1 {
                    triangles.push([first, check(list[w], body)?, check(list[w + 1], body)?]);
                }
            }
            "tristrips" => {
                for run in list.split(|&x| x < 0.0) {
                    for w in 0..run.len().saturating_sub(2) {
                        let (a, b, c) = (
                            check(run[w], body)?,
                            check(run[w + 1], body)?,
                            check(run[w + 2], body)?,
                        );
                        // Strips alternate winding; degenerate joins are dropped.
                        if a != b && b != c && a != c {
                            triangles.push(if w % 2 == 0 { [a, b, c] } else { [b, a, c] });
                        }
                    }
                }
            }
            _ => {
                let cell = match list.first() {
                    Some(&x) => Some(check(x, body)?),
                    None => None,
                };
                if let Some(g) = grid_cells.as_mut() {
                    g.push(cell);
                }
            }
        }
    }
    Ok(())
}

/// One entry of an index-list element: the values of property `target` go to `list`,
/// every other property is read past.
fn read_target_list(
    body: &mut Body,
    e: &Element,
    target: usize,
    list: &mut Vec<f64>,
) -> Result<(), IoError> {
    for (k, p) in e.props.iter().enumerate() {
        match p {
            Property::Scalar(_, t) => {
                body.read(*t)?;
            }
            Property::List(_, c, t) => {
                let n = read_count(body, *c)?;
                list.clear();
                for _ in 0..n {
                    let x = body.read(*t)?;
                    if k == target {
                        list.push(x);
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
