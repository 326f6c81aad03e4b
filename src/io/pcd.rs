//! PCD (the Point Cloud Library's format, v0.7 headers; v0.6 files read the same): a text
//! header of `FIELDS`, `SIZE`, `TYPE`, `COUNT`, `WIDTH`, `HEIGHT`, `VIEWPOINT`, `POINTS`
//! and `DATA` lines, then the points as text (`ascii`) or packed records (`binary`, in the
//! writer's byte order, which PCL leaves little-endian on every platform it runs on).
//! `binary_compressed` (LZF, fields stored column by column) is refused as unsupported.
//!
//! Only `x`, `y` and `z` are read; every other field (normals, rgb, intensity, curvature)
//! is read past. PCL marks the missing points of organized clouds (`HEIGHT` > 1, Kinect-like
//! images) with NaN in all three coordinates: those are skipped, as PCL's own
//! `removeNaNFromPointCloud` does. Any other non-finite coordinate is an error.
//!
//! Handwritten: the crates that read PCD (`pcd-rs`) allocate from declared counts before
//! checking them against the file, and give no line or byte in their errors.

use super::{IoError, IoErrorKind, LoadOptions};
use crate::mesh::TriMesh;
use glam::DVec3;

/// One field of a record: its byte size, type letter and element count.
#[derive(Clone, Copy, Debug)]
struct Field {
    size: usize,
    kind: u8,
    count: usize,
}

/// What the header says about the body.
struct Header {
    fields: Vec<(String, Field)>,
    points: usize,
    data: Data,
    /// Byte offset of the body.
    body: usize,
    /// Line number of the first body line (ascii error locations).
    body_line: usize,
}

#[derive(Clone, Copy, PartialEq)]
enum Data {
    Ascii,
    Binary,
}

/// Reads a PCD file held in memory; `file` names it in errors. The result has no
/// triangles: a point cloud.
pub(crate) fn read_pcd(bytes: &[u8], file: &str, opts: &LoadOptions) -> Result<TriMesh, IoError> {
    let header = parse_header(bytes, file)?;
    let at_header = |kind| IoError::at(file, format!("line {}", header.body_line - 1), kind);
    opts.check_vertices(header.points, "POINTS")
        .map_err(at_header)?;
    let xyz = ["x", "y", "z"].map(|name| {
        let mut offset = 0;
        let mut value = 0;
        for (n, f) in &header.fields {
            if n == name && f.count == 1 {
                return Some((offset, value, *f));
            }
            offset += f.size * f.count;
            value += f.count;
        }
        None
    });
    let [Some(x), Some(y), Some(z)] = xyz else {
        return Err(at_header(IoErrorKind::bad_header(
            "FIELDS has no x, y and z of COUNT 1",
        )));
    };
    let body = &bytes[header.body.min(bytes.len())..];
    let mut positions = Vec::new();
    match header.data {
        Data::Binary => {
            let stride: usize = header.fields.iter().map(|(_, f)| f.size * f.count).sum();
            let need = stride.saturating_mul(header.points);
            if need > body.len() {
                return Err(IoError::at(
                    file,
                    format!("byte {}", header.body),
                    IoErrorKind::truncated(format!(
                        "POINTS {} of {stride} bytes need {need} bytes but {} remain",
                        header.points,
                        body.len()
                    )),
                ));
            }
            positions.reserve(header.points);
            for (i, record) in body
                .chunks_exact(stride.max(1))
                .take(header.points)
                .enumerate()
            {
                let [px, py, pz] = [x, y, z].map(|(offset, _, f)| decode(&record[offset..], f));
                let at = || format!("byte {}", header.body + i * stride);
                push_point(&mut positions, DVec3::new(px, py, pz), i)
                    .map_err(|kind| IoError::at(file, at(), kind))?;
            }
        }
        Data::Ascii => {
            read_ascii(body, &header, [x.1, y.1, z.1], file, &mut positions)?;
        }
    }
    Ok(TriMesh::new(positions, Vec::new()))
}

/// The ascii body: one point per line, every field's values in order.
fn read_ascii(
    body: &[u8],
    header: &Header,
    xyz: [usize; 3],
    file: &str,
    positions: &mut Vec<DVec3>,
) -> Result<(), IoError> {
    let text = std::str::from_utf8(body)
        .map_err(|_| IoError::new(file, None, IoErrorKind::NotText { what: "the body" }))?;
    let values: usize = header.fields.iter().map(|(_, f)| f.count).sum();
    // Each value takes at least two bytes ("0 "): more points than that cannot be there.
    let room = body.len() / (2 * values.max(1)) + 1;
    if header.points > room {
        return Err(IoError::at(
            file,
            format!("line {}", header.body_line - 1),
            IoErrorKind::too_large(format!(
                "POINTS {} but only {} bytes remain",
                header.points,
                body.len()
            )),
        ));
    }
    positions.reserve(header.points);
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    for i in 0..header.points {
        let Some((k, line)) = lines.next() else {
            return Err(IoError::new(
                file,
                None,
                IoErrorKind::truncated(format!(
                    "POINTS {} but the file ends after {i}",
                    header.points
                )),
            ));
        };
        let at = |kind| IoError::at(file, format!("line {}", header.body_line + k), kind);
        let tokens: Vec<&str> = line.split_ascii_whitespace().take(values + 1).collect();
        if tokens.len() != values {
            return Err(at(IoErrorKind::malformed(format!(
                "point {i} has {}{} values, FIELDS and COUNT give {values}",
                tokens.len(),
                if tokens.len() > values { "+" } else { "" }
            ))));
        }
        let mut p = [0.0; 3];
        for (c, &v) in xyz.iter().enumerate() {
            p[c] = tokens[v].parse::<f64>().map_err(|_| {
                at(IoErrorKind::malformed(format!(
                    "'{}' is not a number",
                    tokens[v]
                )))
            })?;
        }
        push_point(positions, DVec3::from_array(p), i).map_err(at)?;
    }
    if let Some((k, _)) = lines.next() {
        return Err(IoError::at(
            file,
            format!("line {}", header.body_line + k),
            IoErrorKind::count_mismatch(format!(
                "more points than POINTS {} declares",
                header.points
            )),
        ));
    }
    Ok(())
}

/// Keeps a finite point, skips PCL's missing-point marker (all three NaN) and refuses
/// anything else that is not finite.
fn push_point(positions: &mut Vec<DVec3>, p: DVec3, index: usize) -> Result<(), IoErrorKind> {
    if p.is_finite() {
        positions.push(p);
        Ok(())
    } else if p.is_nan_mask().all() {
        Ok(())
    } else {
        Err(IoErrorKind::non_finite(format!(
            "point {index} has a non-finite coordinate"
        )))
    }
}

/// One little-endian value of a field (its first element).
fn decode(bytes: &[u8], f: Field) -> f64 {
    let mut a = [0u8; 8];
    a[..f.size].copy_from_slice(&bytes[..f.size]);
    match (f.kind, f.size) {
        (b'F', 4) => f64::from(f32::from_le_bytes([a[0], a[1], a[2], a[3]])),
        (b'F', _) => f64::from_le_bytes(a),
        (b'I', 1) => f64::from(a[0] as i8),
        (b'I', 2) => f64::from(i16::from_le_bytes([a[0], a[1]])),
        (b'I', 4) => f64::from(i32::from_le_bytes([a[0], a[1], a[2], a[3]])),
        (b'I', _) => i64::from_le_bytes(a) as f64,
        (_, 1) => f64::from(a[0]),
        (_, 2) => f64::from(u16::from_le_bytes([a[0], a[1]])),
        (_, 4) => f64::from(u32::from_le_bytes([a[0], a[1], a[2], a[3]])),
        _ => u64::from_le_bytes(a) as f64,
    }
}

/// The header, line by line up to and including `DATA`.
fn parse_header(bytes: &[u8], file: &str) -> Result<Header, IoError> {
    let mut names: Option<Vec<String>> = None;
    let mut sizes: Option<Vec<usize>> = None;
    let mut kinds: Option<Vec<u8>> = None;
    let mut counts: Option<Vec<usize>> = None;
    let (mut width, mut height, mut points) = (None, None, None);
    let mut pos = 0;
    let mut line_no = 0;
    while pos < bytes.len() {
        line_no += 1;
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |k| pos + k + 1);
        let raw = &bytes[pos..end];
        pos = end;
        let err = |kind| IoError::at(file, format!("line {line_no}"), kind);
        let line = std::str::from_utf8(raw)
            .map_err(|_| err(IoErrorKind::NotText { what: "the header" }))?
            .trim();
        let bad = |detail: String| err(IoErrorKind::bad_header(detail));
        let mut words = line.split_ascii_whitespace();
        let Some(key) = words.next() else { continue };
        if key.starts_with('#') {
            continue;
        }
        let rest: Vec<&str> = words.collect();
        let number = |w: &str| {
            w.parse::<usize>()
                .map_err(|_| bad(format!("{key}: '{w}' is not a count")))
        };
        match key.to_ascii_uppercase().as_str() {
            "VERSION" | "VIEWPOINT" => {}
            "FIELDS" | "COLUMNS" => names = Some(rest.iter().map(|s| s.to_string()).collect()),
            "SIZE" => {
                let s = rest
                    .iter()
                    .map(|w| number(w))
                    .collect::<Result<Vec<_>, _>>()?;
                if let Some(b) = s.iter().find(|&&b| ![1, 2, 4, 8].contains(&b)) {
                    return Err(bad(format!("SIZE {b}: fields are 1, 2, 4 or 8 bytes")));
                }
                sizes = Some(s);
            }
            "TYPE" => {
                let mut k = Vec::with_capacity(rest.len());
                for w in &rest {
                    match w.as_bytes() {
                        [t @ (b'F' | b'I' | b'U')] => k.push(*t),
                        _ => return Err(bad(format!("TYPE '{w}': expected F, I or U"))),
                    }
                }
                kinds = Some(k);
            }
            "COUNT" => counts = Some(rest.iter().map(|w| number(w)).collect::<Result<_, _>>()?),
            "WIDTH" | "HEIGHT" | "POINTS" => {
                let [w] = rest.as_slice() else {
                    return Err(bad(format!("{key} takes one count")));
                };
                let n = Some(number(w)?);
                match key.to_ascii_uppercase().as_str() {
                    "WIDTH" => width = n,
                    "HEIGHT" => height = n,
                    _ => points = n,
                }
            }
            "DATA" => {
                let data = match rest.first().copied() {
                    Some("ascii") => Data::Ascii,
                    Some("binary") => Data::Binary,
                    Some("binary_compressed") => {
                        return Err(err(IoErrorKind::unsupported(
                            "PCD DATA binary_compressed (LZF) is not supported: save the cloud as binary or ascii (PCL: pcl_convert_pcd_ascii_binary, Open3D: write_point_cloud(..., compressed=False))",
                        )))
                    }
                    other => {
                        return Err(bad(format!(
                            "DATA '{}': expected ascii, binary or binary_compressed",
                            other.unwrap_or("")
                        )))
                    }
                };
                let fields = fields(names, sizes, kinds, counts).map_err(bad)?;
                let points = match (points, width, height.unwrap_or(1)) {
                    (Some(p), Some(w), h) if w.checked_mul(h) != Some(p) => {
                        return Err(err(IoErrorKind::count_mismatch(format!(
                            "POINTS {p} is not WIDTH {w} x HEIGHT {h}"
                        ))))
                    }
                    (Some(p), _, _) => p,
                    (None, Some(w), h) => w.saturating_mul(h),
                    (None, None, _) => return Err(bad("no POINTS or WIDTH before DATA".into())),
                };
                return Ok(Header {
                    fields,
                    points,
                    data,
                    body: pos,
                    body_line: line_no + 1,
                });
            }
            other => return Err(bad(format!("unknown header line '{other}'"))),
        }
    }
    Err(IoError::new(
        file,
        None,
        IoErrorKind::bad_header("no DATA line: not a PCD file or truncated header"),
    ))
}

/// The fields, once their four lines agree in length (`COUNT` defaults to one each).
fn fields(
    names: Option<Vec<String>>,
    sizes: Option<Vec<usize>>,
    kinds: Option<Vec<u8>>,
    counts: Option<Vec<usize>>,
) -> Result<Vec<(String, Field)>, String> {
    let (Some(names), Some(sizes), Some(kinds)) = (names, sizes, kinds) else {
        return Err("FIELDS, SIZE and TYPE must come before DATA".into());
    };
    let counts = counts.unwrap_or_else(|| vec![1; names.len()]);
    if sizes.len() != names.len() || kinds.len() != names.len() || counts.len() != names.len() {
        return Err(format!(
            "{} FIELDS but {} SIZE, {} TYPE and {} COUNT entries",
            names.len(),
            sizes.len(),
            kinds.len(),
            counts.len()
        ));
    }
    let mut out = Vec::with_capacity(names.len());
    for (((name, size), kind), count) in names.into_iter().zip(sizes).zip(kinds).zip(counts) {
        if kind == b'F' && size < 4 {
            return Err(format!(
                "field {name}: TYPE F takes SIZE 4 or 8, not {size}"
            ));
        }
        // A record can be no larger than the file; this also keeps offsets from overflowing.
        if count > u32::MAX as usize {
            return Err(format!("field {name}: COUNT {count} is too large"));
        }
        out.push((name, Field { size, kind, count }));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEAD: &str = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\n";

    #[test]
    fn ascii_and_binary_agree() {
        let opts = LoadOptions::default();
        let ascii = format!("{HEAD}DATA ascii\n1 2 3 4278190080\n4 5 6 0\n");
        let a = read_pcd(ascii.as_bytes(), "a.pcd", &opts).expect("ascii");
        let mut binary = format!("{HEAD}DATA binary\n").into_bytes();
        for (p, rgb) in [([1.0f32, 2.0, 3.0], 7u32), ([4.0, 5.0, 6.0], 0)] {
            for c in p {
                binary.extend_from_slice(&c.to_le_bytes());
            }
            binary.extend_from_slice(&rgb.to_le_bytes());
        }
        let b = read_pcd(&binary, "b.pcd", &opts).expect("binary");
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.positions[1], DVec3::new(4.0, 5.0, 6.0));
        binary.truncate(binary.len() - 1);
        assert_eq!(
            read_pcd(&binary, "b.pcd", &opts).expect_err("short").kind(),
            "truncated"
        );
    }

    #[test]
    fn columns_and_counts_are_checked() {
        let opts = LoadOptions::default();
        let bad_counts = HEAD.replace("COUNT 1 1 1 1", "COUNT 1 1 1");
        let e = read_pcd(
            format!("{bad_counts}DATA ascii\n").as_bytes(),
            "c.pcd",
            &opts,
        )
        .expect_err("lengths");
        assert_eq!(e.kind(), "bad_header");
        let e = read_pcd(
            // Enough bytes for both declared points, so only the short first line is wrong.
            format!("{HEAD}DATA ascii\n1 2 3\n4 5 6 0\n").as_bytes(),
            "c.pcd",
            &opts,
        )
        .expect_err("short line");
        assert_eq!(e.kind(), "malformed");
        assert!(e.to_string().starts_with("c.pcd (line 12)"), "{e}");
    }
}
