//! PCA normals: the eigenvector of the smallest eigenvalue of the covariance of each point's k
//! nearest neighbours (itself included). Also returns the k-NN graph for orientation.
//! `O(n k log n)`, parallel.

use crate::geometry::Point3;
use crate::geometry::pca::pca;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;
use std::num::NonZero;

/// Unoriented unit normals and, per point, its neighbour indices (without itself).
pub fn estimate_normals(points: &[Point3], k: usize) -> (Vec<Point3>, Vec<Vec<u32>>) {
    let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(points) else {
        return (
            vec![[0.0, 0.0, 1.0]; points.len()],
            vec![Vec::new(); points.len()],
        );
    };
    let want = NonZero::new((k + 1).min(points.len())).unwrap_or(NonZero::<usize>::MIN);
    points
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let nn = tree
                .query(p)
                .nearest_n::<SquaredEuclidean<f64>>(want)
                .execute();
            let local: Vec<Point3> = nn.iter().map(|it| points[it.item as usize]).collect();
            let n = pca(&local).axes[2];
            let nbrs = nn
                .iter()
                .map(|it| it.item)
                .filter(|&j| j as usize != i)
                .collect();
            (n, nbrs)
        })
        .unzip()
}
