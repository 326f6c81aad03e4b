//! The PLY body, value by value (ascii or binary), with fixed-layout fast paths for the
//! binary little-endian layouts scanners write.

use super::header::{Element, Encoding, Property, Scalar};
use crate::io::{IoError, IoErrorKind};
use glam::DVec3;

/// Reads values one at a time from the body, ascii or binary.
pub(super) struct Body<'a> {
    pub(super) bytes: &'a [u8],
    pub(super) pos: usize,
    pub(super) encoding: Encoding,
    /// Current line (ascii bodies), for error locations.
    pub(super) line: usize,
    pub(super) file: &'a str,
}

impl Body<'_> {
    fn where_(&self) -> String {
        match self.encoding {
            Encoding::Ascii => format!("line {}", self.line),
            _ => format!("byte {}", self.pos),
        }
    }

    pub(super) fn error(&self, kind: IoErrorKind) -> IoError {
        IoError::at(self.file, self.where_(), kind)
    }

    pub(super) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    pub(super) fn read(&mut self, ty: Scalar) -> Result<f64, IoError> {
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
                    return Err(self.error(IoErrorKind::truncated("unexpected end of file")));
                }
                let tok = std::str::from_utf8(&self.bytes[start..self.pos])
                    .map_err(|_| self.error(IoErrorKind::NotText { what: "a number" }))?;
                tok.parse::<f64>().map_err(|_| {
                    self.error(IoErrorKind::malformed(format!("'{tok}' is not a number")))
                })
            }
            enc => {
                let n = ty.size();
                let b = self
                    .bytes
                    .get(self.pos..self.pos + n)
                    .ok_or_else(|| self.error(IoErrorKind::truncated("unexpected end of file")))?;
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
    pub(super) fn fast_vertices(
        &mut self,
        e: &Element,
        xyz: [usize; 3],
        out: &mut Vec<DVec3>,
    ) -> bool {
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
    pub(super) fn fast_triangles(
        &mut self,
        e: &Element,
        vertices: usize,
        out: &mut Vec<[u32; 3]>,
    ) -> bool {
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
    pub(super) fn min_element_bytes(&self, e: &Element) -> usize {
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

pub(super) fn read_count(body: &mut Body, ty: Scalar) -> Result<usize, IoError> {
    let n = body.read(ty)?;
    if !(0.0..=1e9).contains(&n) || n.fract() != 0.0 {
        return Err(body.error(IoErrorKind::malformed(format!("bad list length {n}"))));
    }
    let n = n as usize;
    // Each list item takes at least one byte: reject lengths the file cannot hold.
    if n > body.remaining() {
        return Err(body.error(IoErrorKind::too_large(format!(
            "list of {n} items runs past the end of the file"
        ))));
    }
    Ok(n)
}
