//! Searching while removing: the neighbour search of Kojekine et al. (2002), section 3.1,
//! Algorithm III ("sorting data using an octal tree"), which looks for neighbours only among
//! points still in the input list and removes the ones it finds.
//!
//! Instead of deleting from a list, a [`RemovalSet`] marks points as taken and keeps a count of
//! remaining points per node, so fully taken subtrees are skipped. Removing a point walks from
//! its leaf to the root (`O(depth)`), so removing all `n` points costs `O(n · depth)` in total.

use crate::geometry::{Point3, dist2};

use super::octree::{NO_NODE, Octree};
use super::octree_search::Class;

/// Which points of one [`Octree`] are still available; created by [`Octree::removal_set`].
#[derive(Debug, Clone)]
pub struct RemovalSet {
    /// `alive[pos]` for the point at leaf-order position `pos`.
    alive: Vec<bool>,
    /// Remaining points per node.
    node_alive: Vec<u32>,
    /// Remaining points in total.
    remaining: usize,
}

impl RemovalSet {
    /// Number of points not yet removed.
    pub fn remaining(&self) -> usize {
        self.remaining
    }
}

impl Octree {
    /// A fresh [`RemovalSet`] with every point available.
    pub fn removal_set(&self) -> RemovalSet {
        RemovalSet {
            alive: vec![true; self.pts.len()],
            node_alive: self.nodes.iter().map(|n| n.end - n.start).collect(),
            remaining: self.pts.len(),
        }
    }

    /// True when the point with original index `i` has not been removed from `set`.
    /// Out-of-range indices are reported as not available.
    pub fn is_available(&self, set: &RemovalSet, i: usize) -> bool {
        self.pos_of
            .get(i)
            .is_some_and(|&pos| set.alive[pos as usize])
    }

    /// Remove the point with original index `i` from `set`; returns false when it was already
    /// removed (or `i` is out of range).
    pub fn remove(&self, set: &mut RemovalSet, i: usize) -> bool {
        match self.pos_of.get(i) {
            Some(&pos) if set.alive[pos as usize] => {
                self.remove_pos(set, pos as usize);
                true
            }
            _ => false,
        }
    }

    fn remove_pos(&self, set: &mut RemovalSet, pos: usize) {
        set.alive[pos] = false;
        set.remaining -= 1;
        let mut ni = self.leaf_of[pos];
        while ni != NO_NODE {
            set.node_alive[ni as usize] -= 1;
            ni = self.nodes[ni as usize].parent;
        }
    }

    /// Original indices of all still-available points with `|p − q| ≤ r`, written to `out`
    /// (cleared first, in tree order), and removed from `set`.
    pub fn take_within(&self, q: &Point3, r: f64, set: &mut RemovalSet, out: &mut Vec<u32>) {
        out.clear();
        let r2 = r * r;
        {
            let node_alive = &set.node_alive;
            let alive = &set.alive;
            self.walk_sphere(
                q,
                r,
                |ni| node_alive[ni] == 0,
                |ni, class| {
                    for pos in self.nodes[ni].range() {
                        if alive[pos] && (class == Class::Inside || dist2(self.pts[pos], *q) <= r2)
                        {
                            out.push(pos as u32);
                        }
                    }
                },
            );
        }
        // `out` holds leaf-order positions so far; remove them and translate to original indices.
        for slot in out.iter_mut() {
            let pos = *slot as usize;
            self.remove_pos(set, pos);
            *slot = self.idx[pos];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::octree::OctreeParams;
    use super::super::test_clouds::{all_clouds, queries};
    use super::*;

    #[test]
    fn take_within_returns_available_neighbours_once() {
        for (name, pts) in all_clouds(400, 21) {
            let tree = Octree::build(&pts, &OctreeParams { leaf_size: 4 }).unwrap();
            let mut set = tree.removal_set();
            let mut taken = vec![false; pts.len()];
            let mut out = Vec::new();
            for (step, q) in queries(&pts, 5).iter().enumerate() {
                let r = [0.05, 0.2, 0.0, 0.5][step % 4];
                // Brute force over the points not yet taken.
                let want: Vec<u32> = (0..pts.len() as u32)
                    .filter(|&i| {
                        !taken[i as usize] && crate::geometry::dist2(pts[i as usize], *q) <= r * r
                    })
                    .collect();
                tree.take_within(q, r, &mut set, &mut out);
                out.sort_unstable();
                assert_eq!(out, want, "{name}: step {step}");
                for &i in &out {
                    taken[i as usize] = true;
                }
                let left = taken.iter().filter(|t| !**t).count();
                assert_eq!(set.remaining(), left);
                for (i, &t) in taken.iter().enumerate() {
                    assert_eq!(tree.is_available(&set, i), !t);
                }
            }
        }
    }

    #[test]
    fn remove_reports_state() {
        let pts = vec![[0.0; 3], [1.0; 3]];
        let tree = Octree::build(&pts, &OctreeParams::default()).unwrap();
        let mut set = tree.removal_set();
        assert!(tree.remove(&mut set, 1));
        assert!(!tree.remove(&mut set, 1));
        assert!(!tree.remove(&mut set, 7));
        assert!(!tree.is_available(&set, 7));
        let mut out = Vec::new();
        tree.take_within(&[0.5; 3], 2.0, &mut set, &mut out);
        assert_eq!(out, vec![0]);
        assert_eq!(set.remaining(), 0);
    }
}
