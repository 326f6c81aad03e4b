//! The PLY header: encoding, elements and their properties, and the Stanford range-grid
//! size; everything the body reader needs before it trusts a byte of the body.

use crate::io::{IoError, IoErrorKind};

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Scalar {
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
    pub(super) fn parse(s: &str) -> Option<Scalar> {
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
    pub(super) fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }
}

#[derive(Clone, Debug)]
pub(super) enum Property {
    Scalar(String, Scalar),
    List(String, Scalar, Scalar),
}

#[derive(Clone, Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: usize,
    pub(super) props: Vec<Property>,
}

#[derive(Clone, Copy, PartialEq, Debug)]
pub(super) enum Encoding {
    Ascii,
    Little,
    Big,
}

pub(super) struct Header {
    pub(super) encoding: Encoding,
    pub(super) elements: Vec<Element>,
    /// Stanford range grids: `obj_info num_cols` and `num_rows`.
    pub(super) num_cols: Option<usize>,
    pub(super) num_rows: Option<usize>,
    pub(super) body_offset: usize,
    /// Line number of the first body line (ascii error locations count from it).
    pub(super) body_first_line: usize,
}

pub(super) fn parse_header(bytes: &[u8], file: &str) -> Result<Header, IoError> {
    let err = |line: usize, detail: String| {
        IoError::at(
            file,
            format!("line {line}"),
            IoErrorKind::bad_header(detail),
        )
    };
    let end = find(bytes, b"end_header").ok_or_else(|| {
        IoError::new(
            file,
            None,
            IoErrorKind::bad_header("no end_header: not a PLY file or truncated header"),
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
    // Comments in a legacy 8-bit encoding are common; a byte that is not UTF-8 elsewhere
    // spoils a keyword or a number, which is then reported on its line.
    let text = String::from_utf8_lossy(&bytes[..end]);
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
            // A keyword this reader knows, in a form it does not, is an error; a line
            // that starts with none is free text (Blender 2.4x wrote its "Created by"
            // comment without the `comment` keyword) and carries no geometry.
            [first, ..] if HEADER_KEYWORDS.contains(first) => {
                return Err(err(n, format!("cannot read header line '{}'", line.trim())))
            }
            _ => tracing::warn!(
                file,
                line = n,
                "PLY header line without a keyword skipped: '{}'",
                line.trim()
            ),
        }
    }
    let encoding = encoding.ok_or_else(|| {
        IoError::new(
            file,
            None,
            IoErrorKind::bad_header("header has no format line"),
        )
    })?;
    Ok(Header {
        encoding,
        elements,
        num_cols,
        num_rows,
        body_offset,
        // n header lines before `end_header`, which is line n + 1.
        body_first_line: n + 2,
    })
}

/// The keywords of PLY header lines: a line starting with one must have its form.
const HEADER_KEYWORDS: [&str; 6] = [
    "ply", "format", "comment", "obj_info", "element", "property",
];

fn find(hay: &[u8], needle: &[u8]) -> Option<usize> {
    hay.windows(needle.len()).position(|w| w == needle)
}
