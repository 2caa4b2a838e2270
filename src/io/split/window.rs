//! A window of a file's bytes: the bytes `[base, base + data.len())` of a file of `len` bytes,
//! read as if the whole file were there. A worker that holds only the segments of an input
//! around one range plans the split from the first segment (the header) and reads its range
//! from the window ([`super::Split::read_window`]); a read outside the window is an error, never
//! silently short data.

use std::io::{BufRead, Read, Seek, SeekFrom};

use super::super::PointFormat;

/// Bytes `[base, base + data.len())` of an input of `len` bytes in format `format`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Window<'a> {
    /// The window's bytes.
    pub data: &'a [u8],
    /// Offset of `data[0]` in the input.
    pub base: u64,
    /// The whole input's length, bytes.
    pub len: u64,
    /// The input's format.
    #[cfg_attr(not(feature = "nats"), allow(dead_code))]
    pub format: PointFormat,
}

/// A reader over a [`Window`]: positions are the input's.
pub(super) struct WindowReader<'a> {
    w: Window<'a>,
    pos: u64,
}

impl<'a> WindowReader<'a> {
    pub(super) fn new(w: Window<'a>) -> Self {
        WindowReader { w, pos: w.base }
    }

    /// The bytes from the position to the window's end; an error when the position lies
    /// outside the window but inside the input.
    fn available(&self) -> std::io::Result<&'a [u8]> {
        let end = self.w.base + self.w.data.len() as u64;
        if self.pos >= self.w.len {
            return Ok(&[]);
        }
        if self.pos < self.w.base || self.pos >= end {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                format!(
                    "byte {} is outside the segments held ({}..{end})",
                    self.pos, self.w.base
                ),
            ));
        }
        Ok(&self.w.data[(self.pos - self.w.base) as usize..])
    }
}

impl Read for WindowReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let a = self.available()?;
        let k = a.len().min(buf.len());
        buf[..k].copy_from_slice(&a[..k]);
        self.pos += k as u64;
        Ok(k)
    }
}

impl BufRead for WindowReader<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        self.available()
    }
    fn consume(&mut self, amt: usize) {
        self.pos += amt as u64;
    }
}

impl Seek for WindowReader<'_> {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let target = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => self.w.len.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos = target.ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start")
        })?;
        Ok(self.pos)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_inside_the_window_and_refuses_outside() {
        let file: Vec<u8> = (0..100u8).collect();
        let w = Window {
            data: &file[40..60],
            base: 40,
            len: 100,
            format: PointFormat::Xyz,
        };
        let mut r = WindowReader::new(w);
        let mut buf = [0u8; 8];
        r.seek(SeekFrom::Start(50)).unwrap();
        r.read_exact(&mut buf).unwrap();
        assert_eq!(buf, [50, 51, 52, 53, 54, 55, 56, 57]);
        let mut rest = Vec::new();
        assert!(r.read_to_end(&mut rest).is_err(), "past the window");
        assert_eq!(rest, [58, 59]);
        r.seek(SeekFrom::Start(10)).unwrap();
        assert!(r.fill_buf().is_err(), "before the window");
        r.seek(SeekFrom::End(0)).unwrap();
        assert!(r.fill_buf().unwrap().is_empty(), "the input's end");
    }
}
