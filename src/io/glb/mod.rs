//! Binary glTF 2.0 (GLB): encoder (one buffer; POSITION f32 VEC3 with exact min/max, NORMAL f32
//! VEC3 unit length, COLOR_0 f32 VEC3 linear RGB when the mesh has colours, u32 indices; one
//! mesh/node/scene; a far-from-origin mesh stored relative to a node translation; the CRS in
//! `asset.extras.crs`) with a read-back check, and a decoder that reads POSITION (+ NORMAL,
//! COLOR_0) and indices of every triangle primitive from the BIN chunk.
//!
//! The decoder reads accessors itself with checked arithmetic (no panics on hostile offsets) and
//! ignores node transforms (meshes are taken in their own frame). Time and memory O(mesh size).
//!
//! Reference: Khronos Group, glTF 2.0 Specification (2021), sections 3.6 (buffers, accessors) and 4.4 (GLB).

use std::borrow::Cow;
use std::collections::BTreeMap;

use gltf_json as json;
use json::validation::{Checked::Valid, USize64};

mod decode;

pub(crate) use decode::decode_glb_named;
pub use decode::{decode_glb, glb_crs};

use super::{IoError, MeshMeta};
use crate::geometry::{Point3, TriMesh, cross, normalized, sub};

const GENERATOR: &str = "rbfsurf";

fn enc_err(message: impl Into<String>) -> IoError {
    IoError::Encode {
        format: "GLB",
        message: message.into(),
    }
}

/// Checks what every writer needs: vertices and triangles present, indices in range, finite
/// coordinates, normals either absent or one per vertex.
pub(crate) fn check_mesh(mesh: &TriMesh, format: &'static str) -> Result<(), IoError> {
    let err = |message: String| IoError::Encode { format, message };
    let n = mesh.vertices.len();
    if n == 0 || mesh.triangles.is_empty() {
        return Err(err(format!(
            "the mesh is empty ({n} vertices, {} triangles); nothing to write",
            mesh.triangles.len()
        )));
    }
    if u32::try_from(n).is_err() || i32::try_from(n).is_err() {
        return Err(err(format!("{n} vertices exceed the 32-bit index range")));
    }
    if !mesh.normals.is_empty() && mesh.normals.len() != n {
        return Err(err(format!(
            "{} normals for {n} vertices (must be equal, or no normals)",
            mesh.normals.len()
        )));
    }
    if let Some((t, tri)) = mesh
        .triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
    {
        return Err(err(format!(
            "triangle {t} {tri:?} refers to a vertex ≥ {n}"
        )));
    }
    if !mesh.colors.is_empty() && mesh.colors.len() != n {
        return Err(err(format!(
            "{} colours for {n} vertices (must be equal, or no colours)",
            mesh.colors.len()
        )));
    }
    if let Some(v) = (mesh.colors.iter()).position(|c| c.iter().any(|x| !(0.0..=1.0).contains(x))) {
        return Err(err(format!(
            "vertex {v} has a colour outside [0, 1]: {:?}",
            mesh.colors[v]
        )));
    }
    if let Some(v) = mesh
        .vertices
        .iter()
        .position(|p| p.iter().any(|c| !c.is_finite()))
    {
        return Err(err(format!(
            "vertex {v} has a non-finite coordinate {:?}",
            mesh.vertices[v]
        )));
    }
    Ok(())
}

/// Unit normals for output: the given normal renormalised; when it is zero or not finite, the
/// area-weighted normal of the incident triangles; +Z only for a vertex with no usable triangle.
pub(crate) fn unit_normals(mesh: &TriMesh) -> Vec<[f32; 3]> {
    let mut face_sum: Option<Vec<Point3>> = None;
    let mut out = Vec::with_capacity(mesh.normals.len());
    for (i, &nrm) in mesh.normals.iter().enumerate() {
        let n = match normalized(nrm) {
            Some(n) => n,
            None => {
                let sums = face_sum.get_or_insert_with(|| area_weighted_normals(mesh));
                normalized(sums[i]).unwrap_or([0.0, 0.0, 1.0])
            }
        };
        out.push([n[0] as f32, n[1] as f32, n[2] as f32]);
    }
    out
}

fn area_weighted_normals(mesh: &TriMesh) -> Vec<Point3> {
    let mut sums = vec![[0.0; 3]; mesh.vertices.len()];
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let n = cross(sub(b, a), sub(c, a));
        for &i in t {
            let s = &mut sums[i as usize];
            *s = [s[0] + n[0], s[1] + n[1], s[2] + n[2]];
        }
    }
    sums
}

pub(super) fn push_view(
    root: &mut json::Root,
    buf: json::Index<json::Buffer>,
    off: usize,
    len: usize,
    target: json::buffer::Target,
) -> json::Index<json::buffer::View> {
    root.push(json::buffer::View {
        buffer: buf,
        byte_offset: Some(USize64::from(off)),
        byte_length: USize64::from(len),
        byte_stride: None,
        target: Some(Valid(target)),
        extensions: Default::default(),
        extras: Default::default(),
    })
}

pub(super) fn push_accessor(
    root: &mut json::Root,
    view: json::Index<json::buffer::View>,
    count: usize,
    kind: (json::accessor::ComponentType, json::accessor::Type),
    bounds: Option<Bounds>,
) -> json::Index<json::Accessor> {
    root.push(json::Accessor {
        buffer_view: Some(view),
        byte_offset: Some(USize64(0)),
        count: USize64::from(count),
        component_type: Valid(json::accessor::GenericComponentType(kind.0)),
        type_: Valid(kind.1),
        min: bounds.map(|b| json::Value::from(b.0.to_vec())),
        max: bounds.map(|b| json::Value::from(b.1.to_vec())),
        normalized: false,
        sparse: None,
        extensions: Default::default(),
        extras: Default::default(),
    })
}

/// Encodes a mesh as GLB bytes (glTF 2.0 binary), then decodes the result and checks the vertex
/// and index counts (an error, not a panic, if they differ).
///
/// Coordinates are converted from f64 to f32; vertices that round to the same f32 position are merged
/// first and the triangles that then repeat a corner dropped (so no zero-area triangle appears when
/// the file is read back and welded); normals are written unit length when `mesh.normals` is
/// non-empty. Fails with [`IoError::Encode`] on an empty mesh, out-of-range
/// indices or coordinates that are not finite in f32.
///
/// ```
/// use rbfsurf::geometry::TriMesh;
/// let mesh = TriMesh { vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///                      normals: vec![], triangles: vec![[0, 1, 2]], colors: vec![] };
/// let glb = rbfsurf::io::encode_glb(&mesh).unwrap();
/// assert_eq!(&glb[..4], b"glTF");
/// assert_eq!(rbfsurf::io::decode_glb(&glb).unwrap().triangles, mesh.triangles);
/// ```
pub fn encode_glb(mesh: &TriMesh) -> Result<Vec<u8>, IoError> {
    encode_glb_with(mesh, &MeshMeta::default())
}

/// [`encode_glb`] with metadata: `meta.crs` goes to `asset.extras.crs`. Vertex colours (sRGB in
/// [`TriMesh::colors`]) are written as `COLOR_0` in linear RGB, as glTF requires.
pub fn encode_glb_with(mesh: &TriMesh, meta: &MeshMeta) -> Result<Vec<u8>, IoError> {
    check_mesh(mesh, "GLB")?;
    let origin = origin_for(mesh);
    let shifted = shift(mesh, origin);
    let merged = super::snap::merge_f32_duplicates(&shifted);
    let mesh: &TriMesh = &merged;
    check_mesh(mesh, "GLB")?;
    let (pos, bounds) = f32_positions(mesh)?;
    let normals = unit_normals(mesh);
    let mut bin: Vec<u8> = Vec::with_capacity(pos.len() * 24 + mesh.triangles.len() * 12);
    bin.extend(pos.iter().flatten().flat_map(|c| c.to_le_bytes()));
    bin.extend(normals.iter().flatten().flat_map(|c| c.to_le_bytes()));
    let linear = mesh.colors.iter().flatten().map(|&c| srgb_to_linear(c));
    bin.extend(linear.flat_map(|c| c.to_le_bytes()));
    let flat = mesh.triangles.iter().flatten();
    bin.extend(flat.flat_map(|i| i.to_le_bytes()));
    let layout = Layout {
        vertices: pos.len(),
        indices: mesh.triangles.len() * 3,
        normals: !normals.is_empty(),
        colors: !mesh.colors.is_empty(),
        bin_len: bin.len(),
        bounds,
        origin,
    };
    let out = container(&document(&layout), meta, bin)?;
    let back = decode_glb(&out).map_err(|e| enc_err(format!("read-back failed: {e}")))?;
    let colors_back = back.colors.len() == mesh.colors.len();
    if back.vertices.len() != pos.len()
        || back.triangles.len() != mesh.triangles.len()
        || !colors_back
    {
        return Err(enc_err(format!(
            "read-back mismatch: wrote {} vertices / {} triangles, read {} / {}",
            pos.len(),
            mesh.triangles.len(),
            back.vertices.len(),
            back.triangles.len()
        )));
    }
    Ok(out)
}

/// Per-axis (min, max) of f32 positions.
pub(super) type Bounds = ([f32; 3], [f32; 3]);

/// Positions as f32 with their exact per-axis (min, max); errors if a coordinate overflows f32.
pub(super) fn f32_positions(mesh: &TriMesh) -> Result<(Vec<[f32; 3]>, Bounds), IoError> {
    let pos: Vec<[f32; 3]> = mesh.vertices.iter().map(|p| p.map(|c| c as f32)).collect();
    if let Some(v) = pos.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
        let p = mesh.vertices[v];
        return Err(enc_err(format!("vertex {v} {p:?} overflows f32")));
    }
    let mut min = [f32::INFINITY; 3];
    let mut max = [f32::NEG_INFINITY; 3];
    for p in &pos {
        for ((lo, hi), &c) in min.iter_mut().zip(max.iter_mut()).zip(p) {
            *lo = lo.min(c);
            *hi = hi.max(c);
        }
    }
    Ok((pos, (min, max)))
}

/// Sizes of the BIN chunk sections: positions, then normals (optional), then u32 indices.
struct Layout {
    vertices: usize,
    indices: usize,
    normals: bool,
    /// A COLOR_0 section (f32 VEC3) follows the normals.
    colors: bool,
    bin_len: usize,
    bounds: Bounds,
    /// Node translation (the positions are stored relative to it), `None` at the origin.
    origin: Option<[f32; 3]>,
}

/// Where to store positions from: for a mesh far from the origin (bbox centre farther than its
/// extent), its bbox centre rounded to f32 (exactly representable, so `origin + p` loses nothing
/// but the f32 rounding of the small relative `p`: at x ≈ 6·10⁵ absolute f32 coordinates are
/// 0.06 apart); `None` otherwise (positions stored as they are).
pub(crate) fn origin_for(mesh: &TriMesh) -> Option<[f32; 3]> {
    let b = crate::geometry::Aabb::from_points(&mesh.vertices);
    let (c, e) = (b.center(), b.extent());
    let far = (0..3).any(|k| c[k].abs() > e.iter().fold(0.0f64, |a, &x| a.max(x)));
    let o = c.map(|x| x as f32);
    (far && o.iter().all(|x| x.is_finite())).then_some(o)
}

/// `mesh` with `origin` subtracted from every vertex (borrowed when `None`).
fn shift(mesh: &TriMesh, origin: Option<[f32; 3]>) -> Cow<'_, TriMesh> {
    match origin {
        None => Cow::Borrowed(mesh),
        Some(o) => Cow::Owned(TriMesh {
            vertices: (mesh.vertices.iter())
                .map(|p| [0, 1, 2].map(|k| p[k] - f64::from(o[k])))
                .collect(),
            normals: mesh.normals.clone(),
            triangles: mesh.triangles.clone(),
            colors: mesh.colors.clone(),
        }),
    }
}

/// The glTF JSON document: one buffer, 2–3 views and accessors, one mesh, node and scene.
fn document(l: &Layout) -> json::Root {
    use json::accessor::{ComponentType, Type};
    use json::buffer::Target;
    let mut root = json::Root::default();
    root.asset.generator = Some(GENERATOR.into());
    let buf = root.push(json::Buffer {
        byte_length: USize64::from(l.bin_len),
        uri: None,
        extensions: Default::default(),
        extras: Default::default(),
    });
    let vec3 = (ComponentType::F32, Type::Vec3);
    let span = l.vertices * 12;
    let pv = push_view(&mut root, buf, 0, span, Target::ArrayBuffer);
    let pa = push_accessor(&mut root, pv, l.vertices, vec3, Some(l.bounds));
    let mut attributes = BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), pa);
    if l.normals {
        let nv = push_view(&mut root, buf, span, span, Target::ArrayBuffer);
        let na = push_accessor(&mut root, nv, l.vertices, vec3, None);
        attributes.insert(Valid(json::mesh::Semantic::Normals), na);
    }
    let mut off = if l.normals { 2 * span } else { span };
    if l.colors {
        let cv = push_view(&mut root, buf, off, span, Target::ArrayBuffer);
        let ca = push_accessor(&mut root, cv, l.vertices, vec3, None);
        attributes.insert(Valid(json::mesh::Semantic::Colors(0)), ca);
        off += span;
    }
    let iv = push_view(
        &mut root,
        buf,
        off,
        l.indices * 4,
        Target::ElementArrayBuffer,
    );
    let scalar = (ComponentType::U32, Type::Scalar);
    let ia = push_accessor(&mut root, iv, l.indices, scalar, None);
    let primitive = json::mesh::Primitive {
        attributes,
        indices: Some(ia),
        mode: Valid(json::mesh::Mode::Triangles),
        material: None,
        targets: None,
        extensions: Default::default(),
        extras: Default::default(),
    };
    let m = root.push(json::Mesh {
        primitives: vec![primitive],
        weights: None,
        extensions: Default::default(),
        extras: Default::default(),
    });
    let node = root.push(json::Node {
        mesh: Some(m),
        translation: l.origin,
        ..Default::default()
    });
    let scene = root.push(json::Scene {
        nodes: vec![node],
        extensions: Default::default(),
        extras: Default::default(),
    });
    root.scene = Some(scene);
    root
}

/// GLB container: 12-byte header, JSON chunk padded with spaces, BIN chunk padded with zeros.
/// `meta.crs`, when present, is added as `asset.extras.crs` (a string).
pub(super) fn container(
    root: &json::Root,
    meta: &MeshMeta,
    bin: Vec<u8>,
) -> Result<Vec<u8>, IoError> {
    let mut value = json::serialize::to_value(root).map_err(|e| enc_err(format!("JSON: {e}")))?;
    if let (Some(crs), Some(asset)) = (&meta.crs, value.get_mut("asset")) {
        asset["extras"] = serde_json::json!({ "crs": crs });
    }
    let json_bytes = serde_json::to_vec(&value).map_err(|e| enc_err(format!("JSON: {e}")))?;
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: 0,
        },
        json: Cow::Owned(json_bytes),
        bin: Some(Cow::Owned(bin)),
    };
    let mut out = Vec::new();
    glb.to_writer(&mut out)
        .map_err(|e| enc_err(format!("GLB container: {e}")))?;
    Ok(out)
}

/// sRGB transfer function inverse (IEC 61966-2-1): encoded value in [0, 1] → linear light.
pub(crate) fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// sRGB transfer function: linear light in [0, 1] → encoded value.
pub(crate) fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

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
        let glb = encode_glb(&m).unwrap();
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
            let glb = encode_glb(&m).unwrap();
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

    #[test]
    fn degenerate_normals_fall_back_to_faces() {
        let mut m = octahedron();
        m.normals[4] = [0.0, 0.0, 0.0];
        m.normals[0] = [f64::NAN, 0.0, 0.0];
        let back = decode_glb(&encode_glb(&m).unwrap()).unwrap();
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
        let mut bad = m.clone();
        bad.triangles[3] = [0, 1, 6];
        assert!(matches!(encode_glb(&bad), Err(IoError::Encode { .. })));
        let mut bad = m.clone();
        bad.vertices[2][1] = f64::INFINITY;
        assert!(matches!(encode_glb(&bad), Err(IoError::Encode { .. })));
        let mut bad = m.clone();
        bad.vertices[2][1] = 1e300;
        assert!(matches!(encode_glb(&bad), Err(IoError::Encode { .. })));
        let mut bad = m.clone();
        bad.normals.pop();
        assert!(matches!(encode_glb(&bad), Err(IoError::Encode { .. })));
        assert!(matches!(
            encode_glb(&TriMesh::default()),
            Err(IoError::Encode { .. })
        ));
    }

    #[test]
    fn decoding_damaged_glb_never_panics() {
        let glb = encode_glb(&octahedron()).unwrap();
        assert!(matches!(
            decode_glb(b"glTF garbage"),
            Err(IoError::Invalid { .. })
        ));
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
