//! Text point readers: XYZ / TXT, PTS and CSV, one point per line. Time O(file size).
//!
//! Rules (the same for all three formats):
//! - Separators: any run of whitespace, `,` or `;` (empty CSV fields are therefore not supported).
//! - Blank lines and lines starting with `#` are skipped; a line starting with `//` is a comment,
//!   except as the first line, where it may carry CloudCompare's header (`//X,Y,Z,Nx,Ny,Nz`).
//! - The first non-comment line may be a single non-negative integer: the point count (PTS style);
//!   it is checked against [`ReadLimits::max_points`] and otherwise ignored.
//! - The first data line may be a header of column names (all tokens non-numeric). Names map
//!   columns case-insensitively: `x y z` (also `px`, `pos_x`, `position_x`, ...) and
//!   `nx ny nz` (also `normal_x`, `n_x`, ...); normals are used only when all three are named.
//! - Without a header, the first data row's column count decides: 6 columns → `x y z nx ny nz`;
//!   any other count ≥ 3 → `x y z` followed by ignored extras (4 = x y z intensity,
//!   7 = x y z intensity r g b, 9 = x y z r g b nx ny nz is NOT guessed: name the columns).
//! - Only the used columns are parsed; `nan` / `inf` parse to non-finite values (passed through).
//!   A row with too few columns or a non-numeric used token is a `Parse` error with its line.
//!
//! Streaming: lines are read one at a time from any [`BufRead`] (a buffered file or a slice), so
//! only the points themselves are held; the point array is reserved from an estimate made on the
//! first 64 KiB, and rows beyond [`ReadLimits::max_points`] or the memory budget
//! ([`ReadLimits::max_memory_mib`]) are refused as they come.

use std::io::{BufRead, Read};
use std::path::Path;

use super::budget::{CountSource, check_reader_memory, estimate_lines, points_within_budget};
use super::stream::{PointSink, VecSink};
use super::{IoError, PointFormat, ReadLimits};
use crate::geometry::PointCloud;

/// Column indices of the used fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct Columns {
    pub(super) xyz: [usize; 3],
    pub(super) normals: Option<[usize; 3]>,
}

impl Columns {
    pub(super) fn min_tokens(&self) -> usize {
        let m = self.xyz.iter().max().copied().unwrap_or(0);
        self.normals
            .map_or(m, |n| m.max(n.iter().max().copied().unwrap_or(0)))
            + 1
    }

    pub(super) fn from_count(n: usize) -> Columns {
        Columns {
            xyz: [0, 1, 2],
            normals: (n == 6).then_some([3, 4, 5]),
        }
    }
}

pub(super) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|&c| c.is_ascii_whitespace() || c == b',' || c == b';')
        .filter(|t| !t.is_empty())
}

pub(super) fn parse_f64(t: &[u8]) -> Option<f64> {
    std::str::from_utf8(t).ok()?.parse::<f64>().ok()
}

/// Canonical field (0..3 xyz, 3..6 normals) of a header name.
fn field_of(name: &[u8]) -> Option<usize> {
    let name = String::from_utf8_lossy(name).to_ascii_lowercase();
    let name = name.trim_matches(|c| c == '"' || c == '\'' || c == '/');
    let axis = |s: &str| match s {
        "x" => Some(0),
        "y" => Some(1),
        "z" => Some(2),
        _ => None,
    };
    if let Some(a) = axis(name) {
        return Some(a);
    }
    for prefix in ["pos_", "position_", "point_", "p", "coord_"] {
        if let Some(a) = name.strip_prefix(prefix).and_then(axis) {
            return Some(a);
        }
    }
    for prefix in ["n", "n_", "normal_", "normal", "nrm_"] {
        if let Some(a) = name.strip_prefix(prefix).and_then(axis) {
            return Some(3 + a);
        }
    }
    None
}

pub(super) fn columns_from_header(
    names: &[&[u8]],
    fmt: &'static str,
    src: &Path,
) -> Result<Columns, IoError> {
    let mut found: [Option<usize>; 6] = [None; 6];
    for (i, n) in names.iter().enumerate() {
        if let Some(f) = field_of(n) {
            found[f].get_or_insert(i);
        }
    }
    let mut xyz = [0; 3];
    for (a, slot) in xyz.iter_mut().enumerate() {
        *slot = found[a].ok_or_else(|| IoError::MissingField {
            path: src.to_path_buf(),
            format: fmt,
            field: ["x", "y", "z"][a].into(),
        })?;
    }
    let normals = match (found[3], found[4], found[5]) {
        (Some(a), Some(b), Some(c)) => Some([a, b, c]),
        _ => None,
    };
    Ok(Columns { xyz, normals })
}

/// Hands rows to a [`PointSink`]; owns the limit checks and error context.
struct Sink<'a, 's> {
    out: &'s mut dyn PointSink,
    /// Rows handed on so far.
    count: u64,
    /// Most points the memory budget allows: without, with normals (checked only when the sink
    /// holds its points).
    budget_points: [u64; 2],
    limits: &'a ReadLimits,
    src: &'a Path,
    fmt: &'static str,
}

impl Sink<'_, '_> {
    fn err(&self, line: usize, message: String) -> IoError {
        IoError::Parse {
            path: self.src.to_path_buf(),
            format: self.fmt,
            line,
            message,
        }
    }

    fn push_row(&mut self, toks: &[&[u8]], c: &Columns, line: usize) -> Result<(), IoError> {
        if toks.len() < c.min_tokens() {
            let msg = format!(
                "expected at least {} columns, found {}",
                c.min_tokens(),
                toks.len()
            );
            return Err(self.err(line, msg));
        }
        if self.count >= self.limits.max_points as u64 {
            return Err(IoError::TooManyPoints {
                path: self.src.to_path_buf(),
                declared: self.count + 1,
                limit: self.limits.max_points,
            });
        }
        let with_normals = c.normals.is_some();
        let next = self.count + 1;
        if self.out.holds_points() && next > self.budget_points[usize::from(with_normals)] {
            let counted = CountSource::ReadSoFar;
            check_reader_memory(next, with_normals, counted, self.limits, self.src)?;
        }
        let get = |k: usize| {
            parse_f64(toks[k]).ok_or_else(|| {
                let t = String::from_utf8_lossy(toks[k]);
                self.err(line, format!("`{t}` (column {}) is not a number", k + 1))
            })
        };
        let p = [get(c.xyz[0])?, get(c.xyz[1])?, get(c.xyz[2])?];
        let n = match c.normals {
            Some(n) => Some([get(n[0])?, get(n[1])?, get(n[2])?]),
            None => None,
        };
        self.count = next;
        self.out.push(p, n)
    }
}

/// The point count of a PTS-style count line (a single non-negative integer), if `toks` is one.
pub(super) fn count_line(toks: &[&[u8]]) -> Option<u64> {
    match toks {
        [t] => std::str::from_utf8(t).ok()?.parse::<u64>().ok(),
        _ => None,
    }
}

/// Empties `v` and hands its allocation on for tokens of the next line (in-place collect).
fn recycle<'a>(mut v: Vec<&[u8]>) -> Vec<&'a [u8]> {
    v.clear();
    v.into_iter().map(|_| &[][..]).collect()
}

impl<'a, 's> Sink<'a, 's> {
    /// A sink over `out`; a sink that holds its points gets room for `estimate` points plus 5 %
    /// (within the point and memory limits): one allocation when the estimate holds.
    fn new(
        estimate: u64,
        limits: &'a ReadLimits,
        src: &'a Path,
        format: PointFormat,
        out: &'s mut dyn PointSink,
    ) -> Self {
        let budget_points = [
            points_within_budget(limits, false),
            points_within_budget(limits, true),
        ];
        let cap = budget_points[0].min(limits.max_points as u64);
        out.reserve(estimate.saturating_add(estimate / 20 + 16).min(cap) as usize);
        Sink {
            out,
            count: 0,
            budget_points,
            limits,
            src,
            fmt: format.name(),
        }
    }
}

/// Reads the next line (with its `\n`) into `raw`; false at the end of the data.
fn next_line<R: BufRead>(
    r: &mut R,
    raw: &mut Vec<u8>,
    line_no: usize,
    sink: &Sink,
) -> Result<bool, IoError> {
    raw.clear();
    let n = Read::take(r, MAX_LINE)
        .read_until(b'\n', raw)
        .map_err(|source| IoError::Read {
            path: sink.src.to_path_buf(),
            source,
        })?;
    if n as u64 == MAX_LINE && raw.last() != Some(&b'\n') {
        return Err(sink.err(line_no, format!("line longer than {MAX_LINE} bytes")));
    }
    Ok(n > 0)
}

/// A PTS count line's point count against the point limit and the memory budget.
pub(super) fn check_count_line(n: u64, limits: &ReadLimits, src: &Path) -> Result<(), IoError> {
    if n > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: n,
            limit: limits.max_points,
        });
    }
    check_reader_memory(n, false, CountSource::Declared, limits, src)
}

/// Longest text line accepted (bytes); a longer one is a parse error, not an unbounded buffer.
pub(super) const MAX_LINE: u64 = 16 << 20;

/// Reads XYZ / PTS / CSV text as described in the module docs from `r`, whose total size is
/// `len` bytes (used to estimate the point count from the first 64 KiB).
pub(crate) fn read_text_points<R: BufRead>(
    r: R,
    len: u64,
    format: PointFormat,
    limits: &ReadLimits,
    src: &Path,
) -> Result<PointCloud, IoError> {
    let mut out = VecSink::default();
    let has_normals = read_text_into(r, len, format, limits, src, &mut out)?;
    Ok(out.into_cloud(has_normals))
}

/// [`read_text_points`] handing each row to `out` as it is parsed; returns whether the rows
/// carry normals.
pub(crate) fn read_text_into<R: BufRead>(
    mut r: R,
    len: u64,
    format: PointFormat,
    limits: &ReadLimits,
    src: &Path,
    out: &mut dyn PointSink,
) -> Result<bool, IoError> {
    let head = r.fill_buf().map_err(|source| IoError::Read {
        path: src.to_path_buf(),
        source,
    })?;
    let mut sink = Sink::new(
        estimate_lines(head, len, |l| !l.is_empty()),
        limits,
        src,
        format,
        out,
    );
    let mut cols: Option<Columns> = None;
    let mut first = true;
    let mut spare: Vec<&[u8]> = Vec::new();
    let mut raw = Vec::new();
    for line_no in 1.. {
        if !next_line(&mut r, &mut raw, line_no, &sink)? {
            break;
        }
        let line = raw.trim_ascii();
        if line.is_empty() || line.starts_with(b"#") {
            continue;
        }
        let is_first = std::mem::replace(&mut first, false);
        let mut toks = recycle(std::mem::take(&mut spare));
        toks.extend(tokens(line));
        if line.starts_with(b"//") {
            if cols.is_none() && is_first {
                cols = columns_from_header(&toks, sink.fmt, src).ok();
            }
            continue;
        }
        if let Some(c) = cols {
            sink.push_row(&toks, &c, line_no)?;
            spare = recycle(toks);
            continue;
        }
        if let Some(n) = count_line(&toks).filter(|_| is_first) {
            check_count_line(n, limits, src)?;
            first = true;
            continue;
        }
        let numeric = toks.iter().filter(|t| parse_f64(t).is_some()).count();
        if numeric == 0 {
            cols = Some(columns_from_header(&toks, sink.fmt, src)?);
            continue;
        }
        if toks.len() < 3 || numeric < 3.min(toks.len()) {
            let msg = match toks.iter().find(|t| parse_f64(t).is_none()) {
                Some(t) => format!("`{}` is not a number", String::from_utf8_lossy(t)),
                None => format!("expected at least 3 numbers (x y z), found {}", toks.len()),
            };
            return Err(sink.err(line_no, msg));
        }
        let c = Columns::from_count(toks.len());
        cols = Some(c);
        sink.push_row(&toks, &c, line_no)?;
        spare = recycle(toks);
    }
    Ok(cols.is_some_and(|c| c.normals.is_some()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point3;
    use crate::io::parse_point_cloud;

    fn read(s: &str, f: PointFormat) -> Result<PointCloud, IoError> {
        parse_point_cloud(s.as_bytes(), f, &ReadLimits::default())
    }

    #[test]
    fn csv_header_in_another_order() {
        let pc = read(
            "nz;x;ny;y;z;nx;intensity\n3;1;2;4;5;1;9\r\n-3;0.5;-2;6;7;-1;9\n",
            PointFormat::Csv,
        )
        .unwrap();
        assert_eq!(pc.points, vec![[1.0, 4.0, 5.0], [0.5, 6.0, 7.0]]);
        assert_eq!(pc.normals, Some(vec![[1.0, 2.0, 3.0], [-1.0, -2.0, -3.0]]));
        let pc = read("\"X\",\"Y\",\"Z\"\n1,2,3\n", PointFormat::Csv).unwrap();
        assert_eq!(pc.points, vec![[1.0, 2.0, 3.0]]);
        let pc = read("//X,Y,Z,Nx,Ny,Nz\n1,2,3,0,0,1\n", PointFormat::Csv).unwrap();
        assert_eq!(pc.normals, Some(vec![[0.0, 0.0, 1.0]]));
    }

    #[test]
    fn column_count_rules() {
        let six = read("1 2 3 0 0 1\n4 5 6 0 1 0\n", PointFormat::Xyz).unwrap();
        assert_eq!(six.normals, Some(vec![[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]));
        for row in ["1 2 3", "1 2 3 0.5", "1 2 3 9 255 0 0", "1,2,3,4,5,6,7,8,9"] {
            let pc = read(&format!("{row}\n{row}\n"), PointFormat::Xyz).unwrap();
            assert_eq!(pc.points, vec![[1.0, 2.0, 3.0]; 2], "{row}");
            assert!(pc.normals.is_none(), "{row}");
        }
    }

    #[test]
    fn pts_count_line_comments_and_non_finite() {
        let pc = read(
            "3\n# comment\n\n1 2 3 10 255 0 0\nnan 2 3 1 1 1 1\n1 inf -inf 1 1 1 1\n",
            PointFormat::Pts,
        )
        .unwrap();
        assert_eq!(pc.points.len(), 3);
        assert!(pc.points[1][0].is_nan() && pc.points[2][1].is_infinite() && pc.points[2][2] < 0.0);
        let limits = ReadLimits {
            max_points: 2,
            max_bytes: 1 << 20,
            ..ReadLimits::default()
        };
        let e = parse_point_cloud(b"1000000000\n1 2 3\n", PointFormat::Pts, &limits).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::TooManyPoints {
                    declared: 1_000_000_000,
                    limit: 2,
                    ..
                }
            ),
            "{e}"
        );
        let e = parse_point_cloud(b"1 2 3\n1 2 3\n1 2 3\n", PointFormat::Xyz, &limits).unwrap_err();
        assert!(
            matches!(e, IoError::TooManyPoints { declared: 3, .. }),
            "{e}"
        );
    }

    #[test]
    fn bad_rows_report_their_line() {
        let e = read("1 2 3\n# c\n4 x 6\n", PointFormat::Xyz).unwrap_err();
        assert!(
            matches!(&e, IoError::Parse { line: 3, message, .. } if message.contains("`x`")),
            "{e}"
        );
        let e = read("1 2 3 0 0 1\n1 2 3\n", PointFormat::Xyz).unwrap_err();
        assert!(matches!(e, IoError::Parse { line: 2, .. }), "{e}");
        let e = read("1 2\n", PointFormat::Xyz).unwrap_err();
        assert!(matches!(e, IoError::Parse { line: 1, .. }), "{e}");
        let e = read("a,y,z\n1,2,3\n", PointFormat::Csv).unwrap_err();
        assert!(
            matches!(&e, IoError::MissingField { field, .. } if field == "x"),
            "{e}"
        );
        let e = read("# only comments\n\n", PointFormat::Xyz).unwrap_err();
        assert!(matches!(e, IoError::Empty { .. }), "{e}");
    }

    #[test]
    fn file_stream_equals_in_memory_and_the_written_values() {
        let mut rng = crate::geometry::synthetic::SplitMix64(11);
        let n = 9000; // about 200 KiB: several buffer refills
        let rows: Vec<[f64; 6]> = (0..n)
            .map(|_| [0; 6].map(|_| rng.next_f64() * 2000.0 - 1000.0))
            .collect();
        let mut text = String::from("//X Y Z Nx Ny Nz\n# comment\n");
        for r in &rows {
            let cells: Vec<String> = r.iter().map(|v| format!("{v:e}")).collect();
            text.push_str(&cells.join(" "));
            text.push('\n');
        }
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cloud.xyz");
        std::fs::write(&p, &text).unwrap();
        let from_file = crate::io::read_point_cloud(&p, &ReadLimits::default()).unwrap();
        let in_memory = read(&text, PointFormat::Xyz).unwrap();
        let want: Vec<Point3> = rows.iter().map(|r| [r[0], r[1], r[2]]).collect();
        let want_n: Vec<Point3> = rows.iter().map(|r| [r[3], r[4], r[5]]).collect();
        assert_eq!(from_file.points, want);
        assert_eq!(from_file.normals.as_ref(), Some(&want_n));
        assert_eq!(in_memory.points, want);
        assert_eq!(in_memory.normals, Some(want_n));
    }
}
