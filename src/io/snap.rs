//! Vertices that round to one f32 position. Writers that store f32 coordinates (GLB, PLY) would give two
//! distinct f64 vertices the same position, and a triangle with two such corners zero area (seen on
//! a 10⁶-point torus: 4 zero-area triangles once the GLB was read back and welded). Before writing,
//! such vertices are merged into the first of them (an edge collapse at rounding level) and the
//! triangles that lose a corner are dropped. `O(V + F)` expected (one hash map over the vertices).

use std::borrow::Cow;
use std::collections::HashMap;

use crate::geometry::TriMesh;

/// `mesh` with every group of vertices whose coordinates are equal after rounding to f32 merged into
/// the group's first vertex (position rounded to f32, that vertex's normal and colour), triangles remapped and
/// those with a repeated corner dropped, vertices renumbered in first-use order of the original
/// indices. Borrowed unchanged when no two vertices round to the same position. Non-finite f32
/// coordinates are left for the caller's checks (they are never merged).
pub(crate) fn merge_f32_duplicates(mesh: &TriMesh) -> Cow<'_, TriMesh> {
    let keys: Vec<Option<[u32; 3]>> = (mesh.vertices.iter())
        .map(|p| {
            let f = p.map(|c| c as f32);
            f.iter().all(|c| c.is_finite()).then(|| f.map(f32::to_bits))
        })
        .collect();
    let snap = |v: usize| mesh.vertices[v].map(|c| f64::from(c as f32));
    match merge_equal_keys(mesh, &keys, snap) {
        Some((merged, _)) => Cow::Owned(merged),
        None => Cow::Borrowed(mesh),
    }
}

/// The merge behind [`merge_f32_duplicates`] for any vertex key: vertices with equal `Some` keys are
/// merged into the group's first vertex (placed at `snap(first)`, with its normal and colour); `None`
/// keys are never merged. Triangles are remapped and those with a repeated corner dropped; vertices
/// are renumbered in order of first occurrence. Returns the merged mesh and, for each new vertex,
/// the index of the old vertex it stands for; `None` when no two keys are equal.
pub(crate) fn merge_equal_keys<K: std::hash::Hash + Eq + Copy>(
    mesh: &TriMesh,
    keys: &[Option<K>],
    snap: impl Fn(usize) -> [f64; 3],
) -> Option<(TriMesh, Vec<usize>)> {
    let mut first: HashMap<K, u32> = HashMap::with_capacity(keys.len());
    let mut to: Vec<u32> = Vec::with_capacity(keys.len());
    let mut source: Vec<usize> = Vec::with_capacity(keys.len());
    for (v, key) in keys.iter().enumerate() {
        let fresh = source.len() as u32;
        let id = match key {
            Some(k) => *first.entry(*k).or_insert(fresh),
            None => fresh,
        };
        if id == fresh {
            source.push(v);
        }
        to.push(id);
    }
    if source.len() == keys.len() {
        return None;
    }
    let has_normals = mesh.normals.len() == mesh.vertices.len();
    let has_colors = mesh.colors.len() == mesh.vertices.len();
    let vertices = source.iter().map(|&v| snap(v)).collect();
    let normals = match has_normals {
        true => source.iter().map(|&v| mesh.normals[v]).collect(),
        false => Vec::new(),
    };
    let colors = match has_colors {
        true => source.iter().map(|&v| mesh.colors[v]).collect(),
        false => Vec::new(),
    };
    let triangles = mesh
        .triangles
        .iter()
        .filter_map(|t| {
            let m = t.map(|v| to.get(v as usize).copied().unwrap_or(v));
            (m[0] != m[1] && m[1] != m[2] && m[0] != m[2]).then_some(m)
        })
        .collect();
    let merged = TriMesh {
        vertices,
        normals,
        triangles,
        colors,
    };
    Some((merged, source))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::analyze;

    #[test]
    fn vertices_one_f32_apart_are_merged_and_their_sliver_dropped() {
        // A square pyramid's apex split into two vertices 1e-9 apart at coordinate ~1e3 (f32 spacing
        // there is 6e-5), joined by a sliver triangle pair.
        let b = 1000.0;
        let mesh = TriMesh {
            vertices: vec![
                [b, b, b],
                [b + 1.0, b, b],
                [b + 1.0, b + 1.0, b],
                [b, b + 1.0, b],
                [b + 0.5, b + 0.5, b + 1.0],
                [b + 0.5 + 1e-9, b + 0.5, b + 1.0],
            ],
            normals: vec![],
            triangles: vec![
                [0, 3, 2],
                [0, 2, 1],
                [0, 1, 4],
                [1, 5, 4],
                [1, 2, 5],
                [2, 3, 5],
                [3, 4, 5],
                [3, 0, 4],
            ],
            colors: Vec::new(),
        };
        let merged = merge_f32_duplicates(&mesh);
        assert_eq!(merged.vertices.len(), 5);
        let t = analyze(&merged);
        assert_eq!(t.degenerate_triangles, 0);
        assert!(t.watertight && t.manifold && t.oriented, "{t:?}");
        assert_eq!(merged.triangles.len(), 6);
        // Written as plain GLB and read back, then welded by position: no degenerate triangle. Far from
        // the origin the positions are stored relative to a node translation, so the two apexes
        // stay distinct (8 triangles, back at their place); near the origin they are merged (6).
        for (shift, triangles) in [(0.0, 6), (b, 8)] {
            let mut m = mesh.clone();
            for p in &mut m.vertices {
                *p = p.map(|c| c - b + shift);
            }
            let plain = crate::io::GlbCompression::None;
            let glb = crate::io::encode_glb_with(&m, &Default::default(), plain).unwrap();
            let back = crate::io::decode_glb(&glb).unwrap();
            let mut ids: HashMap<[u64; 3], u32> = HashMap::new();
            let weld: Vec<u32> = (back.vertices.iter())
                .map(|p| {
                    let n = ids.len() as u32;
                    *ids.entry(p.map(f64::to_bits)).or_insert(n)
                })
                .collect();
            let welded = TriMesh {
                vertices: back.vertices.clone(),
                normals: vec![],
                triangles: (back.triangles.iter())
                    .map(|t| t.map(|v| weld[v as usize]))
                    .collect(),
                colors: Vec::new(),
            };
            assert_eq!(analyze(&welded).degenerate_triangles, 0, "shift {shift}");
            assert_eq!(back.triangles.len(), triangles, "shift {shift}");
            assert!((back.vertices[1][0] - (shift + 1.0)).abs() < 1e-6);
        }
        // The PLY writer merges the same way near the origin (f32 coordinates); far from it, it
        // writes f64 coordinates and keeps both apexes.
        for (shift, head) in [
            (
                0.0,
                "property float x\nproperty float y\nproperty float z\nelement face 6",
            ),
            (
                b,
                "property double x\nproperty double y\nproperty double z\nelement face 8",
            ),
        ] {
            let mut m = mesh.clone();
            m.vertices
                .iter_mut()
                .for_each(|p| *p = p.map(|c| c - b + shift));
            let ply = crate::io::write::encode_ply(&m, &Default::default()).unwrap();
            let text_end = ply.windows(11).position(|w| w == b"end_header\n").unwrap();
            let header = String::from_utf8_lossy(&ply[..text_end]);
            let vertices = if shift == 0.0 { 5 } else { 6 };
            assert!(
                header.contains(&format!("element vertex {vertices}")),
                "{header}"
            );
            assert!(header.contains(head), "{header}");
        }
        // Nothing to merge: borrowed as is.
        let far = TriMesh {
            vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            normals: vec![],
            triangles: vec![[0, 1, 2]],
            colors: Vec::new(),
        };
        assert!(matches!(merge_f32_duplicates(&far), Cow::Borrowed(_)));
    }
}
