//! Fixed-size records by byte ranges: binary PLY vertices and uncompressed LAS points. A range
//! is a run of whole records; it is read with one seek and sequential reads of at most
//! [`CHUNK_RECORDS`] records. Time O(range), memory O(chunk).

use std::io::SeekFrom;
use std::path::Path;

use super::{ByteRange, Chunks, LasRecords, PlyRecords, Source};
use crate::io::IoError;

/// Records read at a time.
const CHUNK_RECORDS: usize = 16_384;

/// Reads the records of `range` (`record` bytes each) from `r`, handing each chunk's raw bytes
/// to `decode`, which returns false to stop.
fn read_records(
    r: &mut dyn Source,
    range: ByteRange,
    record: usize,
    src: &Path,
    mut decode: impl FnMut(&[u8]) -> bool,
) -> Result<(), IoError> {
    let read_err = |source| IoError::Read {
        path: src.to_path_buf(),
        source,
    };
    r.seek(SeekFrom::Start(range.start)).map_err(read_err)?;
    let mut left = (range.end - range.start) / record as u64;
    let mut buf = vec![0u8; CHUNK_RECORDS.min(left as usize) * record];
    while left > 0 {
        let n = (left as usize).min(CHUNK_RECORDS);
        let raw = &mut buf[..n * record];
        r.read_exact(raw).map_err(read_err)?;
        if !decode(raw) {
            break;
        }
        left -= n as u64;
    }
    Ok(())
}

/// The binary PLY vertices of `range`.
pub(super) fn read_ply<E>(
    p: &PlyRecords,
    r: &mut Box<dyn Source + '_>,
    range: ByteRange,
    src: &Path,
    out: &mut Chunks<'_, E>,
) -> Result<(), IoError> {
    read_records(&mut **r, range, p.record_bytes, src, |raw| {
        for rec in raw.chunks_exact(p.record_bytes) {
            let v = p.decode(rec);
            if !out.push([v[0], v[1], v[2]], [v[3], v[4], v[5]]) {
                return false;
            }
        }
        true
    })
}

/// The LAS points of `range`.
pub(super) fn read_las<E>(
    l: &LasRecords,
    r: &mut Box<dyn Source + '_>,
    range: ByteRange,
    src: &Path,
    out: &mut Chunks<'_, E>,
) -> Result<(), IoError> {
    let mut points = Vec::with_capacity(CHUNK_RECORDS);
    read_records(&mut **r, range, l.record_bytes, src, |raw| {
        points.clear();
        l.decode(raw, &mut points);
        points.iter().all(|&p| out.push(p, [0.0; 3]))
    })
}
