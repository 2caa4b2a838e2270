//! GLB decoder: POSITION (+ NORMAL, COLOR_0) and indices of every triangle primitive from the BIN
//! chunk, accessors read with checked arithmetic (no panics on hostile offsets); the CRS from
//! `asset.extras.crs`.

use std::path::Path;

use super::super::{IoError, MEMORY_SOURCE};
use super::linear_to_srgb;
use crate::geometry::{Point3, TriMesh};

/// Decodes GLB bytes (or glTF JSON without external buffers) into one triangle mesh: all triangle
/// primitives of all meshes, concatenated, each mesh placed by the world transform of the first
/// node that uses it (a singular transform, such as the zero scale that hides a morph frame, moves
/// by its translation only). Reads plain float files, `KHR_mesh_quantization` accessors (integer
/// and normalized positions, normals, colours) and `EXT_meshopt_compression` views. Normals are
/// kept only when every primitive has them.
pub fn decode_glb(bytes: &[u8]) -> Result<TriMesh, IoError> {
    decode_glb_named(bytes, Path::new(MEMORY_SOURCE))
}

pub(crate) fn decode_glb_named(bytes: &[u8], src: &Path) -> Result<TriMesh, IoError> {
    let invalid = |message: String| IoError::Invalid {
        path: src.to_path_buf(),
        format: "GLB",
        message,
    };
    let glb;
    let (json, bin): (&[u8], &[u8]) = if bytes.starts_with(b"glTF") {
        glb = gltf::binary::Glb::from_slice(bytes).map_err(|e| invalid(e.to_string()))?;
        (&glb.json, glb.bin.as_deref().unwrap_or_default())
    } else {
        (bytes, &[])
    };
    let mut value: serde_json::Value =
        serde_json::from_slice(json).map_err(|e| invalid(format!("JSON: {e}")))?;
    let unpacked = super::unpack::unpack(&mut value, bin, src)?;
    let blob: &[u8] = unpacked.as_deref().unwrap_or(bin);
    check_position_indices(&value).map_err(invalid)?;
    let root: gltf_json::Root =
        serde_json::from_value(value).map_err(|e| invalid(format!("JSON: {e}")))?;
    let document = gltf::Document::from_json(root).map_err(|e| invalid(e.to_string()))?;
    let world = world_transforms(&document);
    let mut out = TriMesh::default();
    let mut all_normals = true;
    let mut all_colors = true;
    for mesh in document.meshes() {
        let m = (document.nodes())
            .find(|n| n.mesh().is_some_and(|m| m.index() == mesh.index()))
            .map_or(Affine::IDENTITY, |n| world[n.index()]);
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let acc = prim
                .get(&gltf::Semantic::Positions)
                .ok_or_else(|| invalid("triangle primitive without POSITION".into()))?;
            let base = out.vertices.len();
            let pos = read_vec3(&acc, blob, src)?;
            let count = pos.len();
            out.vertices.extend(pos.into_iter().map(|p| m.point(p)));
            match prim.get(&gltf::Semantic::Normals) {
                Some(nacc) if all_normals => {
                    let ns = read_vec3(&nacc, blob, src)?;
                    if ns.len() != count {
                        return Err(invalid(format!(
                            "NORMAL has {} entries, POSITION {count}",
                            ns.len()
                        )));
                    }
                    out.normals.extend(ns.into_iter().map(|n| m.normal(n)));
                }
                _ => all_normals = false,
            }
            match prim.get(&gltf::Semantic::Colors(0)) {
                Some(cacc) if all_colors => {
                    let cs = read_colors(&cacc, blob, src)?;
                    if cs.len() != count {
                        return Err(invalid(format!(
                            "COLOR_0 has {} entries, POSITION {count}",
                            cs.len()
                        )));
                    }
                    out.colors.extend(cs);
                }
                _ => all_colors = false,
            }
            let idx: Vec<u32> = match prim.indices() {
                Some(iacc) => read_indices(&iacc, blob, src)?,
                None => (0..count as u32).collect(),
            };
            if !idx.len().is_multiple_of(3) {
                return Err(invalid(format!(
                    "{} indices is not a multiple of 3",
                    idx.len()
                )));
            }
            if let Some(bad) = idx.iter().find(|&&i| i as usize >= count) {
                return Err(invalid(format!("index {bad} ≥ vertex count {count}")));
            }
            let base = u32::try_from(base).map_err(|_| invalid("too many vertices".into()))?;
            out.triangles.extend(
                idx.chunks_exact(3)
                    .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
            );
        }
    }
    if !all_normals {
        out.normals.clear();
    }
    if !all_colors {
        out.colors.clear();
    }
    Ok(out)
}

/// gltf-json's validation reads `accessors[POSITION]` before checking that index (and panics on a
/// bad one): check every POSITION index first.
fn check_position_indices(doc: &serde_json::Value) -> Result<(), String> {
    let accessors = doc
        .get("accessors")
        .and_then(|a| a.as_array())
        .map_or(0, Vec::len);
    let meshes = doc.get("meshes").and_then(|m| m.as_array());
    for (m, mesh) in meshes.into_iter().flatten().enumerate() {
        let prims = mesh.get("primitives").and_then(|p| p.as_array());
        for (p, prim) in prims.into_iter().flatten().enumerate() {
            let pos = prim.get("attributes").and_then(|a| a.get("POSITION"));
            if let Some(i) = pos.and_then(serde_json::Value::as_u64)
                && i >= accessors as u64
            {
                return Err(format!(
                    "meshes[{m}].primitives[{p}].attributes.POSITION = {i}, but there are {accessors} accessors"
                ));
            }
        }
    }
    Ok(())
}

/// The bytes of each element of a non-sparse accessor stored in the BIN chunk: (slice, stride, element size, count).
fn accessor_span<'b>(
    acc: &gltf::Accessor,
    blob: &'b [u8],
    src: &Path,
) -> Result<(&'b [u8], usize, usize, usize), IoError> {
    let unsupported = |feature: &str| IoError::Unsupported {
        path: src.to_path_buf(),
        format: "GLB",
        feature: feature.into(),
    };
    if acc.sparse().is_some() {
        return Err(unsupported("sparse accessors"));
    }
    let view = acc
        .view()
        .ok_or_else(|| unsupported("accessors without a bufferView"))?;
    if !matches!(view.buffer().source(), gltf::buffer::Source::Bin) || view.buffer().index() != 0 {
        return Err(unsupported(
            "buffers other than the GLB BIN chunk (external URIs, fallback buffers)",
        ));
    }
    let elem = acc.size();
    let stride = view.stride().unwrap_or(elem).max(elem);
    let count = acc.count();
    let view_bytes = view
        .offset()
        .checked_add(view.length())
        .and_then(|end| blob.get(view.offset()..end));
    let need = count
        .checked_sub(1)
        .map_or(Some(0), |c| c.checked_mul(stride)?.checked_add(elem))
        .and_then(|n| n.checked_add(acc.offset()));
    match (view_bytes, need) {
        (Some(v), Some(need)) if need <= v.len() => {
            Ok((&v[acc.offset()..need], stride, elem, count))
        }
        _ => Err(IoError::Truncated {
            path: src.to_path_buf(),
            format: "GLB",
            what: format!(
                "accessor {} needs {count} elements of {elem} bytes",
                acc.index()
            ),
            expected: need.unwrap_or(usize::MAX) as u64,
            found: blob.len() as u64,
        }),
    }
}

/// A VEC3 accessor as f64: f32, or (`KHR_mesh_quantization`) 8/16-bit integers, normalized
/// (signed: `max(v / max, −1)`, unsigned: `v / max`) or not (the integer value).
fn read_vec3(acc: &gltf::Accessor, blob: &[u8], src: &Path) -> Result<Vec<Point3>, IoError> {
    use gltf::accessor::{DataType, Dimensions};
    if acc.dimensions() != Dimensions::Vec3 || acc.data_type() == DataType::U32 {
        return Err(IoError::Unsupported {
            path: src.to_path_buf(),
            format: "GLB",
            feature: format!(
                "vertex attribute of type {:?} {:?} (expected VEC3 of f32 or 8/16-bit integers)",
                acc.data_type(),
                acc.dimensions()
            ),
        });
    }
    let (bytes, stride, _, count) = accessor_span(acc, blob, src)?;
    let (kind, norm) = (acc.data_type(), acc.normalized());
    let f = |o: usize| -> f64 {
        let b = &bytes[o..];
        match kind {
            DataType::I8 => scale_signed(f64::from(b[0] as i8), 127.0, norm),
            DataType::U8 => scale_unsigned(f64::from(b[0]), 255.0, norm),
            DataType::I16 => {
                scale_signed(f64::from(i16::from_le_bytes([b[0], b[1]])), 32767.0, norm)
            }
            DataType::U16 => {
                scale_unsigned(f64::from(u16::from_le_bytes([b[0], b[1]])), 65535.0, norm)
            }
            _ => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        }
    };
    let size = kind.size();
    Ok((0..count)
        .map(|i| i * stride)
        .map(|o| [f(o), f(o + size), f(o + 2 * size)])
        .collect())
}

fn scale_signed(v: f64, max: f64, normalized: bool) -> f64 {
    if normalized { (v / max).max(-1.0) } else { v }
}

fn scale_unsigned(v: f64, max: f64, normalized: bool) -> f64 {
    if normalized { v / max } else { v }
}

/// An affine map of positions (f64, row-major 3×4) and the matrix its normals take.
#[derive(Debug, Clone, Copy)]
struct Affine {
    m: [[f64; 4]; 3],
    /// Inverse transpose of the linear part (normals); `None` for a singular map.
    normal: Option<[[f64; 3]; 3]>,
}

impl Affine {
    const IDENTITY: Affine = Affine {
        m: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ],
        normal: Some([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
    };

    fn from_gltf(t: gltf::scene::Transform) -> Affine {
        let m = match t {
            gltf::scene::Transform::Matrix { matrix: c } => {
                [0, 1, 2].map(|r| [0, 1, 2, 3].map(|col| f64::from(c[col][r])))
            }
            gltf::scene::Transform::Decomposed {
                translation: t,
                rotation: q,
                scale: s,
            } => {
                let [x, y, z, w] = q.map(f64::from);
                let n = (x * x + y * y + z * z + w * w)
                    .sqrt()
                    .max(f64::MIN_POSITIVE);
                let [x, y, z, w] = [x / n, y / n, z / n, w / n];
                let r = [
                    [
                        1.0 - 2.0 * (y * y + z * z),
                        2.0 * (x * y - z * w),
                        2.0 * (x * z + y * w),
                    ],
                    [
                        2.0 * (x * y + z * w),
                        1.0 - 2.0 * (x * x + z * z),
                        2.0 * (y * z - x * w),
                    ],
                    [
                        2.0 * (x * z - y * w),
                        2.0 * (y * z + x * w),
                        1.0 - 2.0 * (x * x + y * y),
                    ],
                ];
                let s = s.map(f64::from);
                [0, 1, 2].map(|i| {
                    let row = [0, 1, 2].map(|j| r[i][j] * s[j]);
                    [row[0], row[1], row[2], f64::from(t[i])]
                })
            }
        };
        Affine::new(m)
    }

    fn new(m: [[f64; 4]; 3]) -> Affine {
        let a = |i: usize, j: usize| m[i][j];
        let cof = |i: usize, j: usize| {
            let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
            let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
            a(r0, c0) * a(r1, c1) - a(r0, c1) * a(r1, c0)
        };
        let det = (0..3).map(|j| a(0, j) * cof(0, j)).sum::<f64>();
        let scale = (0..3)
            .map(|i| (0..3).map(|j| a(i, j).abs()).sum::<f64>())
            .fold(0.0, f64::max);
        // Normals transform by the inverse transpose = cofactor matrix / det (sign kept for
        // orientation; the result is renormalised).
        let normal = (det.abs() > 1e-12 * scale.powi(3) && det.is_finite())
            .then(|| [0, 1, 2].map(|i| [0, 1, 2].map(|j| cof(i, j) * det.signum())));
        Affine { m, normal }
    }

    fn then(self, parent: Affine) -> Affine {
        let (p, c) = (parent.m, self.m);
        let m = [0, 1, 2].map(|i| {
            [0, 1, 2, 3].map(|j| {
                let lin = (0..3).map(|k| p[i][k] * c[k][j]).sum::<f64>();
                if j == 3 { lin + p[i][3] } else { lin }
            })
        });
        Affine::new(m)
    }

    /// A position; a singular map moves by its translation only.
    fn point(&self, p: Point3) -> Point3 {
        let m = &self.m;
        match self.normal {
            Some(_) => {
                [0, 1, 2].map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3])
            }
            None => [0, 1, 2].map(|i| p[i] + m[i][3]),
        }
    }

    /// A normal, renormalised (unchanged for a singular map or a zero result).
    fn normal(&self, n: Point3) -> Point3 {
        let Some(c) = self.normal else { return n };
        let v = [0, 1, 2].map(|i| c[i][0] * n[0] + c[i][1] * n[1] + c[i][2] * n[2]);
        crate::geometry::normalized(v).unwrap_or(n)
    }
}

/// The world transform of every node (parents via `children`; a cycle is cut after as many steps
/// as there are nodes).
fn world_transforms(doc: &gltf::Document) -> Vec<Affine> {
    let n = doc.nodes().len();
    let mut parent = vec![None; n];
    for node in doc.nodes() {
        for c in node.children() {
            parent[c.index()] = Some(node.index());
        }
    }
    let local: Vec<Affine> = doc
        .nodes()
        .map(|n| Affine::from_gltf(n.transform()))
        .collect();
    (0..n)
        .map(|i| {
            let mut m = local[i];
            let mut at = parent[i];
            for _ in 0..n {
                let Some(p) = at else { break };
                m = m.then(local[p]);
                at = parent[p];
            }
            m
        })
        .collect()
}

/// COLOR_0 (f32, or normalized u8 / u16; VEC3 or VEC4 with alpha dropped), linear in the file,
/// returned sRGB-encoded as [`TriMesh::colors`] holds them.
fn read_colors(acc: &gltf::Accessor, blob: &[u8], src: &Path) -> Result<Vec<[f32; 3]>, IoError> {
    use gltf::accessor::{DataType, Dimensions};
    let (bytes, stride, _, count) = accessor_span(acc, blob, src)?;
    let comp = match acc.data_type() {
        DataType::F32 => 4,
        DataType::U16 if acc.normalized() => 2,
        DataType::U8 if acc.normalized() => 1,
        other => {
            return Err(IoError::Unsupported {
                path: src.to_path_buf(),
                format: "GLB",
                feature: format!(
                    "COLOR_0 of type {other:?} (normalized: {})",
                    acc.normalized()
                ),
            });
        }
    };
    if !matches!(acc.dimensions(), Dimensions::Vec3 | Dimensions::Vec4) {
        return Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "GLB",
            message: "COLOR_0 must be VEC3 or VEC4".into(),
        });
    }
    let value = |o: usize| -> f32 {
        let b = &bytes[o..o + comp];
        match comp {
            4 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            2 => f32::from(u16::from_le_bytes([b[0], b[1]])) / 65535.0,
            _ => f32::from(b[0]) / 255.0,
        }
    };
    Ok((0..count)
        .map(|i| [0, 1, 2].map(|k| linear_to_srgb(value(i * stride + k * comp).clamp(0.0, 1.0))))
        .collect())
}

/// The CRS a GLB declares in `asset.extras.crs` (as [`super::encode_glb_with`] writes it), if any.
pub fn glb_crs(bytes: &[u8]) -> Option<String> {
    Some(glb_asset_extra(bytes, "crs")?.as_str()?.to_string())
}

/// `asset.extras[key]` of a GLB (`crs`; `lod` in a level-of-detail file), if present.
pub fn glb_asset_extra(bytes: &[u8], key: &str) -> Option<serde_json::Value> {
    let glb = gltf::binary::Glb::from_slice(bytes).ok()?;
    let mut v: serde_json::Value = serde_json::from_slice(&glb.json).ok()?;
    Some(v.get_mut("asset")?.get_mut("extras")?.get_mut(key)?.take())
}

fn read_indices(acc: &gltf::Accessor, blob: &[u8], src: &Path) -> Result<Vec<u32>, IoError> {
    use gltf::accessor::{DataType, Dimensions};
    let (bytes, stride, elem, count) = accessor_span(acc, blob, src)?;
    let ok = acc.dimensions() == Dimensions::Scalar
        && matches!(
            acc.data_type(),
            DataType::U8 | DataType::U16 | DataType::U32
        );
    if !ok {
        return Err(IoError::Invalid {
            path: src.to_path_buf(),
            format: "GLB",
            message: "indices must be u8, u16 or u32 scalars".into(),
        });
    }
    Ok((0..count)
        .map(|i| {
            let b = &bytes[i * stride..i * stride + elem];
            match elem {
                1 => u32::from(b[0]),
                2 => u32::from(u16::from_le_bytes([b[0], b[1]])),
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            }
        })
        .collect())
}
