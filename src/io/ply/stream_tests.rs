//! Streaming PLY tests: a file read through `read_point_cloud` (buffered file, 64 KiB chunks), the
//! same bytes through `parse_point_cloud`, and tiny chunk sizes that cut records anywhere must all
//! give bit-identical clouds equal to what the test-side writer encoded; truncation names the
//! record; the memory budget refuses before allocating.

use std::path::Path;

use super::tests::{Spec, make_ply};
use super::*;
use crate::geometry::Point3;
use crate::geometry::synthetic::SplitMix64;
use crate::io::{PointFormat, parse_point_cloud, read_point_cloud};

fn random_cloud(rng: &mut SplitMix64, n: usize) -> Vec<Point3> {
    (0..n)
        .map(|_| [0, 1, 2].map(|_| (rng.next_f64() - 0.5) * 2000.0))
        .collect()
}

/// What the reader must return for value `v` written as `ty` in `enc` by [`make_ply`].
fn expected(v: f64, enc: &str, ty: &str) -> f64 {
    match (enc, ty) {
        ("ascii", _) | (_, "double") => v,
        _ => f64::from(v as f32),
    }
}

fn same_bits(a: &[Point3], b: &[Point3]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(p, q)| (0..3).all(|k| p[k].to_bits() == q[k].to_bits()))
}

fn read_chunked(bytes: &[u8], chunk: usize) -> Result<PointCloud, IoError> {
    let src = Path::new("chunked.ply");
    read_ply_points(
        bytes,
        bytes.len() as u64,
        &ReadLimits::default(),
        src,
        chunk,
    )
}

#[test]
fn file_stream_slice_and_tiny_chunks_agree_with_the_writer() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = SplitMix64(7);
    for round in 0..12u64 {
        let n = 1 + (rng.next_f64() * 300.0) as usize;
        let pts = random_cloud(&mut rng, n);
        let nrm = random_cloud(&mut rng, n);
        let enc = ["ascii", "binary_little_endian", "binary_big_endian"][round as usize % 3];
        let ty = ["float", "double"][(round / 3) as usize % 2];
        for mask in 0..8u8 {
            let s = Spec {
                enc,
                ty,
                normals: mask & 1 != 0,
                extras: mask & 2 != 0,
                face_first: mask & 4 != 0,
            };
            let bytes = make_ply(&pts, &nrm, s);
            let path = dir.path().join(format!("r{round}m{mask}.ply"));
            std::fs::write(&path, &bytes).unwrap();
            let ctx = format!("round {round} {enc} {ty} mask {mask}");
            let from_file = read_point_cloud(&path, &ReadLimits::default()).unwrap();
            let in_memory =
                parse_point_cloud(&bytes, PointFormat::Ply, &ReadLimits::default()).unwrap();
            let want: Vec<Point3> = pts
                .iter()
                .map(|p| p.map(|v| expected(v, enc, ty)))
                .collect();
            assert!(same_bits(&from_file.points, &want), "{ctx}");
            assert!(same_bits(&in_memory.points, &want), "{ctx}");
            match (&from_file.normals, &in_memory.normals, s.normals) {
                (Some(a), Some(b), true) => {
                    let want: Vec<Point3> = nrm
                        .iter()
                        .map(|p| p.map(|v| expected(v, enc, ty)))
                        .collect();
                    assert!(same_bits(a, &want) && same_bits(b, &want), "{ctx}");
                }
                (None, None, false) => {}
                _ => panic!("{ctx}: normals disagree"),
            }
            // Chunks shorter than one record: every boundary falls inside a record or a token.
            for chunk in [1, 5, 7, 13] {
                let c = read_chunked(&bytes, chunk).unwrap();
                assert!(
                    same_bits(&c.points, &from_file.points),
                    "{ctx} chunk {chunk}"
                );
                assert_eq!(c.normals.is_some(), s.normals, "{ctx} chunk {chunk}");
            }
        }
    }
}

#[test]
fn a_chunk_boundary_inside_a_record_changes_nothing() {
    // 36-byte records (double xyz + float normals) read in 64-byte chunks: the second record
    // starts at byte 36 and ends at 72, across the first chunk boundary.
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n".to_vec();
    for (t, n) in [("double", "x"), ("double", "y"), ("double", "z")] {
        b.extend(format!("property {t} {n}\n").as_bytes());
    }
    for n in ["nx", "ny", "nz"] {
        b.extend(format!("property float {n}\n").as_bytes());
    }
    b.extend(b"end_header\n");
    let pts: [Point3; 3] = [[1.5, -2.0, 3.25], [4.0, 5.5, -6.0], [7.0, 8.0, 9.125]];
    for p in pts {
        p.iter().for_each(|v| b.extend(v.to_le_bytes()));
        [0.0f32, 0.0, 1.0]
            .iter()
            .for_each(|v| b.extend(v.to_le_bytes()));
    }
    for chunk in [1, 35, 36, 37, 64, 71, CHUNK_BYTES] {
        let pc = read_chunked(&b, chunk).unwrap();
        assert_eq!(pc.points, pts.to_vec(), "chunk {chunk}");
        assert_eq!(pc.normals, Some(vec![[0.0, 0.0, 1.0]; 3]), "chunk {chunk}");
    }
}

#[test]
fn truncation_inside_the_body_names_the_vertex() {
    // A list property makes records variable-sized (21 bytes here, at least 13 by the header), so
    // the up-front size check passes and the stream finds the end inside vertex 7.
    let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\nproperty list uchar float uv\nend_header\n".to_vec();
    let header = b.len();
    for i in 0..10 {
        [i as f32, 0.0, 1.0]
            .iter()
            .for_each(|v| b.extend(v.to_le_bytes()));
        b.push(2);
        [0.5f32, 0.25]
            .iter()
            .for_each(|v| b.extend(v.to_le_bytes()));
    }
    assert_eq!(b.len() - header, 210);
    b.truncate(header + 150);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cut.ply");
    std::fs::write(&path, &b).unwrap();
    for e in [
        read_point_cloud(&path, &ReadLimits::default()).unwrap_err(),
        read_chunked(&b, 16).unwrap_err(),
    ] {
        assert!(matches!(e, IoError::Truncated { found: 150, .. }), "{e}");
        let msg = e.to_string();
        assert!(
            msg.contains("record 7 (0-based) of element `vertex`"),
            "{msg}"
        );
    }
    let whole = b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty list uchar float uv\nend_header\n0 0 0 0\n1 1 1 2 0.5         \n";
    let e = parse_point_cloud(whole, PointFormat::Ply, &ReadLimits::default()).unwrap_err();
    assert!(matches!(e, IoError::Parse { line: 11, .. }), "{e}");
    assert!(
        e.to_string().contains("data ends inside element `vertex`"),
        "{e}"
    );
}

#[test]
fn memory_budget_refuses_before_allocating() {
    let b = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0\0";
    let fits = ReadLimits::default();
    let pc = parse_point_cloud(b, PointFormat::Ply, &fits).unwrap();
    assert_eq!(pc.points.len(), 2);
    let none = ReadLimits {
        max_memory_mib: 0,
        ..ReadLimits::default()
    };
    let e = parse_point_cloud(b, PointFormat::Ply, &none).unwrap_err();
    assert!(
        matches!(
            e,
            IoError::OverMemory {
                points: 2,
                budget_mib: 0,
                ..
            }
        ),
        "{e}"
    );
    let msg = e.to_string();
    assert!(msg.contains("declared by the file's header"), "{msg}");
    assert!(msg.contains("--max-memory-mib"), "{msg}");
    // Text: refused at the first row beyond the budget.
    let e = parse_point_cloud(b"1 2 3\n", PointFormat::Xyz, &none).unwrap_err();
    assert!(matches!(e, IoError::OverMemory { points: 1, .. }), "{e}");
}
