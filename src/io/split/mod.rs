//! Reading a point file by byte ranges, each range on its own and in any order, so that the
//! passes of the out-of-core task graph over a large input can be split into tasks
//! ([`crate::pipeline::tiled`]). Reading every range in order gives exactly the points of the
//! whole-file reader, in the same order.
//!
//! Formats whose ranges are well defined:
//! - **binary PLY** whose vertex element, and every element before it, has no list property:
//!   fixed-size records, a range is a run of whole records;
//! - **uncompressed LAS**: fixed-size point records, likewise;
//! - **XYZ / PTS / CSV text**: a range `[start, end)` of the data holds the lines that *begin*
//!   in it (a line begins at the first data byte or after a `\n`), the usual rule of line-based
//!   splits: the reader of a range skips to the first line beginning at or after `start` and
//!   reads whole lines while they begin before `end`, the last one possibly past `end`. The
//!   header lines (a `//` or named-column header, a PTS count line) are read once, when the
//!   split is planned, with the whole-file reader's rules.
//!
//! Not split (`None` from [`split_input`]): ASCII PLY (its values are whitespace-separated
//! tokens that may span lines), PLY with list properties in or before the vertex element, LAZ
//! (compressed in chunks), E57 and OBJ.

mod lines;
mod records;
#[cfg(test)]
mod tests;
mod window;

pub(crate) use window::Window;

use std::io::{BufRead, BufReader, Cursor, Seek};
use std::path::{Path, PathBuf};

use super::las::LasRecords;
use super::ply::PlyRecords;
use super::{IoError, PointFormat, ReadLimits, StreamInput};
use crate::geometry::Point3;

/// A half-open interval of byte offsets `[start, end)` of a file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ByteRange {
    /// First byte, from the start of the file.
    pub start: u64,
    /// One past the last byte.
    pub end: u64,
}

/// How the points of a file are laid out.
#[derive(Debug, Clone)]
enum Layout {
    Ply(PlyRecords),
    Las(Box<LasRecords>),
    Lines(lines::LineLayout),
}

/// A point input cut into byte ranges ([`split_input`]).
#[derive(Debug, Clone)]
pub(crate) struct Split {
    layout: Layout,
    ranges: Vec<ByteRange>,
    src: PathBuf,
}

/// What a range's reader hands its chunks to: points and, when the file has them, normals.
pub(crate) type ChunkConsumer<'f, E> =
    dyn FnMut(&[Point3], Option<&[Point3]>) -> Result<(), E> + 'f;

/// What the readers of a split read from: a file or bytes in memory.
trait Source: BufRead + Seek {}
impl<T: BufRead + Seek> Source for T {}

/// Where a split reads: the input, or a window of it.
#[derive(Clone, Copy)]
enum Origin<'a> {
    Input(StreamInput<'a>),
    #[cfg_attr(not(feature = "nats"), allow(dead_code))]
    Window(Window<'a>),
}

fn open<'a>(input: Origin<'a>) -> Result<Box<dyn Source + 'a>, IoError> {
    match input {
        Origin::Input(StreamInput::File(path)) => {
            let f = std::fs::File::open(path).map_err(|source| IoError::Open {
                path: path.to_path_buf(),
                source,
            })?;
            Ok(Box::new(BufReader::with_capacity(
                super::budget::READ_BUFFER_BYTES,
                f,
            )))
        }
        Origin::Input(StreamInput::Bytes { data, .. }) => Ok(Box::new(Cursor::new(data))),
        Origin::Window(w) => Ok(Box::new(window::WindowReader::new(w))),
    }
}

fn source_name(input: StreamInput<'_>) -> PathBuf {
    match input {
        StreamInput::File(p) => p.to_path_buf(),
        StreamInput::Bytes { .. } => Path::new(super::MEMORY_SOURCE).to_path_buf(),
    }
}

/// Cuts `input` into ranges of about `range_bytes` bytes (at least one record or one byte each),
/// or `None` when its format cannot be split (see the module doc). Applies `limits`' byte and
/// point limits as the whole-file reader does before its body (not the memory budget: the
/// points are not held) and reports the same errors for a bad header.
pub(crate) fn split_input(
    input: StreamInput<'_>,
    limits: &ReadLimits,
    range_bytes: u64,
) -> Result<Option<Split>, IoError> {
    let src = source_name(input);
    let (len, format) = match input {
        StreamInput::File(path) => {
            let (_, len, format) = super::open_point_file(path, limits)?;
            (len, format)
        }
        StreamInput::Bytes { data, format } => {
            super::check_bytes(data, limits, &src)?;
            (data.len() as u64, format)
        }
    };
    plan_split(Origin::Input(input), len, format, limits, range_bytes, src)
}

/// [`split_input`] for an input of which only the window `w` is held: the header must lie in
/// it (a window that begins the input and holds its first megabytes). The input's size was
/// checked against the limits when it was stored.
#[cfg_attr(not(feature = "nats"), allow(dead_code))]
pub(crate) fn split_window(
    w: Window<'_>,
    limits: &ReadLimits,
    range_bytes: u64,
) -> Result<Option<Split>, IoError> {
    let src = Path::new(super::MEMORY_SOURCE).to_path_buf();
    plan_split(Origin::Window(w), w.len, w.format, limits, range_bytes, src)
}

fn plan_split(
    input: Origin<'_>,
    len: u64,
    format: PointFormat,
    limits: &ReadLimits,
    range_bytes: u64,
    src: PathBuf,
) -> Result<Option<Split>, IoError> {
    let range_bytes = range_bytes.max(1);
    let r = open(input)?;
    let layout = match format {
        PointFormat::Ply => super::ply::vertex_records(r, len, limits, &src)?.map(Layout::Ply),
        PointFormat::Las => {
            super::las::fixed_records(r, len, limits, &src)?.map(|l| Layout::Las(Box::new(l)))
        }
        PointFormat::Xyz | PointFormat::Pts | PointFormat::Csv => {
            lines::layout(r, len, format, limits, &src)?.map(Layout::Lines)
        }
        PointFormat::Obj | PointFormat::E57 => None,
    };
    let Some(layout) = layout else {
        return Ok(None);
    };
    let ranges = match &layout {
        Layout::Ply(p) => record_ranges(p.body_start, p.record_bytes, p.count, range_bytes),
        Layout::Las(l) => record_ranges(l.body_start, l.record_bytes, l.count, range_bytes),
        Layout::Lines(l) => byte_ranges(l.data_start, len, range_bytes),
    };
    if ranges.is_empty() {
        return Ok(None);
    }
    Ok(Some(Split {
        layout,
        ranges,
        src,
    }))
}

/// Runs of whole records of about `range_bytes` each.
fn record_ranges(start: u64, record: usize, count: u64, range_bytes: u64) -> Vec<ByteRange> {
    if record == 0 {
        return Vec::new();
    }
    let per = (range_bytes / record as u64).max(1);
    let rec = record as u64;
    let at = |k: u64| start + k.saturating_mul(per).min(count) * rec;
    (0..count.div_ceil(per))
        .map(|k| ByteRange {
            start: at(k),
            end: at(k + 1),
        })
        .collect()
}

/// `[start, end)` in pieces of `range_bytes` (the last one shorter).
fn byte_ranges(start: u64, end: u64, range_bytes: u64) -> Vec<ByteRange> {
    let at = |k: u64| start.saturating_add(k.saturating_mul(range_bytes)).min(end);
    (0..end.saturating_sub(start).div_ceil(range_bytes))
        .map(|k| ByteRange {
            start: at(k),
            end: at(k + 1),
        })
        .collect()
}

impl Split {
    /// The ranges, in file order.
    pub(crate) fn ranges(&self) -> &[ByteRange] {
        &self.ranges
    }

    /// Whether the points carry normals.
    pub(crate) fn has_normals(&self) -> bool {
        match &self.layout {
            Layout::Ply(p) => p.has_normals,
            Layout::Las(_) => false,
            Layout::Lines(l) => l.has_normals(),
        }
    }

    fn format_name(&self) -> &'static str {
        match &self.layout {
            Layout::Ply(_) => "PLY",
            Layout::Las(_) => "LAS",
            Layout::Lines(l) => l.fmt,
        }
    }

    /// Refuses a total of `points` read over all ranges that the whole-file reader would have
    /// refused as it read them (text has no declared count to check before).
    pub(crate) fn check_total(&self, points: u64, limits: &ReadLimits) -> Result<(), IoError> {
        if points > limits.max_points as u64 {
            return Err(IoError::TooManyPoints {
                path: self.src.clone(),
                declared: limits.max_points as u64 + 1,
                limit: limits.max_points,
            });
        }
        if points == 0 {
            return Err(IoError::Empty {
                path: self.src.clone(),
                what: format!("no points found in the {} data", self.format_name()),
            });
        }
        Ok(())
    }

    /// Reads range `r` of `input` (the input the split was planned on), handing `f` chunks of at
    /// most `chunk_points` points and their normals (when the file has them), in file order.
    /// Errors are the whole-file reader's, line numbers included.
    pub(crate) fn read_range<E: From<IoError>>(
        &self,
        input: StreamInput<'_>,
        r: usize,
        chunk_points: usize,
        f: &mut ChunkConsumer<'_, E>,
    ) -> Result<(), E> {
        self.read_from(Origin::Input(input), r, chunk_points, f)
    }

    /// [`Split::read_range`] from a window of the input that holds the range (and, for text,
    /// the byte before it and the end of its last line: see [`Split::window_bounds`]).
    #[cfg_attr(not(feature = "nats"), allow(dead_code))]
    pub(crate) fn read_window<E: From<IoError>>(
        &self,
        w: Window<'_>,
        r: usize,
        chunk_points: usize,
        f: &mut ChunkConsumer<'_, E>,
    ) -> Result<(), E> {
        self.read_from(Origin::Window(w), r, chunk_points, f)
    }

    /// The bytes a window must hold to read range `r`: the range, and for text the byte before
    /// it (whether a line begins at its start) and `slack` bytes after it (its last line).
    #[cfg_attr(not(feature = "nats"), allow(dead_code))]
    pub(crate) fn window_bounds(&self, r: usize, slack: u64) -> ByteRange {
        let range = self.ranges[r];
        match self.layout {
            Layout::Lines(_) => ByteRange {
                start: range.start.saturating_sub(1),
                end: range.end.saturating_add(slack),
            },
            _ => range,
        }
    }

    fn read_from<E: From<IoError>>(
        &self,
        input: Origin<'_>,
        r: usize,
        chunk_points: usize,
        f: &mut ChunkConsumer<'_, E>,
    ) -> Result<(), E> {
        let range = self.ranges[r];
        let mut out = Chunks::new(chunk_points, self.has_normals(), f);
        let mut src = open(input)?;
        match &self.layout {
            Layout::Ply(p) => records::read_ply(p, &mut src, range, &self.src, &mut out)?,
            Layout::Las(l) => records::read_las(l, &mut src, range, &self.src, &mut out)?,
            Layout::Lines(l) => lines::read(l, &mut src, range, &self.src, &mut out)?,
        }
        out.flush()
    }
}

/// Collects points into chunks for the consumer of a range.
struct Chunks<'f, E> {
    points: Vec<Point3>,
    normals: Option<Vec<Point3>>,
    cap: usize,
    f: &'f mut ChunkConsumer<'f, E>,
    /// The consumer's error, kept until the reader returns.
    failed: Option<E>,
}

impl<'f, E> Chunks<'f, E> {
    fn new(cap: usize, normals: bool, f: &'f mut ChunkConsumer<'f, E>) -> Self {
        let cap = cap.max(1);
        Chunks {
            points: Vec::with_capacity(cap),
            normals: normals.then(|| Vec::with_capacity(cap)),
            cap,
            f,
            failed: None,
        }
    }

    /// Adds one point; false once the consumer has failed (the reader then stops).
    fn push(&mut self, p: Point3, n: Point3) -> bool {
        self.points.push(p);
        if let Some(v) = self.normals.as_mut() {
            v.push(n);
        }
        if self.points.len() >= self.cap
            && let Err(e) = self.flush_inner()
        {
            self.failed = Some(e);
        }
        self.failed.is_none()
    }

    fn flush_inner(&mut self) -> Result<(), E> {
        if self.points.is_empty() {
            return Ok(());
        }
        (self.f)(&self.points, self.normals.as_deref())?;
        self.points.clear();
        if let Some(v) = self.normals.as_mut() {
            v.clear();
        }
        Ok(())
    }

    fn flush(&mut self) -> Result<(), E> {
        if let Some(e) = self.failed.take() {
            return Err(e);
        }
        self.flush_inner()
    }
}
