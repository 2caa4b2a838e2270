//! Fringes of open scans: pieces of a trimmed surface with no interior, every vertex within
//! [`FRINGE_DEPTH`] support radii of the piece's own border (measured along its edges), that lie
//! beside a piece that stays (within [`FRINGE_REACH`] support radii of it).
//!
//! A single-view range scan leaves such strips where the view grazes the object or jumps in
//! depth: mixed pixels at silhouettes, the few samples of a surface seen edge-on behind an
//! occluding part. The trim keeps what lies within R of a point, so each strip becomes a ribbon
//! about 2R wide, a separate piece beside the scan's sheet. A piece with a point more than 3R
//! inside its border is a scanned surface and stays, however small; so does a shallow piece
//! farther than 4R from every piece that stays (a small separate object: the clusters of the
//! shared `poste_france` scan keep their six pieces, 8R took one of them); the largest piece
//! always stays. Measured on the ten Stanford bunny range views (`x y z`, defaults): 34 pieces
//! → 22, seven of ten views in at most two pieces (bun000: 4 → 2). `O(E log V)` (Dijkstra from
//! the border vertices) plus a k-d tree over the kept vertices.

use crate::geometry::{Point3, TriMesh, dist2};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Pieces whose deepest vertex lies at most this many support radii from their border are
/// fringes (when beside another piece).
pub const FRINGE_DEPTH: f64 = 3.0;

/// A shallow piece is a fringe when one of its vertices lies within this many support radii of a
/// piece that stays; a shallow piece on its own (a small separate object of a scene) stays.
pub const FRINGE_REACH: f64 = 4.0;

/// Per triangle, whether it belongs to a fringe of `mesh` (support radius `radius`, mesh units),
/// and the number of fringe pieces. Closed pieces and the largest piece are never fringes.
pub fn fringes(mesh: &TriMesh, radius: f64) -> (Vec<bool>, usize) {
    let (labels, sizes) = super::topology::triangle_components(mesh);
    let mut drop = vec![false; mesh.triangles.len()];
    if sizes.len() < 2 || radius.is_nan() || radius <= 0.0 {
        return (drop, 0);
    }
    let depth = border_distance(mesh);
    let mut deepest = vec![0.0f64; sizes.len()];
    for (t, &c) in mesh.triangles.iter().zip(&labels) {
        for &v in t {
            deepest[c as usize] = deepest[c as usize].max(depth[v as usize]);
        }
    }
    let largest = (0..sizes.len())
        .max_by_key(|&c| (sizes[c], Reverse(c)))
        .unwrap_or(0);
    let shallow: Vec<bool> = (0..sizes.len())
        .map(|c| c != largest && deepest[c] <= FRINGE_DEPTH * radius)
        .collect();
    let fringe = beside_kept(mesh, &labels, &shallow, FRINGE_REACH * radius);
    for (d, &c) in drop.iter_mut().zip(&labels) {
        *d = fringe[c as usize];
    }
    (drop, fringe.iter().filter(|&&f| f).count())
}

/// Which `shallow` pieces have a vertex within `reach` of a vertex of a piece that is not shallow.
fn beside_kept(mesh: &TriMesh, labels: &[u32], shallow: &[bool], reach: f64) -> Vec<bool> {
    let mut piece = vec![u32::MAX; mesh.vertices.len()];
    for (t, &c) in mesh.triangles.iter().zip(labels) {
        t.iter().for_each(|&v| piece[v as usize] = c);
    }
    let kept: Vec<Point3> = (0..mesh.vertices.len())
        .filter(|&v| piece[v] != u32::MAX && !shallow[piece[v] as usize])
        .map(|v| mesh.vertices[v])
        .collect();
    let mut near = vec![false; shallow.len()];
    let Ok(index) = crate::spatial::build_index(&kept, crate::spatial::IndexKind::KdTree, 16)
    else {
        return near;
    };
    let mut knn = Vec::new();
    for (v, &c) in piece.iter().enumerate() {
        if c == u32::MAX || !shallow[c as usize] || near[c as usize] {
            continue;
        }
        index.nearest_k(&mesh.vertices[v], 1, &mut knn);
        near[c as usize] = knn.first().is_some_and(|&(_, d)| d <= reach);
    }
    near
}

/// Per vertex, the length of the shortest edge path to a border vertex (a vertex of an edge
/// used by one triangle); infinite on pieces without a border and for unused vertices.
fn border_distance(mesh: &TriMesh) -> Vec<f64> {
    let n = mesh.vertices.len();
    let edges = super::topology::collect_edges(&mesh.triangles);
    // Neighbours of each vertex, compressed rows.
    let mut start = vec![0usize; n + 1];
    for e in &edges {
        start[e.lo as usize + 1] += 1;
        start[e.hi as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start[..n].to_vec();
    let mut next = vec![0u32; start[n]];
    for e in &edges {
        for (a, b) in [(e.lo, e.hi), (e.hi, e.lo)] {
            next[fill[a as usize]] = b;
            fill[a as usize] += 1;
        }
    }
    let mut dist = vec![f64::INFINITY; n];
    let mut heap = BinaryHeap::new();
    for e in edges.iter().filter(|e| e.forward + e.backward == 1) {
        for v in [e.lo, e.hi] {
            if dist[v as usize] > 0.0 {
                dist[v as usize] = 0.0;
                heap.push((Reverse(Ordered(0.0)), v));
            }
        }
    }
    while let Some((Reverse(Ordered(d)), v)) = heap.pop() {
        if d > dist[v as usize] {
            continue;
        }
        let p = mesh.vertices[v as usize];
        for &w in &next[start[v as usize]..start[v as usize + 1]] {
            let nd = d + dist2(p, mesh.vertices[w as usize]).sqrt();
            if nd < dist[w as usize] {
                dist[w as usize] = nd;
                heap.push((Reverse(Ordered(nd)), w));
            }
        }
    }
    dist
}

/// A finite f64 ordered by `total_cmp`, for the heap.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Ordered(f64);

impl Eq for Ordered {}

impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point3;

    /// A flat grid sheet of `nx × ny` cells of size `h` in the plane z = 0 from corner `(x0, y0)`,
    /// appended to `mesh`.
    fn sheet(mesh: &mut TriMesh, nx: usize, ny: usize, h: f64, x0: f64, y0: f64) {
        let base = mesh.vertices.len() as u32;
        for j in 0..=ny {
            for i in 0..=nx {
                let p: Point3 = [x0 + i as f64 * h, y0 + j as f64 * h, 0.0];
                mesh.vertices.push(p);
            }
        }
        let id = |i: usize, j: usize| base + (j * (nx + 1) + i) as u32;
        for j in 0..ny {
            for i in 0..nx {
                mesh.triangles
                    .push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                mesh.triangles
                    .push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }

    #[test]
    fn ribbons_beside_the_scan_go_and_patches_with_an_interior_stay() {
        let h = 0.01;
        let mut mesh = TriMesh::default();
        sheet(&mut mesh, 100, 100, h, 0.0, 0.0); // the scan: 1 × 1
        sheet(&mut mesh, 80, 6, h, 1.05, 0.0); // a ribbon 0.06 wide beside it: depth 0.03
        sheet(&mut mesh, 20, 20, h, 1.05, 0.5); // a patch 0.2 wide beside it: depth 0.1
        sheet(&mut mesh, 6, 6, h, 5.0, 0.0); // a small piece far from everything
        let radius = 0.015; // fringes: depth ≤ 0.045, within 0.06 of a piece that stays
        let (drop, n) = fringes(&mesh, radius);
        assert_eq!(n, 1);
        let (labels, _) = crate::mesh::topology::triangle_components(&mesh);
        for (t, &d) in drop.iter().enumerate() {
            assert_eq!(d, labels[t] == 1, "triangle {t}");
        }
        // A radius so large that the patch has no interior either: it goes too (beside the
        // scan), the scan and the far piece stay.
        let (drop, n) = fringes(&mesh, 0.04);
        assert_eq!(n, 2);
        assert!(drop[..20000].iter().all(|&d| !d));
        assert!(drop[drop.len() - 72..].iter().all(|&d| !d));
        // Depth is measured along edges from the border: the grid's centre lies 0.5 inside.
        let depth = border_distance(&mesh);
        assert!(
            (depth[50 * 101 + 50] - 0.5).abs() < 1e-9,
            "{}",
            depth[50 * 101 + 50]
        );
    }
}
