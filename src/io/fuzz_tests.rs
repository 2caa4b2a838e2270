//! Fuzz stand-in: random bytes and random mutations of valid files must never make the point
//! readers panic (they may return any error).

use proptest::prelude::*;

use super::{PointFormat, ReadLimits, parse_point_cloud};

const FORMATS: [PointFormat; 5] = [
    PointFormat::Ply,
    PointFormat::Xyz,
    PointFormat::Pts,
    PointFormat::Csv,
    PointFormat::Obj,
];

fn valid_binary_ply() -> Vec<u8> {
    let mut v = b"ply\nformat binary_little_endian 1.0\nelement face 1\nproperty list uchar int vertex_indices\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nend_header\n".to_vec();
    v.extend([3u8]);
    for i in [0i32, 1, 2] {
        v.extend(i.to_le_bytes());
    }
    for k in 0..9 {
        v.extend((k as f32).to_le_bytes());
        if k % 3 == 2 {
            v.push(200);
        }
    }
    v
}

fn valid_ascii_ply() -> Vec<u8> {
    b"ply\r\nformat ascii 1.0\r\nelement vertex 2\r\nproperty double x\r\nproperty double y\r\nproperty double z\r\nproperty float nx\r\nproperty float ny\r\nproperty float nz\r\nend_header\r\n1 2 3 0 0 1\r\n4 5 6 0 1 0\r\n".to_vec()
}

fn small_limits() -> ReadLimits {
    ReadLimits {
        max_points: 10_000,
        max_bytes: 1 << 20,
        ..ReadLimits::default()
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        for f in FORMATS {
            let _ = parse_point_cloud(&bytes, f, &small_limits());
        }
        let mut with_magic = b"ply\n".to_vec();
        with_magic.extend(&bytes);
        let _ = parse_point_cloud(&with_magic, PointFormat::Ply, &small_limits());
    }

    #[test]
    fn mutated_ply_never_panics(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..3), 1..8),
        ascii in any::<bool>(),
    ) {
        let mut bytes = if ascii { valid_ascii_ply() } else { valid_binary_ply() };
        for (at, byte, op) in edits {
            let i = at.index(bytes.len().max(1));
            match op {
                0 if i < bytes.len() => bytes[i] = byte,
                1 => bytes.insert(i.min(bytes.len()), byte),
                _ if i < bytes.len() => { bytes.truncate(i); }
                _ => {}
            }
        }
        for f in FORMATS {
            let _ = parse_point_cloud(&bytes, f, &small_limits());
        }
    }
}
