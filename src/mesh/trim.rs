//! Trimming for open scans: drop the triangles that no data supports (centroid farther than
//! `max_distance` from every data point), so a single range image gives an open surface that stays
//! on the data instead of a sheet continued by the carrier. `O(t log n)`, parallel.

use crate::geometry::{Point3, TriMesh};
use crate::spatial::KdTree;
use rayon::prelude::*;

/// Per triangle: `true` when its centroid is farther than `max_distance` from all `points` (same units
/// as the mesh), i.e. no data supports it.
pub fn unsupported_triangles(mesh: &TriMesh, points: &[Point3], max_distance: f64) -> Vec<bool> {
    let tree = match KdTree::build(points) {
        Ok(tree) if !points.is_empty() => tree,
        _ => return vec![false; mesh.triangles.len()],
    };
    mesh.triangles
        .par_iter()
        .map(|t| {
            let c = [0, 1, 2]
                .map(|k| t.iter().map(|&v| mesh.vertices[v as usize][k]).sum::<f64>() / 3.0);
            tree.nearest_one(&c).is_none_or(|(_, d)| d > max_distance)
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

/// Per triangle: `true` when it belongs to a connected component with fewer than `min_fraction`
/// times the triangles of the largest component (floaters left by noise and outliers), and how many
/// components that is. `min_fraction = 0` flags nothing.
pub fn small_components(mesh: &TriMesh, min_fraction: f64) -> (Vec<bool>, usize) {
    let (labels, sizes) = super::topology::triangle_components(mesh);
    let largest = sizes.iter().copied().max().unwrap_or(0) as f64;
    let small: Vec<bool> = sizes
        .iter()
        .map(|&s| (s as f64) < min_fraction * largest)
        .collect();
    let count = small.iter().filter(|s| **s).count();
    (labels.iter().map(|&c| small[c as usize]).collect(), count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn components_below_the_fraction_of_the_largest_are_flagged() {
        // A fan of 4 triangles, a separate pair, a separate single triangle.
        let mut vertices = Vec::new();
        for i in 0..12 {
            vertices.push([i as f64, (i * i) as f64, 0.0]);
        }
        let mesh = TriMesh {
            vertices,
            normals: vec![],
            triangles: vec![
                [0, 1, 2],
                [0, 2, 3],
                [0, 3, 4],
                [0, 4, 5],
                [6, 7, 8],
                [6, 8, 9],
                [10, 11, 9],
            ],
        };
        // [10, 11, 9] joins the pair through vertex 9: components are 4 and 3 triangles.
        let (flag, n) = small_components(&mesh, 0.8);
        assert_eq!(n, 1);
        assert_eq!(flag, vec![false, false, false, false, true, true, true]);
        let (flag, n) = small_components(&mesh, 0.0);
        assert_eq!(n, 0);
        assert!(flag.iter().all(|f| !f));
    }

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
