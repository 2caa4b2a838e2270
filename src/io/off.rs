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
    bytes.split(|&b| b == b'\n').enumerate().filter_map(|(i, raw)| {
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

/// Reads an ASCII OFF file as a triangle mesh, validating every index.
pub(crate) fn read_off(bytes: &[u8], limits: &ReadLimits, src: &Path) -> Result<TriMesh, IoError> {
    let perr = |line: usize, message: String| IoError::Parse {
        path: src.to_path_buf(),
        format: "OFF",
        line,
        message,
    };
    let mut lines = logical_lines(bytes);
    let (mut line_no, mut toks) = lines.next().ok_or_else(|| IoError::Empty {
        path: src.to_path_buf(),
        what: "OFF file has no content".into(),
    })?;
    let mut has_normals = false;
    let kw = String::from_utf8_lossy(toks[0]).to_string();
    if let Some(prefix) = kw.strip_suffix("OFF") {
        if toks.iter().any(|t| t.eq_ignore_ascii_case(b"BINARY")) || prefix.contains('4') || prefix.contains('n') {
            return Err(IoError::Unsupported {
                path: src.to_path_buf(),
                format: "OFF",
                feature: format!("the `{kw}` variant (binary, 4D or n-dimensional)"),
            });
        }
        has_normals = prefix.contains('N');
        toks.remove(0);
        if toks.is_empty() {
            (line_no, toks) = lines
                .next()
                .ok_or_else(|| perr(line_no, "missing vertex/face counts".into()))?;
        }
    }
    let (nv, nf) = match (toks.first().and_then(|t| num::<u64>(t)), toks.get(1).and_then(|t| num::<u64>(t))) {
        (Some(a), Some(b)) => (a, b),
        _ => return Err(perr(line_no, "expected `<vertices> <faces> [edges]` counts".into())),
    };
    if nv > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: nv,
            limit: limits.max_points,
        });
    }
    let cap = (nv as usize).min(bytes.len() / 6);
    let mut vertices: Vec<Point3> = Vec::with_capacity(cap);
    let mut normals: Vec<Point3> = Vec::with_capacity(if has_normals { cap } else { 0 });
    let ends = |line: usize, what: &str| perr(line, format!("data ends early: header declares {nv} vertices and {nf} faces, {what}"));
    for k in 0..nv {
        let (ln, t) = lines.next().ok_or_else(|| ends(line_no, &format!("found {k} vertices")))?;
        line_no = ln;
        let mut f = [0.0f64; 6];
        let want = if has_normals { 6 } else { 3 };
        for (j, slot) in f.iter_mut().enumerate().take(want) {
            let tok = t.get(j).ok_or_else(|| perr(ln, format!("expected {want} numbers per vertex, found {}", t.len())))?;
            *slot = num(tok).ok_or_else(|| perr(ln, format!("`{}` is not a number", String::from_utf8_lossy(tok))))?;
        }
        vertices.push([f[0], f[1], f[2]]);
        if has_normals {
            normals.push(normalized([f[3], f[4], f[5]]).unwrap_or([0.0; 3]));
        }
    }
    let mut triangles = Vec::new();
    let mut poly: Vec<u32> = Vec::new();
    for k in 0..nf {
        let (ln, t) = lines.next().ok_or_else(|| ends(line_no, &format!("found {k} faces")))?;
        line_no = ln;
        let size: usize = num(t[0]).ok_or_else(|| perr(ln, "face must start with its vertex count".into()))?;
        if t.len() <= size {
            return Err(perr(ln, format!("face declares {size} vertices but lists {}", t.len() - 1)));
        }
        poly.clear();
        for tok in &t[1..=size] {
            let i: u32 = num(tok)
                .filter(|&i: &u32| u64::from(i) < nv)
                .ok_or_else(|| perr(ln, format!("`{}` is not a vertex index below {nv}", String::from_utf8_lossy(tok))))?;
            poly.push(i);
        }
        super::ply::fan(&poly, &mut triangles);
    }
    Ok(TriMesh {
        vertices,
        normals,
        triangles,
    })
}
