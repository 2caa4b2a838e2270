//! Wavefront OBJ reader: `v x y z [w | r g b]` vertices, `vn` normals and `f` faces
//! (`a`, `a/b`, `a//c`, `a/b/c`, negative = relative indices; polygons fan-triangulated).
//! Every other statement (groups, materials, texture coordinates, lines) is ignored.
//! Time O(file size).
//!
//! Reference: Wavefront Technologies, "Object Files (.obj)", Advanced Visualizer manual, appendix B.

use std::path::Path;

use super::{IoError, ReadLimits};
use crate::geometry::{Point3, PointCloud, TriMesh, normalized};

/// Everything the readers keep from an OBJ file.
#[derive(Default)]
struct ObjData {
    v: Vec<Point3>,
    vn: Vec<Point3>,
    tris: Vec<[u32; 3]>,
    /// False once a face corner refers to a normal index different from its vertex index.
    normals_follow_vertices: bool,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Want {
    Points,
    Mesh,
}

/// Reads `v` lines as points; `vn` become normals only when there are exactly as many as `v`.
pub(crate) fn read_obj_points(
    bytes: &[u8],
    limits: &ReadLimits,
    src: &Path,
) -> Result<PointCloud, IoError> {
    let d = parse(bytes, limits, src, Want::Points)?;
    let normals = (!d.vn.is_empty() && d.vn.len() == d.v.len()).then_some(d.vn);
    Ok(PointCloud {
        points: d.v,
        normals,
        ..Default::default()
    })
}

/// Reads `v` + `f` as a triangle mesh. Normals are kept (unit length) only when `#vn == #v` and
/// every face corner's normal index equals its vertex index (as [`super::write_mesh`] writes).
pub(crate) fn read_obj_mesh(
    bytes: &[u8],
    limits: &ReadLimits,
    src: &Path,
) -> Result<TriMesh, IoError> {
    let d = parse(bytes, limits, src, Want::Mesh)?;
    let n = d.v.len();
    if let Some(bad) = d.tris.iter().flatten().find(|&&i| i as usize >= n) {
        return Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "OBJ",
            message: format!("face refers to vertex {} but there are only {n}", bad + 1),
        });
    }
    if n == 0 {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "OBJ has no `v` lines".into(),
        });
    }
    let normals = if d.vn.len() == n && d.normals_follow_vertices {
        d.vn.into_iter()
            .map(|v| normalized(v).unwrap_or([0.0; 3]))
            .collect()
    } else {
        Vec::new()
    };
    Ok(TriMesh {
        vertices: d.v,
        normals,
        triangles: d.tris,
        colors: Vec::new(),
    })
}

fn parse(bytes: &[u8], limits: &ReadLimits, src: &Path, want: Want) -> Result<ObjData, IoError> {
    let perr = |line: usize, message: String| IoError::Parse {
        path: src.to_path_buf(),
        format: "OBJ",
        line,
        message,
    };
    let mut d = ObjData {
        normals_follow_vertices: true,
        ..ObjData::default()
    };
    let mut poly: Vec<u32> = Vec::new();
    for (i, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line_no = i + 1;
        let mut toks = raw.split(u8::is_ascii_whitespace).filter(|t| !t.is_empty());
        match toks.next() {
            Some(b"v") => {
                if d.v.len() >= limits.max_points {
                    return Err(IoError::TooManyPoints {
                        path: src.to_path_buf(),
                        declared: d.v.len() as u64 + 1,
                        limit: limits.max_points,
                    });
                }
                d.v.push(three(&mut toks).map_err(|m| perr(line_no, m))?);
            }
            Some(b"vn") => d.vn.push(three(&mut toks).map_err(|m| perr(line_no, m))?),
            Some(b"f") if want == Want::Mesh => {
                poly.clear();
                for t in toks {
                    let (vi, ni) =
                        corner(t, d.v.len(), d.vn.len()).map_err(|m| perr(line_no, m))?;
                    if ni.is_some_and(|n| n != vi) {
                        d.normals_follow_vertices = false;
                    }
                    poly.push(vi);
                }
                super::ply::fan(&poly, &mut d.tris);
            }
            _ => {}
        }
    }
    Ok(d)
}

/// The first three numbers of a `v` / `vn` statement (extra values such as `w` or colours ignored).
fn three<'a>(toks: &mut impl Iterator<Item = &'a [u8]>) -> Result<Point3, String> {
    let mut p = [0.0; 3];
    for (k, slot) in p.iter_mut().enumerate() {
        let t = toks
            .next()
            .ok_or_else(|| format!("expected 3 coordinates, found {k}"))?;
        *slot = std::str::from_utf8(t)
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
            .ok_or_else(|| format!("`{}` is not a number", String::from_utf8_lossy(t)))?;
    }
    Ok(p)
}

/// Resolves one face corner `a[/b[/c]]` to 0-based (vertex, normal) indices.
fn corner(t: &[u8], nv: usize, nvn: usize) -> Result<(u32, Option<u32>), String> {
    let mut parts = t.split(|&b| b == b'/');
    let v = parts.next().unwrap_or_default();
    let vi = resolve(v, nv)?.ok_or_else(|| "face corner without a vertex index".to_string())?;
    let _tex = parts.next();
    let ni = match parts.next() {
        Some(n) => resolve(n, nvn)?,
        None => None,
    };
    Ok((vi, ni))
}

/// 1-based or negative (relative to the `count` seen so far) index → 0-based; empty → `None`.
fn resolve(t: &[u8], count: usize) -> Result<Option<u32>, String> {
    if t.is_empty() {
        return Ok(None);
    }
    let i: i64 = std::str::from_utf8(t)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| format!("`{}` is not an index", String::from_utf8_lossy(t)))?;
    let abs = match i {
        0 => return Err("index 0 is invalid (OBJ indices start at 1)".into()),
        i if i > 0 => i - 1,
        i => count as i64 + i,
    };
    u32::try_from(abs)
        .map(Some)
        .map_err(|_| format!("index {i} is out of range ({count} defined so far)"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{PointFormat, parse_point_cloud};

    const SRC: &str = "# cube corner\nv 0 0 0\nv 1 0 0 1.0\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\nvn 0 0 2\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nvt 0 0\ng quad\nf 1//1 2//2 3//3 4//4\nf -4 -2 -1\nl 1 2\n";

    #[test]
    fn points_with_normals_only_when_counts_match() {
        let pc =
            parse_point_cloud(SRC.as_bytes(), PointFormat::Obj, &ReadLimits::default()).unwrap();
        assert_eq!(pc.points[2], [1.0, 1.0, 0.0]);
        assert_eq!(pc.normals.as_ref().map(Vec::len), Some(4));
        let fewer = SRC.replace("vn 0 0 2\n", "");
        let pc =
            parse_point_cloud(fewer.as_bytes(), PointFormat::Obj, &ReadLimits::default()).unwrap();
        assert!(pc.normals.is_none());
        let e =
            parse_point_cloud(b"v 1 2\n", PointFormat::Obj, &ReadLimits::default()).unwrap_err();
        assert!(matches!(e, IoError::Parse { line: 1, .. }), "{e}");
    }

    #[test]
    fn mesh_faces_all_corner_forms() {
        let m = read_obj_mesh(SRC.as_bytes(), &ReadLimits::default(), Path::new("c.obj")).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
        assert_eq!(
            m.normals[0],
            [0.0, 0.0, 1.0],
            "normals are made unit length"
        );
        let forms = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\nf 1/1 2/1/1 3//1\n";
        let m =
            read_obj_mesh(forms.as_bytes(), &ReadLimits::default(), Path::new("f.obj")).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert!(m.normals.is_empty(), "#vn != #v");
        for bad in [
            "v 0 0 0\nf 1 2 0\n",
            "v 0 0 0\nf 1 -2 1\n",
            "v 0 0 0\nf 1 a 1\n",
        ] {
            let e = read_obj_mesh(bad.as_bytes(), &ReadLimits::default(), Path::new("b.obj"))
                .unwrap_err();
            assert!(matches!(e, IoError::Parse { line: 2, .. }), "{bad}: {e}");
        }
        let e = read_obj_mesh(
            b"v 0 0 0\nf 1 2 3\n",
            &ReadLimits::default(),
            Path::new("b.obj"),
        )
        .unwrap_err();
        assert!(matches!(e, IoError::Invalid { .. }), "{e}");
    }
}
