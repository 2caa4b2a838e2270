//! Manifold borders for trimmed meshes. Cutting a closed, manifold mesh along a jagged line (the
//! band the data support, or the triangles farther than the support radius from the data) leaves
//! bow-tie vertices: two fans of triangles that touch at one vertex only. Each pass removes, at every
//! vertex whose triangles form more than one edge-connected fan, all fans but the one that belongs to
//! the largest edge-connected piece of the mesh (the dangling ones; ties: the larger fan, then the
//! first), and at every edge used by more than two triangles all triangles but the first two;
//! removing triangles can create new bow-ties, so passes repeat until none is left.
//!
//! Purely combinatorial (indices only). One pass is `O(F log F)` for `F` triangles.

use super::incidence::{UnionFind, vertex_triangles};
use crate::geometry::TriMesh;
use rayon::prelude::*;

/// Passes before giving up (each removes at least one triangle; real borders settle in 2–4).
const MAX_PASSES: usize = 32;

/// Removes triangles until no vertex is a bow-tie and no edge has more than two triangles (or
/// [`MAX_PASSES`] passes ran). Returns how many triangles were removed. Unused vertices are left for
/// the GPU reordering to drop. Deterministic: ties keep the fan with the lowest triangle index.
pub fn make_manifold(mesh: &mut TriMesh) -> usize {
    let before = mesh.triangles.len();
    for _ in 0..MAX_PASSES {
        let n = mesh.vertices.len();
        let (mut drop, piece) = crowded_edges(&mesh.triangles);
        flag_extra_fans(&mesh.triangles, n, &piece, &mut drop);
        if !drop.iter().any(|d| *d) {
            break;
        }
        super::trim::remove_triangles(mesh, &drop);
    }
    before - mesh.triangles.len()
}

/// Per triangle: `true` for the third and later triangles (by index) on an edge; and the triangle
/// count of its edge-connected piece (triangles joined through shared edges).
fn crowded_edges(triangles: &[[u32; 3]]) -> (Vec<bool>, Vec<u32>) {
    let half = super::topology::sorted_half_edges(triangles);
    let mut drop = vec![false; triangles.len()];
    let mut uf = UnionFind::new(triangles.len());
    for (i, &(edge, ti)) in half.iter().enumerate() {
        if i >= 2 && half[i - 2].0 == edge {
            drop[ti as usize] = true;
        } else if i >= 1 && half[i - 1].0 == edge {
            uf.union(half[i - 1].1, ti);
        }
    }
    let mut size = vec![0u32; triangles.len()];
    let roots: Vec<u32> = (0..triangles.len() as u32).map(|t| uf.find(t)).collect();
    for &r in &roots {
        size[r as usize] += 1;
    }
    (drop, roots.iter().map(|&r| size[r as usize]).collect())
}

/// Flags, at each vertex whose (not yet flagged) triangles form several edge-connected fans, the
/// triangles of every fan but the one kept (see the module doc; `piece[t]` is the size of the
/// edge-connected piece of triangle `t`).
fn flag_extra_fans(triangles: &[[u32; 3]], n: usize, piece: &[u32], drop: &mut [bool]) {
    let incident = vertex_triangles(n, triangles, |t| drop[t]);
    // The vertices' decisions read only their fans (not `drop`): in parallel, then applied.
    let flagged: Vec<u32> = (0..n)
        .into_par_iter()
        .with_min_len(4096)
        .map_init(Vec::new, |group, v| {
            let mut out = Vec::new();
            let fan = incident.of(v);
            if fan.len() > 1 {
                fan_groups(triangles, v as u32, fan, group);
                all_but_one(fan, group, piece, &mut out);
            }
            out
        })
        .flatten_iter()
        .collect();
    for t in flagged {
        drop[t as usize] = true;
    }
}

/// `group[i]`: the fan (smallest local index in it) of `fan[i]`, triangles around `v` joined when
/// they share an edge through `v`. `O(m²)` for `m` triangles around `v` (m is small).
fn fan_groups(triangles: &[[u32; 3]], v: u32, fan: &[u32], group: &mut Vec<usize>) {
    group.clear();
    group.extend(0..fan.len());
    let others = |ti: u32| {
        let t = triangles[ti as usize];
        let mut o = t.into_iter().filter(move |&w| w != v);
        [o.next(), o.next()]
    };
    let mut changed = true;
    while changed {
        changed = false;
        for i in 0..fan.len() {
            for j in i + 1..fan.len() {
                if group[i] == group[j] {
                    continue;
                }
                let (a, b) = (others(fan[i]), others(fan[j]));
                let shared = a.iter().any(|x| x.is_some() && b.contains(x));
                if shared {
                    let g = group[i].min(group[j]);
                    (group[i], group[j]) = (g, g);
                    changed = true;
                }
            }
        }
    }
}

/// Pushes to `out` the triangles of every group but the one on the largest piece (ties: the larger
/// group, then the group listed first).
fn all_but_one(fan: &[u32], group: &[usize], piece: &[u32], out: &mut Vec<u32>) {
    // (piece size, fan size) per group, indexed by the group's first local index.
    let mut key = vec![(0u32, 0usize); fan.len()];
    for (i, &g) in group.iter().enumerate() {
        key[g].0 = key[g].0.max(piece[fan[i] as usize]);
        key[g].1 += 1;
    }
    if key.iter().filter(|k| k.1 > 0).count() <= 1 {
        return;
    }
    let best = (0..key.len()).fold(0, |b, g| if key[g] > key[b] { g } else { b });
    for (i, &g) in group.iter().enumerate() {
        if g != best {
            out.push(fan[i]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::analyze;

    /// A flat `n × n` grid of unit squares, two triangles each, counter-clockwise from +z.
    fn grid(n: u32) -> TriMesh {
        crate::mesh::test_meshes::sheet(n, n, |_, _| true)
    }

    #[test]
    fn bow_ties_are_removed_and_the_sheet_keeps_one_border() {
        // A 6×6 sheet plus a square attached at one corner vertex only (a bow-tie), and a
        // checkerboard notch: the sheet with squares removed so that two squares meet at a vertex.
        let mut mesh = grid(6);
        // Remove square (1, 1)'s neighbours (0,1) and (1,0): square (0,0) then touches (1,1) only
        // through the vertex (1, 1).
        let square = |i: usize, j: usize| [2 * (j * 6 + i), 2 * (j * 6 + i) + 1];
        let mut drop = vec![false; mesh.triangles.len()];
        for (i, j) in [(0, 1), (1, 0)] {
            for t in square(i, j) {
                drop[t] = true;
            }
        }
        crate::mesh::trim::remove_triangles(&mut mesh, &drop);
        let before = analyze(&mesh);
        assert_eq!(before.non_manifold_vertices, 1, "{before:?}");
        let removed = make_manifold(&mut mesh);
        let after = analyze(&mesh);
        // The dangling corner square (2 triangles) goes, the rest is one manifold disk.
        assert_eq!(removed, 2);
        assert!(after.manifold && after.oriented, "{after:?}");
        assert_eq!((after.components, after.boundary_loops), (1, 1));
        assert_eq!(after.triangles, 36 * 2 - 6);
        // A manifold mesh is left alone.
        let mut clean = grid(3);
        assert_eq!(make_manifold(&mut clean), 0);
        assert_eq!(clean.triangles.len(), 18);
    }

    #[test]
    fn edges_with_three_triangles_keep_two() {
        let mut mesh = crate::mesh::test_meshes::fin();
        assert_eq!(analyze(&mesh).non_manifold_edges, 1);
        assert_eq!(make_manifold(&mut mesh), 1);
        let t = analyze(&mesh);
        assert!(t.manifold, "{t:?}");
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [1, 0, 3]]);
    }
}
