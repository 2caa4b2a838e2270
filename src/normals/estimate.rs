//! PCA normals: the eigenvector of the smallest eigenvalue of the covariance of each point's k
//! nearest neighbours (itself included). Also returns the k-NN lists that the orientation graph is
//! built from. Neighbours come from [`crate::spatial::KdTree`]. `O(n k log n)`, parallel.

use crate::geometry::Point3;
use crate::geometry::pca::pca;
use crate::spatial::{KdTree, SpatialIndex};
use rayon::prelude::*;

/// Unoriented unit normals and, per point, its neighbour indices (without itself, nearest first).
///
/// Falls back to `+z` normals and empty neighbour lists when the index cannot be built (more than
/// `u32::MAX` points).
pub fn estimate_normals(points: &[Point3], k: usize) -> (Vec<Point3>, Vec<Vec<u32>>) {
    let Ok(tree) = KdTree::build(points) else {
        return (
            vec![[0.0, 0.0, 1.0]; points.len()],
            vec![Vec::new(); points.len()],
        );
    };
    let want = (k + 1).min(points.len()).max(1);
    points
        .par_iter()
        .enumerate()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(nn, local), (i, p)| {
                tree.nearest_k(p, want, nn);
                local.clear();
                local.extend(nn.iter().map(|&(j, _)| points[j as usize]));
                let n = pca(local).axes[2];
                let nbrs = nn
                    .iter()
                    .map(|&(j, _)| j)
                    .filter(|&j| j as usize != i)
                    .collect();
                (n, nbrs)
            },
        )
        .unzip()
}

/// Area represented by each point: `π d² / m` where `d` is the distance to the farthest of its `m`
/// listed neighbours (the disc the neighbourhood covers, shared by its points). Zero without
/// neighbours.
pub(crate) fn point_areas(points: &[Point3], neighbours: &[Vec<u32>]) -> Vec<f64> {
    points
        .iter()
        .zip(neighbours)
        .map(|(p, list)| {
            let d2 = list
                .iter()
                .map(|&j| crate::geometry::dist2(*p, points[j as usize]))
                .fold(0.0, f64::max);
            std::f64::consts::PI * d2 / list.len().max(1) as f64
        })
        .collect()
}
