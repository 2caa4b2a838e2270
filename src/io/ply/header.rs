//! PLY header parser: `ply`, `format`, `comment` / `obj_info`, `element`, scalar and list
//! `property` lines, `end_header` (LF or CRLF). [`read_header`] takes the header lines off a
//! buffered reader (at most [`MAX_HEADER_BYTES`]) and leaves the reader at the first body byte.
//! Time O(header length).
//!
//! Reference: G. Turk, "The PLY Polygon File Format" (1994).

use std::io::{BufRead, Read};
use std::path::Path;

use crate::io::IoError;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

impl Encoding {
    pub(super) fn label(self) -> &'static str {
        match self {
            Encoding::Ascii => "ASCII PLY",
            Encoding::BinaryLe | Encoding::BinaryBe => "binary PLY",
        }
    }
}

/// A PLY scalar type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
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
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
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

    /// The value that stands for full intensity when a colour has this type: the largest value
    /// of an integer type of 8 or 16 bits (255, 65535; signed ones too, as files write them),
    /// 1 for floating point, 255 for wider integers (the common 8-bit values written as int).
    pub(super) fn full_scale(self) -> f64 {
        match self {
            Scalar::I16 | Scalar::U16 => 65535.0,
            Scalar::F32 | Scalar::F64 => 1.0,
            _ => 255.0,
        }
    }

    /// Decodes `b` (exactly `self.size()` bytes).
    pub(super) fn decode(self, b: &[u8], big: bool) -> f64 {
        fn arr<const N: usize>(b: &[u8], big: bool) -> [u8; N] {
            let mut a = [0u8; N];
            a.copy_from_slice(&b[..N]);
            if big {
                a.reverse();
            }
            a
        }
        match self {
            Scalar::I8 => f64::from(b[0] as i8),
            Scalar::U8 => f64::from(b[0]),
            Scalar::I16 => f64::from(i16::from_le_bytes(arr(b, big))),
            Scalar::U16 => f64::from(u16::from_le_bytes(arr(b, big))),
            Scalar::I32 => f64::from(i32::from_le_bytes(arr(b, big))),
            Scalar::U32 => f64::from(u32::from_le_bytes(arr(b, big))),
            Scalar::F32 => f64::from(f32::from_le_bytes(arr(b, big))),
            Scalar::F64 => f64::from_le_bytes(arr(b, big)),
        }
    }
}

#[derive(Debug, Clone, Copy)]
pub(super) enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
pub(super) struct Property {
    pub(super) name: String,
    pub(super) kind: PropKind,
}

#[derive(Debug)]
pub(super) struct Element {
    pub(super) name: String,
    pub(super) count: u64,
    pub(super) props: Vec<Property>,
}

impl Element {
    /// Minimum bytes one record occupies in `enc` (exact for binary elements without lists).
    pub(super) fn min_record_bytes(&self, enc: Encoding) -> u64 {
        self.props
            .iter()
            .map(|p| match (enc, p.kind) {
                (Encoding::Ascii, _) => 2,
                (_, PropKind::Scalar(s)) => s.size() as u64,
                (_, PropKind::List { count, .. }) => count.size() as u64,
            })
            .sum()
    }
}

#[derive(Debug)]
pub(super) struct Header {
    pub(super) encoding: Encoding,
    pub(super) elements: Vec<Element>,
    /// 1-based line number of the first body line (for ASCII error messages).
    pub(super) body_line: usize,
}

pub(super) fn parse_err(src: &Path, line: usize, message: String) -> IoError {
    IoError::Parse {
        path: src.to_path_buf(),
        format: "PLY",
        line,
        message,
    }
}

/// Longest header read before giving up (bytes): a file without `end_header` is not read whole.
pub(crate) const MAX_HEADER_BYTES: u64 = 16 << 20;

/// Reads the header lines (through `end_header`) from `r` and parses them; returns the header and
/// its length in bytes. `r` is left at the first body byte. Reads at most [`MAX_HEADER_BYTES`].
pub(crate) fn read_header<R: BufRead>(r: &mut R, src: &Path) -> Result<(Header, u64), IoError> {
    let mut bytes = Vec::new();
    let mut line_no = 0usize;
    loop {
        let room = MAX_HEADER_BYTES.saturating_sub(bytes.len() as u64);
        let start = bytes.len();
        let n = Read::take(&mut *r, room)
            .read_until(b'\n', &mut bytes)
            .map_err(|source| IoError::Read {
                path: src.to_path_buf(),
                source,
            })?;
        line_no += 1;
        let key = bytes[start..]
            .split(|b| b.is_ascii_whitespace())
            .find(|t| !t.is_empty());
        // Stop at `end_header`, at the data's end, at the size cap, or after a first line that is
        // not `ply` (the parser reports each of these).
        let not_ply = line_no == 1 && key != Some(b"ply".as_slice());
        if n == 0 || key == Some(b"end_header".as_slice()) || not_ply || n as u64 >= room {
            break;
        }
    }
    let h = parse_header(&bytes, src)?;
    Ok((h, bytes.len() as u64))
}

/// Parses the header up to and including `end_header`.
pub(super) fn parse_header(bytes: &[u8], src: &Path) -> Result<Header, IoError> {
    let mut pos = 0usize;
    let mut line_no = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    while pos < bytes.len() {
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| pos + i);
        let raw = &bytes[pos..end];
        pos = (end + 1).min(bytes.len());
        line_no += 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| parse_err(src, line_no, "header line is not text".into()))?
            .trim();
        let mut tok = line.split_ascii_whitespace();
        let Some(key) = tok.next() else { continue };
        let rest: Vec<&str> = tok.collect();
        match key {
            "ply" if line_no == 1 => {}
            _ if line_no == 1 => {
                return Err(parse_err(src, 1, "file does not start with `ply`".into()));
            }
            "comment" | "obj_info" => {}
            "format" => encoding = Some(parse_format(&rest, src, line_no)?),
            "element" => elements.push(parse_element(&rest, src, line_no)?),
            "property" => {
                let el = elements.last_mut().ok_or_else(|| {
                    parse_err(src, line_no, "`property` before any `element`".into())
                })?;
                el.props.push(parse_property(&rest, src, line_no)?);
            }
            "end_header" => {
                let encoding = encoding
                    .ok_or_else(|| parse_err(src, line_no, "no `format` line in header".into()))?;
                return Ok(Header {
                    encoding,
                    elements,
                    body_line: line_no + 1,
                });
            }
            other => {
                return Err(parse_err(
                    src,
                    line_no,
                    format!("unknown header keyword `{other}`"),
                ));
            }
        }
    }
    Err(parse_err(
        src,
        line_no.max(1),
        "header has no `end_header` line".into(),
    ))
}

fn parse_format(rest: &[&str], src: &Path, line: usize) -> Result<Encoding, IoError> {
    match rest.first().copied() {
        Some("ascii") => Ok(Encoding::Ascii),
        Some("binary_little_endian") => Ok(Encoding::BinaryLe),
        Some("binary_big_endian") => Ok(Encoding::BinaryBe),
        other => Err(parse_err(
            src,
            line,
            format!(
                "unknown format `{}` (expected ascii, binary_little_endian or binary_big_endian)",
                other.unwrap_or("")
            ),
        )),
    }
}

fn parse_element(rest: &[&str], src: &Path, line: usize) -> Result<Element, IoError> {
    let (Some(name), Some(count)) = (rest.first(), rest.get(1)) else {
        return Err(parse_err(
            src,
            line,
            "expected `element <name> <count>`".into(),
        ));
    };
    let count = count
        .parse::<u64>()
        .map_err(|_| parse_err(src, line, format!("element count `{count}` is not a count")))?;
    Ok(Element {
        name: (*name).to_string(),
        count,
        props: Vec::new(),
    })
}

fn parse_property(rest: &[&str], src: &Path, line: usize) -> Result<Property, IoError> {
    let scalar = |t: &str| {
        Scalar::parse(t).ok_or_else(|| parse_err(src, line, format!("unknown property type `{t}`")))
    };
    match rest {
        ["list", ct, it, name] => Ok(Property {
            name: (*name).to_string(),
            kind: PropKind::List {
                count: scalar(ct)?,
                item: scalar(it)?,
            },
        }),
        [ty, name] if *ty != "list" => Ok(Property {
            name: (*name).to_string(),
            kind: PropKind::Scalar(scalar(ty)?),
        }),
        _ => Err(parse_err(
            src,
            line,
            "expected `property <type> <name>` or `property list <count type> <item type> <name>`"
                .into(),
        )),
    }
}
