//! Which triangles' centroids lie within a distance of the data, and the nearest data point of
//! those that do not: the question the open-scan trim ([`super::trim`]) and the border peel
//! ([`super::peel`]) ask of every triangle of a fresh grid mesh.
//!
//! Answered run by run: the mesh comes out of the polygonizer tile by tile, so a run of
//! [`RUN`] consecutive triangles lies in a small box. One radius query per run gathers the points
//! within `threshold` plus the box's half diagonal of its centre (every point within `threshold`
//! of any centroid in the box), sorted by distance from that centre; each centroid then scans
//! that list until a point within `threshold` turns up, usually among the first few. Only a
//! centroid with no point that near (a triangle to trim or peel, a few per cent) asks the k-d
//! tree for its nearest point. A run whose box is wider than [`WIDEST_RUN`] thresholds (triangles
//! not in grid order) asks the tree for every centroid. The answers are those of a nearest-point
//! query per centroid ("nearest distance ≤ `threshold`"), whatever the triangle order.

use crate::geometry::{Aabb, Point3, TriMesh, dist2};
use crate::spatial::{KdTree, SpatialIndex};
use rayon::prelude::*;

/// Consecutive triangles answered from one gathered list.
const RUN: usize = 32;

/// Widest run box (half diagonal, in thresholds) still answered from a list.
const WIDEST_RUN: f64 = 2.0;

/// Relative margin on the gathering radius, for the rounding of centres and distances.
const MARGIN: f64 = 1e-9;

/// A triangle's centroid against the data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Reach {
    /// Some point lies within the threshold.
    Within,
    /// None does: the nearest point and its distance (`None` when there are no points).
    Beyond(Option<(u32, f64)>),
}

/// The centroid of triangle `t` of `mesh`.
pub(crate) fn centroid(mesh: &TriMesh, t: &[u32; 3]) -> Point3 {
    [0, 1, 2].map(|k| t.iter().map(|&v| mesh.vertices[v as usize][k]).sum::<f64>() / 3.0)
}

/// Per triangle of `mesh`, whether a point of `tree` (over `points`) lies within `threshold` of
/// its centroid (the mesh's units), and otherwise which is nearest (see the module doc).
pub(crate) fn centroid_reach(
    mesh: &TriMesh,
    (tree, points): (&KdTree, &[Point3]),
    threshold: f64,
) -> Vec<Reach> {
    (mesh.triangles.par_chunks(RUN))
        .map_init(Vec::new, |near, run| {
            let centres: Vec<Point3> = run.iter().map(|t| centroid(mesh, t)).collect();
            run_reach(&centres, (tree, points), threshold, near)
        })
        .flatten_iter()
        .collect()
}

/// [`centroid_reach`] of one run's `centres`; `near` is scratch space.
fn run_reach(
    centres: &[Point3],
    (tree, points): (&KdTree, &[Point3]),
    threshold: f64,
    near: &mut Vec<u32>,
) -> Vec<Reach> {
    // The k-d tree's answer for one centroid.
    let by_tree = |x: &Point3| match tree.nearest_one(x) {
        Some((_, d)) if d <= threshold => Reach::Within,
        hit => Reach::Beyond(hit),
    };
    let bbox = Aabb::from_points(centres);
    let (c, h) = (bbox.center(), 0.5 * bbox.diagonal());
    if !(threshold >= 0.0 && h.is_finite() && h <= WIDEST_RUN * threshold.max(f64::MIN_POSITIVE)) {
        return centres.iter().map(by_tree).collect();
    }
    tree.within(&c, (threshold + h) * (1.0 + MARGIN), near);
    let mut list: Vec<(f64, Point3)> = (near.iter())
        .map(|&i| (dist2(points[i as usize], c), points[i as usize]))
        .collect();
    list.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    (centres.iter())
        .map(|x| {
            // The same distance as the tree's answer: `dist2(p, x).sqrt()`.
            if list.iter().any(|(_, p)| dist2(*p, *x).sqrt() <= threshold) {
                Reach::Within
            } else {
                by_tree(x)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::torus;

    /// A nearest-point query per centroid: the answer [`centroid_reach`] must give.
    fn brute(mesh: &TriMesh, points: &[Point3], threshold: f64) -> Vec<Reach> {
        (mesh.triangles.iter())
            .map(|t| {
                let c = centroid(mesh, t);
                let best = (points.iter().enumerate())
                    .map(|(i, p)| (i as u32, dist2(*p, c).sqrt()))
                    .min_by(|a, b| a.1.total_cmp(&b.1));
                match best {
                    Some((_, d)) if d <= threshold => Reach::Within,
                    hit => Reach::Beyond(hit),
                }
            })
            .collect()
    }

    #[test]
    fn reach_matches_a_nearest_query_per_centroid_in_any_triangle_order() {
        // Points above the torus's equator only, scattered off it: the lower half is beyond.
        let mut mesh = torus(1.0, 0.3, 48, 24);
        let points: Vec<Point3> = (0..600)
            .map(|i| {
                let (u, v) = (
                    i as f64 * 0.61,
                    0.2 + 2.7 * ((i * 7919) % 600) as f64 / 600.0,
                );
                let r = 1.0 + 0.33 * v.cos();
                [r * u.cos(), r * u.sin(), 0.33 * v.sin()]
            })
            .collect();
        let tree = KdTree::build(&points).unwrap();
        for threshold in [0.0, 0.05, 0.2, 3.0] {
            let want = brute(&mesh, &points, threshold);
            let got = centroid_reach(&mesh, (&tree, &points), threshold);
            assert_eq!(got, want, "threshold {threshold}");
            let within = got.iter().filter(|r| **r == Reach::Within).count();
            if threshold == 0.2 {
                assert!(within > 0 && within < got.len(), "{within}");
            }
        }
        // Shuffled triangles: runs with wide boxes take the per-centroid path.
        let n = mesh.triangles.len();
        let order: Vec<usize> = (0..n).map(|i| (i * 7919) % n).collect();
        mesh.triangles = order.iter().map(|&i| mesh.triangles[i]).collect();
        let got = centroid_reach(&mesh, (&tree, &points), 0.2);
        assert_eq!(got, brute(&mesh, &points, 0.2));
        let empty = KdTree::build(&[]).unwrap();
        assert!(
            centroid_reach(&mesh, (&empty, &[]), 0.2)
                .iter()
                .all(|r| *r == Reach::Beyond(None))
        );
    }
}
