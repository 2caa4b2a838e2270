//! PLY reader tests: every encoding, scalar type and layout against a test-side writer, header
//! and body errors, and fail-fast size checks.

use std::path::Path;

use super::*;
use crate::geometry::Point3;
use crate::io::{PointFormat, parse_point_cloud};

pub(super) fn splitmix(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64 * 200.0 - 100.0
}

#[derive(Clone, Copy)]
pub(super) struct Spec {
    pub(super) enc: &'static str,
    pub(super) ty: &'static str,
    pub(super) normals: bool,
    pub(super) extras: bool,
    pub(super) face_first: bool,
}

/// Encodes one value of PLY type `ty` in `enc` (test-side writer, independent of the reader).
pub(super) fn put(out: &mut Vec<u8>, enc: &str, ty: &str, v: f64) {
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

pub(super) fn make_ply(pts: &[Point3], nrm: &[Point3], s: Spec) -> Vec<u8> {
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
                // The extras carry red, green and blue as 8-bit 200.
                let want = s.extras.then(|| vec![[200.0f32 / 255.0; 3]; pts.len()]);
                assert_eq!(pc.colors, want, "{enc} {ty} {mask}");
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
    let len = b.len() as u64;
    let e = read_ply_points(
        &b[..],
        len,
        &ReadLimits::default(),
        Path::new("kitten.ply"),
        CHUNK_BYTES,
    )
    .unwrap_err();
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
    assert!(
        msg.starts_with(
            "kitten.ply: truncated binary PLY: header declares 5210 `vertex` records (125040 bytes)"
        ),
        "{msg}"
    );
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
        max_memory_mib: u64::MAX,
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

/// A PLY of `values` as red, green, blue of type `ty` (and `channels` of them), ASCII.
fn colored_ply(ty: &str, channels: &[&str], values: &[[f64; 3]]) -> Vec<u8> {
    let mut h = format!("ply\nformat ascii 1.0\nelement vertex {}\n", values.len());
    h.push_str("property float x\nproperty float y\nproperty float z\n");
    channels
        .iter()
        .for_each(|c| h.push_str(&format!("property {ty} {c}\n")));
    h.push_str("end_header\n");
    for (i, v) in values.iter().enumerate() {
        h.push_str(&format!("{i} 0 0"));
        (0..channels.len()).for_each(|k| h.push_str(&format!(" {}", v[k])));
        h.push('\n');
    }
    h.into_bytes()
}

#[test]
fn colours_are_scaled_by_their_type_and_need_all_three_channels() {
    let rgb = ["red", "green", "blue"];
    let read = |bytes: Vec<u8>| {
        parse_point_cloud(&bytes, PointFormat::Ply, &ReadLimits::default())
            .unwrap()
            .colors
    };
    let eight = read(colored_ply(
        "uchar",
        &rgb,
        &[[0.0, 51.0, 255.0], [255.0, 0.0, 102.0]],
    ));
    assert_eq!(eight, Some(vec![[0.0, 0.2, 1.0], [1.0, 0.0, 0.4]]));
    let sixteen = read(colored_ply("ushort", &rgb, &[[65535.0, 0.0, 13107.0]]));
    assert_eq!(sixteen, Some(vec![[1.0, 0.0, 0.2]]));
    // Floating point as stored, clamped to [0, 1].
    let float = read(colored_ply("float", &rgb, &[[0.25, 1.5, -0.5]]));
    assert_eq!(float, Some(vec![[0.25, 1.0, 0.0]]));
    // The short names and the diffuse_ names of other writers.
    let short = read(colored_ply("uchar", &["r", "g", "b"], &[[255.0, 0.0, 0.0]]));
    assert_eq!(short, Some(vec![[1.0, 0.0, 0.0]]));
    let diffuse = ["diffuse_red", "diffuse_green", "diffuse_blue"];
    assert_eq!(
        read(colored_ply("uchar", &diffuse, &[[0.0, 255.0, 0.0]])),
        Some(vec![[0.0, 1.0, 0.0]])
    );
    // Red and green alone are no colour.
    assert_eq!(
        read(colored_ply("uchar", &rgb[..2], &[[1.0, 2.0, 0.0]])),
        None
    );
}
