//! Fringes of open scans: pieces of a trimmed surface with no interior, every vertex within
//! [`FRINGE_DEPTH`] support radii of the piece's own border (measured along its edges), that lie
//! beside a piece that stays (within [`FRINGE_REACH`] support radii of it) and hold no data of
//! their own (no point they carry farther than [`OWN_DATA_GAP`] support radii from every point
//! the staying pieces carry).
//!
//! A single-view range scan leaves such strips where the view grazes the object or jumps in
//! depth: mixed pixels at silhouettes, the few samples of a surface seen edge-on behind an
//! occluding part. The trim keeps what lies within R of a point, so each strip becomes a ribbon
//! about 2R wide, a separate piece beside the scan's sheet. A piece with a point more than 3R
//! inside its border is a scanned surface and stays, however small; so does a shallow piece
//! farther than 4R from every piece that stays (a small separate object: the clusters of the
//! shared `poste_france` scan keep their six pieces, 8R took one of them); the largest piece
//! always stays. A shallow piece nearer than that stays too when the data under it are a piece
//! of their own: every point it carries lies more than [`OWN_DATA_GAP`] support radii from the
//! points the staying pieces carry (a narrow strip of surface seen across a depth jump), while a
//! ribbon of the scan's own silhouette carries points next to the sheet's. Measured with
//! defaults (`x y z`, scan pieces from `benches/range_pieces.py`; the shared scans by looking at
//! the points under each piece): strips on a sheet's own scan piece (the ten Stanford bunny range
//! views: silhouettes of feet, nose, ear tips) lie 1.8–3.5 R from the sheet's data; pieces with
//! data of their own 3.7–4.8 R (bunny views: the 33-, 462- and 102-point scan pieces; the shared
//! `hippo1` and `hippo2`: a leg scanned apart from the body, 314–326 points, and an 84-point
//! patch by the head). Two pieces of the outdoor scene `b9_training` that have data of their own
//! (a gable and a roof face, 63 and 135 points) lie 3.1 and 3.6 R from the ground's data and are
//! dropped; a gap that separates them would also keep the bunny's strips.
//! `O(E log V)`
//! (Dijkstra from the border vertices) plus k-d trees over the kept vertices, the mesh's vertices
//! and the kept pieces' points.

use crate::geometry::{Point3, TriMesh, dist2};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Pieces whose deepest vertex lies at most this many support radii from their border are
/// fringes (when beside another piece).
pub const FRINGE_DEPTH: f64 = 3.0;

/// A shallow piece is a fringe when one of its vertices lies within this many support radii of a
/// piece that stays; a shallow piece on its own (a small separate object of a scene) stays.
pub const FRINGE_REACH: f64 = 4.0;

/// A shallow piece beside a staying one still stays when every point it carries (a point whose
/// nearest mesh vertex is in it, within one support radius) lies farther than this many support
/// radii from every point a staying piece carries, and it carries at least
/// [`super::floaters::OWNED_MIN_POINTS`]: the data under it are cut from the rest by a gap (see
/// the module doc for the measurements behind 3.6).
pub const OWN_DATA_GAP: f64 = 3.6;

/// Per triangle, whether it belongs to a fringe of `mesh` made from `points` (support radius
/// `radius`, mesh units), and the number of fringe pieces. Closed pieces and the largest piece
/// are never fringes.
pub fn fringes(mesh: &TriMesh, points: &[Point3], radius: f64) -> (Vec<bool>, usize) {
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
    let mut fringe = beside_kept(mesh, &labels, &shallow, FRINGE_REACH * radius);
    if fringe.iter().any(|&f| f) {
        for c in own_data(mesh, &labels, &shallow, &fringe, points, radius) {
            fringe[c] = false;
        }
    }
    for (d, &c) in drop.iter_mut().zip(&labels) {
        *d = fringe[c as usize];
    }
    (drop, fringe.iter().filter(|&&f| f).count())
}

/// Which `shallow` pieces have a vertex within `reach` of a vertex of a piece that is not shallow.
fn beside_kept(mesh: &TriMesh, labels: &[u32], shallow: &[bool], reach: f64) -> Vec<bool> {
    let piece = super::floaters::vertex_pieces(mesh, labels);
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

/// The `candidates` (shallow pieces beside a staying one) that carry data of their own: at
/// least [`super::floaters::OWNED_MIN_POINTS`] of `points` have their nearest mesh vertex in the
/// piece within `radius`, and all of them lie farther than [`OWN_DATA_GAP`] `· radius` from
/// every point whose nearest vertex (within `radius`) is in a piece that is not `shallow`.
fn own_data(
    mesh: &TriMesh,
    labels: &[u32],
    shallow: &[bool],
    candidates: &[bool],
    points: &[Point3],
    radius: f64,
) -> Vec<usize> {
    use crate::spatial::{IndexKind, build_index};
    // The piece carrying each point (u32::MAX: none within `radius`).
    let carrier = super::floaters::carriers(mesh, labels, points, radius);
    let kept: Vec<Point3> = (points.iter().zip(&carrier))
        .filter(|&(_, &c)| c != u32::MAX && !shallow[c as usize])
        .map(|(p, _)| *p)
        .collect();
    let Ok(kept) = build_index(&kept, IndexKind::KdTree, 16) else {
        return Vec::new();
    };
    let gap = OWN_DATA_GAP * radius;
    let mut carried = vec![0usize; candidates.len()];
    let mut near = vec![false; candidates.len()];
    let mut knn = Vec::new();
    for (p, &c) in points.iter().zip(&carrier) {
        if c == u32::MAX || !candidates[c as usize] || near[c as usize] {
            continue;
        }
        carried[c as usize] += 1;
        kept.nearest_k(p, 1, &mut knn);
        near[c as usize] = knn.first().is_none_or(|&(_, d)| d <= gap);
    }
    (0..candidates.len())
        .filter(|&c| candidates[c] && !near[c] && carried[c] >= super::floaters::OWNED_MIN_POINTS)
        .collect()
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
        let (drop, n) = fringes(&mesh, &[], radius);
        assert_eq!(n, 1);
        let (labels, _) = crate::mesh::topology::triangle_components(&mesh);
        for (t, &d) in drop.iter().enumerate() {
            assert_eq!(d, labels[t] == 1, "triangle {t}");
        }
        // A radius so large that the patch has no interior either: it goes too (beside the
        // scan), the scan and the far piece stay.
        let (drop, n) = fringes(&mesh, &[], 0.04);
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

    #[test]
    fn a_strip_with_data_of_its_own_stays_and_a_ribbon_of_the_sheets_data_goes() {
        let h = 0.01;
        let mut mesh = TriMesh::default();
        sheet(&mut mesh, 100, 100, h, 0.0, 0.0); // the scan: 1 × 1, its points at its vertices
        let mut points: Vec<Point3> = mesh.vertices.clone();
        // A ribbon 0.03 beside the sheet's right edge, carrying only points along its near edge
        // (0.03 from the sheet's points: the sheet's own silhouette).
        sheet(&mut mesh, 60, 6, h, 1.03, 0.2);
        points.extend((0..=60).map(|i| [1.03 + i as f64 * h, 0.2, 0.0]));
        // A strip 0.05 above the sheet's top edge with points on all but its nearest row (0.06
        // from the sheet's points, 4 R: more than the gap of 3.6 R, a piece of surface of its
        // own, as the bunny views' and the hippos' pieces at 3.7–4.8 R).
        sheet(&mut mesh, 60, 6, h, 0.2, 1.05);
        points.extend(
            (0..=60)
                .flat_map(|i| (1..=6).map(move |j| (i, j)))
                .map(|(i, j)| [0.2 + i as f64 * h, 1.05 + j as f64 * h, 0.0]),
        );
        let radius = 0.015; // both shallow (depth 0.03 ≤ 0.045) and within 0.06 of the sheet
        let (labels, _) = crate::mesh::topology::triangle_components(&mesh);
        // Without the points both are fringes.
        let (_, n) = fringes(&mesh, &[], radius);
        assert_eq!(n, 2);
        let (drop, n) = fringes(&mesh, &points, radius);
        assert_eq!(n, 1);
        for (t, &d) in drop.iter().enumerate() {
            assert_eq!(d, labels[t] == labels[20000], "triangle {t}");
        }
        assert_ne!(labels[20000], labels[0]);
        // Fewer than ten points of its own are not enough to keep the strip.
        let few: Vec<Point3> = (points[..points.len() - 61 * 6].iter())
            .copied()
            .chain((0..9).map(|i| [0.2 + 6.0 * i as f64 * h, 1.1, 0.0]))
            .collect();
        assert_eq!(fringes(&mesh, &few, radius).1, 2);
    }
}
