//! Vertices that round to one f32 position. Writers that store f32 coordinates (GLB, PLY) would give two
//! distinct f64 vertices the same position, and a triangle with two such corners zero area (seen on
//! a 10⁶-point torus: 4 zero-area triangles once the GLB was read back and welded). Before writing,
//! such vertices are merged into the first of them (an edge collapse at rounding level) and the
//! triangles that lose a corner are dropped. `O(V + F)` expected (one hash map over the vertices).

use std::borrow::Cow;
use std::collections::HashMap;

use crate::geometry::TriMesh;
use crate::mesh::incidence::ByVertex;

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
///
/// A merge is an edge collapse, and a collapse can break the surface (two sheets closer than the
/// rounding pinched into one vertex, an edge shared by three triangles). A group whose merge makes a
/// vertex non-manifold that was manifold before is kept apart instead (its vertices keep their ids,
/// at the same rounded position: a zero-area sliver, but the mesh stays closed and manifold by its
/// indices); checked again until no merge breaks a vertex ([`MAX_ROUNDS`], then nothing is merged).
pub(crate) fn merge_equal_keys<K: std::hash::Hash + Eq + Copy>(
    mesh: &TriMesh,
    keys: &[Option<K>],
    snap: impl Fn(usize) -> [f64; 3],
) -> Option<(TriMesh, Vec<usize>)> {
    let mut apart = vec![false; keys.len()];
    let mut before: Option<Vec<bool>> = None;
    for _ in 0..MAX_ROUNDS {
        let (to, source) = group(keys, &apart);
        if source.len() == keys.len() {
            return None;
        }
        let triangles = remap_triangles(&mesh.triangles, &to);
        let blamed = unsafe_groups(mesh, &triangles, &to, source.len(), &mut before);
        if blamed.is_empty() {
            return Some((assemble(mesh, triangles, &source, &snap), source));
        }
        for v in 0..keys.len() {
            apart[v] |= blamed.contains(&to[v]);
        }
    }
    None
}

/// Rounds of [`merge_equal_keys`]' manifold check before it gives up merging.
const MAX_ROUNDS: usize = 8;

/// `to[v]` (new id of old vertex `v`, numbered by first occurrence) and `source` (old vertex of each
/// new id): equal `Some` keys share an id unless the vertex is kept `apart`.
fn group<K: std::hash::Hash + Eq + Copy>(
    keys: &[Option<K>],
    apart: &[bool],
) -> (Vec<u32>, Vec<usize>) {
    let mut first: HashMap<K, u32> = HashMap::with_capacity(keys.len());
    let mut to: Vec<u32> = Vec::with_capacity(keys.len());
    let mut source: Vec<usize> = Vec::with_capacity(keys.len());
    for (v, key) in keys.iter().enumerate() {
        let fresh = source.len() as u32;
        let id = match key {
            Some(k) if !apart[v] => *first.entry(*k).or_insert(fresh),
            _ => fresh,
        };
        if id == fresh {
            source.push(v);
        }
        to.push(id);
    }
    (to, source)
}

/// Triangles through `to`, without those that lost a corner.
fn remap_triangles(triangles: &[[u32; 3]], to: &[u32]) -> Vec<[u32; 3]> {
    (triangles.iter())
        .filter_map(|t| {
            let m = t.map(|v| to.get(v as usize).copied().unwrap_or(v));
            (m[0] != m[1] && m[1] != m[2] && m[0] != m[2]).then_some(m)
        })
        .collect()
}

fn assemble(
    mesh: &TriMesh,
    triangles: Vec<[u32; 3]>,
    source: &[usize],
    snap: &impl Fn(usize) -> [f64; 3],
) -> TriMesh {
    let n = mesh.vertices.len();
    TriMesh {
        vertices: source.iter().map(|&v| snap(v)).collect(),
        normals: pick(&mesh.normals, source, n),
        colors: pick(&mesh.colors, source, n),
        triangles,
    }
}

/// `attr` of the `source` vertices when it has one item per vertex (`n`), else empty.
fn pick<T: Copy>(attr: &[T], source: &[usize], n: usize) -> Vec<T> {
    match attr.len() == n {
        true => source.iter().map(|&v| attr[v]).collect(),
        false => Vec::new(),
    }
}

/// The merged vertices (new ids, groups of two or more) whose merge made a vertex non-manifold
/// that was manifold before: a merged vertex itself, or the merged neighbours of a vertex whose
/// fan broke. Only vertices next to a merged group can break, so only their fans are checked;
/// `before` caches the original mesh's verdict from the first round (later rounds merge less, so
/// they touch a subset of those vertices).
fn unsafe_groups(
    mesh: &TriMesh,
    triangles: &[[u32; 3]],
    to: &[u32],
    new_len: usize,
    before: &mut Option<Vec<bool>>,
) -> std::collections::HashSet<u32> {
    let mut size = vec![0u32; new_len];
    for &m in to {
        size[m as usize] += 1;
    }
    let was_bad = before.get_or_insert_with(|| {
        let grouped: Vec<bool> = to.iter().map(|&m| size[m as usize] > 1).collect();
        non_manifold_vertices(&mesh.triangles, &next_to(&mesh.triangles, &grouped))
    });
    let mut bad_member = vec![false; new_len];
    for (v, &m) in to.iter().enumerate() {
        bad_member[m as usize] |= was_bad[v];
    }
    let merged: Vec<bool> = size.iter().map(|&c| c > 1).collect();
    let now_bad = non_manifold_vertices(triangles, &next_to(triangles, &merged));
    let mut blamed = std::collections::HashSet::new();
    for t in triangles {
        for (i, &m) in t.iter().enumerate() {
            let m = m as usize;
            if !now_bad[m] || bad_member[m] {
                continue;
            }
            if size[m] > 1 {
                blamed.insert(m as u32);
            }
            for &u in [t[(i + 1) % 3], t[(i + 2) % 3]].iter() {
                if size[u as usize] > 1 {
                    blamed.insert(u);
                }
            }
        }
    }
    blamed
}

/// `marked` grown by every vertex that shares a triangle with a marked one.
fn next_to(triangles: &[[u32; 3]], marked: &[bool]) -> Vec<bool> {
    let mut out = marked.to_vec();
    for t in triangles {
        if t.iter().any(|&v| marked.get(v as usize) == Some(&true)) {
            for &v in t {
                if let Some(o) = out.get_mut(v as usize) {
                    *o = true;
                }
            }
        }
    }
    out
}

/// Per vertex (checked where `wanted`, else false): its fan is not one oriented disc or
/// half-disc (a link vertex entered or left twice: a non-manifold or flipped edge; or the link in
/// two or more pieces: a pinch).
fn non_manifold_vertices(triangles: &[[u32; 3]], wanted: &[bool]) -> Vec<bool> {
    let n = wanted.len();
    // Link edges a → b of the wanted vertices (triangle [v, a, b] in its winding order), grouped by
    // vertex.
    let link = ByVertex::build(n, triangles.len(), |ti, i| {
        let t = &triangles[ti];
        let inside = t.iter().all(|&v| (v as usize) < n);
        (inside && wanted[t[i] as usize]).then(|| (t[i], (t[(i + 1) % 3], t[(i + 2) % 3])))
    });
    (0..n).map(|v| wanted[v] && !is_disc(link.of(v))).collect()
}

/// Whether the oriented link edges form one cycle or one path. A fan has a handful of edges, so
/// linear scans beat hashing.
fn is_disc(edges: &[(u32, u32)]) -> bool {
    let Some(&(first, _)) = edges.first() else {
        return true;
    };
    let next = |a: u32| edges.iter().find(|e| e.0 == a).map(|e| e.1);
    for (k, &(a, b)) in edges.iter().enumerate() {
        let later = &edges[k + 1..];
        if later.iter().any(|e| e.0 == a || e.1 == b) {
            return false;
        }
    }
    let starts: Vec<u32> = (edges.iter())
        .map(|e| e.0)
        .filter(|&a| !edges.iter().any(|e| e.1 == a))
        .collect();
    if starts.len() > 1 {
        return false;
    }
    let mut at = starts.first().copied().unwrap_or(first);
    let mut walked = 0;
    while let Some(b) = next(at) {
        walked += 1;
        if walked > edges.len() {
            break;
        }
        at = b;
        if starts.is_empty() && at == first {
            break;
        }
    }
    walked == edges.len()
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

    #[test]
    fn a_merge_that_would_pinch_two_sheets_is_kept_apart() {
        // Two closed tetrahedra whose apexes round to one key: merging them would join the two
        // surfaces at one vertex (a non-manifold pinch). They stay apart; the sliver pair of the
        // pyramid (a safe collapse) in the same mesh is still merged.
        let tet = |o: f64| -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
            (
                vec![
                    [o, 0.0, 0.0],
                    [o + 1.0, 0.0, 0.0],
                    [o, 1.0, 0.0],
                    [o, 0.0, 1.0],
                ],
                vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            )
        };
        let (mut vertices, mut triangles) = tet(0.0);
        let (v2, t2) = tet(1.0);
        vertices.extend(v2);
        triangles.extend(t2.iter().map(|t| t.map(|v| v + 4)));
        let mesh = TriMesh {
            vertices,
            normals: vec![],
            triangles,
            colors: Vec::new(),
        };
        let before = analyze(&mesh);
        assert!(before.manifold && before.watertight);
        // Vertex 1 of the first and vertex 0 of the second coincide already ((1, 0, 0)).
        let keys: Vec<Option<[u64; 3]>> = (mesh.vertices.iter())
            .map(|p| Some(p.map(f64::to_bits)))
            .collect();
        assert!(merge_equal_keys(&mesh, &keys, |v| mesh.vertices[v]).is_none());
        // The unguarded merge would have pinched them: check that the guard is what kept them.
        let (to, source) = group(&keys, &vec![false; keys.len()]);
        assert_eq!(source.len(), 7);
        let pinched = remap_triangles(&mesh.triangles, &to);
        assert!(
            non_manifold_vertices(&pinched, &[true; 7])
                .iter()
                .any(|&b| b)
        );
    }
}
