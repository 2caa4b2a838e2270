//! Memory budget of the point readers, and cheap point-count hints from a file's first bytes.
//!
//! [`peek_point_count`] reads at most a PLY header or the first 64 KiB of a text file, so a caller
//! can refuse a scan that cannot fit before reading it; [`reader_peak_mib`] is what the readers
//! themselves need (the point and normal arrays as f64 plus the read buffers), checked against
//! [`ReadLimits::max_memory_mib`] before those arrays are allocated.

use std::io::{BufRead, BufReader};
use std::path::Path;

use super::{IoError, PointFormat, ReadLimits, detect_point_format, open_limited};

/// Capacity of the buffered file reader, bytes (64 KiB); also the size of the sniffed head.
pub(crate) const READ_BUFFER_BYTES: usize = 64 << 10;

const MIB: f64 = (1u64 << 20) as f64;

/// Bytes the reader holds per point: 3 f64 coordinates, plus 3 f64 normal components.
fn bytes_per_point(has_normals: bool) -> u64 {
    if has_normals { 48 } else { 24 }
}

/// Peak memory of the point-cloud reader itself, MiB, for `points` points: the coordinate array
/// (24 bytes per point), the normal array (another 24 when `has_normals`) and the fixed read
/// buffers (the buffered file reader and the PLY chunk, 64 KiB each).
///
/// ```
/// let mib = rbfsurf::io::reader_peak_mib(10_000_000, true);
/// assert!((mib - 457.9).abs() < 0.1);
/// ```
pub fn reader_peak_mib(points: u64, has_normals: bool) -> f64 {
    let buffers = (READ_BUFFER_BYTES + super::ply::CHUNK_BYTES) as f64;
    (points as f64 * bytes_per_point(has_normals) as f64 + buffers) / MIB
}

/// Largest point count whose [`reader_peak_mib`] fits `limits.max_memory_mib`.
pub(crate) fn points_within_budget(limits: &ReadLimits, has_normals: bool) -> u64 {
    let buffers = (READ_BUFFER_BYTES + super::ply::CHUNK_BYTES) as u64;
    let budget = limits.max_memory_mib.saturating_mul(1 << 20);
    budget.saturating_sub(buffers) / bytes_per_point(has_normals)
}

/// Where a point count used in a memory check comes from (quoted in the error message).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CountSource {
    /// Declared by the file (PLY `element vertex`, PTS count line): exact.
    Declared,
    /// Estimated from the file size and the first lines.
    Estimated,
    /// Counted while reading a text file (the reader stopped there).
    ReadSoFar,
}

impl CountSource {
    fn label(self) -> &'static str {
        match self {
            CountSource::Declared => "declared by the file's header",
            CountSource::Estimated => "estimated from the file size",
            CountSource::ReadSoFar => "read so far",
        }
    }
}

/// `OverMemory` when reading `points` points would exceed the budget of `limits`.
pub(crate) fn check_reader_memory(
    points: u64,
    has_normals: bool,
    counted: CountSource,
    limits: &ReadLimits,
    src: &Path,
) -> Result<(), IoError> {
    if points <= points_within_budget(limits, has_normals) {
        return Ok(());
    }
    Err(IoError::OverMemory {
        path: src.to_path_buf(),
        points,
        counted: counted.label(),
        needed_mib: reader_peak_mib(points, has_normals),
        budget_mib: limits.max_memory_mib,
    })
}

/// Per-point bytes and fixed buffers of a reader, for [`check_memory`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct ReaderCost {
    /// Bytes kept per point: 24 for the f64 coordinates, plus 12 for f32 RGB, 4 for f32
    /// intensity, 24 for f64 normals, whichever the file has.
    pub(crate) per_point: u64,
    /// Fixed buffers while reading (one chunk of records, decoder state), bytes.
    pub(crate) buffers: u64,
}

impl ReaderCost {
    /// Peak MiB for `points` points.
    pub(crate) fn mib(self, points: u64) -> f64 {
        (points as f64 * self.per_point as f64 + self.buffers as f64) / MIB
    }
}

/// `OverMemory` when `points` points at `cost` exceed `limits.max_memory_mib`: the scanner
/// readers' form of [`check_reader_memory`] (their points carry colour and intensity too).
pub(crate) fn check_memory(
    points: u64,
    cost: ReaderCost,
    counted: CountSource,
    limits: &ReadLimits,
    src: &Path,
) -> Result<(), IoError> {
    let budget = limits.max_memory_mib.saturating_mul(1 << 20);
    let need = u128::from(points) * u128::from(cost.per_point.max(1)) + u128::from(cost.buffers);
    if need <= u128::from(budget) {
        return Ok(());
    }
    Err(IoError::OverMemory {
        path: src.to_path_buf(),
        points,
        counted: counted.label(),
        needed_mib: cost.mib(points),
        budget_mib: limits.max_memory_mib,
    })
}

/// A point count known before reading a file (see [`peek_point_count`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PointCountHint {
    /// Number of points (PLY: declared vertices; text and OBJ: estimated data lines).
    pub points: u64,
    /// True when `points` is the count the file declares (PLY), false for an estimate.
    pub exact: bool,
    /// Whether the points carry normals, when the first bytes tell (PLY: nx, ny, nz declared;
    /// text: the first rows' columns); `None` when unknown (OBJ).
    pub has_normals: Option<bool>,
}

impl PointCountHint {
    /// Refuses (`OverMemory`) when reading this many points would exceed `limits.max_memory_mib`
    /// by [`reader_peak_mib`]; unknown normals count as absent, so only certain overruns refuse.
    pub fn check_budget(&self, limits: &ReadLimits, path: &Path) -> Result<(), IoError> {
        let counted = if self.exact {
            CountSource::Declared
        } else {
            CountSource::Estimated
        };
        let normals = self.has_normals.unwrap_or(false);
        check_reader_memory(self.points, normals, counted, limits, path)
    }
}

/// Point count of a file without reading it: PLY reads the header only (exact count); XYZ, PTS,
/// CSV and OBJ read the first 64 KiB and scale its data-line count by the file size (estimate).
/// The format is detected as by [`super::read_point_cloud`].
///
/// ```
/// let dir = tempfile::tempdir().unwrap();
/// let p = dir.path().join("big.ply");
/// std::fs::write(&p, "ply\nformat binary_little_endian 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n").unwrap();
/// let hint = rbfsurf::io::peek_point_count(&p).unwrap();
/// assert_eq!((hint.points, hint.exact, hint.has_normals), (100_000_000, true, Some(false)));
/// ```
pub fn peek_point_count(path: &Path) -> Result<PointCountHint, IoError> {
    let (file, len) = open_limited(path, u64::MAX)?;
    let mut r = BufReader::with_capacity(READ_BUFFER_BYTES, file);
    let head = r.fill_buf().map_err(|source| IoError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let format = detect_point_format(path, head)?;
    if matches!(format, PointFormat::Las | PointFormat::E57) {
        let (points, has_normals) = if format == PointFormat::Las {
            (super::las::peek_points(&mut r, len, path)?, false)
        } else {
            (super::e57::peek_points(&mut r, len, path)?, false)
        };
        return Ok(PointCountHint {
            points,
            exact: true,
            has_normals: Some(has_normals),
        });
    }
    if format == PointFormat::Ply {
        let (points, normals) = super::ply::peek_vertices(r, path)?;
        return Ok(PointCountHint {
            points,
            exact: true,
            has_normals: Some(normals),
        });
    }
    let (points, has_normals) = if format == PointFormat::Obj {
        (estimate_lines(head, len, is_obj_vertex), None)
    } else {
        let complete = &head[..complete_lines_len(head, len)];
        let probe = ReadLimits::default();
        let normals =
            super::text::read_text_points(complete, complete.len() as u64, format, &probe, path)
                .ok()
                .map(|pc| pc.normals.is_some());
        (estimate_lines(head, len, is_text_data), normals)
    };
    Ok(PointCountHint {
        points,
        exact: false,
        has_normals,
    })
}

/// Length of the prefix of `head` made of complete lines (all of it when it is the whole file).
fn complete_lines_len(head: &[u8], total_len: u64) -> usize {
    if head.len() as u64 >= total_len {
        return head.len();
    }
    head.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1)
}

/// A text line that holds a point (not blank, not a `#` or `//` comment).
fn is_text_data(line: &[u8]) -> bool {
    !line.is_empty() && !line.starts_with(b"#") && !line.starts_with(b"//")
}

/// An OBJ `v` line.
fn is_obj_vertex(line: &[u8]) -> bool {
    line.starts_with(b"v ") || line.starts_with(b"v\t")
}

/// Estimated number of `is_data` lines in a file of `total_len` bytes from its first bytes
/// `head`: the count in the complete lines of `head`, scaled by `total_len / their length`.
pub(crate) fn estimate_lines(head: &[u8], total_len: u64, is_data: fn(&[u8]) -> bool) -> u64 {
    let head = &head[..head.len().min(READ_BUFFER_BYTES)];
    let n = complete_lines_len(head, total_len);
    if n == 0 {
        // One line longer than the head: at least one point, if any.
        return u64::from(!head.trim_ascii().is_empty());
    }
    let seen = &head[..n];
    let data = seen
        .split(|&b| b == b'\n')
        .filter(|l| is_data(l.trim_ascii()))
        .count() as u64;
    if data == 0 {
        return 0;
    }
    let scaled = u128::from(total_len) * u128::from(data) / seen.len() as u128;
    u64::try_from(scaled).unwrap_or(u64::MAX).max(data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::SplitMix64;

    #[test]
    fn reader_peak_is_the_arrays_plus_two_buffers() {
        let buffers = 128.0 / 1024.0;
        assert!((reader_peak_mib(0, true) - buffers).abs() < 1e-12);
        let n = 1u64 << 20;
        assert!((reader_peak_mib(n, false) - (24.0 + buffers)).abs() < 1e-9);
        assert!((reader_peak_mib(n, true) - (48.0 + buffers)).abs() < 1e-9);
        let limits = ReadLimits {
            max_memory_mib: 1024,
            ..ReadLimits::default()
        };
        let k = points_within_budget(&limits, true);
        assert!(reader_peak_mib(k, true) <= 1024.0 && reader_peak_mib(k + 1, true) > 1024.0);
    }

    #[test]
    fn ply_hint_is_the_declared_count() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("n.ply");
        let head = "ply\nformat ascii 1.0\nelement vertex 200000000\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n";
        std::fs::write(&p, head).unwrap();
        let h = peek_point_count(&p).unwrap();
        assert_eq!(
            h,
            PointCountHint {
                points: 200_000_000,
                exact: true,
                has_normals: Some(true)
            }
        );
        let e = h.check_budget(&ReadLimits::default(), &p).unwrap_err();
        let msg = e.to_string();
        for needle in ["200000000 points", "9155 MiB", "8192 MiB", "subsample"] {
            assert!(msg.contains(needle), "{needle}: {msg}");
        }
        std::fs::write(&p, "ply\nformat ascii 1.0\nelement face 3\nend_header\n").unwrap();
        let e = peek_point_count(&p).unwrap_err();
        assert!(matches!(e, IoError::MissingField { .. }), "{e}");
    }

    #[test]
    fn text_and_obj_estimates_are_close() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = SplitMix64(3);
        let n = 40_000;
        let mut xyz = String::from("# scan\n");
        let mut obj = String::from("# mesh\no thing\n");
        for _ in 0..n {
            let v: Vec<f64> = (0..6).map(|_| rng.next_f64() * 10.0 - 5.0).collect();
            let digits = 1 + (rng.next_f64() * 6.0) as usize;
            xyz.push_str(&format!(
                "{:.d$} {:.d$} {:.d$} {:.3} {:.3} {:.3}\n",
                v[0],
                v[1],
                v[2],
                v[3],
                v[4],
                v[5],
                d = digits
            ));
            obj.push_str(&format!(
                "v {:.6} {:.6} {:.6}\nvn 0 0 1\n",
                v[0], v[1], v[2]
            ));
        }
        for (name, text, normals) in [("a.xyz", &xyz, Some(true)), ("a.obj", &obj, None)] {
            let p = dir.path().join(name);
            std::fs::write(&p, text).unwrap();
            let h = peek_point_count(&p).unwrap();
            assert!(!h.exact && h.has_normals == normals, "{name}: {h:?}");
            let err = (h.points as f64 - n as f64).abs() / n as f64;
            assert!(err < 0.05, "{name}: estimate {} for {n}", h.points);
        }
        let small = dir.path().join("s.csv");
        std::fs::write(&small, "x,y,z\n1,2,3\n4,5,6\n").unwrap();
        let h = peek_point_count(&small).unwrap();
        assert_eq!((h.points, h.exact, h.has_normals), (3, false, Some(false)));
    }
}
