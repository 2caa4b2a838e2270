//! PLY body sources: the binary byte stream and the ASCII token stream, both read through one
//! fixed-size chunk buffer from any [`Read`] (a file or an in-memory slice). Memory O(chunk).

use super::ROW;
use std::io::Read;
use std::path::Path;

use super::header::{Scalar, parse_err};
use crate::io::IoError;

/// Where in the body a value is read: element name and 0-based record index (for errors).
#[derive(Debug, Clone, Copy)]
pub(super) struct At<'a> {
    pub(super) el: &'a str,
    pub(super) record: u64,
}

/// One used property of a fixed-size binary record: byte offset, type and destination slot.
#[derive(Debug, Clone, Copy)]
pub(super) struct Field {
    pub(super) offset: usize,
    pub(super) ty: Scalar,
    pub(super) slot: usize,
}

/// Source of property values: the ASCII token stream or the binary byte stream.
pub(super) trait Body {
    /// File name for error messages.
    fn src(&self) -> &Path;
    /// The next scalar of type `t`, as f64.
    fn scalar(&mut self, t: Scalar, at: At) -> Result<f64, IoError>;
    /// Skips `n` scalars of type `t`.
    fn skip(&mut self, t: Scalar, n: u64, at: At) -> Result<(), IoError>;
    /// Binary bodies: decodes one whole record of `size` bytes, writing `fields` into `row`, and
    /// returns true. ASCII bodies return false without reading (records are read value by value).
    fn fixed_record(
        &mut self,
        size: usize,
        fields: &[Field],
        row: &mut [f64; ROW],
        at: At,
    ) -> Result<bool, IoError>;
}

/// A chunk buffer over a reader: `buf[start..end]` holds the bytes not yet consumed.
struct Chunked<'a, R> {
    r: R,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    /// Body bytes consumed so far.
    consumed: u64,
    eof: bool,
    src: &'a Path,
}

impl<'a, R: Read> Chunked<'a, R> {
    fn new(r: R, chunk: usize, src: &'a Path) -> Self {
        Chunked {
            r,
            buf: vec![0; chunk.max(1)],
            start: 0,
            end: 0,
            consumed: 0,
            eof: false,
            src,
        }
    }

    fn available(&self) -> &[u8] {
        &self.buf[self.start..self.end]
    }

    fn consume(&mut self, n: usize) {
        self.start += n;
        self.consumed += n as u64;
    }

    /// Makes at least `need` bytes available unless the data ends first (then fewer are).
    /// The buffer grows only when one record is larger than the chunk.
    fn fill(&mut self, need: usize) -> Result<(), IoError> {
        if self.end - self.start >= need || self.eof {
            return Ok(());
        }
        self.buf.copy_within(self.start..self.end, 0);
        self.end -= self.start;
        self.start = 0;
        if need > self.buf.len() {
            self.buf.resize(need, 0);
        }
        while self.end < need && !self.eof {
            match self.r.read(&mut self.buf[self.end..]) {
                Ok(0) => self.eof = true,
                Ok(k) => self.end += k,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(source) => {
                    return Err(IoError::Read {
                        path: self.src.to_path_buf(),
                        source,
                    });
                }
            }
        }
        Ok(())
    }

    /// The error for data ending `need` bytes short of what record `at` requires.
    fn truncated(&self, need: u64, at: At) -> IoError {
        IoError::Truncated {
            path: self.src.to_path_buf(),
            format: "binary PLY",
            what: format!(
                "data ends inside record {} (0-based) of element `{}`",
                at.record, at.el
            ),
            expected: self.consumed.saturating_add(need),
            found: self.consumed + (self.end - self.start) as u64,
        }
    }
}

/// Binary body, little- or big-endian.
pub(super) struct BinBody<'a, R> {
    c: Chunked<'a, R>,
    big: bool,
}

impl<'a, R: Read> BinBody<'a, R> {
    /// Body of `chunk`-byte reads from `r`; `big` = big-endian.
    pub(super) fn new(r: R, big: bool, chunk: usize, src: &'a Path) -> Self {
        BinBody {
            c: Chunked::new(r, chunk, src),
            big,
        }
    }

    /// The next `n` bytes (consumed), or a truncation error naming `at`.
    fn take(&mut self, n: usize, at: At) -> Result<&[u8], IoError> {
        self.c.fill(n)?;
        if self.c.end - self.c.start < n {
            return Err(self.c.truncated(n as u64, at));
        }
        let s = self.c.start;
        self.c.consume(n);
        Ok(&self.c.buf[s..s + n])
    }
}

impl<R: Read> Body for BinBody<'_, R> {
    fn src(&self) -> &Path {
        self.c.src
    }

    fn scalar(&mut self, t: Scalar, at: At) -> Result<f64, IoError> {
        let big = self.big;
        Ok(t.decode(self.take(t.size(), at)?, big))
    }

    fn skip(&mut self, t: Scalar, n: u64, at: At) -> Result<(), IoError> {
        let total = u128::from(n) * t.size() as u128;
        let mut left = total;
        while left > 0 {
            if self.c.available().is_empty() {
                self.c.fill(1)?;
                if self.c.available().is_empty() {
                    let need = u64::try_from(left).unwrap_or(u64::MAX);
                    return Err(self.c.truncated(need, at));
                }
            }
            let k = (self.c.available().len() as u128).min(left) as usize;
            self.c.consume(k);
            left -= k as u128;
        }
        Ok(())
    }

    fn fixed_record(
        &mut self,
        size: usize,
        fields: &[Field],
        row: &mut [f64; ROW],
        at: At,
    ) -> Result<bool, IoError> {
        let big = self.big;
        let rec = self.take(size, at)?;
        for f in fields {
            row[f.slot] = f.ty.decode(&rec[f.offset..], big);
        }
        Ok(true)
    }
}

/// Longest ASCII value kept for parsing (bytes); longer tokens are reported as not a number.
const MAX_TOKEN: usize = 1024;

/// ASCII body: whitespace-separated tokens, line numbers counted for errors.
pub(super) struct AsciiBody<'a, R> {
    c: Chunked<'a, R>,
    /// 1-based line of the current position.
    line: usize,
    tok: Vec<u8>,
}

impl<'a, R: Read> AsciiBody<'a, R> {
    /// Body of `chunk`-byte reads from `r` whose first line is line `first_line` of the file.
    pub(super) fn new(r: R, first_line: usize, chunk: usize, src: &'a Path) -> Self {
        AsciiBody {
            c: Chunked::new(r, chunk, src),
            line: first_line,
            tok: Vec::new(),
        }
    }

    /// Reads the next token (into `self.tok` when `keep`, at most [`MAX_TOKEN`] bytes of it).
    fn token(&mut self, at: At, keep: bool) -> Result<(), IoError> {
        loop {
            self.c.fill(1)?;
            let a = self.c.available();
            if a.is_empty() {
                return Err(parse_err(
                    self.c.src,
                    self.line,
                    format!(
                        "data ends inside element `{}` (fewer records than the header declares)",
                        at.el
                    ),
                ));
            }
            let ws = a.iter().position(|b| !b.is_ascii_whitespace());
            let k = ws.unwrap_or(a.len());
            self.line += a[..k].iter().filter(|&&b| b == b'\n').count();
            self.c.consume(k);
            if ws.is_some() {
                break;
            }
        }
        self.tok.clear();
        loop {
            self.c.fill(1)?;
            let a = self.c.available();
            if a.is_empty() {
                return Ok(());
            }
            let end = a.iter().position(|b| b.is_ascii_whitespace());
            let k = end.unwrap_or(a.len());
            if keep && self.tok.len() < MAX_TOKEN {
                let room = MAX_TOKEN + 1 - self.tok.len();
                self.tok.extend_from_slice(&a[..k.min(room)]);
            }
            self.c.consume(k);
            if end.is_some() {
                return Ok(());
            }
        }
    }
}

impl<R: Read> Body for AsciiBody<'_, R> {
    fn src(&self) -> &Path {
        self.c.src
    }

    fn scalar(&mut self, _t: Scalar, at: At) -> Result<f64, IoError> {
        self.token(at, true)?;
        let tok = &self.tok;
        let v = (tok.len() <= MAX_TOKEN)
            .then(|| std::str::from_utf8(tok).ok()?.parse::<f64>().ok())
            .flatten();
        v.ok_or_else(|| {
            let shown = String::from_utf8_lossy(&tok[..tok.len().min(64)]);
            let more = if tok.len() > 64 { "..." } else { "" };
            parse_err(
                self.c.src,
                self.line,
                format!("`{shown}{more}` in element `{}` is not a number", at.el),
            )
        })
    }

    fn skip(&mut self, _t: Scalar, n: u64, at: At) -> Result<(), IoError> {
        for _ in 0..n {
            self.token(at, false)?;
        }
        Ok(())
    }

    fn fixed_record(
        &mut self,
        _size: usize,
        _fields: &[Field],
        _row: &mut [f64; ROW],
        _at: At,
    ) -> Result<bool, IoError> {
        Ok(false)
    }
}
