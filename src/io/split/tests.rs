//! Every byte-range reader against the whole-file reader: the ranges read in order give the same
//! points, whatever the range size and wherever a cut falls (inside a line or a record).

use super::*;
use crate::io::{IoError, parse_point_cloud};

/// All ranges of `split` in order.
fn read_all(split: &Split, input: StreamInput<'_>) -> Result<(Vec<Point3>, Vec<Point3>), IoError> {
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for r in 0..split.ranges().len() {
        split.read_range(input, r, 7, &mut |p: &[Point3], n: Option<&[Point3]>| {
            assert!(p.len() <= 7);
            points.extend_from_slice(p);
            normals.extend_from_slice(n.unwrap_or(&[]));
            Ok::<(), IoError>(())
        })?;
    }
    Ok((points, normals))
}

/// Coordinates as bits (NaN equals NaN).
fn bits(v: &[Point3]) -> Vec<[u64; 3]> {
    v.iter().map(|p| p.map(f64::to_bits)).collect()
}

/// The split of `data` with the two ranges `[data start, cut)` and `[cut, end)`.
fn cut_at(split: &Split, cut: u64) -> Split {
    let mut s = split.clone();
    let (start, end) = (s.ranges[0].start, s.ranges.last().unwrap().end);
    s.ranges = vec![ByteRange { start, end: cut }, ByteRange { start: cut, end }];
    s
}

/// For every range size and every two-range cut, the ranges give the whole reader's points.
fn check_every_split(data: &[u8], format: PointFormat) {
    let whole = parse_point_cloud(data, format, &ReadLimits::default()).unwrap();
    let input = StreamInput::Bytes { data, format };
    let one = split_input(input, &ReadLimits::default(), u64::MAX)
        .unwrap()
        .expect("splittable");
    assert_eq!(one.ranges().len(), 1);
    assert_eq!(one.has_normals(), whole.normals.is_some());
    let want_n = whole.normals.clone().unwrap_or_default();
    let (start, end) = (one.ranges[0].start, one.ranges[0].end);
    for size in 1..=(end - start) {
        let s = split_input(input, &ReadLimits::default(), size)
            .unwrap()
            .unwrap();
        let (p, n) = read_all(&s, input).unwrap();
        assert_eq!(bits(&p), bits(&whole.points), "range size {size}");
        assert_eq!(n, want_n, "range size {size}");
    }
    if matches!(one.layout, Layout::Lines(_)) {
        for cut in start..=end {
            let (p, n) = read_all(&cut_at(&one, cut), input).unwrap();
            assert_eq!(bits(&p), bits(&whole.points), "cut at byte {cut}");
            assert_eq!(n, want_n, "cut at byte {cut}");
        }
    }
}

#[test]
fn text_ranges_give_the_whole_readers_points_at_every_cut() {
    let cases: [(&str, PointFormat); 6] = [
        ("1 2 3\n4 5 6\n7 8 9\n", PointFormat::Xyz),
        // Comments, blank lines, CRLF, no newline at the end, extra columns.
        (
            "# scan\r\n\r\n1 2 3 0.5\r\n# mid\r\n\r\n4 5 6 0.5\r\n  \r\n7 8 9 0.5",
            PointFormat::Xyz,
        ),
        // A CloudCompare header, later `//` comments, normals.
        (
            "//X,Y,Z,Nx,Ny,Nz\n1,2,3,0,0,1\n// note\n4,5,6,0,1,0\n\n-7,8e1,nan,1,0,0\n",
            PointFormat::Csv,
        ),
        // A PTS count line, then rows with intensity and colour.
        (
            "3\n1 2 3 10 255 0 0\n4 5 6 11 0 255 0\n7 8 9 12 0 0 255\n",
            PointFormat::Pts,
        ),
        // Named columns in another order.
        (
            "nz;x;ny;y;z;nx\n3;1;2;4;5;1\r\n-3;0.5;-2;6;7;-1\n",
            PointFormat::Csv,
        ),
        // Six columns without a header are x y z nx ny nz.
        (
            "1 2 3 0 0 1\n\n\n4 5 6 0 1 0\n7 8 9 1 0 0\n",
            PointFormat::Xyz,
        ),
    ];
    for (text, format) in cases {
        check_every_split(text.as_bytes(), format);
    }
}

#[test]
fn text_errors_are_the_whole_readers_with_their_line() {
    let limits = ReadLimits::default();
    for text in ["1 2 3\n# c\n4 x 6\n7 8 9\n", "1 2 3 0 0 1\n\n1 2 3\n"] {
        let whole = parse_point_cloud(text.as_bytes(), PointFormat::Xyz, &limits).unwrap_err();
        let input = StreamInput::Bytes {
            data: text.as_bytes(),
            format: PointFormat::Xyz,
        };
        for size in [1, 3, 5, 100] {
            let s = split_input(input, &limits, size).unwrap().unwrap();
            let e = read_all(&s, input).unwrap_err();
            assert_eq!(e.to_string(), whole.to_string(), "range size {size}");
        }
    }
    // A header the whole reader refuses is refused when the split is planned.
    let bad = StreamInput::Bytes {
        data: b"a,y,z\n1,2,3\n",
        format: PointFormat::Csv,
    };
    assert!(matches!(
        split_input(bad, &limits, 4),
        Err(IoError::MissingField { .. })
    ));
    // No data rows: not split (the whole reader reports the empty file).
    let empty = StreamInput::Bytes {
        data: b"# only comments\n\n",
        format: PointFormat::Xyz,
    };
    assert!(split_input(empty, &limits, 4).unwrap().is_none());
}

/// A binary little-endian PLY with an element before the vertices, an unused property between
/// the used ones, and (when `list`) a list property in the vertex element.
fn binary_ply(n: usize, list: bool) -> Vec<u8> {
    let mut h = String::from("ply\nformat binary_little_endian 1.0\nelement camera 2\n");
    h.push_str("property float a\nproperty uchar b\n");
    h.push_str(&format!(
        "element vertex {n}\nproperty float x\nproperty double y\n"
    ));
    h.push_str("property ushort quality\nproperty float z\nproperty float nx\n");
    h.push_str("property float ny\nproperty float nz\n");
    if list {
        h.push_str("property list uchar int tags\n");
    }
    h.push_str("element face 1\nproperty list uchar int vertex_indices\nend_header\n");
    let mut b = h.into_bytes();
    for k in 0..2u8 {
        b.extend(1.5f32.to_le_bytes());
        b.push(k);
    }
    for i in 0..n {
        let v = i as f32 * 0.25 - 3.0;
        b.extend(v.to_le_bytes());
        b.extend((f64::from(v) * 1e-3 + 1e6).to_le_bytes());
        b.extend((i as u16).to_le_bytes());
        b.extend(if i == 5 { f32::NAN } else { -v }.to_le_bytes());
        for c in [0.0f32, 0.6, 0.8] {
            b.extend(c.to_le_bytes());
        }
        if list {
            b.push(1);
            b.extend(7i32.to_le_bytes());
        }
    }
    b.push(3);
    for v in [0i32, 1, 2] {
        b.extend(v.to_le_bytes());
    }
    b
}

#[test]
fn binary_ply_ranges_give_the_whole_readers_points() {
    check_every_split(&binary_ply(23, false), PointFormat::Ply);
    let limits = ReadLimits::default();
    let list = binary_ply(4, true);
    let input = StreamInput::Bytes {
        data: &list,
        format: PointFormat::Ply,
    };
    assert!(split_input(input, &limits, 8).unwrap().is_none(), "list");
    let ascii = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    let input = StreamInput::Bytes {
        data: ascii,
        format: PointFormat::Ply,
    };
    assert!(split_input(input, &limits, 8).unwrap().is_none(), "ascii");
    // A truncated body is refused before any range is read, as the whole reader does.
    let mut short = binary_ply(23, false);
    short.truncate(short.len() - 40);
    let input = StreamInput::Bytes {
        data: &short,
        format: PointFormat::Ply,
    };
    assert!(matches!(
        split_input(input, &limits, 8),
        Err(IoError::Truncated { .. })
    ));
    let few = ReadLimits {
        max_points: 10,
        ..ReadLimits::default()
    };
    let data = binary_ply(23, false);
    let input = StreamInput::Bytes {
        data: &data,
        format: PointFormat::Ply,
    };
    assert!(matches!(
        split_input(input, &few, 8),
        Err(IoError::TooManyPoints { declared: 23, .. })
    ));
}

#[test]
fn las_ranges_give_the_whole_readers_points_and_laz_is_not_split() {
    use std::io::Cursor;
    let mut bytes = Vec::new();
    for compressed in [false, true] {
        let mut b = las::Builder::from((1, 4));
        let mut format = las::point::Format::new(1).unwrap();
        format.is_compressed = compressed;
        b.point_format = format;
        let t = |offset| las::Transform {
            scale: 0.001,
            offset,
        };
        b.transforms = las::Vector {
            x: t(500_000.0),
            y: t(4_100_000.0),
            z: t(0.0),
        };
        let mut w = las::Writer::new(Cursor::new(Vec::new()), b.into_header().unwrap()).unwrap();
        for i in 0..37 {
            let f = f64::from(i);
            w.write_point(las::Point {
                x: 500_000.0 + f * 0.731,
                y: 4_100_000.0 - f * 0.113,
                z: f * 0.01,
                gps_time: Some(f),
                ..Default::default()
            })
            .unwrap();
        }
        bytes = w.into_inner().unwrap().into_inner();
        if compressed {
            let input = StreamInput::Bytes {
                data: &bytes,
                format: PointFormat::Las,
            };
            let s = split_input(input, &ReadLimits::default(), 64).unwrap();
            assert!(s.is_none(), "LAZ");
        } else {
            check_every_split(&bytes, PointFormat::Las);
        }
    }
    assert!(!bytes.is_empty());
}

#[test]
fn files_split_like_their_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cloud.ply");
    let data = binary_ply(50, false);
    std::fs::write(&path, &data).unwrap();
    let whole = crate::io::read_point_cloud(&path, &ReadLimits::default()).unwrap();
    let input = StreamInput::File(&path);
    let s = split_input(input, &ReadLimits::default(), 100)
        .unwrap()
        .unwrap();
    assert!(s.ranges().len() > 5);
    let (p, n) = read_all(&s, input).unwrap();
    assert_eq!(bits(&p), bits(&whole.points));
    assert_eq!(Some(n), whole.normals);
}
