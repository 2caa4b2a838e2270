//! Trimming for open scans: drop the triangles that no data supports (centroid farther than
//! `max_distance` from every data point), so a single range image gives an open surface that stays
//! on the data instead of a sheet continued by the carrier. `O(t log n)`, parallel.

use crate::geometry::{Point3, TriMesh};
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// Per triangle: `true` when its centroid is farther than `max_distance` from all `points` (same units
/// as the mesh), i.e. no data supports it.
pub fn unsupported_triangles(mesh: &TriMesh, points: &[Point3], max_distance: f64) -> Vec<bool> {
    let Ok(tree) = ImmutableKdTree::<f64, 3>::new_from_slice(points) else {
        return vec![false; mesh.triangles.len()];
    };
    let limit2 = max_distance * max_distance;
    mesh.triangles
        .par_iter()
        .map(|t| {
            let c = [0, 1, 2]
                .map(|k| t.iter().map(|&v| mesh.vertices[v as usize][k]).sum::<f64>() / 3.0);
            tree.query(&c)
                .nearest_one::<SquaredEuclidean<f64>>()
                .execute()
                .distance
                > limit2
        })
        .collect()
}

/// Remove the triangles flagged in `drop`; returns how many. Unused vertices are left for the GPU
/// reordering to drop.
pub fn remove_triangles(mesh: &mut TriMesh, drop: &[bool]) -> usize {
    let before = mesh.triangles.len();
    let mut i = 0;
    mesh.triangles.retain(|_| {
        i += 1;
        !drop[i - 1]
    });
    before - mesh.triangles.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triangles_away_from_the_data_are_removed() {
        let mut mesh = TriMesh {
            vertices: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [5.0, 5.0, 0.0],
                [6.0, 5.0, 0.0],
                [5.0, 6.0, 0.0],
            ],
            normals: vec![],
            triangles: vec![[0, 1, 2], [3, 4, 5]],
        };
        let drop = unsupported_triangles(&mesh, &[[0.3, 0.3, 0.0]], 0.5);
        assert_eq!(drop, vec![false, true]);
        let removed = remove_triangles(&mut mesh, &drop);
        assert_eq!(removed, 1);
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    }
}
