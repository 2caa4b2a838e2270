//! Point readers as streams: the PLY and text parsers hand each point to a [`PointSink`] as they
//! decode it, so the same parsers either fill the arrays of a [`PointCloud`] ([`VecSink`]) or
//! pass bounded chunks on ([`stream_points`]) without the cloud ever being held.
//!
//! [`stream_points`] runs the reader on its own thread and hands the consumer chunks of at most
//! `chunk_points` points through a channel of two chunks: memory O(chunk), whatever the file's
//! size, and parsing overlaps with whatever the consumer does with the points. PLY (ASCII and
//! binary) and XYZ/PTS/CSV text stream; OBJ, LAS/LAZ and E57 are read whole by their readers
//! (which need the whole file or seek) and then handed on in chunks, so they hold their cloud once.

use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use super::{IoError, PointFormat, ReadLimits};
use crate::geometry::{Point3, PointCloud};

/// Where a reader puts the points it decodes, one at a time.
pub(crate) trait PointSink {
    /// Whether the points stay in memory (then the reader's memory budget applies).
    fn holds_points(&self) -> bool;
    /// A hint: about `n` points will follow.
    fn reserve(&mut self, n: usize);
    /// One point and, when the format has them, its normal.
    fn push(&mut self, p: Point3, n: Option<Point3>) -> Result<(), IoError>;
    /// The colour of the point just pushed (red, green, blue in [0, 1], as stored), when the
    /// format has one; ignored unless the sink keeps colours.
    fn push_color(&mut self, _c: [f32; 3]) {}
}

/// Collects the points into arrays (the readers' in-memory form).
#[derive(Default)]
pub(crate) struct VecSink {
    points: Vec<Point3>,
    normals: Vec<Point3>,
    colors: Vec<[f32; 3]>,
}

impl VecSink {
    /// The collected cloud; normals only when the format has them, colours when every point
    /// had one.
    pub(crate) fn into_cloud(self, has_normals: bool) -> PointCloud {
        let colored = !self.colors.is_empty() && self.colors.len() == self.points.len();
        PointCloud {
            colors: colored.then_some(self.colors),
            points: self.points,
            normals: has_normals.then_some(self.normals),
            ..Default::default()
        }
    }
}

impl PointSink for VecSink {
    fn holds_points(&self) -> bool {
        true
    }

    fn reserve(&mut self, n: usize) {
        self.points
            .reserve_exact(n.saturating_sub(self.points.len()));
    }

    fn push(&mut self, p: Point3, n: Option<Point3>) -> Result<(), IoError> {
        if let Some(n) = n {
            if self.normals.capacity() < self.points.capacity() {
                let more = self.points.capacity() - self.normals.len();
                self.normals.reserve_exact(more);
            }
            self.normals.push(n);
        }
        self.points.push(p);
        Ok(())
    }

    fn push_color(&mut self, c: [f32; 3]) {
        if self.colors.capacity() < self.points.capacity() {
            let more = self.points.capacity() - self.colors.len();
            self.colors.reserve_exact(more);
        }
        self.colors.push(c);
    }
}

/// Consecutive points of a streamed input (in file order) and their normals when it has them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointChunk {
    /// Positions, in the file's units (non-finite ones passed through).
    pub points: Vec<Point3>,
    /// Normals, one per point, when the format has them.
    pub normals: Option<Vec<Point3>>,
}

/// Cuts the points into chunks and sends them down a channel.
struct ChunkSink {
    chunk: PointChunk,
    cap: usize,
    tx: SyncSender<Result<PointChunk, IoError>>,
    /// Points sent so far.
    sent: u64,
    src: std::path::PathBuf,
}

impl ChunkSink {
    fn flush(&mut self) -> Result<(), IoError> {
        if self.chunk.points.is_empty() {
            return Ok(());
        }
        let full = std::mem::take(&mut self.chunk);
        self.sent += full.points.len() as u64;
        self.tx.send(Ok(full)).map_err(|_| IoError::Read {
            path: self.src.clone(),
            source: std::io::Error::other("the consumer of the point stream stopped"),
        })
    }
}

impl PointSink for ChunkSink {
    fn holds_points(&self) -> bool {
        false
    }

    fn reserve(&mut self, _n: usize) {}

    fn push(&mut self, p: Point3, n: Option<Point3>) -> Result<(), IoError> {
        if self.chunk.points.is_empty() {
            self.chunk.points.reserve_exact(self.cap);
            if n.is_some() {
                self.chunk.normals = Some(Vec::with_capacity(self.cap));
            }
        }
        self.chunk.points.push(p);
        if let (Some(v), Some(n)) = (self.chunk.normals.as_mut(), n) {
            v.push(n);
        }
        if self.chunk.points.len() >= self.cap {
            self.flush()?;
        }
        Ok(())
    }
}

/// A point input that can be read more than once.
#[derive(Debug, Clone, Copy)]
pub enum StreamInput<'a> {
    /// A point file (format from content and extension, as [`super::read_point_cloud`]).
    File(&'a Path),
    /// A file's bytes in memory, of a known format (errors name `<input>`).
    Bytes {
        /// The bytes.
        data: &'a [u8],
        /// Their format.
        format: PointFormat,
    },
}

/// The chunks of a running [`stream_points`]; the last item is the reader's error, if any.
pub struct PointChunks {
    rx: Receiver<Result<PointChunk, IoError>>,
}

impl Iterator for PointChunks {
    type Item = Result<PointChunk, IoError>;
    fn next(&mut self) -> Option<Self::Item> {
        self.rx.recv().ok()
    }
}

/// Reads `input` on a scoped thread and lets `consume` iterate over its points in chunks of at
/// most `chunk_points` (≥ 1) points. The reader applies `limits`' byte and point limits but not
/// its memory budget (the points are not held). Errors are the in-memory readers' own, with the
/// same wording, delivered after the chunks read before them; a file without points ends with
/// [`IoError::Empty`]. When `consume` returns early the reader stops at its next chunk.
pub fn stream_points<T>(
    input: StreamInput<'_>,
    limits: &ReadLimits,
    chunk_points: usize,
    consume: impl FnOnce(&mut PointChunks) -> T,
) -> T {
    let (tx, rx) = sync_channel(2);
    std::thread::scope(|scope| {
        let reader_tx = tx.clone();
        scope.spawn(move || {
            let src = match input {
                StreamInput::File(p) => p.to_path_buf(),
                StreamInput::Bytes { .. } => Path::new(super::MEMORY_SOURCE).to_path_buf(),
            };
            let mut sink = ChunkSink {
                chunk: PointChunk::default(),
                cap: chunk_points.max(1),
                tx: reader_tx,
                sent: 0,
                src: src.clone(),
            };
            let result = read_into(input, limits, &mut sink).and_then(|format| {
                sink.flush()?;
                if sink.sent == 0 {
                    return Err(IoError::Empty {
                        path: src.clone(),
                        what: format!("no points found in the {} data", format.name()),
                    });
                }
                Ok(())
            });
            if let Err(e) = result {
                let _ = sink.tx.send(Err(e));
            }
        });
        drop(tx);
        let mut chunks = PointChunks { rx };
        consume(&mut chunks)
    })
}

/// Runs the reader of `input`'s format into `sink`; returns the format.
fn read_into(
    input: StreamInput<'_>,
    limits: &ReadLimits,
    sink: &mut ChunkSink,
) -> Result<PointFormat, IoError> {
    match input {
        StreamInput::File(path) => {
            let (r, len, format) = super::open_point_file(path, limits)?;
            match format {
                PointFormat::Ply => {
                    super::ply::stream_ply_points(r, len, limits, path, sink)?;
                }
                PointFormat::Xyz | PointFormat::Pts | PointFormat::Csv => {
                    super::text::read_text_into(r, len, format, limits, path, sink)?;
                }
                PointFormat::Obj | PointFormat::Las | PointFormat::E57 => {
                    drop(r);
                    let cloud = super::read_point_cloud(path, limits)?;
                    hand_on(cloud, sink)?;
                }
            }
            Ok(format)
        }
        StreamInput::Bytes { data, format } => {
            let src = Path::new(super::MEMORY_SOURCE);
            super::check_bytes(data, limits, src)?;
            let len = data.len() as u64;
            match format {
                PointFormat::Ply => {
                    super::ply::stream_ply_points(data, len, limits, src, sink)?;
                }
                PointFormat::Xyz | PointFormat::Pts | PointFormat::Csv => {
                    super::text::read_text_into(data, len, format, limits, src, sink)?;
                }
                PointFormat::Obj | PointFormat::Las | PointFormat::E57 => {
                    hand_on(super::parse_point_cloud(data, format, limits)?, sink)?;
                }
            }
            Ok(format)
        }
    }
}

/// Passes a cloud read whole on to `sink` point by point.
fn hand_on(cloud: PointCloud, sink: &mut ChunkSink) -> Result<(), IoError> {
    for (i, p) in cloud.points.iter().enumerate() {
        sink.push(*p, cloud.normals.as_ref().map(|n| n[i]))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn collect(input: StreamInput<'_>, chunk: usize) -> Result<(PointCloud, usize), IoError> {
        stream_points(input, &ReadLimits::default(), chunk, |chunks| {
            let mut out = VecSink::default();
            let (mut count, mut normals) = (0, false);
            for c in chunks {
                let c = c?;
                assert!(c.points.len() <= chunk);
                count += 1;
                normals = c.normals.is_some();
                for (i, p) in c.points.iter().enumerate() {
                    out.push(*p, c.normals.as_ref().map(|n| n[i]))?;
                }
            }
            Ok((out.into_cloud(normals), count))
        })
    }

    #[test]
    fn chunks_hold_the_same_points_as_the_in_memory_readers() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("data");
        let whole =
            super::super::read_point_cloud(&data.join("kitten.ply"), &ReadLimits::default())
                .unwrap();
        let (streamed, chunks) =
            collect(StreamInput::File(&data.join("kitten.ply")), 1000).unwrap();
        assert_eq!(chunks, 6);
        assert_eq!(streamed.points, whole.points);
        assert_eq!(streamed.normals, whole.normals);
        let text = b"# c\n1 2 3 0 0 1\n4 5 6 0 1 0\n7 8 9 1 0 0\n";
        let input = StreamInput::Bytes {
            data: text,
            format: PointFormat::Xyz,
        };
        let (streamed, chunks) = collect(input, 2).unwrap();
        assert_eq!(chunks, 2);
        assert_eq!(
            streamed.points,
            vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]
        );
        assert_eq!(streamed.normals.unwrap()[2], [1.0, 0.0, 0.0]);
    }

    #[test]
    fn errors_are_the_in_memory_readers_own() {
        let mut text = String::new();
        for i in 0..10_000 {
            text.push_str(&format!("{i} 1 2\n"));
        }
        text.push_str("3 x 4\n");
        let input = StreamInput::Bytes {
            data: text.as_bytes(),
            format: PointFormat::Xyz,
        };
        let streamed = collect(input, 4096).unwrap_err();
        let whole =
            super::super::parse_point_cloud(text.as_bytes(), PointFormat::Xyz, &Default::default())
                .unwrap_err();
        assert_eq!(streamed.to_string(), whole.to_string());
        assert!(
            matches!(streamed, IoError::Parse { line: 10_001, .. }),
            "{streamed}"
        );
        let input = StreamInput::Bytes {
            data: b"# nothing\n",
            format: PointFormat::Xyz,
        };
        assert!(matches!(collect(input, 8), Err(IoError::Empty { .. })));
    }
}
