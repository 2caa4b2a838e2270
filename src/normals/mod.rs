//! Normals for clouds that have none: PCA over the k nearest neighbours ([`estimate`]), then a
//! consistent orientation ([`orient`]) that survives thin limbs and near-touching sheets:
//! confident local propagation inside patches ([`graph`], [`patches`]) and a global sign per patch
//! from the winding-number (dipole) field of the others ([`dipole`]), then outward per component,
//! inward regions ([`regions`]) and, on closed clean surfaces, each point by ray parity
//! ([`parity`]).
//!
//! Measured against true normals with `cargo run --release --example normal_flips` (figures in
//! docs/robustness.md, section "Normals against the truth").

mod dipole;
mod estimate;
mod graph;
mod orient;
mod parity;
mod patches;
mod regions;
#[cfg(test)]
mod tests;

pub use estimate::estimate_normals;
pub use orient::orient_normals;

use crate::geometry::{Point3, dot, norm};

/// Parameters of normal estimation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NormalParams {
    /// Neighbours for the PCA plane fit and the orientation graph (default 12; 8–30).
    pub neighbours: usize,
}

impl Default for NormalParams {
    fn default() -> Self {
        NormalParams { neighbours: 12 }
    }
}

/// Share of sampled neighbour pairs whose given normals point in strongly opposed directions
/// (`n_i·n_j < −0.5`), over at most ~4000 points and their `k` nearest neighbours found with
/// `nearest_k` (a point is its own first neighbour). Near 0 for consistently oriented normals on a
/// surface sampled finer than its thickness; ~0.5 for randomly flipped ones.
pub fn inconsistent_fraction(
    points: &[Point3],
    normals: &[Point3],
    k: usize,
    nearest_k: impl Fn(&Point3, usize, &mut Vec<(u32, f64)>) + Sync,
) -> f64 {
    use rayon::prelude::*;
    let step = (points.len() / 4000).max(1);
    let samples: Vec<usize> = (0..points.len()).step_by(step).collect();
    let (bad, total) = samples
        .par_iter()
        .map_init(Vec::new, |knn, &i| {
            nearest_k(&points[i], k + 1, knn);
            let (mut bad, mut total) = (0usize, 0usize);
            for &(j, _) in knn.iter().filter(|(j, _)| *j as usize != i) {
                let (a, b) = (normals[i], normals[j as usize]);
                let (na, nb) = (norm(a), norm(b));
                if na > 0.0 && nb > 0.0 {
                    total += 1;
                    if dot(a, b) < -0.5 * na * nb {
                        bad += 1;
                    }
                }
            }
            (bad, total)
        })
        .reduce(|| (0, 0), |x, y| (x.0 + y.0, x.1 + y.1));
    bad as f64 / total.max(1) as f64
}

/// Re-orient given normals consistently (their lines kept, signs chosen as for estimated normals,
/// see [`orient`]). Returns the normals and how many were flipped.
pub fn reorient_normals(
    points: &[Point3],
    normals: &[Point3],
    params: &NormalParams,
) -> (Vec<Point3>, usize) {
    let k = params.neighbours.clamp(3, points.len().max(3));
    let (_, graph) = estimate_normals(points, k);
    let oriented = orient_normals(points, normals.to_vec(), &graph);
    let flipped = oriented
        .iter()
        .zip(normals)
        .filter(|(a, b)| dot(**a, **b) < 0.0)
        .count();
    (oriented, flipped)
}

/// Estimated, consistently oriented unit normals (outward for a closed surface sampled all round).
pub fn estimate_oriented_normals(points: &[Point3], params: &NormalParams) -> Vec<Point3> {
    let k = params.neighbours.clamp(3, points.len().max(3));
    let (normals, graph) = estimate_normals(points, k);
    orient_normals(points, normals, &graph)
}
