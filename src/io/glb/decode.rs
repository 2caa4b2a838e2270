//! GLB decoder: POSITION (+ NORMAL, COLOR_0) and indices of every triangle primitive from the BIN
//! chunk, accessors read with checked arithmetic (no panics on hostile offsets); the CRS from
//! `asset.extras.crs`.

use std::path::Path;

use super::super::{IoError, MEMORY_SOURCE};
use super::linear_to_srgb;
use crate::geometry::{Point3, TriMesh};

/// Decodes GLB bytes into one triangle mesh (all triangle primitives of all meshes, concatenated;
/// a mesh is moved by the translation of the first node that uses it, other node transforms are
/// ignored). Normals are kept only when every primitive has them.
pub fn decode_glb(bytes: &[u8]) -> Result<TriMesh, IoError> {
    decode_glb_named(bytes, Path::new(MEMORY_SOURCE))
}

pub(crate) fn decode_glb_named(bytes: &[u8], src: &Path) -> Result<TriMesh, IoError> {
    let invalid = |message: String| IoError::Invalid {
        path: src.to_path_buf(),
        format: "GLB",
        message,
    };
    let gltf = gltf::Gltf::from_slice(bytes).map_err(|e| invalid(e.to_string()))?;
    let blob: &[u8] = gltf.blob.as_deref().unwrap_or_default();
    let mut out = TriMesh::default();
    let mut all_normals = true;
    let mut all_colors = true;
    for mesh in gltf.document.meshes() {
        let t = (gltf.document.nodes())
            .find(|n| n.mesh().is_some_and(|m| m.index() == mesh.index()))
            .map_or([0.0; 3], |n| n.transform().decomposed().0);
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
            out.vertices.extend(
                pos.into_iter()
                    .map(|p| [0, 1, 2].map(|k| p[k] + f64::from(t[k]))),
            );
            match prim.get(&gltf::Semantic::Normals) {
                Some(nacc) if all_normals => {
                    let ns = read_vec3(&nacc, blob, src)?;
                    if ns.len() != count {
                        return Err(invalid(format!(
                            "NORMAL has {} entries, POSITION {count}",
                            ns.len()
                        )));
                    }
                    out.normals.extend(ns);
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
    if !matches!(view.buffer().source(), gltf::buffer::Source::Bin) {
        return Err(unsupported("external (URI) buffers"));
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

fn read_vec3(acc: &gltf::Accessor, blob: &[u8], src: &Path) -> Result<Vec<Point3>, IoError> {
    use gltf::accessor::{DataType, Dimensions};
    if acc.data_type() != DataType::F32 || acc.dimensions() != Dimensions::Vec3 {
        return Err(IoError::Unsupported {
            path: src.to_path_buf(),
            format: "GLB",
            feature: format!(
                "vertex attribute of type {:?} {:?} (expected f32 VEC3)",
                acc.data_type(),
                acc.dimensions()
            ),
        });
    }
    let (bytes, stride, _, count) = accessor_span(acc, blob, src)?;
    let f = |o: usize| {
        f64::from(f32::from_le_bytes([
            bytes[o],
            bytes[o + 1],
            bytes[o + 2],
            bytes[o + 3],
        ]))
    };
    Ok((0..count)
        .map(|i| i * stride)
        .map(|o| [f(o), f(o + 4), f(o + 8)])
        .collect())
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

/// The CRS a GLB declares in `asset.extras.crs` (as [`encode_glb_with`] writes it), if any.
pub fn glb_crs(bytes: &[u8]) -> Option<String> {
    let glb = gltf::binary::Glb::from_slice(bytes).ok()?;
    let v: serde_json::Value = serde_json::from_slice(&glb.json).ok()?;
    Some(
        v.get("asset")?
            .get("extras")?
            .get("crs")?
            .as_str()?
            .to_string(),
    )
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
