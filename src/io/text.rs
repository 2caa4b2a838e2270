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

use std::path::Path;

use super::{IoError, PointFormat, ReadLimits};
use crate::geometry::{Point3, PointCloud};

/// Column indices of the used fields.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Columns {
    xyz: [usize; 3],
    normals: Option<[usize; 3]>,
}

impl Columns {
    fn min_tokens(&self) -> usize {
        let m = self.xyz.iter().max().copied().unwrap_or(0);
        self.normals
            .map_or(m, |n| m.max(n.iter().max().copied().unwrap_or(0)))
            + 1
    }

    fn from_count(n: usize) -> Columns {
        Columns {
            xyz: [0, 1, 2],
            normals: (n == 6).then_some([3, 4, 5]),
        }
    }
}

fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|&c| c.is_ascii_whitespace() || c == b',' || c == b';')
        .filter(|t| !t.is_empty())
}

fn parse_f64(t: &[u8]) -> Option<f64> {
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

fn columns_from_header(names: &[&[u8]], fmt: &'static str, src: &Path) -> Result<Columns, IoError> {
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

/// Accumulates rows; owns the limit checks and error context.
struct Sink<'a> {
    points: Vec<Point3>,
    normals: Vec<Point3>,
    limits: &'a ReadLimits,
    src: &'a Path,
    fmt: &'static str,
}

impl Sink<'_> {
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
        if self.points.len() >= self.limits.max_points {
            return Err(IoError::TooManyPoints {
                path: self.src.to_path_buf(),
                declared: self.points.len() as u64 + 1,
                limit: self.limits.max_points,
            });
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
        self.points.push(p);
        self.normals.extend(n);
        Ok(())
    }
}

/// The point count of a PTS-style count line (a single non-negative integer), if `toks` is one.
fn count_line(toks: &[&[u8]]) -> Option<u64> {
    match toks {
        [t] => std::str::from_utf8(t).ok()?.parse::<u64>().ok(),
        _ => None,
    }
}

/// Reads XYZ / PTS / CSV text as described in the module docs.
pub(crate) fn read_text_points(
    bytes: &[u8],
    format: PointFormat,
    limits: &ReadLimits,
    src: &Path,
) -> Result<PointCloud, IoError> {
    let mut sink = Sink {
        points: Vec::new(),
        normals: Vec::new(),
        limits,
        src,
        fmt: format.name(),
    };
    let mut cols: Option<Columns> = None;
    let mut first = true;
    let mut toks: Vec<&[u8]> = Vec::new();
    for (i, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line_no = i + 1;
        let line = raw.trim_ascii();
        if line.is_empty() || line.starts_with(b"#") {
            continue;
        }
        let is_first = std::mem::replace(&mut first, false);
        toks.clear();
        toks.extend(tokens(line));
        if line.starts_with(b"//") {
            if cols.is_none() && is_first {
                cols = columns_from_header(&toks, sink.fmt, src).ok();
            }
            continue;
        }
        if let Some(c) = cols {
            sink.push_row(&toks, &c, line_no)?;
            continue;
        }
        if let Some(n) = count_line(&toks).filter(|_| is_first) {
            if n > limits.max_points as u64 {
                return Err(IoError::TooManyPoints {
                    path: src.to_path_buf(),
                    declared: n,
                    limit: limits.max_points,
                });
            }
            // Reserve, bounded by what the bytes can hold (at least 6 bytes per point).
            sink.points.reserve((n as usize).min(bytes.len() / 6));
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
    }
    let has_normals = cols.is_some_and(|c| c.normals.is_some());
    Ok(PointCloud {
        points: sink.points,
        normals: has_normals.then_some(sink.normals),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
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
}
