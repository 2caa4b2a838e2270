//! Searching the octal tree: Kojekine et al. (2002), section 3.1, Algorithm II, plus k-NN.
//!
//! Radius search classifies each node against the `r`-sphere by its tight bounding box:
//! (a) entirely inside (farthest corner within `r`): all its points are taken without distance
//! tests, as one contiguous slice; (b) entirely outside (nearest box point beyond `r`): skipped;
//! (c) partial: children are visited, or a leaf's points are tested one by one.
//! Box and point distances use the same floating-point operations in the same order, so the
//! classification never disagrees with a direct test (results equal brute force exactly).
//! Cost about `O(depth + hits)` for compact queries.
//!
//! k-NN is depth-first, nearest box first: candidates are kept in a max-heap of size `k`, and a
//! node's remaining children are skipped once the nearest of them lies beyond the current `k`-th
//! candidate (the exact `k` nearest, ties by index, as brute force).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::geometry::{Point3, dist2};

use super::SpatialIndex;
use super::octree::Octree;

/// Upper bound on the depth-first stack: at most 7 pending siblings per level plus one.
const STACK_CAP: usize = 8 * (super::MAX_DEPTH + 2);

/// Partial nodes with at most this many points are scanned without descending (measured on the
/// `benches/spatial.rs` sphere; the points of a node are contiguous, so the scan is cache-friendly).
const SCAN_BELOW: usize = 64;

/// A squared distance with a total order, for the heaps.
#[derive(Debug, Clone, Copy, PartialEq)]
struct D2(f64);

impl Eq for D2 {}
impl PartialOrd for D2 {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for D2 {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// How a node's box relates to the `r`-sphere.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Class {
    /// Every point of the box is within `r`.
    Inside,
    /// No point of the box is within `r`.
    Outside,
    /// Some may be.
    Partial,
}

impl Octree {
    /// Classify node `ni` against the sphere of squared radius `r2` around `q`.
    #[inline]
    pub(super) fn classify(&self, ni: usize, q: &Point3, r2: f64) -> Class {
        let b = &self.nodes[ni].bbox;
        if b.dist2_to(q) > r2 {
            Class::Outside
        } else if b.max_dist2_to(q) <= r2 {
            Class::Inside
        } else {
            Class::Partial
        }
    }

    /// A partial inner node this small is cheaper to scan point by point than to descend into.
    #[inline]
    fn scan_directly(&self, ni: usize) -> bool {
        self.nodes[ni].range().len() <= SCAN_BELOW
    }

    /// Depth-first walk over the nodes the `r`-sphere touches. `visit(ni, class)` is called for
    /// each `Inside` node and each `Partial` leaf or small node (whose points the visitor then
    /// tests one by one); children of other `Partial` nodes are pushed. `skip(ni)` lets a caller
    /// prune nodes (e.g. fully removed ones).
    #[inline]
    pub(super) fn walk_sphere(
        &self,
        q: &Point3,
        r: f64,
        skip: impl Fn(usize) -> bool,
        mut visit: impl FnMut(usize, Class),
    ) {
        if self.nodes.is_empty() || r.is_nan() || r < 0.0 {
            return;
        }
        let r2 = r * r;
        let mut stack = [0u32; STACK_CAP];
        let mut sp = 1usize;
        while sp > 0 {
            sp -= 1;
            let ni = stack[sp] as usize;
            if skip(ni) {
                continue;
            }
            match self.classify(ni, q, r2) {
                Class::Outside => {}
                Class::Inside => visit(ni, Class::Inside),
                Class::Partial if self.nodes[ni].is_leaf() || self.scan_directly(ni) => {
                    visit(ni, Class::Partial)
                }
                Class::Partial => {
                    for c in self.nodes[ni].children() {
                        stack[sp] = c as u32;
                        sp += 1;
                    }
                }
            }
        }
    }

    /// Algorithm II: original indices of all points with `|p − q| ≤ r` into `out` (cleared
    /// first, unsorted).
    pub fn within(&self, q: &Point3, r: f64, out: &mut Vec<u32>) {
        out.clear();
        let r2 = r * r;
        self.walk_sphere(
            q,
            r,
            |_| false,
            |ni, class| {
                let range = self.nodes[ni].range();
                if class == Class::Inside {
                    out.extend_from_slice(&self.idx[range]);
                } else {
                    for pos in range {
                        if dist2(self.pts[pos], *q) <= r2 {
                            out.push(self.idx[pos]);
                        }
                    }
                }
            },
        );
    }

    /// The `k` nearest points as `(original index, distance)`, sorted by distance then index.
    pub fn nearest_k(&self, q: &Point3, k: usize, out: &mut Vec<(u32, f64)>) {
        out.clear();
        if k == 0 || self.nodes.is_empty() {
            return;
        }
        let mut best: BinaryHeap<(D2, u32)> = BinaryHeap::with_capacity(k + 1);
        self.nearest_in(0, q, k, &mut best);
        out.extend(
            best.into_sorted_vec()
                .into_iter()
                .map(|(d, i)| (i, d.0.sqrt())),
        );
    }

    /// The k-NN search below node `ni`: a leaf's points enter `best` (the `k` smallest
    /// `(squared distance, index)` so far); an inner node's children are visited nearest box
    /// first, and the rest skipped once a box lies beyond the `k`-th candidate.
    fn nearest_in(&self, ni: usize, q: &Point3, k: usize, best: &mut BinaryHeap<(D2, u32)>) {
        let node = &self.nodes[ni];
        if node.is_leaf() {
            for pos in node.range() {
                let cand = (D2(dist2(self.pts[pos], *q)), self.idx[pos]);
                if best.len() < k {
                    best.push(cand);
                } else if best.peek().is_some_and(|w| cand < *w) {
                    best.pop();
                    best.push(cand);
                }
            }
            return;
        }
        let mut kids = [(0.0f64, 0usize); 8];
        let mut n = 0;
        for c in node.children() {
            let d2 = self.nodes[c].bbox.dist2_to(q);
            // Insertion by box distance (ties by child order).
            let mut at = n;
            while at > 0 && kids[at - 1].0 > d2 {
                kids[at] = kids[at - 1];
                at -= 1;
            }
            kids[at] = (d2, c);
            n += 1;
        }
        for &(d2, c) in &kids[..n] {
            if best.len() == k && best.peek().is_some_and(|w| d2 > w.0.0) {
                break;
            }
            self.nearest_in(c, q, k, best);
        }
    }
}

impl SpatialIndex for Octree {
    fn within(&self, q: &Point3, r: f64, out: &mut Vec<u32>) {
        Octree::within(self, q, r, out);
    }
    fn nearest_k(&self, q: &Point3, k: usize, out: &mut Vec<(u32, f64)>) {
        Octree::nearest_k(self, q, k, out);
    }
    fn len(&self) -> usize {
        self.pts.len()
    }
}

#[cfg(test)]
mod tests {
    use super::super::octree::OctreeParams;
    use super::super::test_clouds::{all_clouds, assert_matches_brute_force};
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn octree_matches_brute_force_on_all_clouds() {
        for leaf_size in [1, 4, 16] {
            for (name, pts) in all_clouds(700, 42) {
                let tree = Octree::build(&pts, &OctreeParams { leaf_size }).unwrap();
                assert_matches_brute_force(&tree, &pts, &format!("{name}/K={leaf_size}"), 7);
            }
        }
    }

    #[test]
    fn inside_nodes_are_taken_whole() {
        // A radius covering the whole cloud classifies the root as inside: every point, no tests.
        let pts = super::super::test_clouds::uniform_cube(500, 3);
        let tree = Octree::build(&pts, &OctreeParams { leaf_size: 8 }).unwrap();
        let q = [0.5, 0.5, 0.5];
        assert_eq!(tree.classify(0, &q, 1.0), Class::Inside);
        assert_eq!(tree.classify(0, &[9.0, 9.0, 9.0], 1.0), Class::Outside);
        assert_eq!(tree.classify(0, &q, 0.01), Class::Partial);
        let mut out = Vec::new();
        tree.within(&q, 1.0, &mut out);
        assert_eq!(out, tree.original_indices());
    }

    #[test]
    fn negative_and_nan_radius_give_nothing() {
        let pts = super::super::test_clouds::uniform_cube(50, 1);
        let tree = Octree::build(&pts, &OctreeParams::default()).unwrap();
        let mut out = vec![1, 2];
        tree.within(&pts[0], -1.0, &mut out);
        assert!(out.is_empty());
        tree.within(&pts[0], f64::NAN, &mut out);
        assert!(out.is_empty());
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn octree_equals_brute_force_on_random_clouds(
            pts in prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 0..120),
            q in prop::array::uniform3(-1.5f64..1.5),
            r in 0.0f64..2.0,
            k in 0usize..20,
            leaf_size in 1usize..12,
        ) {
            let tree = Octree::build(&pts, &OctreeParams { leaf_size }).unwrap();
            let (mut got, mut want) = (Vec::new(), Vec::new());
            tree.within(&q, r, &mut got);
            got.sort_unstable();
            crate::spatial::brute_force::within(&pts, &q, r, &mut want);
            prop_assert_eq!(got, want);
            let (mut gk, mut wk) = (Vec::new(), Vec::new());
            tree.nearest_k(&q, k, &mut gk);
            crate::spatial::brute_force::nearest_k(&pts, &q, k, &mut wk);
            prop_assert_eq!(gk, wk);
        }
    }
}
