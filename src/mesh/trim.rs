//! Trimming for open scans: drop the triangles that no data supports (centroid farther than
//! `max_distance` from every data point), so a single range image gives an open surface that stays
//! on the data instead of a sheet continued by the carrier. `O(t log n)`, parallel.

use super::reach::{Reach, centroid_reach};
use crate::geometry::{Point3, TriMesh};
use crate::spatial::KdTree;

/// Per triangle: `true` when its centroid is farther than `max_distance` from all `points` (same units
/// as the mesh), i.e. no data supports it.
pub fn unsupported_triangles(mesh: &TriMesh, points: &[Point3], max_distance: f64) -> Vec<bool> {
    if points.is_empty() {
        return vec![false; mesh.triangles.len()];
    }
    let Ok(tree) = KdTree::build(points) else {
        return vec![true; mesh.triangles.len()];
    };
    (centroid_reach(mesh, (&tree, points), max_distance).into_iter())
        .map(|r| r != Reach::Within)
        .collect()
}

/// Un-flags the pinholes of a trim: every edge-connected region of flagged triangles that shares an
/// edge with a kept triangle but has no border edge of `mesh` (an edge used by one triangle) is a
/// hole enclosed by supported surface, not a border, and is kept. Used on a mesh polygonized only in
/// the data band: a data gap wider than the band is a hole of the band itself and stays open, while
/// a gap just wider than the trim radius would otherwise leave a one- or two-triangle hole. Returns
/// how many triangles were un-flagged. `O(t log t)`.
pub fn keep_enclosed_holes(mesh: &TriMesh, drop: &mut [bool]) -> usize {
    let t = mesh.triangles.len();
    let half = super::topology::sorted_half_edges(&mesh.triangles);
    let mut uf = super::incidence::UnionFind::new(t);
    // Per region root (after all unions): touches a border / touches a kept triangle.
    let mut pairs: Vec<(u32, u32)> = Vec::new();
    let mut border: Vec<u32> = Vec::new();
    let mut i = 0;
    while i < half.len() {
        let mut j = i + 1;
        while j < half.len() && half[j].0 == half[i].0 {
            j += 1;
        }
        match &half[i..j] {
            [(_, a)] => border.push(*a),
            [(_, a), (_, b)] => match (drop[*a as usize], drop[*b as usize]) {
                (true, true) => {
                    uf.union(*a, *b);
                }
                (true, false) => pairs.push((*a, *b)),
                (false, true) => pairs.push((*b, *a)),
                (false, false) => {}
            },
            many => border.extend(many.iter().map(|h| h.1)),
        }
        i = j;
    }
    let mut open = vec![false; t];
    let mut beside_kept = vec![false; t];
    for a in border.into_iter().filter(|&a| drop[a as usize]) {
        let r = uf.find(a);
        open[r as usize] = true;
    }
    for (a, _) in pairs {
        let r = uf.find(a);
        beside_kept[r as usize] = true;
    }
    let mut restored = 0;
    for ti in 0..t as u32 {
        let r = uf.find(ti) as usize;
        if drop[ti as usize] && beside_kept[r] && !open[r] {
            drop[ti as usize] = false;
            restored += 1;
        }
    }
    restored
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
            colors: Vec::new(),
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
    fn enclosed_pinholes_are_kept_and_border_regions_dropped() {
        // A closed torus with one flagged triangle: a hole enclosed by kept surface, un-flagged.
        let torus = crate::mesh::test_meshes::torus(1.0, 0.3, 12, 8);
        let mut drop = vec![false; torus.triangles.len()];
        drop[7] = true;
        assert_eq!(keep_enclosed_holes(&torus, &mut drop), 1);
        assert!(drop.iter().all(|d| !*d));
        // Every triangle flagged: no kept neighbour (a whole unsupported piece), stays dropped.
        let mut all = vec![true; torus.triangles.len()];
        assert_eq!(keep_enclosed_holes(&torus, &mut all), 0);
        assert!(all.iter().all(|d| *d));
        // An open strip of 3 unit squares along x: the flagged last square reaches the strip's
        // border, so it is a border region and stays dropped.
        let mut vertices = Vec::new();
        for i in 0..=3 {
            vertices.push([i as f64, 0.0, 0.0]);
            vertices.push([i as f64, 1.0, 0.0]);
        }
        let mut triangles = Vec::new();
        for i in 0..3u32 {
            let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
        let strip = TriMesh {
            vertices,
            normals: vec![],
            triangles,
            colors: Vec::new(),
        };
        let mut drop = vec![false, false, false, false, true, true];
        assert_eq!(keep_enclosed_holes(&strip, &mut drop), 0);
        assert_eq!(drop, vec![false, false, false, false, true, true]);
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
            colors: Vec::new(),
        };
        let drop = unsupported_triangles(&mesh, &[[0.3, 0.3, 0.0]], 0.5);
        assert_eq!(drop, vec![false, true]);
        let removed = remove_triangles(&mut mesh, &drop);
        assert_eq!(removed, 1);
        assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    }
}
