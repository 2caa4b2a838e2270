//! Stanford PLY reader (own parser): header, then the `vertex` element as points (x, y, z and
//! optional nx, ny, nz) and, for meshes, the `face` element's index lists (fan-triangulated).
//!
//! Handles `ascii`, `binary_little_endian` and `binary_big_endian`, every scalar type under both
//! naming schemes, any property order, list properties and unrelated elements in any position, and
//! CRLF header lines. Before any allocation proportional to a declared count it checks the vertex
//! count against [`ReadLimits::max_points`] and the minimum body size implied by the header against
//! the bytes present. Time O(file size), memory O(points).
//!
//! Reference: G. Turk, "The PLY Polygon File Format" (1994).

use std::path::Path;

mod header;

use header::{Element, Encoding, Header, PropKind, Scalar, parse_err, parse_header};

use super::{IoError, ReadLimits};
use crate::geometry::{Point3, PointCloud, TriMesh};

/// Source of property values: the ASCII token stream or the binary byte stream.
trait Body {
    /// File name for error messages.
    fn src(&self) -> &Path;
    fn scalar(&mut self, t: Scalar, el: &str) -> Result<f64, IoError>;
    /// Skips `n` scalars of type `t`.
    fn skip(&mut self, t: Scalar, n: u64, el: &str) -> Result<(), IoError>;
}

struct BinBody<'a> {
    data: &'a [u8],
    pos: usize,
    big: bool,
    src: &'a Path,
}

impl BinBody<'_> {
    fn truncated(&self, need: u64, el: &str) -> IoError {
        IoError::Truncated {
            path: self.src.to_path_buf(),
            format: "binary PLY",
            what: format!("element `{el}` needs more data at body offset {}", self.pos),
            expected: need,
            found: self.data.len() as u64,
        }
    }
}

impl Body for BinBody<'_> {
    fn src(&self) -> &Path {
        self.src
    }

    fn scalar(&mut self, t: Scalar, el: &str) -> Result<f64, IoError> {
        let n = t.size();
        let Some(b) = self.data.get(self.pos..self.pos + n) else {
            return Err(self.truncated((self.pos + n) as u64, el));
        };
        self.pos += n;
        Ok(t.decode(b, self.big))
    }

    fn skip(&mut self, t: Scalar, n: u64, el: &str) -> Result<(), IoError> {
        let need = u128::from(n) * t.size() as u128 + self.pos as u128;
        if need > self.data.len() as u128 {
            return Err(self.truncated(u64::try_from(need).unwrap_or(u64::MAX), el));
        }
        self.pos = need as usize;
        Ok(())
    }
}

struct AsciiBody<'a> {
    data: &'a [u8],
    pos: usize,
    line: usize,
    src: &'a Path,
}

impl<'a> AsciiBody<'a> {
    fn token(&mut self, el: &str) -> Result<&'a [u8], IoError> {
        while let Some(&b) = self.data.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            if b == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        let start = self.pos;
        while self
            .data
            .get(self.pos)
            .is_some_and(|b| !b.is_ascii_whitespace())
        {
            self.pos += 1;
        }
        if start == self.pos {
            return Err(parse_err(
                self.src,
                self.line,
                format!("data ends inside element `{el}` (fewer records than the header declares)"),
            ));
        }
        Ok(&self.data[start..self.pos])
    }
}

impl Body for AsciiBody<'_> {
    fn src(&self) -> &Path {
        self.src
    }

    fn scalar(&mut self, _t: Scalar, el: &str) -> Result<f64, IoError> {
        let tok = self.token(el)?;
        std::str::from_utf8(tok)
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
            .ok_or_else(|| {
                parse_err(
                    self.src,
                    self.line,
                    format!(
                        "`{}` in element `{el}` is not a number",
                        String::from_utf8_lossy(tok)
                    ),
                )
            })
    }

    fn skip(&mut self, _t: Scalar, n: u64, el: &str) -> Result<(), IoError> {
        for _ in 0..n {
            self.token(el)?;
        }
        Ok(())
    }
}

/// What to extract from the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Want {
    Points,
    Mesh,
}

/// Points, optional normals and (for [`Want::Mesh`]) fan-triangulated faces.
struct PlyContent {
    points: Vec<Point3>,
    normals: Option<Vec<Point3>>,
    triangles: Vec<[u32; 3]>,
}

/// Reads the `vertex` element of a PLY file as a point cloud (other elements skipped).
pub(crate) fn read_ply_points(
    bytes: &[u8],
    limits: &ReadLimits,
    src: &Path,
) -> Result<PointCloud, IoError> {
    let c = read_ply(bytes, limits, src, Want::Points)?;
    Ok(PointCloud {
        points: c.points,
        normals: c.normals,
    })
}

/// Reads `vertex` + `face` (`vertex_indices` or `vertex_index` list) as a triangle mesh.
pub(crate) fn read_ply_mesh(
    bytes: &[u8],
    limits: &ReadLimits,
    src: &Path,
) -> Result<TriMesh, IoError> {
    let c = read_ply(bytes, limits, src, Want::Mesh)?;
    let n = c.points.len();
    if let Some(bad) = c.triangles.iter().flatten().find(|&&i| i as usize >= n) {
        return Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "PLY",
            message: format!("face refers to vertex {bad} but there are only {n} vertices"),
        });
    }
    let normals = c
        .normals
        .map(|ns| {
            ns.into_iter()
                .map(|v| crate::geometry::normalized(v).unwrap_or([0.0; 3]))
                .collect()
        })
        .unwrap_or_default();
    Ok(TriMesh {
        vertices: c.points,
        normals,
        triangles: c.triangles,
    })
}

/// Column slots of the vertex element: 0..3 = xyz, 3..6 = normals, `None` = ignored.
fn vertex_slots(el: &Element, src: &Path) -> Result<(Vec<Option<usize>>, bool), IoError> {
    let names: [&[&str]; 6] = [
        &["x"],
        &["y"],
        &["z"],
        &["nx", "normal_x"],
        &["ny", "normal_y"],
        &["nz", "normal_z"],
    ];
    let mut slots = vec![None; el.props.len()];
    let mut found = [false; 6];
    for (i, p) in el.props.iter().enumerate() {
        if !matches!(p.kind, PropKind::Scalar(_)) {
            continue;
        }
        let slot = names
            .iter()
            .position(|alts| alts.contains(&p.name.as_str()));
        if let Some(s) = slot.filter(|&s| !found[s]) {
            found[s] = true;
            slots[i] = Some(s);
        }
    }
    if let Some(miss) = (0..3).find(|&s| !found[s]) {
        return Err(IoError::MissingField {
            path: src.to_path_buf(),
            format: "PLY",
            field: names[miss][0].to_string(),
        });
    }
    let normals = found[3..].iter().all(|&f| f);
    if !normals {
        slots
            .iter_mut()
            .filter(|s| s.is_some_and(|k| k >= 3))
            .for_each(|s| *s = None);
    }
    Ok((slots, normals))
}

/// Fails fast when the body is shorter than the header's elements need at minimum.
fn check_body_size(h: &Header, body_len: usize, src: &Path) -> Result<(), IoError> {
    let need: u128 = h
        .elements
        .iter()
        .map(|e| u128::from(e.count) * u128::from(e.min_record_bytes(h.encoding)))
        .sum();
    // The last ASCII token needs no trailing separator.
    let slack = u128::from(h.encoding == Encoding::Ascii);
    if need > body_len as u128 + slack {
        let what = h
            .elements
            .iter()
            .map(|e| format!("{} `{}` records", e.count, e.name))
            .collect::<Vec<_>>()
            .join(" + ");
        return Err(IoError::Truncated {
            path: src.to_path_buf(),
            format: h.encoding.label(),
            what: format!("header declares {what}"),
            expected: u64::try_from(need).unwrap_or(u64::MAX),
            found: body_len as u64,
        });
    }
    Ok(())
}

fn read_ply(
    bytes: &[u8],
    limits: &ReadLimits,
    src: &Path,
    want: Want,
) -> Result<PlyContent, IoError> {
    let h = parse_header(bytes, src)?;
    let vi = h
        .elements
        .iter()
        .position(|e| e.name == "vertex")
        .ok_or_else(|| IoError::MissingField {
            path: src.to_path_buf(),
            format: "PLY",
            field: "element vertex".into(),
        })?;
    let count = h.elements[vi].count;
    if count > limits.max_points as u64 {
        return Err(IoError::TooManyPoints {
            path: src.to_path_buf(),
            declared: count,
            limit: limits.max_points,
        });
    }
    let (slots, has_normals) = vertex_slots(&h.elements[vi], src)?;
    let body = &bytes[h.body_start..];
    check_body_size(&h, body.len(), src)?;
    if count == 0 {
        return Err(IoError::Empty {
            path: src.to_path_buf(),
            what: "PLY header declares 0 vertices".into(),
        });
    }
    let plan = Plan {
        vertex: vi,
        slots: &slots,
        has_normals,
        want,
    };
    match h.encoding {
        Encoding::Ascii => {
            let mut b = AsciiBody {
                data: body,
                pos: 0,
                line: h.body_line,
                src,
            };
            walk(&mut b, &h, &plan, src)
        }
        Encoding::BinaryLe | Encoding::BinaryBe => {
            let mut b = BinBody {
                data: body,
                pos: 0,
                big: h.encoding == Encoding::BinaryBe,
                src,
            };
            walk(&mut b, &h, &plan, src)
        }
    }
}

struct Plan<'a> {
    vertex: usize,
    slots: &'a [Option<usize>],
    has_normals: bool,
    want: Want,
}

/// Reads every element in file order, keeping what `plan` asks for.
fn walk<B: Body>(b: &mut B, h: &Header, plan: &Plan, src: &Path) -> Result<PlyContent, IoError> {
    // Counts were checked against the limit and the body size, so this allocation is bounded.
    let n = h.elements[plan.vertex].count as usize;
    let mut out = PlyContent {
        points: Vec::with_capacity(n),
        normals: plan.has_normals.then(|| Vec::with_capacity(n)),
        triangles: Vec::new(),
    };
    for (ei, el) in h.elements.iter().enumerate() {
        let face_list = (plan.want == Want::Mesh && el.name == "face")
            .then(|| {
                el.props.iter().position(|p| {
                    matches!(p.kind, PropKind::List { .. })
                        && (p.name == "vertex_indices" || p.name == "vertex_index")
                })
            })
            .flatten();
        if ei == plan.vertex {
            read_vertices(b, el, plan, &mut out)?;
        } else if let Some(li) = face_list {
            read_faces(b, el, li, &mut out.triangles, src)?;
        } else {
            skip_element(b, el)?;
        }
    }
    Ok(out)
}

fn read_vertices<B: Body>(
    b: &mut B,
    el: &Element,
    plan: &Plan,
    out: &mut PlyContent,
) -> Result<(), IoError> {
    for _ in 0..el.count {
        let mut row = [0.0f64; 6];
        for (p, slot) in el.props.iter().zip(plan.slots) {
            match p.kind {
                PropKind::Scalar(t) => {
                    let v = b.scalar(t, &el.name)?;
                    if let Some(s) = slot {
                        row[*s] = v;
                    }
                }
                PropKind::List { count, item } => {
                    let len = list_len(b.scalar(count, &el.name)?, el, b.src())?;
                    b.skip(item, len, &el.name)?;
                }
            }
        }
        out.points.push([row[0], row[1], row[2]]);
        if let Some(ns) = out.normals.as_mut() {
            ns.push([row[3], row[4], row[5]]);
        }
    }
    Ok(())
}

fn read_faces<B: Body>(
    b: &mut B,
    el: &Element,
    list_prop: usize,
    tris: &mut Vec<[u32; 3]>,
    src: &Path,
) -> Result<(), IoError> {
    let mut poly: Vec<u32> = Vec::new();
    for _ in 0..el.count {
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                PropKind::Scalar(t) => b.skip(t, 1, &el.name)?,
                PropKind::List { count, item } => {
                    let len = list_len(b.scalar(count, &el.name)?, el, src)?;
                    if pi != list_prop {
                        b.skip(item, len, &el.name)?;
                        continue;
                    }
                    poly.clear();
                    for _ in 0..len {
                        let v = b.scalar(item, &el.name)?;
                        poly.push(index_value(v, src)?);
                    }
                    fan(&poly, tris);
                }
            }
        }
    }
    Ok(())
}

fn skip_element<B: Body>(b: &mut B, el: &Element) -> Result<(), IoError> {
    if el.props.is_empty() {
        return Ok(());
    }
    if let Some(t) = fixed_scalar_type(el) {
        // All properties scalar of one size: skip the whole element at once.
        return b.skip(t, el.count.saturating_mul(el.props.len() as u64), &el.name);
    }
    for _ in 0..el.count {
        for p in &el.props {
            match p.kind {
                PropKind::Scalar(t) => b.skip(t, 1, &el.name)?,
                PropKind::List { count, item } => {
                    let len = list_len(b.scalar(count, &el.name)?, el, b.src())?;
                    b.skip(item, len, &el.name)?;
                }
            }
        }
    }
    Ok(())
}

/// The common type when all properties are scalars of the same type.
fn fixed_scalar_type(el: &Element) -> Option<Scalar> {
    let mut t = None;
    for p in &el.props {
        match (p.kind, t) {
            (PropKind::Scalar(s), None) => t = Some(s),
            (PropKind::Scalar(s), Some(u)) if s.size() == u.size() => {}
            _ => return None,
        }
    }
    t
}

fn list_len(v: f64, el: &Element, src: &Path) -> Result<u64, IoError> {
    if v >= 0.0 && v.fract() == 0.0 && v < 4.0e9 {
        Ok(v as u64)
    } else {
        Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "PLY",
            message: format!(
                "list length {v} in element `{}` is not a valid count",
                el.name
            ),
        })
    }
}

fn index_value(v: f64, src: &Path) -> Result<u32, IoError> {
    if v >= 0.0 && v.fract() == 0.0 && v < f64::from(u32::MAX) {
        Ok(v as u32)
    } else {
        Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "PLY",
            message: format!("face index {v} is not a valid vertex index"),
        })
    }
}

/// Fan triangulation of a polygon (v0, vi, vi+1); polygons with < 3 corners add nothing.
pub(crate) fn fan(poly: &[u32], tris: &mut Vec<[u32; 3]>) {
    for i in 1..poly.len().saturating_sub(1) {
        tris.push([poly[0], poly[i], poly[i + 1]]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{PointFormat, parse_point_cloud};

    fn splitmix(state: &mut u64) -> f64 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 * 200.0 - 100.0
    }

    #[derive(Clone, Copy)]
    struct Spec {
        enc: &'static str,
        ty: &'static str,
        normals: bool,
        extras: bool,
        face_first: bool,
    }

    /// Encodes one value of PLY type `ty` in `enc` (test-side writer, independent of the reader).
    fn put(out: &mut Vec<u8>, enc: &str, ty: &str, v: f64) {
        let be = enc == "binary_big_endian";
        let mut b: Vec<u8> = match ty {
            "uchar" | "uint8" => vec![v as u8],
            "char" | "int8" => vec![(v as i8) as u8],
            "short" | "int16" => (v as i16).to_le_bytes().to_vec(),
            "ushort" | "uint16" => (v as u16).to_le_bytes().to_vec(),
            "int" | "int32" => (v as i32).to_le_bytes().to_vec(),
            "uint" | "uint32" => (v as u32).to_le_bytes().to_vec(),
            "float" | "float32" => (v as f32).to_le_bytes().to_vec(),
            _ => v.to_le_bytes().to_vec(),
        };
        if enc == "ascii" {
            let s = if ty.starts_with("float") || ty == "double" {
                format!("{v:e} ")
            } else {
                format!("{} ", v as i64)
            };
            out.extend(s.as_bytes());
            return;
        }
        if be {
            b.reverse();
        }
        out.extend(b);
    }

    fn make_ply(pts: &[Point3], nrm: &[Point3], s: Spec) -> Vec<u8> {
        let mut props: Vec<(&str, &str)> = Vec::new();
        let t = s.ty;
        if s.extras {
            props.extend([
                ("red", "uchar"),
                ("z", t),
                ("nx", t),
                ("x", t),
                ("green", "uint8"),
            ]);
            props.extend([
                ("y", t),
                ("ny", t),
                ("LIST", "list"),
                ("nz", t),
                ("blue", "uchar"),
            ]);
        } else {
            props.extend([
                ("x", t),
                ("y", t),
                ("z", t),
                ("nx", t),
                ("ny", t),
                ("nz", t),
            ]);
        }
        if !s.normals {
            props.retain(|p| !p.0.starts_with('n'));
        }
        let mut h = format!("ply\nformat {} 1.0\ncomment test\nobj_info x\n", s.enc);
        let face_head =
            "element face 2\nproperty list uchar int vertex_indices\nproperty uchar flags\n";
        if s.face_first {
            h.push_str(face_head);
        }
        h.push_str(&format!("element vertex {}\n", pts.len()));
        for (name, ty) in &props {
            if *ty == "list" {
                h.push_str("property list uchar float texcoord\n");
            } else {
                h.push_str(&format!("property {ty} {name}\n"));
            }
        }
        if !s.face_first {
            h.push_str(face_head);
        }
        h.push_str("end_header\n");
        let mut body = Vec::new();
        let faces = |body: &mut Vec<u8>| {
            for f in [[0.0, 1.0, 2.0], [2.0, 1.0, 0.0]] {
                put(body, s.enc, "uchar", 3.0);
                f.iter().for_each(|&i| put(body, s.enc, "int", i));
                put(body, s.enc, "uchar", 7.0);
                if s.enc == "ascii" {
                    body.push(b'\n');
                }
            }
        };
        if s.face_first {
            faces(&mut body);
        }
        for (i, p) in pts.iter().enumerate() {
            for (name, ty) in &props {
                let v = match *name {
                    "x" => p[0],
                    "y" => p[1],
                    "z" => p[2],
                    "nx" => nrm[i][0],
                    "ny" => nrm[i][1],
                    "nz" => nrm[i][2],
                    "LIST" => {
                        put(&mut body, s.enc, "uchar", 2.0);
                        put(&mut body, s.enc, "float", 0.5);
                        put(&mut body, s.enc, "float", 0.25);
                        continue;
                    }
                    _ => 200.0,
                };
                put(&mut body, s.enc, ty, v);
            }
            if s.enc == "ascii" {
                body.push(b'\n');
            }
        }
        if !s.face_first {
            faces(&mut body);
        }
        let mut out = h.into_bytes();
        out.extend(body);
        out
    }

    #[test]
    fn round_trip_all_encodings_types_and_layouts() {
        let mut st = 42u64;
        let pts: Vec<Point3> = (0..37)
            .map(|_| [splitmix(&mut st), splitmix(&mut st), splitmix(&mut st)])
            .collect();
        let nrm: Vec<Point3> = (0..37)
            .map(|_| [splitmix(&mut st), splitmix(&mut st), splitmix(&mut st)])
            .collect();
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            for ty in ["float", "double", "float32", "float64"] {
                for mask in 0..8u8 {
                    let s = Spec {
                        enc,
                        ty,
                        normals: mask & 1 != 0,
                        extras: mask & 2 != 0,
                        face_first: mask & 4 != 0,
                    };
                    let bytes = make_ply(&pts, &nrm, s);
                    let pc = parse_point_cloud(&bytes, PointFormat::Ply, &ReadLimits::default())
                        .unwrap_or_else(|e| panic!("{enc} {ty} {mask}: {e}"));
                    let tol = if ty.contains("32") || ty == "float" {
                        1e-5
                    } else {
                        1e-12
                    };
                    let close = |a: &[Point3], b: &[Point3]| {
                        a.len() == b.len()
                            && a.iter().zip(b).all(|(p, q)| {
                                (0..3).all(|k| (p[k] - q[k]).abs() <= tol * q[k].abs().max(1.0))
                            })
                    };
                    assert!(close(&pc.points, &pts), "{enc} {ty} {mask}");
                    match (s.normals, &pc.normals) {
                        (true, Some(n)) => assert!(close(n, &nrm), "{enc} {ty} {mask}"),
                        (false, None) => {}
                        other => panic!("{enc} {ty} {mask}: normals {:?}", other.0),
                    }
                    let mesh =
                        read_ply_mesh(&bytes, &ReadLimits::default(), Path::new("t.ply")).unwrap();
                    assert_eq!(
                        mesh.triangles,
                        vec![[0, 1, 2], [2, 1, 0]],
                        "{enc} {ty} {mask}"
                    );
                }
            }
        }
    }

    #[test]
    fn every_scalar_type_both_endiannesses() {
        let types = [
            "char", "uchar", "short", "ushort", "int", "uint", "float", "double",
        ];
        let vals = [
            -5.0,
            250.0,
            -30000.0,
            60000.0,
            -70000.0,
            4_000_000_000.0,
            1.5,
            -2.25,
        ];
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            for (k, (ty, v)) in types.iter().zip(vals).enumerate() {
                let others = ["x", "y", "z"].iter().filter(|&&n| n != "x");
                let mut h = format!("ply\nformat {enc} 1.0\nelement vertex 1\nproperty {ty} x\n");
                others.for_each(|n| h.push_str(&format!("property int8 {n}\n")));
                h.push_str("end_header\n");
                let mut b = h.into_bytes();
                put(&mut b, enc, ty, v);
                put(&mut b, enc, "int8", 1.0);
                put(&mut b, enc, "int8", -1.0);
                let pc = parse_point_cloud(&b, PointFormat::Ply, &ReadLimits::default()).unwrap();
                assert_eq!(pc.points, vec![[v, 1.0, -1.0]], "{enc} type {k} {ty}");
            }
        }
    }

    #[test]
    fn crlf_header_and_nan_passthrough() {
        let b = b"ply\r\nformat ascii 1.0\r\nelement vertex 2\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nproperty float nx\r\nproperty float ny\r\nend_header\r\nnan 2 3 0 1\r\n4 inf -6 1 0\r\n";
        let pc = parse_point_cloud(b, PointFormat::Ply, &ReadLimits::default()).unwrap();
        assert!(pc.points[0][0].is_nan() && pc.points[1][1] == f64::INFINITY);
        assert_eq!(pc.points[1][2], -6.0);
        assert!(
            pc.normals.is_none(),
            "two of three normal components must not give normals"
        );
    }

    #[test]
    fn truncated_binary_is_reported_with_sizes() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 5210\n".to_vec();
        for n in ["x", "y", "z", "nx", "ny", "nz"] {
            b.extend(format!("property float {n}\n").as_bytes());
        }
        b.extend(b"end_header\n");
        b.extend(vec![0u8; 4096]);
        let e = read_ply_points(&b, &ReadLimits::default(), Path::new("kitten.ply")).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::Truncated {
                    expected: 125_040,
                    found: 4096,
                    ..
                }
            ),
            "{e}"
        );
        let msg = e.to_string();
        assert!(msg.starts_with("kitten.ply: truncated binary PLY: header declares 5210 `vertex` records (125040 bytes)"), "{msg}");
    }

    #[test]
    fn billion_vertices_fail_fast_without_allocating() {
        let b = b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0";
        let start = std::time::Instant::now();
        let e = parse_point_cloud(b, PointFormat::Ply, &ReadLimits::default()).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::TooManyPoints {
                    declared: 1_000_000_000,
                    limit: 50_000_000,
                    ..
                }
            ),
            "{e}"
        );
        // With the point limit lifted, the size check must still stop it before allocating.
        let open = ReadLimits {
            max_points: usize::MAX,
            max_bytes: u64::MAX,
        };
        let e = parse_point_cloud(b, PointFormat::Ply, &open).unwrap_err();
        assert!(
            matches!(
                e,
                IoError::Truncated {
                    expected: 12_000_000_000,
                    found: 4,
                    ..
                }
            ),
            "{e}"
        );
        let a = b"ply\nformat ascii 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
        let e = parse_point_cloud(a, PointFormat::Ply, &open).unwrap_err();
        assert!(matches!(e, IoError::Truncated { .. }), "{e}");
        // A huge list-only element ahead of the vertices must also end at the data's end.
        let l = b"ply\nformat binary_little_endian 1.0\nelement junk 18000000000000000000\nproperty list uchar int v\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0";
        let e = parse_point_cloud(l, PointFormat::Ply, &open).unwrap_err();
        assert!(matches!(e, IoError::Truncated { .. }), "{e}");
        assert!(
            start.elapsed().as_millis() < 200,
            "took {:?}",
            start.elapsed()
        );
    }

    #[test]
    fn header_and_body_errors() {
        let lim = ReadLimits::default();
        let parse = |b: &[u8]| parse_point_cloud(b, PointFormat::Ply, &lim).unwrap_err();
        let e = parse(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\nend_header\n1 2\n");
        assert!(
            matches!(&e, IoError::MissingField { field, .. } if field == "x"),
            "{e}"
        );
        let e = parse(b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 five 6\n");
        assert!(matches!(e, IoError::Parse { line: 9, .. }), "{e}");
        let e = parse(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n");
        assert!(matches!(e, IoError::Parse { line: 4, .. }), "{e}");
        let e = parse(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
        assert!(matches!(e, IoError::Parse { .. }), "{e}");
        let e = parse(b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n");
        assert!(matches!(e, IoError::Empty { .. }), "{e}");
        let e = parse(b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty list int float x\nproperty float y\nproperty float z\nend_header\n\xff\xff\xff\xff\0\0\0\0\0\0\0\0");
        assert!(matches!(e, IoError::MissingField { .. }), "{e}");
        let e = parse(b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty list int float q\nproperty float x\nproperty float y\nproperty float z\nend_header\n\xff\xff\xff\xff\0\0\0\0\0\0\0\0\0\0\0\0");
        assert!(
            matches!(e, IoError::Invalid { .. }),
            "negative list length: {e}"
        );
    }

    #[test]
    fn mesh_faces_are_fanned_and_validated() {
        let quad = b"ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar uint vertex_index\nend_header\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
        let m = read_ply_mesh(quad, &ReadLimits::default(), Path::new("q.ply")).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(m.normals.is_empty());
        let bad = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n1 1 0\n3 0 1 3\n";
        let e = read_ply_mesh(bad, &ReadLimits::default(), Path::new("q.ply")).unwrap_err();
        assert!(matches!(e, IoError::Invalid { .. }), "{e}");
    }
}
