//! Line-based text (XYZ / PTS / CSV) by byte ranges: the header lines are read once with the
//! whole-file reader's rules ([`layout`]), then each range reads the lines that begin in it
//! ([`read`]). Time O(range + one line), memory O(one line).

use std::io::{BufRead, Read};
use std::path::Path;

use super::super::text::{
    Columns, MAX_LINE, check_count_line, columns_from_header, count_line, parse_f64, tokens,
};
use super::{ByteRange, Chunks, Source};
use crate::io::{IoError, PointFormat, ReadLimits};

/// Where the data lines of a text file begin and which columns they use.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct LineLayout {
    /// Offset of the first line after the header lines (the first data row, or the line after a
    /// column-name header or a count line).
    pub data_start: u64,
    cols: Columns,
    /// The format's name, for errors.
    pub fmt: &'static str,
    /// Bytes in the file.
    len: u64,
}

impl LineLayout {
    pub(super) fn has_normals(&self) -> bool {
        self.cols.normals.is_some()
    }
}

fn read_err(src: &Path, source: std::io::Error) -> IoError {
    IoError::Read {
        path: src.to_path_buf(),
        source,
    }
}

/// Reads the line at the reader's position (with its `\n`) into `raw`, at most `left` bytes of
/// the file; `Ok(None)` at the end, `Ok(Some(false))` for a line longer than [`MAX_LINE`].
fn next_line(
    r: &mut dyn Source,
    raw: &mut Vec<u8>,
    left: u64,
    src: &Path,
) -> Result<Option<bool>, IoError> {
    raw.clear();
    let limit = MAX_LINE.min(left);
    let n = Read::take(r, limit)
        .read_until(b'\n', raw)
        .map_err(|e| read_err(src, e))?;
    if n == 0 {
        return Ok(None);
    }
    Ok(Some(!(n as u64 == MAX_LINE && raw.last() != Some(&b'\n'))))
}

/// The header of a text file as the whole-file reader reads it: comments, a first-line `//`
/// header, a PTS count line, a column-name header, or the first data row whose column count
/// decides the columns. `None` when the reader would fail or find no data there (the whole-file
/// reader then reports it).
pub(super) fn layout(
    mut r: Box<dyn Source + '_>,
    len: u64,
    format: PointFormat,
    limits: &ReadLimits,
    src: &Path,
) -> Result<Option<LineLayout>, IoError> {
    let fmt = format.name();
    let at = |data_start: u64, cols: Columns| LineLayout {
        data_start,
        cols,
        fmt,
        len,
    };
    let (mut pos, mut first, mut raw) = (0u64, true, Vec::new());
    loop {
        let Some(whole) = next_line(&mut *r, &mut raw, len - pos, src)? else {
            return Ok(None);
        };
        if !whole {
            return Ok(None);
        }
        let start = pos;
        pos += raw.len() as u64;
        let line = raw.trim_ascii();
        if line.is_empty() || line.starts_with(b"#") {
            continue;
        }
        let is_first = std::mem::replace(&mut first, false);
        let toks: Vec<&[u8]> = tokens(line).collect();
        if line.starts_with(b"//") {
            let header = match is_first {
                true => columns_from_header(&toks, fmt, src).ok(),
                false => None,
            };
            if let Some(c) = header {
                return Ok(Some(at(pos, c)));
            }
            continue;
        }
        if let Some(n) = count_line(&toks).filter(|_| is_first) {
            check_count_line(n, limits, src)?;
            first = true;
            continue;
        }
        let numeric = toks.iter().filter(|t| parse_f64(t).is_some()).count();
        if numeric == 0 {
            return Ok(Some(at(pos, columns_from_header(&toks, fmt, src)?)));
        }
        if toks.len() < 3 || numeric < 3.min(toks.len()) {
            return Ok(None);
        }
        return Ok(Some(at(start, Columns::from_count(toks.len()))));
    }
}

/// The 1-based line number of the line beginning at byte `offset`.
fn line_at(r: &mut dyn Source, offset: u64, src: &Path) -> Result<usize, IoError> {
    r.seek(std::io::SeekFrom::Start(0))
        .map_err(|e| read_err(src, e))?;
    let mut left = offset;
    let mut lines = 1;
    while left > 0 {
        let buf = r.fill_buf().map_err(|e| read_err(src, e))?;
        if buf.is_empty() {
            break;
        }
        let k = (buf.len() as u64).min(left) as usize;
        lines += buf[..k].iter().filter(|&&b| b == b'\n').count();
        r.consume(k);
        left -= k as u64;
    }
    Ok(lines)
}

/// Moves the reader to the first line beginning at or after `start` (after the data start) and
/// returns its offset (`len` when there is none).
fn seek_line(l: &LineLayout, r: &mut dyn Source, start: u64, src: &Path) -> Result<u64, IoError> {
    let at = start.max(l.data_start);
    if at == l.data_start {
        r.seek(std::io::SeekFrom::Start(at))
            .map_err(|e| read_err(src, e))?;
        return Ok(at);
    }
    // The line begins at `at` when byte `at - 1` ends the previous one.
    let mut pos = at - 1;
    r.seek(std::io::SeekFrom::Start(pos))
        .map_err(|e| read_err(src, e))?;
    loop {
        let buf = r.fill_buf().map_err(|e| read_err(src, e))?;
        if buf.is_empty() {
            return Ok(l.len);
        }
        if let Some(k) = buf.iter().position(|&b| b == b'\n') {
            r.consume(k + 1);
            return Ok(pos + k as u64 + 1);
        }
        let k = buf.len();
        r.consume(k);
        pos += k as u64;
    }
}

/// Reads the rows of the lines beginning in `range` into `out`.
pub(super) fn read<E>(
    l: &LineLayout,
    r: &mut Box<dyn Source + '_>,
    range: ByteRange,
    src: &Path,
    out: &mut Chunks<'_, E>,
) -> Result<(), IoError> {
    let mut pos = seek_line(l, &mut **r, range.start, src)?;
    let mut raw = Vec::new();
    let c = l.cols;
    // A window of the input cannot count the lines before it: the error then names the byte
    // the line begins at.
    let err = |r: &mut Box<dyn Source + '_>, at: u64, message: String| {
        let (line, message) = match line_at(&mut **r, at, src) {
            Ok(line) => (line, message),
            Err(_) => (0, format!("{message} (in the line beginning at byte {at})")),
        };
        Ok::<_, IoError>(IoError::Parse {
            path: src.to_path_buf(),
            format: l.fmt,
            line,
            message,
        })
    };
    while pos < range.end.min(l.len) {
        let Some(whole) = next_line(&mut **r, &mut raw, l.len - pos, src)? else {
            break;
        };
        if !whole {
            return Err(err(r, pos, format!("line longer than {MAX_LINE} bytes"))?);
        }
        let start = pos;
        pos += raw.len() as u64;
        let line = raw.trim_ascii();
        if line.is_empty() || line.starts_with(b"#") || line.starts_with(b"//") {
            continue;
        }
        let toks: Vec<&[u8]> = tokens(line).collect();
        if toks.len() < c.min_tokens() {
            let msg = format!(
                "expected at least {} columns, found {}",
                c.min_tokens(),
                toks.len()
            );
            return Err(err(r, start, msg)?);
        }
        let mut row = [0.0f64; 6];
        let used = c.xyz.iter().chain(c.normals.iter().flatten());
        for (slot, &k) in used.enumerate() {
            match parse_f64(toks[k]) {
                Some(v) => row[slot] = v,
                None => {
                    let t = String::from_utf8_lossy(toks[k]).into_owned();
                    let msg = format!("`{t}` (column {}) is not a number", k + 1);
                    return Err(err(r, start, msg)?);
                }
            }
        }
        if !out.push([row[0], row[1], row[2]], [row[3], row[4], row[5]]) {
            break;
        }
    }
    Ok(())
}
