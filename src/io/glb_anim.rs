//! An animated GLB of a mesh sequence (a morph): one mesh and node per frame under one scene, and
//! one animation whose STEP-interpolated `scale` channels show frame `i` (scale 1) and hide the
//! others (scale 0) during `[i·dt, (i+1)·dt)`. Any glTF player plays it; [`super::decode_glb`]
//! reads all frames concatenated. Positions f32 (exact min/max), unit normals, u32 indices.

use std::collections::BTreeMap;

use gltf_json as json;
use json::validation::{Checked::Valid, USize64};

use super::IoError;
use super::glb::{
    Bounds, check_mesh, container, enc_err, f32_positions, push_accessor, push_view, triangle_mesh,
    unit_normals,
};
use crate::geometry::TriMesh;

fn pad4(bin: &mut Vec<u8>) {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
}

/// Encode `frames` (at least one, each non-empty) shown `seconds_per_frame` each.
pub fn encode_animated_glb(frames: &[TriMesh], seconds_per_frame: f32) -> Result<Vec<u8>, IoError> {
    if frames.is_empty() || !(seconds_per_frame > 0.0 && seconds_per_frame.is_finite()) {
        return Err(enc_err(
            "an animation needs at least one frame and a positive duration",
        ));
    }
    let mut root = json::Root::default();
    root.asset.generator = Some("rbfsurf morph".into());
    let mut bin: Vec<u8> = Vec::new();
    let mut nodes = Vec::with_capacity(frames.len());
    for (i, frame) in frames.iter().enumerate() {
        let mesh = push_frame(&mut root, &mut bin, frame)?;
        let visible = if i == 0 { 1.0 } else { 0.0 };
        nodes.push(root.push(json::Node {
            mesh: Some(mesh),
            scale: Some([visible; 3]),
            ..Default::default()
        }));
    }
    push_animation(&mut root, &mut bin, &nodes, seconds_per_frame);
    pad4(&mut bin);
    root.push(json::Buffer {
        byte_length: USize64::from(bin.len()),
        uri: None,
        extensions: Default::default(),
        extras: Default::default(),
    });
    let scene = root.push(json::Scene {
        nodes,
        extensions: Default::default(),
        extras: Default::default(),
    });
    root.scene = Some(scene);
    let out = container(&root, &super::MeshMeta::default(), bin)?;
    let back = super::decode_glb(&out).map_err(|e| enc_err(format!("read-back failed: {e}")))?;
    let want: usize = frames.iter().map(|f| f.triangles.len()).sum();
    if back.triangles.len() > want || back.triangles.is_empty() {
        return Err(enc_err(format!(
            "read-back mismatch: {} triangles, at most {want} written",
            back.triangles.len()
        )));
    }
    Ok(out)
}

/// The one buffer every view refers to (pushed last: index 0).
fn buffer0() -> json::Index<json::Buffer> {
    json::Index::new(0)
}

/// Append one frame's positions, normals and indices to `bin`; returns its mesh.
fn push_frame(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    frame: &TriMesh,
) -> Result<json::Index<json::Mesh>, IoError> {
    use json::accessor::{ComponentType, Type};
    use json::buffer::Target;
    check_mesh(frame, "GLB")?;
    let merged = super::snap::merge_f32_duplicates(frame);
    check_mesh(&merged, "GLB")?;
    let (pos, bounds): (Vec<[f32; 3]>, Bounds) = f32_positions(&merged)?;
    let normals = unit_normals(&merged);
    let vec3 = (ComponentType::F32, Type::Vec3);
    let off = bin.len();
    bin.extend(pos.iter().flatten().flat_map(|c| c.to_le_bytes()));
    let pv = push_view(root, buffer0(), off, pos.len() * 12, Target::ArrayBuffer);
    let pa = push_accessor(root, pv, pos.len(), vec3, Some(bounds));
    let mut attributes = BTreeMap::new();
    attributes.insert(Valid(json::mesh::Semantic::Positions), pa);
    if !normals.is_empty() {
        let off = bin.len();
        bin.extend(normals.iter().flatten().flat_map(|c| c.to_le_bytes()));
        let nv = push_view(
            root,
            buffer0(),
            off,
            normals.len() * 12,
            Target::ArrayBuffer,
        );
        let na = push_accessor(root, nv, normals.len(), vec3, None);
        attributes.insert(Valid(json::mesh::Semantic::Normals), na);
    }
    let off = bin.len();
    bin.extend(
        merged
            .triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes()),
    );
    let n = merged.triangles.len() * 3;
    let iv = push_view(root, buffer0(), off, n * 4, Target::ElementArrayBuffer);
    let ia = push_accessor(root, iv, n, (ComponentType::U32, Type::Scalar), None);
    Ok(root.push(triangle_mesh(attributes, ia)))
}

/// One animation: per node a STEP `scale` channel that is 1 at its own key time, 0 at the others.
fn push_animation(
    root: &mut json::Root,
    bin: &mut Vec<u8>,
    nodes: &[json::Index<json::Node>],
    seconds_per_frame: f32,
) {
    use json::accessor::{ComponentType, Type};
    let count = nodes.len();
    // Key times 0, dt, …, (n−1)·dt (STEP: each value holds until the next key).
    let times: Vec<f32> = (0..count).map(|k| k as f32 * seconds_per_frame).collect();
    let off = bin.len();
    bin.extend(times.iter().flat_map(|t| t.to_le_bytes()));
    let tv = animation_view(root, off, count * 4);
    let ta = push_accessor(root, tv, count, (ComponentType::F32, Type::Scalar), None);
    if let Some(a) = root.accessors.get_mut(ta.value()) {
        a.min = Some(json::Value::from(vec![0.0f32]));
        a.max = Some(json::Value::from(vec![times[count - 1]]));
    }
    let mut channels = Vec::with_capacity(count);
    let mut samplers = Vec::with_capacity(count);
    for (i, node) in nodes.iter().enumerate() {
        let off = bin.len();
        for k in 0..count {
            let s: f32 = if k == i { 1.0 } else { 0.0 };
            bin.extend([s, s, s].iter().flat_map(|c| c.to_le_bytes()));
        }
        let sv = animation_view(root, off, count * 12);
        let sa = push_accessor(root, sv, count, (ComponentType::F32, Type::Vec3), None);
        samplers.push(json::animation::Sampler {
            input: ta,
            interpolation: Valid(json::animation::Interpolation::Step),
            output: sa,
            extensions: Default::default(),
            extras: Default::default(),
        });
        channels.push(json::animation::Channel {
            sampler: json::Index::new(i as u32),
            target: json::animation::Target {
                node: *node,
                path: Valid(json::animation::Property::Scale),
                extensions: Default::default(),
                extras: Default::default(),
            },
            extensions: Default::default(),
            extras: Default::default(),
        });
    }
    root.push(json::Animation {
        channels,
        samplers,
        extensions: Default::default(),
        extras: Default::default(),
    });
}

/// A buffer view for animation data (no target).
fn animation_view(
    root: &mut json::Root,
    off: usize,
    len: usize,
) -> json::Index<json::buffer::View> {
    root.push(json::buffer::View {
        buffer: buffer0(),
        byte_offset: Some(USize64::from(off)),
        byte_length: USize64::from(len),
        byte_stride: None,
        target: None,
        extensions: Default::default(),
        extras: Default::default(),
    })
}
