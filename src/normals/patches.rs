//! Patches: pieces of the cloud inside which the orientation is certain. A maximum-confidence
//! spanning forest (Kruskal) over the edges of the Riemannian graph ([`super::graph`]) whose
//! confidence reaches a threshold; each tree is one patch, oriented by the signs along its edges.
//! Patches smaller than a minimum size are then merged into a neighbour along their most
//! confident remaining edge, so that the global step sees a bounded number of patches.
//!
//! The union-find carries a parity per element (its sign relative to its set's root), so a tree
//! is oriented without walking it. `O(E α(n))` after the edges are sorted.

use super::graph::Edge;
use crate::geometry::Point3;
use crate::mesh::incidence::SignedSets;

/// A partition of the points into patches, each internally consistently oriented.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Patches {
    /// Patch of each point, `0..count`.
    pub label: Vec<u32>,
    /// Number of patches.
    pub count: usize,
}

/// Grow patches over `edges` (sorted by decreasing confidence): join along edges with confidence
/// at least `min_confidence`, then merge patches with fewer than `min_size` points along their best
/// remaining edges. Flips `normals` so each patch is consistent.
pub(crate) fn grow_patches(
    normals: &mut [Point3],
    edges: &[Edge],
    min_confidence: f64,
    min_size: usize,
) -> Patches {
    let n = normals.len();
    let mut sets = SignedSets::new(n);
    for e in edges.iter().take_while(|e| e.confidence >= min_confidence) {
        sets.union(e.a, e.b, e.agree);
    }
    let min_size = min_size as u32;
    for e in edges {
        if sets.set_size(e.a) < min_size || sets.set_size(e.b) < min_size {
            sets.union(e.a, e.b, e.agree);
        }
    }
    let mut label = vec![u32::MAX; n];
    let mut count = 0u32;
    for i in 0..n {
        let (root, flip) = sets.find(i as u32);
        if label[root as usize] == u32::MAX {
            label[root as usize] = count;
            count += 1;
        }
        label[i] = label[root as usize];
        if flip {
            normals[i] = normals[i].map(|v| -v);
        }
    }
    Patches {
        label,
        count: count as usize,
    }
}

/// Connected components of the graph `edges` over `n` points (`0..count` per point).
pub(crate) fn components(n: usize, edges: &[Edge]) -> Vec<u32> {
    let mut sets = SignedSets::new(n);
    for e in edges {
        sets.union(e.a, e.b, true);
    }
    let mut id = vec![u32::MAX; n];
    let mut count = 0;
    (0..n)
        .map(|i| {
            let r = sets.find(i as u32).0 as usize;
            if id[r] == u32::MAX {
                id[r] = count;
                count += 1;
            }
            id[r]
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(a: u32, b: u32, agree: bool, confidence: f64) -> Edge {
        Edge {
            a,
            b,
            agree,
            confidence,
        }
    }

    #[test]
    fn confident_edges_orient_a_chain_and_weak_ones_split_it() {
        let mut normals = vec![[0.0, 0.0, 1.0]; 6];
        let edges = [
            edge(0, 1, false, 0.99),
            edge(1, 2, true, 0.98),
            edge(3, 4, false, 0.97),
            edge(4, 5, false, 0.96),
            edge(2, 3, false, 0.1),
        ];
        let p = grow_patches(&mut normals, &edges, 0.5, 1);
        assert_eq!(p.count, 2);
        assert_eq!(p.label, vec![0, 0, 0, 1, 1, 1]);
        let z: Vec<f64> = normals.iter().map(|n| n[2]).collect();
        assert_eq!(z[1], z[2]);
        assert_eq!(z[0], -z[1]);
        assert_eq!(z[3], -z[4]);
        assert_eq!(z[4], -z[5]);
        // With a minimum size of 4 the two halves merge along the weak edge.
        let mut normals = vec![[0.0, 0.0, 1.0]; 6];
        assert_eq!(grow_patches(&mut normals, &edges, 0.5, 4).count, 1);
        assert_eq!(normals[3][2], -normals[2][2]);
    }

    #[test]
    fn components_follow_the_edges() {
        let c = components(5, &[edge(0, 1, true, 1.0), edge(3, 4, false, 0.0)]);
        assert_eq!(c, vec![0, 0, 1, 2, 2]);
    }
}
