//! Tests of the GLB encoders and decoder.

use super::*;

/// The plain float encoding (exact layout checks).
fn plain(m: &TriMesh) -> Result<Vec<u8>, IoError> {
    encode_glb_with(m, &MeshMeta::default(), GlbCompression::None)
}

/// Octahedron with outward normals of length 2 (the writer must renormalise them).
pub(crate) fn octahedron() -> TriMesh {
    let vertices = vec![
        [1.5, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0 / 3.0],
    ];
    let normals = vertices
        .iter()
        .map(|&p: &Point3| normalized(p).unwrap().map(|c| 2.0 * c))
        .collect();
    let triangles = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    TriMesh {
        vertices,
        normals,
        triangles,
        colors: Vec::new(),
    }
}

fn chunks(glb: &[u8]) -> (&[u8], &[u8]) {
    let u = |o: usize| u32::from_le_bytes(glb[o..o + 4].try_into().unwrap()) as usize;
    assert_eq!(u(8), glb.len(), "header length");
    let jl = u(12);
    assert_eq!(&glb[16..20], b"JSON");
    let json = &glb[20..20 + jl];
    let b0 = 20 + jl;
    assert_eq!(&glb[b0 + 4..b0 + 8], b"BIN\0");
    (json, &glb[b0 + 8..b0 + 8 + u(b0)])
}

#[test]
fn round_trip_and_container_layout() {
    let m = octahedron();
    let glb = plain(&m).unwrap();
    let back = decode_glb(&glb).unwrap();
    assert_eq!(back.triangles, m.triangles);
    for (a, b) in back.vertices.iter().zip(&m.vertices) {
        assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-7), "{a:?} {b:?}");
    }
    for (n, p) in back.normals.iter().zip(&m.vertices) {
        let want = normalized(*p).unwrap();
        assert!((0..3).all(|k| (n[k] - want[k]).abs() < 1e-6), "{n:?}");
    }
    let (json, bin) = chunks(&glb);
    assert_eq!(json.len() % 4, 0);
    assert_eq!(bin.len() % 4, 0);
    assert_eq!(bin.len(), 6 * 24 + 8 * 12);
    let v: serde_json::Value = serde_json::from_slice(json).unwrap();
    assert_eq!(v["asset"]["generator"], "rbfsurf");
    let pos = &v["accessors"][0];
    let f = |x: f64| f64::from(x as f32);
    assert_eq!(
        pos["min"],
        serde_json::json!([f(-1.0), f(-1.0), f(-1.0 / 3.0)])
    );
    assert_eq!(pos["max"], serde_json::json!([f(1.5), f(1.0), f(1.0)]));
    assert!(v["accessors"][2].get("min").is_none());
    assert_eq!(v["bufferViews"][2]["target"], 34963);
}

#[test]
fn json_padding_is_spaces() {
    // Vary the vertex count so the JSON length takes several values mod 4.
    let mut m = octahedron();
    m.normals.clear();
    for extra in 0..4 {
        m.vertices.push([f64::from(extra), 0.125, 7.0]);
        for glb in [plain(&m).unwrap(), encode_glb(&m).unwrap()] {
            let (json, _) = chunks(&glb);
            let text = std::str::from_utf8(json).unwrap();
            assert_eq!(
                text.trim_end().len() + text.len() - text.trim_end().len(),
                json.len()
            );
            assert!(text.trim_end().ends_with('}'));
            assert!(json[text.trim_end().len()..].iter().all(|&b| b == b' '));
            assert!(decode_glb(&glb).unwrap().normals.is_empty());
        }
    }
}

#[test]
fn degenerate_normals_fall_back_to_faces() {
    let mut m = octahedron();
    m.normals[4] = [0.0, 0.0, 0.0];
    m.normals[0] = [f64::NAN, 0.0, 0.0];
    let back = decode_glb(&plain(&m).unwrap()).unwrap();
    let n4 = back.normals[4];
    assert!(
        n4[2] > 0.9 && (crate::geometry::norm(n4) - 1.0).abs() < 1e-6,
        "{n4:?}"
    );
    assert!(back.normals[0][0] > 0.5, "{:?}", back.normals[0]);
}

#[test]
fn bad_meshes_are_rejected() {
    let m = octahedron();
    let mut bads = Vec::new();
    let mut bad = m.clone();
    bad.triangles[3] = [0, 1, 6];
    bads.push(bad);
    let mut bad = m.clone();
    bad.vertices[2][1] = f64::INFINITY;
    bads.push(bad);
    let mut bad = m.clone();
    bad.vertices[2][1] = 1e300;
    bads.push(bad);
    let mut bad = m.clone();
    bad.normals.pop();
    bads.push(bad);
    bads.push(TriMesh::default());
    for bad in &bads {
        assert!(matches!(encode_glb(bad), Err(IoError::Encode { .. })));
        assert!(matches!(plain(bad), Err(IoError::Encode { .. })));
    }
}

#[test]
fn decoding_damaged_glb_never_panics() {
    assert!(matches!(
        decode_glb(b"glTF garbage"),
        Err(IoError::Invalid { .. })
    ));
    for glb in [
        plain(&octahedron()).unwrap(),
        encode_glb(&octahedron()).unwrap(),
    ] {
        for cut in 0..glb.len() {
            assert!(decode_glb(&glb[..cut]).is_err(), "cut at {cut}");
        }
        // Corrupt the BIN chunk length / offsets: still an error or a valid mesh, never a panic.
        let mut st = 7u64;
        for _ in 0..300 {
            st = st
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let mut g = glb.clone();
            let i = (st >> 33) as usize % g.len();
            g[i] ^= (st >> 20) as u8 | 1;
            let _ = decode_glb(&g);
        }
    }
}

#[test]
fn node_transforms_are_applied_to_positions_and_normals() {
    let glb = plain(&octahedron()).unwrap();
    let (json, bin) = chunks(&glb);
    let mut v: serde_json::Value = serde_json::from_slice(json).unwrap();
    // A quarter turn about +z, scale 2, then a translation.
    let h = std::f64::consts::FRAC_1_SQRT_2;
    v["nodes"][0]["rotation"] = serde_json::json!([0.0, 0.0, h, h]);
    v["nodes"][0]["scale"] = serde_json::json!([2.0, 2.0, 2.0]);
    v["nodes"][0]["translation"] = serde_json::json!([1.0, 2.0, 3.0]);
    let moved = container_value(v, &MeshMeta::default(), bin.to_vec()).unwrap();
    let back = decode_glb(&moved).unwrap();
    let p = back.vertices[0];
    assert!(
        (p[0] - 1.0).abs() < 1e-6 && (p[1] - 5.0).abs() < 1e-6 && (p[2] - 3.0).abs() < 1e-6,
        "{p:?}"
    );
    let n = back.normals[0];
    assert!(n[0].abs() < 1e-6 && (n[1] - 1.0).abs() < 1e-6, "{n:?}");
}
