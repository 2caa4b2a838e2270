//! The 2D curve text format.
//!
//! One sample per line, whitespace- or comma-separated:
//!
//! ```text
//! # comment (also after data: "1 2  # note")
//! x y                 on-curve point (value 0), no normal
//! x y value           point with a value: < 0 interior, > 0 exterior (|value| is the weight)
//! x y nx ny           on-curve point with an outward normal (any non-zero length)
//! x y nx ny value     point with normal and value
//! ```
//!
//! Blank lines are ignored. Numbers are Rust `f64` syntax (`1e-3`, `-0.5`, `inf` is rejected by
//! validation later). Rows in later errors are the 0-based data lines (comments and blank lines
//! excluded; [`parse_curve_lines`] maps them to file lines); parse errors give the 1-based file
//! line. `O(file size)`.

use super::constraints::{Sample, VariationalError};

/// Parse curve text into samples.
///
/// ```
/// use rbfsurf::variational::curve_io::parse_curve;
/// let s = parse_curve("# square\n0 0 -1 -1\n1 0 1 -1\n1 1 1 1\n0 1 -1 1\n0.5 0.5 -1\n").unwrap();
/// assert_eq!(s.len(), 5);
/// assert_eq!(s[4].value, -1.0);
/// assert_eq!(s[1].normal, Some([1.0, -1.0]));
/// ```
pub fn parse_curve(text: &str) -> Result<Vec<Sample<2>>, VariationalError> {
    parse_curve_lines(text).map(|(s, _)| s)
}

/// [`parse_curve`] that also returns the 1-based file line of every sample, so that errors
/// naming sample rows ([`VariationalError::rows`]) can be reported as file lines.
pub fn parse_curve_lines(text: &str) -> Result<(Vec<Sample<2>>, Vec<usize>), VariationalError> {
    let mut out = Vec::new();
    let mut lines = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("");
        let toks: Vec<&str> = line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
            .collect();
        if toks.is_empty() {
            continue;
        }
        let nums: Vec<f64> = toks
            .iter()
            .map(|t| {
                t.parse::<f64>().map_err(|_| VariationalError::Parse {
                    line: k + 1,
                    message: format!("{t:?} is not a number"),
                })
            })
            .collect::<Result<_, _>>()?;
        let s = match *nums.as_slice() {
            [x, y] => Sample {
                p: [x, y],
                normal: None,
                value: 0.0,
            },
            [x, y, v] => Sample {
                p: [x, y],
                normal: None,
                value: v,
            },
            [x, y, nx, ny] => Sample {
                p: [x, y],
                normal: Some([nx, ny]),
                value: 0.0,
            },
            [x, y, nx, ny, v] => Sample {
                p: [x, y],
                normal: Some([nx, ny]),
                value: v,
            },
            _ => {
                return Err(VariationalError::Parse {
                    line: k + 1,
                    message: format!(
                        "{} numbers; expected 2 (x y), 3 (x y value), 4 (x y nx ny) or 5",
                        nums.len()
                    ),
                });
            }
        };
        out.push(s);
        lines.push(k + 1);
    }
    if out.is_empty() {
        return Err(VariationalError::Parse {
            line: 0,
            message: "no data lines".into(),
        });
    }
    Ok((out, lines))
}

/// Write samples in the same format (round-trips through [`parse_curve`] exactly).
pub fn write_curve(samples: &[Sample<2>]) -> String {
    let mut s = String::from("# x y [nx ny] [value]  (value < 0 inside, > 0 outside)\n");
    for x in samples {
        let mut line = format!("{:?} {:?}", x.p[0], x.p[1]);
        if let Some(n) = x.normal {
            line += &format!(" {:?} {:?}", n[0], n[1]);
        }
        if x.value != 0.0 {
            line += &format!(" {:?}", x.value);
        }
        s += &line;
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variational::datasets;

    #[test]
    fn round_trip_and_errors() {
        for name in ["shen27", "koch2-interior", "five-point"] {
            let s = datasets::by_name(name).unwrap();
            assert_eq!(parse_curve(&write_curve(&s)).unwrap(), s);
        }
        assert_eq!(
            parse_curve("0 0\n\n1 2 3 4 5 6\n"),
            Err(VariationalError::Parse {
                line: 3,
                message: "6 numbers; expected 2 (x y), 3 (x y value), 4 (x y nx ny) or 5".into()
            })
        );
        assert!(matches!(
            parse_curve("0 0\n1 x\n"),
            Err(VariationalError::Parse { line: 2, .. })
        ));
        assert_eq!(parse_curve("1,2 # c\n").unwrap()[0].p, [1.0, 2.0]);
    }
}
