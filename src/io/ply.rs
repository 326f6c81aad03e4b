//! PLY reader (ascii, binary little- and big-endian): vertices, polygon faces, triangle
//! strips and Stanford raw range grids. Handwritten so that every error can name a line or
//! byte offset and no declared count is trusted before it is checked against the file size.

use super::{IoError, LoadOptions, Loaded, RangeGrid};
use crate::mesh::TriMesh;
use glam::DVec3;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(s: &str) -> Option<Scalar> {
        Some(match s {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
}

#[derive(Clone, Copy, PartialEq, Debug)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    num_cols: Option<usize>,
    num_rows: Option<usize>,
    body_offset: usize,
    header_lines: usize,
}

fn parse_header(bytes: &[u8], file: &str) -> Result<Header, IoError> {
    let err =
        |line: usize, reason: String| IoError::new(file, Some(format!("line {line}")), reason);
    let end = find(bytes, b"end_header").ok_or_else(|| {
        IoError::new(
            file,
            None,
            "no end_header: not a PLY file or truncated header",
        )
    })?;
    let mut body_offset = end + b"end_header".len();
    // The header ends with "\n" or "\r\n".
    if bytes.get(body_offset) == Some(&b'\r') {
        body_offset += 1;
    }
    if bytes.get(body_offset) == Some(&b'\n') {
        body_offset += 1;
    }
    let text = std::str::from_utf8(&bytes[..end])
        .map_err(|_| IoError::new(file, None, "header is not text"))?;
    let mut lines = text.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err(err(1, "missing 'ply' magic".into()));
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let (mut num_cols, mut num_rows) = (None, None);
    let mut n = 1;
    for line in lines {
        n += 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [] => {}
            ["format", f, ..] => {
                encoding = Some(match *f {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::Little,
                    "binary_big_endian" => Encoding::Big,
                    other => return Err(err(n, format!("unknown format '{other}'"))),
                })
            }
            ["comment", ..] => {}
            ["obj_info", rest @ ..] => {
                if let [key, value, ..] = rest {
                    match *key {
                        "num_cols" => num_cols = value.parse().ok(),
                        "num_rows" => num_rows = value.parse().ok(),
                        _ => {}
                    }
                }
            }
            ["element", name, count] => {
                let count = count
                    .parse()
                    .map_err(|_| err(n, format!("bad element count '{count}'")))?;
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                });
            }
            ["property", "list", ct, it, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| err(n, "property before any element".into()))?;
                let ct = Scalar::parse(ct).ok_or_else(|| err(n, format!("unknown type '{ct}'")))?;
                let it = Scalar::parse(it).ok_or_else(|| err(n, format!("unknown type '{it}'")))?;
                e.props.push(Property::List(name.to_string(), ct, it));
            }
            ["property", ty, name] => {
                let e = elements
                    .last_mut()
                    .ok_or_else(|| err(n, "property before any element".into()))?;
                let ty = Scalar::parse(ty).ok_or_else(|| err(n, format!("unknown type '{ty}'")))?;
                e.props.push(Property::Scalar(name.to_string(), ty));
            }
            _ => return Err(err(n, format!("cannot read header line '{}'", line.trim()))),
        }
    }
    let encoding = encoding.ok_or_else(|| IoError::new(file, None, "header has no format line"))?;
    Ok(Header {
        encoding,
        elements,
        num_cols,
        num_rows,
        body_offset,
        header_lines: n + 1,
    })
}

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}

/// Reads values one at a time from the body, ascii or binary.
struct Body<'a> {
    bytes: &'a [u8],
    pos: usize,
    encoding: Encoding,
    line: usize,
    file: &'a str,
}

impl Body<'_> {
    fn where_(&self) -> String {
        match self.encoding {
            Encoding::Ascii => format!("line {}", self.line),
            _ => format!("byte {}", self.pos),
        }
    }

    fn error(&self, reason: impl Into<String>) -> IoError {
        IoError::new(self.file, Some(self.where_()), reason)
    }

    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn read(&mut self, ty: Scalar) -> Result<f64, IoError> {
        match self.encoding {
            Encoding::Ascii => {
                while let Some(&b) = self.bytes.get(self.pos) {
                    if b == b'\n' {
                        self.line += 1;
                    }
                    if !b.is_ascii_whitespace() {
                        break;
                    }
                    self.pos += 1;
                }
                let start = self.pos;
                while self.pos < self.bytes.len() && !self.bytes[self.pos].is_ascii_whitespace() {
                    self.pos += 1;
                }
                if start == self.pos {
                    return Err(self.error("unexpected end of file"));
                }
                let tok = std::str::from_utf8(&self.bytes[start..self.pos])
                    .map_err(|_| self.error("non-text number"))?;
                tok.parse::<f64>()
                    .map_err(|_| self.error(format!("'{tok}' is not a number")))
            }
            enc => {
                let n = ty.size();
                let b = self
                    .bytes
                    .get(self.pos..self.pos + n)
                    .ok_or_else(|| self.error("unexpected end of file"))?;
                let mut a = [0u8; 8];
                a[..n].copy_from_slice(b);
                if enc == Encoding::Big {
                    a[..n].reverse();
                }
                self.pos += n;
                Ok(decode_le(ty, a))
            }
        }
    }

    /// Binary little-endian elements made of scalars only, at fixed offsets with no
    /// per-value dispatch (the common layout of scanner output). Returns false, having
    /// consumed nothing, when a position is not finite: the general reader then reports it.
    fn fast_vertices(&mut self, e: &Element, xyz: [usize; 3], out: &mut Vec<DVec3>) -> bool {
        let mut offset = 0;
        let mut at = [(0, Scalar::F32); 3];
        for (k, p) in e.props.iter().enumerate() {
            let Property::Scalar(_, t) = p else {
                return false;
            };
            for (c, &i) in xyz.iter().enumerate() {
                if i == k {
                    at[c] = (offset, *t);
                }
            }
            offset += t.size();
        }
        let stride = offset;
        let Some(body) = self.bytes.get(self.pos..self.pos + stride * e.count) else {
            return false;
        };
        let start = out.len();
        for item in body.chunks_exact(stride.max(1)).take(e.count) {
            let [x, y, z] = at.map(|(o, t)| {
                let mut a = [0u8; 8];
                a[..t.size()].copy_from_slice(&item[o..o + t.size()]);
                decode_le(t, a)
            });
            let p = DVec3::new(x, y, z);
            if !p.is_finite() {
                out.truncate(start);
                return false;
            }
            out.push(p);
        }
        self.pos += stride * e.count;
        true
    }

    /// Binary little-endian faces that are only a `vertex_indices` list of 32-bit indices
    /// with an 8-bit count, all triangles with indices in range. Returns false, having
    /// consumed nothing, at anything else: the general reader then handles or reports it.
    fn fast_triangles(&mut self, e: &Element, vertices: usize, out: &mut Vec<[u32; 3]>) -> bool {
        let signed = match e.props.as_slice() {
            [Property::List(_, Scalar::U8, Scalar::I32)] => true,
            [Property::List(_, Scalar::U8, Scalar::U32)] => false,
            _ => return false,
        };
        let Some(body) = self.bytes.get(self.pos..self.pos + 13 * e.count) else {
            return false;
        };
        let start = out.len();
        out.reserve(e.count);
        for item in body.chunks_exact(13).take(e.count) {
            let index = |k: usize| {
                let b = [item[k], item[k + 1], item[k + 2], item[k + 3]];
                let x = if signed {
                    i64::from(i32::from_le_bytes(b))
                } else {
                    i64::from(u32::from_le_bytes(b))
                };
                (x >= 0 && (x as u64) < vertices as u64).then_some(x as u32)
            };
            match (item[0], index(1), index(5), index(9)) {
                (3, Some(a), Some(b), Some(c)) => out.push([a, b, c]),
                _ => {
                    out.truncate(start);
                    return false;
                }
            }
        }
        self.pos += 13 * e.count;
        true
    }

    /// Smallest number of bytes an element can occupy: bounds declared counts.
    fn min_element_bytes(&self, e: &Element) -> usize {
        let per: usize = e
            .props
            .iter()
            .map(|p| match (self.encoding, p) {
                (Encoding::Ascii, _) => 2,
                (_, Property::Scalar(_, t)) => t.size(),
                (_, Property::List(_, c, _)) => c.size(),
            })
            .sum();
        per.max(1)
    }
}

fn decode_le(ty: Scalar, a: [u8; 8]) -> f64 {
    match ty {
        Scalar::I8 => a[0] as i8 as f64,
        Scalar::U8 => a[0] as f64,
        Scalar::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
        Scalar::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
        Scalar::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        Scalar::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        Scalar::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        Scalar::F64 => f64::from_le_bytes(a),
    }
}

pub fn read_ply(bytes: &[u8], file: &str, opts: &LoadOptions) -> Result<Loaded, IoError> {
    let header = parse_header(bytes, file)?;
    let mut body = Body {
        bytes,
        pos: header.body_offset,
        encoding: header.encoding,
        line: header.header_lines,
        file,
    };
    let mut positions: Vec<DVec3> = Vec::new();
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    let mut grid_cells: Option<Vec<Option<u32>>> = None;
    let mut list = Vec::new();
    for e in &header.elements {
        let min = body.min_element_bytes(e);
        if e.count > body.remaining() / min {
            return Err(body.error(format!(
                "element '{}' declares {} entries but only {} bytes remain",
                e.name,
                e.count,
                body.remaining()
            )));
        }
        match e.name.as_str() {
            "vertex" => {
                let idx = |n: &str| {
                    e.props
                        .iter()
                        .position(|p| matches!(p, Property::Scalar(s, _) if s == n))
                };
                let (ix, iy, iz) = match (idx("x"), idx("y"), idx("z")) {
                    (Some(x), Some(y), Some(z)) => (x, y, z),
                    _ => return Err(body.error("vertex element lacks x, y or z")),
                };
                positions.reserve(e.count);
                if body.encoding == Encoding::Little
                    && body.fast_vertices(e, [ix, iy, iz], &mut positions)
                {
                    continue;
                }
                let mut vals = vec![0.0; e.props.len()];
                for v in 0..e.count {
                    for (k, p) in e.props.iter().enumerate() {
                        match p {
                            Property::Scalar(_, t) => vals[k] = body.read(*t)?,
                            Property::List(_, c, t) => {
                                let n = read_count(&mut body, *c)?;
                                for _ in 0..n {
                                    body.read(*t)?;
                                }
                            }
                        }
                    }
                    let p = DVec3::new(vals[ix], vals[iy], vals[iz]);
                    if !p.is_finite() {
                        return Err(body.error(format!("vertex {v} has a non-finite coordinate")));
                    }
                    positions.push(p);
                }
            }
            "face" | "tristrips" | "range_grid" => {
                let target = e
                    .props
                    .iter()
                    .position(|p| matches!(p, Property::List(n, _, _) if n == "vertex_indices" || n == "vertex_index"))
                    .ok_or_else(|| body.error(format!("element '{}' has no vertex_indices list", e.name)))?;
                if e.name == "range_grid" {
                    grid_cells = Some(Vec::with_capacity(e.count));
                }
                if e.name == "face"
                    && body.encoding == Encoding::Little
                    && body.fast_triangles(e, positions.len(), &mut triangles)
                {
                    continue;
                }
                for item in 0..e.count {
                    for (k, p) in e.props.iter().enumerate() {
                        match p {
                            Property::Scalar(_, t) => {
                                body.read(*t)?;
                            }
                            Property::List(_, c, t) => {
                                let n = read_count(&mut body, *c)?;
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
                    let check = |x: f64, body: &Body| -> Result<u32, IoError> {
                        if x >= 0.0 && x.fract() == 0.0 && (x as usize) < positions.len() {
                            Ok(x as u32)
                        } else {
                            Err(body.error(format!(
                                "{} {item}: vertex index {x} out of range (0..{})",
                                e.name,
                                positions.len()
                            )))
                        }
                    };
                    match e.name.as_str() {
                        "face" => {
                            if list.len() < 3 {
                                return Err(
                                    body.error(format!("face {item} has {} vertices", list.len()))
                                );
                            }
                            let first = check(list[0], &body)?;
                            for w in 1..list.len() - 1 {
                                triangles.push([
                                    first,
                                    check(list[w], &body)?,
                                    check(list[w + 1], &body)?,
                                ]);
                            }
                        }
                        "tristrips" => {
                            for run in list.split(|&x| x < 0.0) {
                                for w in 0..run.len().saturating_sub(2) {
                                    let (a, b, c) = (
                                        check(run[w], &body)?,
                                        check(run[w + 1], &body)?,
                                        check(run[w + 2], &body)?,
                                    );
                                    // Strips alternate winding; degenerate joins are dropped.
                                    if a != b && b != c && a != c {
                                        triangles.push(if w % 2 == 0 {
                                            [a, b, c]
                                        } else {
                                            [b, a, c]
                                        });
                                    }
                                }
                            }
                        }
                        _ => {
                            let cell = match list.first() {
                                Some(&x) => Some(check(x, &body)?),
                                None => None,
                            };
                            if let Some(g) = grid_cells.as_mut() {
                                g.push(cell);
                            }
                        }
                    }
                }
            }
            _ => {
                for _ in 0..e.count {
                    for p in &e.props {
                        match p {
                            Property::Scalar(_, t) => {
                                body.read(*t)?;
                            }
                            Property::List(_, c, t) => {
                                let n = read_count(&mut body, *c)?;
                                for _ in 0..n {
                                    body.read(*t)?;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    let grid = match grid_cells {
        Some(cells) => {
            let (cols, rows) = match (header.num_cols, header.num_rows) {
                (Some(c), Some(r)) if c * r == cells.len() => (c, r),
                _ => {
                    return Err(IoError::new(
                        file,
                        None,
                        format!(
                        "range_grid has {} cells but obj_info num_cols x num_rows does not match",
                        cells.len()
                    ),
                    ))
                }
            };
            let points: Vec<Option<DVec3>> = cells
                .iter()
                .map(|c| c.map(|i| positions[i as usize]))
                .collect();
            let grid = RangeGrid { rows, cols, points };
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

fn read_count(body: &mut Body, ty: Scalar) -> Result<usize, IoError> {
    let n = body.read(ty)?;
    if !(0.0..=1e9).contains(&n) || n.fract() != 0.0 {
        return Err(body.error(format!("bad list length {n}")));
    }
    let n = n as usize;
    // Each list item takes at least one byte: reject lengths the file cannot hold.
    if n > body.remaining() {
        return Err(body.error(format!("list of {n} items runs past the end of the file")));
    }
    Ok(n)
}

/// Triangulates a range image: each full 2x2 cell is split on its shorter diagonal, a cell
/// with three points gives one triangle, and triangles with an edge longer than
/// `max_edge_factor` times the median grid spacing (depth jumps) are dropped.
pub fn triangulate_range_grid(
    grid: &RangeGrid,
    cells: &[Option<u32>],
    max_edge_factor: f64,
) -> Vec<[u32; 3]> {
    let at = |r: usize, c: usize| cells[r * grid.cols + c];
    let pos = |r: usize, c: usize| grid.points[r * grid.cols + c];
    let mut spacing = Vec::new();
    for r in 0..grid.rows {
        for c in 0..grid.cols {
            if let Some(p) = pos(r, c) {
                if c + 1 < grid.cols {
                    if let Some(q) = pos(r, c + 1) {
                        spacing.push((p - q).length());
                    }
                }
                if r + 1 < grid.rows {
                    if let Some(q) = pos(r + 1, c) {
                        spacing.push((p - q).length());
                    }
                }
            }
        }
    }
    if spacing.is_empty() {
        return Vec::new();
    }
    let mid = spacing.len() / 2;
    let median = *spacing.select_nth_unstable_by(mid, f64::total_cmp).1;
    let max_edge = median * max_edge_factor;
    let mut tris = Vec::new();
    let mut push = |a: (usize, usize), b: (usize, usize), c: (usize, usize)| {
        if let (Some(ia), Some(ib), Some(ic), Some(pa), Some(pb), Some(pc)) = (
            at(a.0, a.1),
            at(b.0, b.1),
            at(c.0, c.1),
            pos(a.0, a.1),
            pos(b.0, b.1),
            pos(c.0, c.1),
        ) {
            if (pa - pb).length() <= max_edge
                && (pb - pc).length() <= max_edge
                && (pc - pa).length() <= max_edge
            {
                tris.push([ia, ib, ic]);
            }
        }
    };
    for r in 0..grid.rows.saturating_sub(1) {
        for c in 0..grid.cols.saturating_sub(1) {
            // Corners counter-clockwise in (col, row): a=(r,c) b=(r,c+1) d=(r+1,c+1) e=(r+1,c).
            let (a, b, d, e) = ((r, c), (r, c + 1), (r + 1, c + 1), (r + 1, c));
            let present = [a, b, d, e]
                .iter()
                .filter(|&&(r, c)| at(r, c).is_some())
                .count();
            match present {
                4 => {
                    let diag_ad = (pos(a.0, a.1).unwrap_or_default()
                        - pos(d.0, d.1).unwrap_or_default())
                    .length();
                    let diag_be = (pos(b.0, b.1).unwrap_or_default()
                        - pos(e.0, e.1).unwrap_or_default())
                    .length();
                    if diag_ad <= diag_be {
                        push(a, b, d);
                        push(a, d, e);
                    } else {
                        push(a, b, e);
                        push(b, d, e);
                    }
                }
                3 => {
                    let ring = [a, b, d, e];
                    let corners: Vec<(usize, usize)> = ring
                        .iter()
                        .copied()
                        .filter(|&(r, c)| at(r, c).is_some())
                        .collect();
                    push(corners[0], corners[1], corners[2]);
                }
                _ => {}
            }
        }
    }
    tris
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
