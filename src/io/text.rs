//! The text of a line-based format's file (OBJ, OFF, XYZ, a PLY header), as exporters
//! write it rather than as the formats say: with a byte-order mark, in UTF-16, or with
//! names and comments in a legacy 8-bit encoding.

use super::{IoError, IoErrorKind};
use std::borrow::Cow;

const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// The text of `bytes`; `file` names it in errors.
/// - A UTF-8 byte-order mark is dropped: kept, it glues itself to the first keyword (an
///   OBJ whose first line is `v ...` lost that vertex as an unknown line).
/// - UTF-16 with a byte-order mark is decoded (Windows tools write it).
/// - Bytes that are not UTF-8 become U+FFFD. In these formats they can only stand in names
///   and comments (an OBJ `usemtl Terraind\xE6k` in Latin-1): a number holding one does
///   not parse and is reported on its line, so no geometry changes unseen.
/// - A NUL byte is refused: no text format holds one, so the file is binary (or UTF-16
///   without a mark) and its "lines" would be noise.
pub(crate) fn decode<'a>(bytes: &'a [u8], file: &str) -> Result<Cow<'a, str>, IoError> {
    let utf16 = match bytes {
        [0xFE, 0xFF, rest @ ..] => Some((rest, u16::from_be_bytes as fn([u8; 2]) -> u16)),
        [0xFF, 0xFE, rest @ ..] => Some((rest, u16::from_le_bytes as fn([u8; 2]) -> u16)),
        _ => None,
    };
    if let Some((rest, unit)) = utf16 {
        let units = rest.chunks(2).map(|c| match c {
            [a, b] => unit([*a, *b]),
            // A lone trailing byte is no code unit.
            _ => 0xFFFD,
        });
        let text: String = char::decode_utf16(units)
            .map(|c| c.unwrap_or(char::REPLACEMENT_CHARACTER))
            .collect();
        return refuse_nul(text.as_bytes(), file).map(|()| Cow::Owned(text));
    }
    let bytes = bytes.strip_prefix(UTF8_BOM).unwrap_or(bytes);
    refuse_nul(bytes, file)?;
    Ok(String::from_utf8_lossy(bytes))
}

fn refuse_nul(bytes: &[u8], file: &str) -> Result<(), IoError> {
    match bytes.iter().position(|&b| b == 0) {
        Some(at) => Err(IoError::at(
            file,
            format!("byte {at}"),
            IoErrorKind::NotText { what: "the file" },
        )),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn text(bytes: &[u8]) -> String {
        decode(bytes, "t").expect("text").into_owned()
    }

    #[test]
    fn marks_and_encodings_are_read_as_exporters_write_them() {
        assert_eq!(text(b"\xEF\xBB\xBFv 1 2 3\n"), "v 1 2 3\n");
        let utf16: Vec<u8> = "v 1 2 3\n"
            .encode_utf16()
            .flat_map(|u| u.to_be_bytes())
            .collect();
        assert_eq!(
            text(&[&[0xFE, 0xFF], utf16.as_slice()].concat()),
            "v 1 2 3\n"
        );
        let utf16: Vec<u8> = "f 1 2 3"
            .encode_utf16()
            .flat_map(|u| u.to_le_bytes())
            .collect();
        assert_eq!(text(&[&[0xFF, 0xFE], utf16.as_slice()].concat()), "f 1 2 3");
        assert_eq!(
            text(b"usemtl Terraind\xE6k\n"),
            "usemtl Terraind\u{FFFD}k\n"
        );
    }

    #[test]
    fn a_nul_byte_is_no_text_and_the_error_says_where() {
        let e = decode(b"v 1 2 3\nv \x00\x01", "model.obj").expect_err("binary");
        assert_eq!(e.kind(), "not_text");
        assert!(e.to_string().contains("byte 10"), "{e}");
        let unmarked_utf16: Vec<u8> = "v 1".encode_utf16().flat_map(|u| u.to_le_bytes()).collect();
        assert!(decode(&unmarked_utf16, "t").is_err());
    }
}
