//! ASCII point clouds: `.xyz` and `.pts`, one point per line as `x y z` followed by any
//! number of extra columns (normals, colour, intensity), which are read past. Values may be
//! separated by spaces, tabs, commas or semicolons (scanner software writes all four). A
//! first content line holding a single integer is a point count (`.pts` always has one,
//! some `.xyz` exporters write one too); it is checked against the bytes left and the
//! budgets before anything is reserved, and against the points actually present at the end.
//! Lines starting with `#` or `//` are comments.
//!
//! Handwritten: no well-kept crate reads these (they are hardly formats), and ours gives the
//! same line-numbered, typed errors as the other readers.

use super::{IoError, IoErrorKind, LoadOptions};
use crate::mesh::TriMesh;
use glam::DVec3;

/// The shortest line a point can take (`0 0 0\n`): a declared count above the bytes left
/// divided by it cannot be honest.
const MIN_POINT_LINE_BYTES: usize = 6;

/// Reads an ASCII point cloud held in memory; `file` names it in errors. The result has
/// no triangles: a point cloud.
pub(crate) fn read_xyz(bytes: &[u8], file: &str, opts: &LoadOptions) -> Result<TriMesh, IoError> {
    let text = super::text::decode(bytes, file)?;
    let at = |line: usize, kind: IoErrorKind| IoError::at(file, format!("line {line}"), kind);
    let mut positions: Vec<DVec3> = Vec::new();
    let mut declared: Option<(usize, usize)> = None;
    let mut content_lines = 0usize;
    let mut offset = 0usize;
    for (k, raw) in text.split_inclusive('\n').enumerate() {
        let line_no = k + 1;
        offset += raw.len();
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') || line.starts_with("//") {
            continue;
        }
        content_lines += 1;
        let mut values = line
            .split(|c: char| c.is_ascii_whitespace() || c == ',' || c == ';')
            .filter(|t| !t.is_empty());
        let first = values.next().unwrap_or_default();
        if content_lines == 1 {
            if let Some(count) = count_line(first, values.clone().next()) {
                check_declared(count, text.len() - offset, opts).map_err(|e| at(line_no, e))?;
                positions.reserve(count);
                declared = Some((count, line_no));
                continue;
            }
        }
        let mut xyz = [0.0; 3];
        let mut columns = 0;
        for (c, token) in std::iter::once(first).chain(values).take(3).enumerate() {
            xyz[c] = token.parse::<f64>().map_err(|_| {
                at(
                    line_no,
                    IoErrorKind::malformed(format!("'{token}' is not a number")),
                )
            })?;
            columns = c + 1;
        }
        if columns < 3 {
            return Err(at(
                line_no,
                IoErrorKind::malformed(format!(
                    "a point needs x y z, this line has {columns} value(s)"
                )),
            ));
        }
        let p = DVec3::from_array(xyz);
        if !p.is_finite() {
            return Err(at(
                line_no,
                IoErrorKind::non_finite(format!(
                    "point {} has a non-finite coordinate",
                    positions.len()
                )),
            ));
        }
        if positions.len() >= opts.max_vertices {
            return Err(at(
                line_no,
                IoErrorKind::too_large(format!(
                    "more than the limit of {} points",
                    opts.max_vertices
                )),
            ));
        }
        positions.push(p);
    }
    if content_lines == 0 {
        return Err(IoError::new(file, None, IoErrorKind::Empty));
    }
    if let Some((count, line)) = declared {
        let found = positions.len();
        if found < count {
            return Err(at(
                line,
                IoErrorKind::truncated(format!(
                    "declares {count} points but the file ends after {found}"
                )),
            ));
        }
        if found > count {
            return Err(at(
                line,
                IoErrorKind::count_mismatch(format!("declares {count} points but holds {found}")),
            ));
        }
    }
    Ok(TriMesh::new(positions, Vec::new()))
}

/// A line holding one non-negative integer and nothing else is a point count.
fn count_line(first: &str, second: Option<&str>) -> Option<usize> {
    if second.is_some() || first.is_empty() || !first.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    // A count too large for usize is still a count: refused as too large, not as a point.
    Some(first.parse::<usize>().unwrap_or(usize::MAX))
}

/// Refuses a declared count above the budget or above what the bytes left could hold.
fn check_declared(count: usize, bytes_left: usize, opts: &LoadOptions) -> Result<(), IoErrorKind> {
    opts.check_vertices(count, "the point count")?;
    let room = bytes_left / MIN_POINT_LINE_BYTES + 1;
    if count > room {
        return Err(IoErrorKind::too_large(format!(
            "declares {count} points but only {bytes_left} bytes remain (room for at most {room})"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Result<TriMesh, IoError> {
        read_xyz(text.as_bytes(), "t.xyz", &LoadOptions::default())
    }

    #[test]
    fn separators_comments_and_extra_columns() {
        let m = read("# x y z r g b\n1 2 3 255 0 0\n4,5,6\n\n7;8;9;0.5\n// end\n")
            .expect("three points");
        assert_eq!(
            m.positions,
            vec![
                DVec3::new(1.0, 2.0, 3.0),
                DVec3::new(4.0, 5.0, 6.0),
                DVec3::new(7.0, 8.0, 9.0)
            ]
        );
        assert!(m.triangles.is_empty());
    }

    #[test]
    fn a_count_line_is_checked_both_ways() {
        assert_eq!(read("2\n0 0 0\n1 1 1\n").expect("ok").positions.len(), 2);
        assert_eq!(
            read("3\n0 0 0\n1 1 1\n").expect_err("short").kind(),
            "truncated"
        );
        assert_eq!(
            read("1\n0 0 0\n1 1 1\n").expect_err("long").kind(),
            "count_mismatch"
        );
        let e = read("99999999\n0 0 0\n").expect_err("no room");
        assert_eq!(e.kind(), "too_large");
        assert!(e.to_string().starts_with("t.xyz (line 1)"), "{e}");
    }
}
