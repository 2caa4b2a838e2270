//! Breadth-first octree ordering: Kojekine et al. (2002), section 3.1, Algorithm III
//! ("sorting data using an octal tree", Figure 1).
//!
//! Take the first remaining input point and append it to the output list; walk the output list
//! and, for each point, append all its not-yet-taken neighbours within `radius` (found with the
//! octree, Algorithm II) removing them from the input; when the walk reaches the end of the list,
//! start again from the first remaining input point (the next connected part). Points within
//! `radius` of each other therefore end up close in the order, which gives a banded matrix.
//! Cost: `n` octree searches, `O(n · (depth + neighbours))`; memory `O(n)`.

use crate::geometry::Point3;
use crate::spatial::{Octree, OctreeParams};

use super::{OrderingError, Permutation};

/// Algorithm III over `points` (n points × 3) with neighbour radius `radius` (> 0, the RBF
/// support). `octree`, if given, must have been built over exactly `points`; otherwise one with
/// leaf size 10 (the paper's `K`) is built.
///
/// # Errors
/// [`OrderingError::InvalidRadius`] for a radius that is not positive and finite,
/// [`OrderingError::OctreeMismatch`] when the octree holds a different number of points.
///
/// ```
/// use rbfsurf::ordering::bfs_order;
/// // Two clusters, interleaved in the input: BFS makes each one contiguous.
/// let pts = [[0.0; 3], [5.0, 0.0, 0.0], [0.1, 0.0, 0.0], [5.1, 0.0, 0.0]];
/// let p = bfs_order(&pts, 0.5, None).unwrap();
/// assert_eq!(p.perm, vec![0, 2, 1, 3]);
/// ```
pub fn bfs_order(
    points: &[Point3],
    radius: f64,
    octree: Option<&Octree>,
) -> Result<Permutation, OrderingError> {
    if !(radius.is_finite() && radius > 0.0) {
        return Err(OrderingError::InvalidRadius { radius });
    }
    let owned;
    let tree = match octree {
        Some(t) if t.len() != points.len() => {
            return Err(OrderingError::OctreeMismatch {
                octree_points: t.len(),
                points: points.len(),
            });
        }
        Some(t) => t,
        None => {
            owned = Octree::build(points, &OctreeParams { leaf_size: 10 })?;
            &owned
        }
    };
    let n = points.len();
    let mut set = tree.removal_set();
    let mut order: Vec<usize> = Vec::with_capacity(n);
    let mut found: Vec<u32> = Vec::new();
    let mut head = 0usize;
    // `first` only moves forward: "take the first point remaining in the input" is amortised O(1).
    for first in 0..n {
        if !tree.remove(&mut set, first) {
            continue;
        }
        order.push(first);
        while head < order.len() {
            let p = points[order[head]];
            tree.take_within(&p, radius, &mut set, &mut found);
            order.extend(found.iter().map(|&i| i as usize));
            head += 1;
        }
    }
    Permutation::from_perm(order)
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{bandwidth_of, components, radius_pattern, shuffled_sphere};
    use super::*;

    #[test]
    fn bfs_is_a_valid_permutation_and_reduces_bandwidth() {
        let pts = shuffled_sphere(1500, 11);
        let r = 0.12;
        let pattern = radius_pattern(&pts, r);
        let p = bfs_order(&pts, r, None).unwrap();
        p.validate().unwrap();
        let before = bandwidth_of(&pattern, &super::super::Permutation::identity(pts.len()));
        let after = bandwidth_of(&pattern, &p);
        assert!(after * 3 < before, "bandwidth {before} → {after}");
    }

    #[test]
    fn bfs_keeps_connected_components_contiguous() {
        // Three separated blobs, interleaved in the input.
        let mut pts = Vec::new();
        let blobs = shuffled_sphere(300, 5);
        for (i, p) in blobs.iter().enumerate() {
            let shift = (i % 3) as f64 * 3.0;
            pts.push([p[0] + shift, p[1], p[2]]);
        }
        let r = 0.3;
        let pattern = radius_pattern(&pts, r);
        let comp = components(&pattern);
        let p = bfs_order(&pts, r, None).unwrap();
        // Along the new order the component label changes exactly (components − 1) times.
        let labels: Vec<usize> = p.perm.iter().map(|&old| comp[old]).collect();
        let changes = labels.windows(2).filter(|w| w[0] != w[1]).count();
        let n_comp = comp.iter().max().map_or(0, |m| m + 1);
        assert_eq!(changes + 1, n_comp);
    }

    #[test]
    fn bfs_neighbour_sets_match_the_pattern_walk() {
        // Every point is either a neighbour (within r) of an earlier point in the order, or a
        // new start, which must be the first (lowest-index) point not yet taken.
        let pts = shuffled_sphere(400, 2);
        let r = 0.2;
        let p = bfs_order(&pts, r, None).unwrap();
        for k in 1..p.perm.len() {
            let cur = pts[p.perm[k]];
            let linked = p.perm[..k]
                .iter()
                .any(|&o| crate::geometry::dist2(pts[o], cur) <= r * r);
            let first_remaining = p.perm[k..].iter().min() == Some(&p.perm[k]);
            assert!(
                linked || first_remaining,
                "point {k} neither linked nor a restart"
            );
        }
    }

    #[test]
    fn bfs_rejects_bad_inputs() {
        let pts = shuffled_sphere(50, 1);
        assert!(matches!(
            bfs_order(&pts, 0.0, None),
            Err(OrderingError::InvalidRadius { .. })
        ));
        assert!(bfs_order(&pts, f64::NAN, None).is_err());
        let tree = Octree::build(&pts[..10], &OctreeParams::default()).unwrap();
        assert!(matches!(
            bfs_order(&pts, 0.1, Some(&tree)),
            Err(OrderingError::OctreeMismatch { .. })
        ));
    }

    #[test]
    fn bfs_with_identical_points() {
        let pts = vec![[0.3, 0.3, 0.3]; 64];
        let p = bfs_order(&pts, 0.01, None).unwrap();
        assert_eq!(p.perm[0], 0);
        p.validate().unwrap();
    }
}
