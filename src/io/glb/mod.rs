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
mod pack;
mod unpack;

pub(crate) use decode::decode_glb_named;
pub use decode::{decode_glb, glb_asset_extra, glb_crs};

use super::{IoError, MeshMeta};
use crate::geometry::{Point3, TriMesh, cross, normalized, sub};

const GENERATOR: &str = "rbfsurf";

/// How a `.glb` is stored.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum GlbCompression {
    /// `KHR_mesh_quantization` + `EXT_meshopt_compression` (the default): 16-bit positions on a
    /// grid over the bounding box (dequantized by the node transform), 8-bit normals, meshoptimizer's
    /// vertex and index codecs. About 4–5 bytes per triangle; needs a loader with the meshopt
    /// decoder (three.js, Babylon.js, gltfpack, rbfsurf).
    #[default]
    Meshopt,
    /// Plain glTF: f32 positions and normals, u32 indices (24 bytes per triangle), for tools that
    /// cannot decode meshopt.
    None,
}

/// How a `.glb` is written ([`super::MeshFormat::Glb`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct GlbOptions {
    /// Storage of the file (default [`GlbCompression::Meshopt`]).
    pub compression: GlbCompression,
    /// Simplified levels of detail written next to the file, `NAME.lod1.glb` … `NAME.lodN.glb`
    /// (see [`crate::mesh::lod`]); default 0. The main file always holds the full mesh.
    pub lods: usize,
}

impl GlbOptions {
    /// `compression`, no levels of detail.
    pub const fn compressed(compression: GlbCompression) -> GlbOptions {
        GlbOptions {
            compression,
            lods: 0,
        }
    }
}

impl GlbCompression {
    /// Every choice.
    pub const ALL: [GlbCompression; 2] = [GlbCompression::Meshopt, GlbCompression::None];

    /// Command-line / API name.
    pub fn name(self) -> &'static str {
        match self {
            GlbCompression::Meshopt => "meshopt",
            GlbCompression::None => "none",
        }
    }
}

impl std::str::FromStr for GlbCompression {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        (GlbCompression::ALL.into_iter())
            .find(|c| c.name() == s)
            .ok_or_else(|| format!("unknown GLB compression '{s}' (use meshopt or none)"))
    }
}

impl std::fmt::Display for GlbCompression {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

pub(super) fn enc_err(message: impl Into<String>) -> IoError {
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

/// Encodes a mesh as a compact GLB ([`GlbCompression::Meshopt`]), then decodes the result and
/// checks the vertex and index counts (an error, not a panic, if they differ). See
/// [`encode_glb_with`].
///
/// ```
/// use rbfsurf::geometry::TriMesh;
/// let mesh = TriMesh { vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
///                      normals: vec![], triangles: vec![[0, 1, 2]], colors: vec![] };
/// let glb = rbfsurf::io::encode_glb(&mesh).unwrap();
/// assert_eq!(&glb[..4], b"glTF");
/// let back = rbfsurf::io::decode_glb(&glb).unwrap();
/// assert_eq!(back.triangles.len(), 1);
/// assert_eq!(back.vertices.len(), 3);
/// ```
pub fn encode_glb(mesh: &TriMesh) -> Result<Vec<u8>, IoError> {
    encode_glb_with(mesh, &MeshMeta::default(), GlbCompression::Meshopt)
}

/// Encodes a mesh as GLB bytes (glTF 2.0 binary) stored as `compression` says, with metadata:
/// `meta.crs` goes to `asset.extras.crs`. Vertex colours (sRGB in [`TriMesh::colors`]) are
/// written as `COLOR_0` in linear RGB, as glTF requires. The result is decoded again and its
/// vertex and triangle counts checked.
///
/// [`GlbCompression::Meshopt`]: positions on a 16-bit grid over the bounding box (error at most
/// 1.3·10⁻⁵ of the longest bbox edge), the node transform dequantizes; vertices on one grid point are merged; vertex and triangle order are
/// optimised (so indices differ from `mesh`'s). [`GlbCompression::None`]: coordinates converted
/// from f64 to f32, vertices that round to the same f32 position merged first and the triangles
/// that then repeat a corner dropped (so no zero-area triangle appears when the file is read back
/// and welded); a mesh far from the origin is stored relative to a node translation. Normals are
/// written unit length when `mesh.normals` is non-empty. Fails with [`IoError::Encode`] on an
/// empty mesh, out-of-range indices or coordinates that are not finite in f32.
pub fn encode_glb_with(
    mesh: &TriMesh,
    meta: &MeshMeta,
    compression: GlbCompression,
) -> Result<Vec<u8>, IoError> {
    let (out, vertices, triangles, colors) = match compression {
        GlbCompression::Meshopt => {
            let (out, v, t) = pack::encode_compressed(mesh, meta)?;
            (out, v, t, !mesh.colors.is_empty())
        }
        GlbCompression::None => encode_float(mesh, meta)?,
    };
    let back = decode_glb(&out).map_err(|e| enc_err(format!("read-back failed: {e}")))?;
    if back.vertices.len() != vertices
        || back.triangles.len() != triangles
        || back.colors.is_empty() == colors
    {
        return Err(enc_err(format!(
            "read-back mismatch: wrote {vertices} vertices / {triangles} triangles, read {} / {}",
            back.vertices.len(),
            back.triangles.len()
        )));
    }
    Ok(out)
}

/// The plain float GLB: bytes, vertex and triangle counts, whether colours were written.
fn encode_float(mesh: &TriMesh, meta: &MeshMeta) -> Result<(Vec<u8>, usize, usize, bool), IoError> {
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
    Ok((
        out,
        pos.len(),
        mesh.triangles.len(),
        !mesh.colors.is_empty(),
    ))
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
    let m = root.push(triangle_mesh(attributes, ia));
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

/// One mesh of one indexed triangle primitive, without material.
pub(super) fn triangle_mesh(
    attributes: BTreeMap<
        json::validation::Checked<json::mesh::Semantic>,
        json::Index<json::Accessor>,
    >,
    indices: json::Index<json::Accessor>,
) -> json::Mesh {
    json::Mesh {
        primitives: vec![json::mesh::Primitive {
            attributes,
            indices: Some(indices),
            mode: Valid(json::mesh::Mode::Triangles),
            material: None,
            targets: None,
            extensions: Default::default(),
            extras: Default::default(),
        }],
        weights: None,
        extensions: Default::default(),
        extras: Default::default(),
    }
}

/// GLB container: 12-byte header, JSON chunk padded with spaces, BIN chunk padded with zeros.
/// `meta.crs`, when present, is added as `asset.extras.crs` (a string).
pub(super) fn container(
    root: &json::Root,
    meta: &MeshMeta,
    bin: Vec<u8>,
) -> Result<Vec<u8>, IoError> {
    let value = json::serialize::to_value(root).map_err(|e| enc_err(format!("JSON: {e}")))?;
    container_value(value, meta, bin)
}

/// [`container`] for a JSON document already built as a value.
pub(super) fn container_value(
    mut value: serde_json::Value,
    meta: &MeshMeta,
    bin: Vec<u8>,
) -> Result<Vec<u8>, IoError> {
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

/// `glb` with `asset.extras[key] = value` added (the BIN chunk unchanged).
pub(crate) fn with_asset_extra(
    glb: &[u8],
    key: &str,
    value: serde_json::Value,
) -> Result<Vec<u8>, IoError> {
    let g = gltf::binary::Glb::from_slice(glb).map_err(|e| enc_err(format!("GLB: {e}")))?;
    let mut doc: serde_json::Value =
        serde_json::from_slice(&g.json).map_err(|e| enc_err(format!("JSON: {e}")))?;
    let asset = &mut doc["asset"];
    if !asset["extras"].is_object() {
        asset["extras"] = serde_json::json!({});
    }
    asset["extras"][key] = value;
    let bin = g.bin.map(|b| b.into_owned()).unwrap_or_default();
    container_value(doc, &MeshMeta::default(), bin)
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
mod compact_tests;
#[cfg(test)]
pub(crate) mod tests;
