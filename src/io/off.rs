//! Geomview OFF mesh reader (ASCII): `[ST][C][N]OFF` keyword (optional), `nv nf ne` counts, one
//! vertex per line (extra values after x y z ignored; with `N`, the next three are the normal),
//! one face per line `k i1 … ik [colour]`, polygons fan-triangulated. `#` starts a comment.
//! Time O(file size).
//!
//! Reference: Geomview manual, "OFF files" (<http://www.geomview.org/docs/html/OFF.html>).

use std::path::Path;

use super::{IoError, ReadLimits};
use crate::geometry::{Point3, TriMesh, normalized};

/// Non-empty lines with comments removed, with their 1-based line numbers.
fn logical_lines(bytes: &[u8]) -> impl Iterator<Item = (usize, Vec<&[u8]>)> {
    bytes
        .split(|&b| b == b'\n')
        .enumerate()
        .filter_map(|(i, raw)| {
            let body = raw.split(|&b| b == b'#').next().unwrap_or_default();
            let toks: Vec<&[u8]> = body
                .split(u8::is_ascii_whitespace)
                .filter(|t| !t.is_empty())
                .collect();
            (!toks.is_empty()).then_some((i + 1, toks))
        })
}

fn num<T: std::str::FromStr>(t: &[u8]) -> Option<T> {
    std::str::from_utf8(t).ok()?.parse().ok()
}

/// Line cursor with the error context of one OFF file.
struct Cursor<'a, I> {
    lines: I,
    line: usize,
    src: &'a Path,
}

impl<'b, I: Iterator<Item = (usize, Vec<&'b [u8]>)>> Cursor<'_, I> {
    fn err(&self, line: usize, message: String) -> IoError {
        IoError::Parse {
            path: self.src.to_path_buf(),
            format: "OFF",
            line,
            message,
        }
    }

    /// The next non-empty line, or an error saying what was expected.
    fn next(&mut self, expected: impl FnOnce() -> String) -> Result<Vec<&'b [u8]>, IoError> {
        match self.lines.next() {
            Some((ln, toks)) => {
                self.line = ln;
                Ok(toks)
            }
            None => Err(self.err(self.line, format!("data ends early: {}", expected()))),
        }
    }

    fn number<T: std::str::FromStr>(&self, tok: &[u8], what: &str) -> Result<T, IoError> {
        num(tok).ok_or_else(|| {
            let t = String::from_utf8_lossy(tok);
            self.err(self.line, format!("`{t}` is not {what}"))
        })
    }
}

/// Parses the keyword and counts: returns (vertices, faces, per-vertex normals present).
fn header<'b, I>(c: &mut Cursor<'_, I>) -> Result<(u64, u64, bool), IoError>
where
    I: Iterator<Item = (usize, Vec<&'b [u8]>)>,
{
    let mut toks = c.next(|| "the file has no content".into())?;
    let mut has_normals = false;
    let kw = String::from_utf8_lossy(toks[0]).to_string();
    if let Some(prefix) = kw.strip_suffix("OFF") {
        let binary = toks.iter().any(|t| t.eq_ignore_ascii_case(b"BINARY"));
        if binary || prefix.contains('4') || prefix.contains('n') {
            return Err(IoError::Unsupported {
                path: c.src.to_path_buf(),
                format: "OFF",
                feature: format!("the `{kw}` variant (binary, 4D or n-dimensional)"),
            });
        }
        has_normals = prefix.contains('N');
        toks.remove(0);
        if toks.is_empty() {
            toks = c.next(|| "missing vertex/face counts".into())?;
        }
    }
    if toks.len() < 2 {
        return Err(c.err(
            c.line,
            "expected `<vertices> <faces> [edges]` counts".into(),
        ));
    }
    let nv = c.number(toks[0], "a vertex count")?;
    let nf = c.number(toks[1], "a face count")?;
    Ok((nv, nf, has_normals))
}

/// Reads an ASCII OFF file as a triangle mesh, validating every index.
pub(crate) fn read_off(bytes: &[u8], limits: &ReadLimits, src: &Path) -> Result<TriMesh, IoError> {
    let mut c = Cursor {
        lines: logical_lines(bytes),
        line: 1,
        src,
    };
    let (nv, nf, has_normals) = header(&mut c)?;
    if nv > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: nv,
            limit: limits.max_points,
        });
    }
    // Bounded by what the bytes can hold (at least 6 bytes per vertex line).
    let cap = (nv as usize).min(bytes.len() / 6);
    let mut mesh = TriMesh {
        vertices: Vec::with_capacity(cap),
        normals: Vec::with_capacity(if has_normals { cap } else { 0 }),
        triangles: Vec::new(),
        colors: Vec::new(),
    };
    let want = if has_normals { 6 } else { 3 };
    for k in 0..nv {
        let t = c.next(|| format!("header declares {nv} vertices, found {k}"))?;
        if t.len() < want {
            let msg = format!("expected {want} numbers per vertex, found {}", t.len());
            return Err(c.err(c.line, msg));
        }
        let mut f = [0.0f64; 6];
        for (slot, tok) in f.iter_mut().zip(&t[..want]) {
            *slot = c.number(tok, "a number")?;
        }
        mesh.vertices.push([f[0], f[1], f[2]]);
        if has_normals {
            let n: Point3 = [f[3], f[4], f[5]];
            mesh.normals.push(normalized(n).unwrap_or([0.0; 3]));
        }
    }
    let mut poly: Vec<u32> = Vec::new();
    for k in 0..nf {
        let t = c.next(|| format!("header declares {nf} faces, found {k}"))?;
        let size: usize = c.number(t[0], "a face size")?;
        if t.len() <= size {
            let msg = format!("face declares {size} vertices but lists {}", t.len() - 1);
            return Err(c.err(c.line, msg));
        }
        poly.clear();
        for tok in &t[1..=size] {
            let i: u32 = c.number(tok, "a vertex index")?;
            if u64::from(i) >= nv {
                return Err(c.err(c.line, format!("vertex index {i} is not below {nv}")));
            }
            poly.push(i);
        }
        super::ply::fan(&poly, &mut mesh.triangles);
    }
    Ok(mesh)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(s: &str) -> Result<TriMesh, IoError> {
        read_off(s.as_bytes(), &ReadLimits::default(), Path::new("m.off"))
    }

    #[test]
    fn quads_comments_and_header_variants() {
        let cube_face = "OFF # a square\n# counts next\n4 1 0\n0 0 0\n1 0 0 # corner\n1 1 0 0.1 0.2 0.3 1\n0 1 0\n\n4 0 1 2 3 255 0 0\n";
        let m = read(cube_face).unwrap();
        assert_eq!(m.vertices[2], [1.0, 1.0, 0.0]);
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        let inline = read("OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 2 1 0\n").unwrap();
        assert_eq!(inline.triangles, vec![[2, 1, 0]]);
        let bare = read("3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap();
        assert_eq!(bare.triangles.len(), 1);
        let n = read("NOFF\n3 1 0\n0 0 0 0 0 2\n1 0 0 0 0 1\n0 1 0 0 0 1\n3 0 1 2\n").unwrap();
        assert_eq!(n.normals[0], [0.0, 0.0, 1.0]);
    }

    #[test]
    fn errors() {
        let e = read("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n").unwrap_err();
        assert!(matches!(e, IoError::Parse { line: 6, .. }), "{e}");
        let e = read("OFF\n3 1 0\n0 0 0\n1 0 0\n").unwrap_err();
        assert!(matches!(e, IoError::Parse { .. }), "{e}");
        let e = read("OFF\n1 0 0\n0 x 0\n").unwrap_err();
        assert!(matches!(e, IoError::Parse { line: 3, .. }), "{e}");
        let e = read("OFF BINARY\n").unwrap_err();
        assert!(matches!(e, IoError::Unsupported { .. }), "{e}");
        let e = read("OFF\n1000000000 1 0\n").unwrap_err();
        assert!(matches!(e, IoError::TooManyPoints { .. }), "{e}");
        let e = read("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n18446744073709551615 0 1 2\n").unwrap_err();
        assert!(matches!(e, IoError::Parse { .. }), "{e}");
    }
}
