//! The octal tree of Kojekine et al. (2002), section 3.1, Algorithm I ("octal tree creation").
//!
//! The root is the bounding cube of the points; a node with more than `K` points (the leaf size)
//! is split into its non-empty octants, down to [`MAX_DEPTH`] levels (a leaf at that depth keeps
//! all its points, so duplicate points cannot recurse forever; a node whose points are all
//! identical is a leaf at once). After creation the tree is simplified as in the paper: a node
//! with exactly one child is replaced by that child ("single-child collapse").
//!
//! Layout: nodes live in one arena (`Vec`), the children of a node are contiguous, and the points
//! are permuted into depth-first leaf order so every node's points are one contiguous slice. Each
//! node stores the tight bounding box of its points, which the searches use for classification.
//! Building is `O(n · depth)` time and `O(n)` memory.

use crate::geometry::{Aabb, Point3};

use super::{SpatialError, check_count};

/// Deepest level a node may be subdivided to (root = level 0). A cube at this level has an edge
/// of `2⁻²¹` times the root's, below `f64` resolution for practical clouds.
pub const MAX_DEPTH: usize = 21;

/// Marks "no node" (the root's parent).
pub(super) const NO_NODE: u32 = u32::MAX;

/// Parameters of [`Octree::build`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OctreeParams {
    /// `K`: maximum number of points in a leaf (nodes with more are subdivided). At least 1;
    /// default 10 (the paper's Table 1); 8–32 works well.
    pub leaf_size: usize,
}

impl Default for OctreeParams {
    fn default() -> Self {
        OctreeParams { leaf_size: 10 }
    }
}

/// Size and shape of a built octree.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct OctreeStats {
    /// Nodes after the single-child collapse (0 for an empty point set).
    pub nodes: usize,
    /// Leaves (nodes without children).
    pub leaves: usize,
    /// Number of levels after the collapse (root only = 1, empty tree = 0).
    pub depth: usize,
    /// Nodes removed by the single-child collapse.
    pub collapsed: usize,
}

/// One node of the arena.
#[derive(Debug, Clone)]
pub(super) struct Node {
    /// Tight bounding box of the node's points.
    pub(super) bbox: Aabb,
    /// The node's points are `pts[start..end]`.
    pub(super) start: u32,
    /// End of the point range (exclusive).
    pub(super) end: u32,
    /// Index of the first child; children are `first_child..first_child + n_children`.
    pub(super) first_child: u32,
    /// Number of children (0 for a leaf).
    pub(super) n_children: u32,
    /// Parent node, [`NO_NODE`] for the root.
    pub(super) parent: u32,
}

impl Node {
    pub(super) fn is_leaf(&self) -> bool {
        self.n_children == 0
    }
    pub(super) fn children(&self) -> std::ops::Range<usize> {
        self.first_child as usize..(self.first_child + self.n_children) as usize
    }
    pub(super) fn range(&self) -> std::ops::Range<usize> {
        self.start as usize..self.end as usize
    }
}

/// The octal tree over a fixed point set (seed Algorithms I and II). See the module docs.
#[derive(Debug, Clone)]
pub struct Octree {
    /// Node arena; node 0 is the root (empty for no points).
    pub(super) nodes: Vec<Node>,
    /// Points in leaf order.
    pub(super) pts: Vec<Point3>,
    /// `idx[pos]` = original index of the point stored at `pos`.
    pub(super) idx: Vec<u32>,
    /// `pos_of[original]` = position in `pts`.
    pub(super) pos_of: Vec<u32>,
    /// `leaf_of[pos]` = leaf node holding the point at `pos`.
    pub(super) leaf_of: Vec<u32>,
    /// Statistics of the built tree.
    stats: OctreeStats,
}

impl Octree {
    /// Build the tree over `points` (n points × 3) with leaf size `params.leaf_size`, then
    /// apply the single-child collapse.
    ///
    /// # Errors
    /// [`SpatialError::InvalidLeafSize`] for `leaf_size == 0`, [`SpatialError::TooManyPoints`]
    /// beyond `u32::MAX` points.
    ///
    /// ```
    /// use rbfsurf::spatial::{Octree, OctreeParams, SpatialIndex};
    /// let pts: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 * 0.01, 0.0, 0.0]).collect();
    /// let tree = Octree::build(&pts, &OctreeParams { leaf_size: 4 }).unwrap();
    /// assert_eq!(tree.len(), 100);
    /// assert!(tree.stats().leaves >= 25);
    /// ```
    pub fn build(points: &[Point3], params: &OctreeParams) -> Result<Self, SpatialError> {
        let mut tree = Self::build_uncollapsed(points, params)?;
        tree.collapse_single_children();
        Ok(tree)
    }

    /// Algorithm I without the simplification step (kept separate so tests can compare).
    pub(super) fn build_uncollapsed(
        points: &[Point3],
        params: &OctreeParams,
    ) -> Result<Self, SpatialError> {
        if params.leaf_size == 0 {
            return Err(SpatialError::InvalidLeafSize {
                leaf_size: params.leaf_size,
            });
        }
        check_count(points.len())?;
        let mut idx: Vec<u32> = (0..points.len() as u32).collect();
        let nodes = if points.is_empty() {
            Vec::new()
        } else {
            subdivide(points, &mut idx, params.leaf_size)
        };
        let pts: Vec<Point3> = idx.iter().map(|&i| points[i as usize]).collect();
        let mut tree = Octree {
            nodes,
            pts,
            idx,
            pos_of: Vec::new(),
            leaf_of: Vec::new(),
            stats: OctreeStats::default(),
        };
        tree.finish();
        Ok(tree)
    }

    /// The seed's simplification: every node with exactly one child is replaced by that child.
    /// Rebuilds the arena (children stay contiguous) and returns the number of removed nodes.
    pub(super) fn collapse_single_children(&mut self) -> usize {
        if self.nodes.is_empty() {
            return 0;
        }
        let old = std::mem::take(&mut self.nodes);
        let mut removed = 0usize;
        let mut resolve = |mut i: usize| {
            while old[i].n_children == 1 {
                i = old[i].first_child as usize;
                removed += 1;
            }
            i
        };
        let mut origin = vec![resolve(0)];
        let mut nodes = vec![Node {
            parent: NO_NODE,
            ..old[origin[0]].clone()
        }];
        let mut head = 0;
        while head < nodes.len() {
            let first = nodes.len() as u32;
            for c in old[origin[head]].children() {
                let c = resolve(c);
                origin.push(c);
                nodes.push(Node {
                    parent: head as u32,
                    ..old[c].clone()
                });
            }
            nodes[head].first_child = first;
            head += 1;
        }
        self.nodes = nodes;
        self.finish();
        self.stats.collapsed += removed;
        removed
    }

    /// Recompute the per-point maps and the statistics after the arena changed.
    fn finish(&mut self) {
        let n = self.pts.len();
        self.pos_of = vec![0; n];
        for (pos, &i) in self.idx.iter().enumerate() {
            self.pos_of[i as usize] = pos as u32;
        }
        self.leaf_of = vec![NO_NODE; n];
        let mut leaves = 0;
        for (ni, node) in self.nodes.iter().enumerate() {
            if node.is_leaf() {
                leaves += 1;
                self.leaf_of[node.range()].fill(ni as u32);
            }
        }
        self.stats = OctreeStats {
            nodes: self.nodes.len(),
            leaves,
            depth: self.levels(),
            collapsed: self.stats.collapsed,
        };
    }

    /// Number of levels (root only = 1).
    fn levels(&self) -> usize {
        let mut level = vec![0usize; self.nodes.len()];
        let mut deepest = 0;
        // Parents precede their children in the arena (both construction orders guarantee it).
        for ni in 0..self.nodes.len() {
            let p = self.nodes[ni].parent;
            level[ni] = if p == NO_NODE {
                1
            } else {
                level[p as usize] + 1
            };
            deepest = deepest.max(level[ni]);
        }
        deepest
    }

    /// Number of indexed points.
    pub fn len(&self) -> usize {
        self.pts.len()
    }

    /// True when the tree holds no points.
    pub fn is_empty(&self) -> bool {
        self.pts.is_empty()
    }

    /// Size and shape of the tree.
    pub fn stats(&self) -> OctreeStats {
        self.stats
    }

    /// The indexed points in leaf order (a node's points are a contiguous slice of this).
    pub fn points_in_leaf_order(&self) -> &[Point3] {
        &self.pts
    }

    /// `original_indices()[pos]` is the index (into the slice the tree was built from) of the
    /// point at `points_in_leaf_order()[pos]`.
    pub fn original_indices(&self) -> &[u32] {
        &self.idx
    }
}

/// Cube used during subdivision: centre and half edge.
#[derive(Debug, Clone, Copy)]
struct Cube {
    center: Point3,
    half: f64,
}

/// Build the arena top-down, permuting `idx` so every node's points are contiguous.
/// Children of a node are allocated together, so they are contiguous in the arena.
fn subdivide(points: &[Point3], idx: &mut [u32], leaf_size: usize) -> Vec<Node> {
    let root_box = Aabb::from_points(points);
    let e = root_box.extent();
    let root = Cube {
        center: root_box.center(),
        half: 0.5 * e[0].max(e[1]).max(e[2]),
    };
    let mut nodes = vec![Node {
        bbox: root_box,
        start: 0,
        end: points.len() as u32,
        first_child: 0,
        n_children: 0,
        parent: NO_NODE,
    }];
    let mut stack = vec![(0usize, root, 0usize)];
    let mut scratch: Vec<u32> = Vec::new();
    while let Some((ni, cube, depth)) = stack.pop() {
        let range = nodes[ni].range();
        let single_location = nodes[ni].bbox.min == nodes[ni].bbox.max;
        if range.len() <= leaf_size || depth >= MAX_DEPTH || single_location {
            continue;
        }
        let counts = partition_octants(points, &mut idx[range.clone()], cube.center, &mut scratch);
        let first = nodes.len();
        let mut start = range.start;
        for (oct, &count) in counts.iter().enumerate() {
            if count == 0 {
                continue;
            }
            let end = start + count;
            let bbox = Aabb::from_points(idx[start..end].iter().map(|&i| &points[i as usize]));
            nodes.push(Node {
                bbox,
                start: start as u32,
                end: end as u32,
                first_child: 0,
                n_children: 0,
                parent: ni as u32,
            });
            stack.push((nodes.len() - 1, child_cube(cube, oct), depth + 1));
            start = end;
        }
        nodes[ni].first_child = first as u32;
        nodes[ni].n_children = (nodes.len() - first) as u32;
    }
    nodes
}

/// Octant of `p` relative to `c`: bit k is set when `p[k] ≥ c[k]`.
#[inline]
fn octant(p: &Point3, c: &Point3) -> usize {
    usize::from(p[0] >= c[0]) | usize::from(p[1] >= c[1]) << 1 | usize::from(p[2] >= c[2]) << 2
}

/// The cube of octant `oct` of `cube`.
fn child_cube(cube: Cube, oct: usize) -> Cube {
    let q = 0.5 * cube.half;
    let mut center = cube.center;
    for (k, c) in center.iter_mut().enumerate() {
        *c += if oct >> k & 1 == 1 { q } else { -q };
    }
    Cube { center, half: q }
}

/// Stable counting sort of `idx` by octant around `center`; returns the count per octant.
fn partition_octants(
    points: &[Point3],
    idx: &mut [u32],
    center: Point3,
    scratch: &mut Vec<u32>,
) -> [usize; 8] {
    partition8(idx, |i| octant(&points[i as usize], &center), scratch)
}

/// Stable counting sort of `items` by `key` (in `0..8`, e.g. an octant), through `scratch`;
/// returns the count per key. `O(n)`.
pub(crate) fn partition8<T: Copy + Default>(
    items: &mut [T],
    key: impl Fn(T) -> usize,
    scratch: &mut Vec<T>,
) -> [usize; 8] {
    let mut counts = [0usize; 8];
    for &i in items.iter() {
        counts[key(i)] += 1;
    }
    let mut offsets = [0usize; 8];
    for o in 1..8 {
        offsets[o] = offsets[o - 1] + counts[o - 1];
    }
    scratch.clear();
    scratch.resize(items.len(), T::default());
    for &i in items.iter() {
        let o = key(i);
        scratch[offsets[o]] = i;
        offsets[o] += 1;
    }
    items.copy_from_slice(scratch);
    counts
}

#[cfg(test)]
mod tests {
    use super::super::test_clouds::{all_clouds, sphere_surface, uniform_cube};
    use super::*;

    /// Structural invariants: ranges nest, leaves tile the points, boxes are tight, sizes obey K.
    fn check_invariants(tree: &Octree, points: &[Point3], leaf_size: usize) {
        let s = tree.stats();
        assert_eq!(s.nodes, tree.nodes.len());
        if points.is_empty() {
            assert_eq!((s.nodes, s.leaves, s.depth), (0, 0, 0));
            return;
        }
        assert_eq!(tree.nodes[0].range(), 0..points.len());
        let e = Aabb::from_points(points).extent();
        let finest_cell = e[0].max(e[1]).max(e[2]) / (1u64 << MAX_DEPTH) as f64;
        let mut covered = 0;
        for (ni, node) in tree.nodes.iter().enumerate() {
            let bbox = Aabb::from_points(&tree.pts[node.range()]);
            assert_eq!(bbox, node.bbox, "node {ni} box not tight");
            assert_ne!(node.n_children, 1, "single child survived the collapse");
            if node.is_leaf() {
                covered += node.range().len();
                // An oversized leaf is either one location or a cell at the depth limit.
                let e = node.bbox.extent();
                let tiny = e[0].max(e[1]).max(e[2]) <= finest_cell;
                assert!(node.range().len() <= leaf_size || tiny, "leaf {ni} too big");
            } else {
                let kids = node.children();
                assert_eq!(tree.nodes[kids.start].start, node.start);
                assert_eq!(tree.nodes[kids.end - 1].end, node.end);
                for c in kids.clone() {
                    assert_eq!(tree.nodes[c].parent as usize, ni);
                    if c + 1 < kids.end {
                        assert_eq!(tree.nodes[c].end, tree.nodes[c + 1].start);
                    }
                }
            }
        }
        assert_eq!(covered, points.len());
        for (pos, &orig) in tree.idx.iter().enumerate() {
            assert_eq!(tree.pts[pos], points[orig as usize]);
            assert_eq!(tree.pos_of[orig as usize] as usize, pos);
        }
    }

    #[test]
    fn invariants_hold_on_all_clouds() {
        for leaf_size in [1, 3, 10, 64] {
            for (name, pts) in all_clouds(600, 9) {
                let tree = Octree::build(&pts, &OctreeParams { leaf_size }).unwrap();
                check_invariants(&tree, &pts, leaf_size);
                let s = tree.stats();
                assert!(
                    s.leaves <= s.nodes && s.depth <= MAX_DEPTH + 1,
                    "{name}: {s:?}"
                );
            }
        }
    }

    #[test]
    fn stats_are_sane_for_uniform_points() {
        let pts = uniform_cube(4096, 5);
        let tree = Octree::build(&pts, &OctreeParams { leaf_size: 8 }).unwrap();
        let s = tree.stats();
        // At least n/K leaves; roughly log8(n/K) + 1 levels for uniform data.
        assert!(s.leaves >= 4096 / 8, "{s:?}");
        assert!((4..=8).contains(&s.depth), "{s:?}");
        // Every internal node has ≥ 2 children, so nodes < 2 · leaves.
        assert!(s.nodes < 2 * s.leaves, "{s:?}");
        let single = Octree::build(&[[1.0, 2.0, 3.0]], &OctreeParams::default()).unwrap();
        assert_eq!(
            single.stats(),
            OctreeStats {
                nodes: 1,
                leaves: 1,
                depth: 1,
                collapsed: 0
            }
        );
    }

    #[test]
    fn identical_points_make_one_leaf() {
        let pts = vec![[0.2, 0.2, 0.2]; 1000];
        let tree = Octree::build(&pts, &OctreeParams { leaf_size: 1 }).unwrap();
        assert_eq!(tree.stats().nodes, 1);
    }

    #[test]
    fn near_duplicates_stop_at_max_depth() {
        // 50 points closer together than the depth-21 cell of a unit cube: the subdivision stops.
        let mut pts: Vec<Point3> = (0..50)
            .map(|i| [0.5 + i as f64 * 1e-12, 0.5, 0.5])
            .collect();
        pts.push([0.0, 0.0, 0.0]);
        pts.push([1.0, 1.0, 1.0]);
        let raw = Octree::build_uncollapsed(&pts, &OctreeParams { leaf_size: 1 }).unwrap();
        assert_eq!(raw.stats().depth, MAX_DEPTH + 1);
        let tree = Octree::build(&pts, &OctreeParams { leaf_size: 1 }).unwrap();
        check_invariants(&tree, &pts, 1);
        assert!(tree.stats().depth < raw.stats().depth);
    }

    #[test]
    fn collapse_removes_single_child_chains_and_keeps_results() {
        // Two tight pairs at opposite corners of a small region far from a third point: the
        // octants around each pair contain nothing else, giving chains of single-child nodes.
        let pts = vec![
            [0.0, 0.0, 0.0],
            [1.0, 1.0, 1.0],
            [0.700_000, 0.700_000, 0.700_000],
            [0.700_001, 0.700_001, 0.700_001],
            [0.700_002, 0.700_000, 0.700_001],
        ];
        let params = OctreeParams { leaf_size: 1 };
        let raw = Octree::build_uncollapsed(&pts, &params).unwrap();
        let mut tree = raw.clone();
        let removed = tree.collapse_single_children();
        assert!(removed >= 10, "removed {removed}");
        assert_eq!(tree.stats().collapsed, removed);
        assert_eq!(raw.stats().nodes - tree.stats().nodes, removed);
        assert_eq!(raw.stats().leaves, tree.stats().leaves);
        assert!(tree.stats().depth < raw.stats().depth);
        check_invariants(&tree, &pts, 1);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for q in &pts {
            for r in [1e-7, 1e-6, 3e-6, 0.1, 1.0, 2.0] {
                raw.within(q, r, &mut a);
                tree.within(q, r, &mut b);
                a.sort_unstable();
                b.sort_unstable();
                assert_eq!(a, b);
            }
        }
        // A second collapse finds nothing.
        assert_eq!(tree.collapse_single_children(), 0);
    }

    #[test]
    fn collapse_counts_match_on_a_sphere() {
        let pts = sphere_surface(3000, 1);
        let params = OctreeParams { leaf_size: 1 };
        let raw = Octree::build_uncollapsed(&pts, &params).unwrap();
        let tree = Octree::build(&pts, &params).unwrap();
        let s = tree.stats();
        assert_eq!(raw.stats().nodes, s.nodes + s.collapsed);
        assert!(s.collapsed > 0);
    }

    #[test]
    fn zero_leaf_size_is_an_error() {
        assert!(Octree::build(&[[0.0; 3]], &OctreeParams { leaf_size: 0 }).is_err());
    }
}
