//! Binary PLY vertex records as fixed-size byte records, for reading the vertex element by
//! byte ranges ([`crate::io::split`]): possible when the vertex element and every element before
//! it have no list properties, so record `k` of the vertex element starts at a known offset.
//! ASCII PLY is not split (its values are whitespace-separated tokens, not lines), nor is a
//! binary vertex element with list properties.

use std::io::BufRead;
use std::path::Path;

use super::header::{Element, Encoding, PropKind, Scalar, read_header};
use super::{check_body_size, vertex_element};
use crate::io::{IoError, ReadLimits};

/// Where the vertex records of a binary PLY lie and how to decode one.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PlyRecords {
    /// Byte offset of vertex record 0 in the file.
    pub body_start: u64,
    /// Bytes per vertex record.
    pub record_bytes: usize,
    /// Vertex records the header declares.
    pub count: u64,
    /// Whether the vertices carry nx, ny, nz.
    pub has_normals: bool,
    big: bool,
    /// Used properties: byte offset in the record, type, slot (0..3 xyz, 3..6 normal).
    fields: Vec<(usize, Scalar, usize)>,
}

impl PlyRecords {
    /// Decodes one record (`record_bytes` bytes) into x, y, z, nx, ny, nz (zero when absent).
    pub(crate) fn decode(&self, rec: &[u8]) -> [f64; 6] {
        let mut row = [0.0; 6];
        for &(offset, ty, slot) in &self.fields {
            row[slot] = ty.decode(&rec[offset..], self.big);
        }
        row
    }
}

/// The slots of x, y, z and (when all three are present) nx, ny, nz among the vertex element's
/// scalar properties: the first property of each name, as the whole-file reader maps them.
fn slots(el: &Element, src: &Path) -> Result<(Vec<Option<usize>>, bool), IoError> {
    let names: [&[&str]; 6] = [
        &["x"],
        &["y"],
        &["z"],
        &["nx", "normal_x"],
        &["ny", "normal_y"],
        &["nz", "normal_z"],
    ];
    let mut slots = vec![None; el.props.len()];
    let mut found = [false; 6];
    for (i, p) in el.props.iter().enumerate() {
        let slot = names.iter().position(|a| a.contains(&p.name.as_str()));
        if let Some(s) = slot.filter(|&s| !found[s]) {
            found[s] = true;
            slots[i] = Some(s);
        }
    }
    if let Some(miss) = (0..3).find(|&s| !found[s]) {
        return Err(IoError::MissingField {
            path: src.to_path_buf(),
            format: "PLY",
            field: names[miss][0].to_string(),
        });
    }
    let normals = found[3..].iter().all(|&f| f);
    if !normals {
        for s in slots.iter_mut().filter(|s| s.is_some_and(|k| k >= 3)) {
            *s = None;
        }
    }
    Ok((slots, normals))
}

/// Fixed record size of `el` in bytes, `None` when it has a list property.
fn record_size(el: &Element) -> Option<usize> {
    el.props
        .iter()
        .map(|p| match p.kind {
            PropKind::Scalar(s) => Some(s.size()),
            PropKind::List { .. } => None,
        })
        .sum()
}

/// The vertex records of the PLY whose bytes `r` starts at (`len` bytes in all), when they can be
/// read by byte ranges; `None` for ASCII PLY or list properties in or before the vertex element.
/// Refuses what the whole-file reader refuses before its body (point limit, empty vertex
/// element, a body shorter than the header declares).
pub(crate) fn vertex_records<R: BufRead>(
    mut r: R,
    len: u64,
    limits: &ReadLimits,
    src: &Path,
) -> Result<Option<PlyRecords>, IoError> {
    let (h, header_len) = read_header(&mut r, src)?;
    let vi = vertex_element(&h, src)?;
    let el = &h.elements[vi];
    if el
        .props
        .iter()
        .any(|p| matches!(p.kind, PropKind::List { .. }))
    {
        return Ok(None);
    }
    if el.count > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: el.count,
            limit: limits.max_points,
        });
    }
    let (slots, has_normals) = slots(el, src)?;
    check_body_size(&h, len.saturating_sub(header_len), src)?;
    if el.count == 0 {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "PLY header declares 0 vertices".into(),
        });
    }
    let big = match h.encoding {
        Encoding::Ascii => return Ok(None),
        Encoding::BinaryLe => false,
        Encoding::BinaryBe => true,
    };
    let mut before = 0u64;
    for e in &h.elements[..vi] {
        let Some(size) = record_size(e) else {
            return Ok(None);
        };
        before = before.saturating_add(e.count.saturating_mul(size as u64));
    }
    let mut fields = Vec::new();
    let mut offset = 0;
    for (p, slot) in el.props.iter().zip(&slots) {
        if let (PropKind::Scalar(ty), Some(slot)) = (p.kind, *slot) {
            fields.push((offset, ty, slot));
        }
        if let PropKind::Scalar(ty) = p.kind {
            offset += ty.size();
        }
    }
    Ok(Some(PlyRecords {
        body_start: header_len + before,
        record_bytes: offset,
        count: el.count,
        has_normals,
        big,
        fields,
    }))
}
