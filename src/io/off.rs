//! OFF reader: Geomview's three-dimensional variants (`[ST][C][N]OFF`, `nOFF` of dimension
//! 3, or no keyword at all: "recommended but optional, as many existing files lack this
//! keyword"), '#' comments, polygons fan-triangulated. Line-based: a vertex line's first
//! three numbers are its position and a face line's first number its size, so texture,
//! colour and normal columns are skipped whatever their count.

use super::{IoError, IoErrorKind, LoadOptions};
use crate::mesh::TriMesh;
use glam::DVec3;

pub(crate) fn read_off(bytes: &[u8], file: &str, opts: &LoadOptions) -> Result<TriMesh, IoError> {
    let text = super::text::decode(bytes, file)?;
    let err = |line: usize, kind: IoErrorKind| IoError::at(file, format!("line {line}"), kind);
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(n, l)| (n + 1, l.split('#').next().unwrap_or("").trim()))
        .filter(|(_, l)| !l.is_empty());
    let (line, first) = lines
        .next()
        .ok_or_else(|| IoError::new(file, None, IoErrorKind::Empty))?;
    let (count_line, counts) = counts_line((line, first), &mut lines, file)?;
    let count = |k: usize, what: &str| -> Result<usize, IoError> {
        let t = counts.get(k).ok_or_else(|| {
            err(
                count_line,
                IoErrorKind::bad_header(format!("missing {what} count")),
            )
        })?;
        let v: usize = t.parse().map_err(|_| {
            err(
                count_line,
                IoErrorKind::bad_header(format!("bad {what} count '{t}'")),
            )
        })?;
        // Every entry needs at least a few bytes: refuse counts the file cannot hold.
        if v > bytes.len() / 2 {
            return Err(err(
                count_line,
                IoErrorKind::too_large(format!(
                    "{what} count {v} exceeds what a {}-byte file can hold",
                    bytes.len()
                )),
            ));
        }
        Ok(v)
    };
    let (nv, nf) = (count(0, "vertex")?, count(1, "face")?);
    // Both counts size allocations below: check them against the budgets first.
    opts.check_vertices(nv, "the OFF header")
        .and_then(|()| opts.check_triangles(nf, nv, "the OFF header"))
        .map_err(|kind| err(count_line, kind))?;
    let num = |n: usize, t: &str| -> Result<f64, IoError> {
        t.parse::<f64>()
            .map_err(|_| err(n, IoErrorKind::malformed(format!("'{t}' is not a number"))))
    };
    let mut positions = Vec::with_capacity(nv);
    for v in 0..nv {
        let (n, l) = lines.next().ok_or_else(|| {
            IoError::new(
                file,
                None,
                IoErrorKind::truncated(format!("file ends at vertex {v} of {nv}")),
            )
        })?;
        let w: Vec<&str> = l.split_whitespace().take(3).collect();
        if w.len() < 3 {
            return Err(err(
                n,
                IoErrorKind::malformed(format!("vertex {v} has fewer than 3 coordinates")),
            ));
        }
        let p = DVec3::new(num(n, w[0])?, num(n, w[1])?, num(n, w[2])?);
        if !p.is_finite() {
            return Err(err(
                n,
                IoErrorKind::non_finite(format!("vertex {v} has a non-finite coordinate")),
            ));
        }
        positions.push(p);
    }
    let mut triangles = Vec::with_capacity(nf);
    let mut idx = Vec::new();
    for f in 0..nf {
        let (n, l) = lines.next().ok_or_else(|| {
            IoError::new(
                file,
                None,
                IoErrorKind::truncated(format!("file ends at face {f} of {nf}")),
            )
        })?;
        let mut w = l.split_whitespace();
        let k: usize = w.next().and_then(|t| t.parse().ok()).ok_or_else(|| {
            err(
                n,
                IoErrorKind::malformed(format!("face {f}: bad vertex count")),
            )
        })?;
        idx.clear();
        for _ in 0..k {
            let t = w.next().ok_or_else(|| {
                err(
                    n,
                    IoErrorKind::malformed(format!("face {f}: fewer than {k} indices")),
                )
            })?;
            let i: usize = t.parse().map_err(|_| {
                err(
                    n,
                    IoErrorKind::malformed(format!("face {f}: bad index '{t}'")),
                )
            })?;
            if i >= nv {
                return Err(err(
                    n,
                    IoErrorKind::index_out_of_range(format!(
                        "face {f}: vertex index {i} out of range (0..{nv})"
                    )),
                ));
            }
            idx.push(i as u32);
        }
        if k < 3 {
            return Err(err(
                n,
                IoErrorKind::malformed(format!("face {f} has {k} vertices")),
            ));
        }
        for j in 1..k - 1 {
            triangles.push([idx[0], idx[j], idx[j + 1]]);
        }
    }
    Ok(TriMesh::new(positions, triangles))
}

/// The counts line's number and words, after the keyword (and `nOFF`'s dimension) on the
/// first line `(line, first)`; refuses the variants this reader does not take.
fn counts_line<'t>(
    (line, first): (usize, &'t str),
    lines: &mut impl Iterator<Item = (usize, &'t str)>,
    file: &str,
) -> Result<(usize, Vec<&'t str>), IoError> {
    let err = |line: usize, kind: IoErrorKind| IoError::at(file, format!("line {line}"), kind);
    let keyword = keyword(first).map_err(|kind| err(line, kind))?;
    let mut next_line = || {
        lines
            .next()
            .map(|(n, l)| (n, l.split_whitespace().collect::<Vec<&str>>()))
            .ok_or_else(|| IoError::new(file, None, IoErrorKind::bad_header("no counts line")))
    };
    let (mut count_line, mut counts): (usize, Vec<&str>) =
        (line, keyword.rest.split_whitespace().collect());
    if keyword.n_dimensional {
        if counts.is_empty() {
            (count_line, counts) = next_line()?;
        }
        let dimension = counts.remove(0);
        if dimension != "3" {
            return Err(err(
                count_line,
                IoErrorKind::unsupported(format!(
                    "'{}' of dimension {dimension}: only three-dimensional OFF is read",
                    keyword.word
                )),
            ));
        }
    }
    if counts.first() == Some(&"BINARY") {
        return Err(err(
            count_line,
            IoErrorKind::unsupported("binary OFF is not read (text OFF only)"),
        ));
    }
    if counts.is_empty() {
        (count_line, counts) = next_line()?;
    }
    Ok((count_line, counts))
}

/// An OFF file's first line: Geomview's `[ST][C][N][4][n]OFF` keyword, or none.
struct Keyword<'a> {
    /// The keyword ("" without one).
    word: &'a str,
    /// `nOFF`: the space's dimension comes next.
    n_dimensional: bool,
    /// The line after the keyword (the whole line without one: it holds the counts).
    rest: &'a str,
}

/// Reads the keyword from the first line. `ST`, `C` and `N` only add columns after a
/// vertex's position; `4` adds a fourth coordinate, which a surface in space has no use
/// for.
fn keyword(first: &str) -> Result<Keyword<'_>, IoErrorKind> {
    let word = first.split_whitespace().next().unwrap_or("");
    if word.parse::<usize>().is_ok() {
        return Ok(Keyword {
            word: "",
            n_dimensional: false,
            rest: first,
        });
    }
    let columns = ["ST", "C", "N"]
        .iter()
        .fold(word, |w, p| w.strip_prefix(p).unwrap_or(w));
    if columns.starts_with('4') {
        return Err(IoErrorKind::unsupported(format!(
            "'{word}': vertices with a fourth coordinate are not read (three-dimensional OFF only)"
        )));
    }
    let n_dimensional = columns.starts_with('n');
    if columns.strip_prefix('n').unwrap_or(columns) != "OFF" {
        return Err(IoErrorKind::bad_header(format!(
            "'{word}' is not an OFF header"
        )));
    }
    Ok(Keyword {
        word,
        n_dimensional,
        rest: first[word.len()..].trim_start(),
    })
}
