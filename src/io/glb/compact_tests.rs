//! Tests of the compact GLB (`KHR_mesh_quantization` + `EXT_meshopt_compression`): round trip
//! within the grid's bound, the document's structure, far-from-origin meshes, hostile streams.

use std::collections::HashMap;

use serde_json::{Value, json};

use super::pack::{Grid, grid_for};
use super::*;
use crate::geometry::synthetic::Shape;

/// A torus with analytic normals and a smooth colour ramp.
fn coloured_torus(resolution: usize) -> TriMesh {
    let mut m = Shape::by_name("torus").unwrap().truth_mesh(resolution);
    m.colors = (m.vertices.iter())
        .map(|p| [0, 1, 2].map(|k| (0.5 + 0.4 * (p[k] * 3.0).sin()) as f32))
        .collect();
    m
}

fn split(glb: &[u8]) -> (Value, Vec<u8>) {
    let g = gltf::binary::Glb::from_slice(glb).unwrap();
    (
        serde_json::from_slice(&g.json).unwrap(),
        g.bin.unwrap().into_owned(),
    )
}

fn rebuild(v: Value, bin: Vec<u8>) -> Vec<u8> {
    container_value(v, &MeshMeta::default(), bin).unwrap()
}

/// Triangle with its smallest corner first (decoding may rotate a triangle's corners).
fn canonical(t: [u32; 3]) -> [u32; 3] {
    let i = (0..3).min_by_key(|&i| t[i]).unwrap();
    [t[i], t[(i + 1) % 3], t[(i + 2) % 3]]
}

/// Decoded mesh vs the source: every decoded vertex is the grid point of a source vertex, the
/// triangles are the source's (up to corner rotation and order), normals and colours close.
/// Returns the largest position error.
fn check_against(m: &TriMesh, back: &TriMesh, grid: &Grid) -> f64 {
    let key: HashMap<[u16; 3], u32> = (m.vertices.iter().enumerate())
        .map(|(i, p)| (grid.quantize(p), i as u32))
        .collect();
    assert_eq!(
        key.len(),
        m.vertices.len(),
        "no two source vertices share a grid point"
    );
    let to_src: Vec<u32> = (back.vertices.iter())
        .map(|p| key[&grid.quantize(p)])
        .collect();
    let mut want: Vec<[u32; 3]> = m.triangles.iter().map(|&t| canonical(t)).collect();
    let mut got: Vec<[u32; 3]> = (back.triangles.iter())
        .map(|t| canonical(t.map(|v| to_src[v as usize])))
        .collect();
    want.sort_unstable();
    got.sort_unstable();
    assert_eq!(got, want, "same triangles, same winding");
    let mut worst: f64 = 0.0;
    for (i, p) in back.vertices.iter().enumerate() {
        let s = to_src[i] as usize;
        worst = worst.max(crate::geometry::norm(crate::geometry::sub(
            *p,
            m.vertices[s],
        )));
        let n = back.normals[i];
        let want = normalized(m.normals[s]).unwrap();
        let dot = crate::geometry::dot(n, want);
        assert!(dot > 0.9995, "normal {n:?} vs {want:?}");
        for k in 0..3 {
            let d = (back.colors[i][k] - m.colors[s][k]).abs();
            assert!(d < 2e-3, "colour {:?} vs {:?}", back.colors[i], m.colors[s]);
        }
    }
    worst
}

#[test]
fn compact_round_trip_is_the_mesh_within_the_grid_bound() {
    let m = coloured_torus(160);
    let grid = grid_for(&m).unwrap();
    let glb = encode_glb(&m).unwrap();
    let back = decode_glb(&glb).unwrap();
    assert_eq!(back.vertices.len(), m.vertices.len());
    let worst = check_against(&m, &back, &grid);
    let b = crate::geometry::Aabb::from_points(&m.vertices);
    let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    assert!(worst <= grid.max_error(), "{worst} > {}", grid.max_error());
    assert!(
        worst <= 1.35e-5 * longest,
        "{worst} vs longest edge {longest}"
    );
    let float = encode_glb_with(&m, &MeshMeta::default(), GlbCompression::None).unwrap();
    // Colours (16-bit linear) cost ~2 bytes per triangle on top; without them, under 6.
    assert!(
        glb.len() * 4 < float.len(),
        "{} vs {} bytes",
        glb.len(),
        float.len()
    );
    let mut bare = m.clone();
    bare.colors.clear();
    let glb = encode_glb(&bare).unwrap();
    let per_triangle = glb.len() as f64 / m.triangles.len() as f64;
    assert!(per_triangle < 6.0, "{per_triangle} B/triangle");
}

#[test]
fn compact_document_follows_the_extensions() {
    let m = coloured_torus(40);
    let meta = MeshMeta {
        crs: Some("EPSG:32633".into()),
    };
    let glb = encode_glb_with(&m, &meta, GlbCompression::Meshopt).unwrap();
    let (v, bin) = split(&glb);
    let both = json!(["EXT_meshopt_compression", "KHR_mesh_quantization"]);
    assert_eq!(v["extensionsUsed"], both);
    assert_eq!(v["extensionsRequired"], both);
    assert_eq!(v["asset"]["extras"]["crs"], "EPSG:32633");
    assert_eq!(v["buffers"][0]["byteLength"], bin.len());
    let fallback = &v["buffers"][1];
    assert_eq!(
        fallback["extensions"]["EXT_meshopt_compression"]["fallback"],
        true
    );
    assert!(fallback.get("uri").is_none());
    let grid = grid_for(&m).unwrap();
    let node = &v["nodes"][0];
    assert_eq!(node["scale"], json!([grid.step, grid.step, grid.step]));
    assert_eq!(node["translation"], json!(grid.origin));
    let views = v["bufferViews"].as_array().unwrap();
    assert_eq!(views.len(), 4, "positions, normals, colours, indices");
    for (view, (stride, mode, header)) in views.iter().zip([
        (8, "ATTRIBUTES", 0xa0),
        (4, "ATTRIBUTES", 0xa0),
        (8, "ATTRIBUTES", 0xa0),
        (2, "TRIANGLES", 0xe1),
    ]) {
        let ext = &view["extensions"]["EXT_meshopt_compression"];
        assert_eq!(view["buffer"], 1);
        assert_eq!(ext["buffer"], 0);
        assert_eq!(ext["mode"], mode);
        assert_eq!(ext["byteStride"], stride);
        let count = ext["count"].as_u64().unwrap();
        assert_eq!(view["byteLength"].as_u64().unwrap(), count * stride);
        let at = ext["byteOffset"].as_u64().unwrap() as usize;
        assert_eq!(at % 4, 0);
        assert_eq!(bin[at], header);
        if mode == "ATTRIBUTES" {
            assert_eq!(view["byteStride"], stride);
        } else {
            assert!(view.get("byteStride").is_none());
        }
    }
    let acc = &v["accessors"];
    assert_eq!(
        (acc[0]["componentType"].as_u64(), acc[0].get("normalized")),
        (Some(5123), None)
    );
    assert_eq!(acc[1]["componentType"], 5120);
    assert_eq!(acc[1]["normalized"], true);
    assert_eq!(acc[2]["componentType"], 5123);
    assert_eq!(acc[2]["normalized"], true);
    let max = acc[0]["max"].as_array().unwrap();
    assert!(
        max.iter()
            .any(|x| x.as_u64() == Some(u64::from(grid.max_q())))
    );
}

#[test]
fn far_from_origin_the_grid_keeps_the_object_precision() {
    let mut m = coloured_torus(60);
    let shift = [5e5, 4.1e6, 250.0];
    for p in &mut m.vertices {
        *p = [0, 1, 2].map(|k| p[k] + shift[k]);
    }
    let grid = grid_for(&m).unwrap();
    let back = decode_glb(&encode_glb(&m).unwrap()).unwrap();
    let worst = check_against(&m, &back, &grid);
    // The torus is 3 units across: 16-bit steps of ~5e-5, whatever the offset.
    assert!(
        worst <= grid.max_error() && grid.max_error() < 1e-4,
        "{worst}"
    );
}

#[test]
fn vertices_on_one_grid_point_are_merged_without_degenerate_triangles() {
    let mut m = super::tests::octahedron();
    // A sliver: vertex 0 split in two, 1e-9 apart (far below the grid step).
    m.vertices.push([1.5 + 1e-9, 0.0, 0.0]);
    m.normals.push([1.0, 0.0, 0.0]);
    m.triangles[0] = [6, 2, 4];
    m.triangles.push([0, 6, 4]);
    let back = decode_glb(&encode_glb(&m).unwrap()).unwrap();
    assert_eq!(back.vertices.len(), 6);
    assert_eq!(back.triangles.len(), 8);
    let t = crate::mesh::analyze(&back);
    assert_eq!(t.degenerate_triangles, 0);
    assert!(t.watertight && t.manifold, "{t:?}");
}

/// Every way of damaging the compressed views gives an error, not a panic or a wrong mesh.
#[test]
fn hostile_compressed_views_are_clear_errors() {
    let glb = encode_glb(&coloured_torus(40)).unwrap();
    let (v, bin) = split(&glb);
    type Edit = fn(&mut Value, &mut Vec<u8>);
    let cases: &[(&str, Edit)] = &[
        ("count ≠ byteLength / stride", |v, _| {
            v["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = json!(7);
        }),
        ("huge count", |v, _| {
            let n = 1u64 << 40;
            v["bufferViews"][0]["byteLength"] = json!(n * 8);
            v["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["count"] = json!(n);
        }),
        ("stride 6", |v, _| {
            v["bufferViews"][0]["byteStride"] = json!(6);
        }),
        ("stride mismatch", |v, _| {
            let e = &mut v["bufferViews"][0]["extensions"]["EXT_meshopt_compression"];
            e["byteStride"] = json!(12);
        }),
        ("index stride 3", |v, _| {
            let e = &mut v["bufferViews"][3]["extensions"]["EXT_meshopt_compression"];
            e["byteStride"] = json!(3);
            let c = e["count"].as_u64().unwrap();
            v["bufferViews"][3]["byteLength"] = json!(c * 3);
        }),
        ("TRIANGLES count not a multiple of 3", |v, _| {
            let e = &mut v["bufferViews"][3]["extensions"]["EXT_meshopt_compression"];
            e["count"] = json!(4);
            v["bufferViews"][3]["byteLength"] = json!(8);
        }),
        ("unknown mode", |v, _| {
            v["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["mode"] = json!("FOO");
        }),
        ("unknown filter", |v, _| {
            let e = &mut v["bufferViews"][1]["extensions"]["EXT_meshopt_compression"];
            e["filter"] = json!("QUATERNION");
        }),
        ("data in the fallback buffer", |v, _| {
            v["bufferViews"][1]["extensions"]["EXT_meshopt_compression"]["buffer"] = json!(1);
        }),
        ("stream beyond the BIN chunk", |v, _| {
            let e = &mut v["bufferViews"][2]["extensions"]["EXT_meshopt_compression"];
            e["byteOffset"] = json!(1u64 << 50);
        }),
        ("missing byteLength", |v, _| {
            let e = &mut v["bufferViews"][2]["extensions"]["EXT_meshopt_compression"];
            e.as_object_mut().unwrap().remove("byteLength");
        }),
        ("vertex codec version 1 header", |v, bin| {
            let at = v["bufferViews"][0]["extensions"]["EXT_meshopt_compression"]["byteOffset"]
                .as_u64()
                .unwrap() as usize;
            bin[at] = 0xa1;
        }),
        ("truncated vertex stream", |v, _| {
            let e = &mut v["bufferViews"][0]["extensions"]["EXT_meshopt_compression"];
            let n = e["byteLength"].as_u64().unwrap();
            e["byteLength"] = json!(n / 2);
        }),
        ("truncated index stream", |v, _| {
            let e = &mut v["bufferViews"][3]["extensions"]["EXT_meshopt_compression"];
            let n = e["byteLength"].as_u64().unwrap();
            e["byteLength"] = json!(n - 9);
        }),
        ("corrupt index stream", |v, bin| {
            let e = &v["bufferViews"][3]["extensions"]["EXT_meshopt_compression"];
            let at = e["byteOffset"].as_u64().unwrap() as usize;
            let n = e["byteLength"].as_u64().unwrap() as usize;
            for b in &mut bin[at + 1..at + n] {
                *b = 0xff;
            }
        }),
        ("POSITION accessor out of range", |v, _| {
            v["meshes"][0]["primitives"][0]["attributes"]["POSITION"] = json!(99);
        }),
        ("POSITION count beyond the view", |v, _| {
            v["accessors"][0]["count"] = json!(1u64 << 33);
        }),
    ];
    for &(name, edit) in cases {
        let (mut v2, mut bin2) = (v.clone(), bin.clone());
        edit(&mut v2, &mut bin2);
        let r = decode_glb(&rebuild(v2, bin2));
        match r {
            Err(
                IoError::Invalid { .. } | IoError::Truncated { .. } | IoError::Unsupported { .. },
            ) => {}
            other => panic!("{name}: {other:?}"),
        }
    }
}

#[test]
fn random_damage_to_compressed_streams_never_panics() {
    let glb = encode_glb(&coloured_torus(30)).unwrap();
    let (v, bin) = split(&glb);
    let mut st = 11u64;
    for _ in 0..400 {
        st = st
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut b = bin.clone();
        let i = (st >> 33) as usize % b.len();
        b[i] ^= (st >> 20) as u8 | 1;
        if let Ok(m) = decode_glb(&rebuild(v.clone(), b)) {
            // Decoded garbage is still a mesh whose indices are in range.
            let n = m.vertices.len() as u32;
            assert!(m.triangles.iter().flatten().all(|&i| i < n));
        }
    }
}

#[test]
fn unused_vertices_are_dropped_not_a_panic() {
    // A torus plus vertices no triangle uses: one at the end, one in the middle of the list (the
    // fetch remap once assumed every vertex is used and indexed past its table: a panic on real
    // scans whose grid merge dropped a vertex's last triangle).
    let mut m = Shape::by_name("torus").unwrap().truth_mesh(24);
    let mid = m.vertices.len() as u32 / 2;
    m.vertices.insert(mid as usize, [0.5, 0.5, 0.5]);
    if !m.normals.is_empty() {
        m.normals.insert(mid as usize, [0.0, 0.0, 1.0]);
    }
    for t in &mut m.triangles {
        for v in t.iter_mut() {
            *v += u32::from(*v >= mid);
        }
    }
    m.vertices.push([0.1, 0.9, 0.5]);
    if !m.normals.is_empty() {
        m.normals.push([1.0, 0.0, 0.0]);
    }
    let back = decode_glb(&encode_glb(&m).unwrap()).unwrap();
    assert_eq!(back.vertices.len(), m.vertices.len() - 2);
    assert_eq!(back.triangles.len(), m.triangles.len());
    let t = crate::mesh::analyze(&back);
    assert!(t.watertight && t.components == 1, "{t:?}");
}
