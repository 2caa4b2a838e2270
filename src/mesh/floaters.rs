//! Floaters: connected components that (almost) no data point carries. Each data point is carried
//! by the component of its nearest mesh vertex when that vertex is within `max_distance` (the band
//! of the surface). A component carried by fewer than `min_share` of all points is a floater, unless
//! it owns its data: it carries more than half of the points within `max_distance` of it and at
//! least [`OWNED_MIN_POINTS`] points (a small real object of a scene). So two separate objects each
//! carry their own points and both stay; a blob of the carrier far from the data (no point), a
//! sheet of the carrier beside the real surface (the points near it are carried by the surface) and
//! a blob around a few outliers are dropped. Measured on the shared LiDAR scene `b9_training`:
//! posts and bushes carry 10–170 of 22,300 points (< 1 %) and all or most of the points near them,
//! while the carrier's sheets beside the ground carry 0–35 of the 2–123 points near them.
//!
//! `O(V log V + n log V)` for `V` mesh vertices and `n` points (one k-d tree over the vertices,
//! one over the vertices of the candidate floaters), parallel over the points; integer counts, so
//! the result does not depend on the thread schedule.

use super::topology::triangle_components;
use crate::geometry::{Point3, TriMesh};
use crate::spatial::{KdTree, SpatialIndex};
use rayon::prelude::*;

/// Fewest carried points for a component below the share to count as a small real object.
pub const OWNED_MIN_POINTS: usize = 10;

/// Data support of the connected components of a mesh.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ComponentSupport {
    /// Per triangle, its component (as [`triangle_components`]).
    pub labels: Vec<u32>,
    /// Per component, its triangle count.
    pub triangles: Vec<usize>,
    /// Per component, the data points whose nearest mesh vertex (within the band) is in it.
    pub points: Vec<usize>,
}

/// Counts, per connected component of `mesh`, the `points` whose nearest mesh vertex lies in it and
/// within `max_distance` (same units as the mesh). Points farther than that from every vertex count
/// for no component.
pub fn component_support(mesh: &TriMesh, points: &[Point3], max_distance: f64) -> ComponentSupport {
    let (labels, triangles) = triangle_components(mesh);
    support_of(mesh, (labels, triangles), points, max_distance)
}

/// [`component_support`] for the components `(labels, triangles)` of
/// [`triangle_components`]`(mesh)`.
fn support_of(
    mesh: &TriMesh,
    (labels, triangles): (Vec<u32>, Vec<usize>),
    points: &[Point3],
    max_distance: f64,
) -> ComponentSupport {
    let mut support = vec![0usize; triangles.len()];
    for c in carriers(mesh, &labels, points, max_distance) {
        if c != u32::MAX {
            support[c as usize] += 1;
        }
    }
    ComponentSupport {
        labels,
        triangles,
        points: support,
    }
}

/// Per vertex, the component (triangle label `labels`) it belongs to; `u32::MAX` for unused
/// vertices.
pub(crate) fn vertex_pieces(mesh: &TriMesh, labels: &[u32]) -> Vec<u32> {
    let mut piece = vec![u32::MAX; mesh.vertices.len()];
    for (t, &c) in mesh.triangles.iter().zip(labels) {
        t.iter().for_each(|&v| piece[v as usize] = c);
    }
    piece
}

/// Per point, the component (triangle label `labels`) carrying it: that of its nearest used mesh
/// vertex when within `max_distance`, else `u32::MAX` (also for every point when the vertices
/// cannot be indexed).
pub(crate) fn carriers(
    mesh: &TriMesh,
    labels: &[u32],
    points: &[Point3],
    max_distance: f64,
) -> Vec<u32> {
    let piece = vertex_pieces(mesh, labels);
    let used: Vec<u32> = (0..mesh.vertices.len() as u32)
        .filter(|&v| piece[v as usize] != u32::MAX)
        .collect();
    let positions: Vec<Point3> = used.iter().map(|&v| mesh.vertices[v as usize]).collect();
    let Ok(tree) = KdTree::build(&positions) else {
        return vec![u32::MAX; points.len()];
    };
    (points.par_iter())
        .map(|p| match tree.nearest_one(p) {
            Some((i, d)) if d <= max_distance => piece[used[i as usize] as usize],
            _ => u32::MAX,
        })
        .collect()
}

/// Per triangle: `true` when its component is a floater (see the module doc: carries fewer than
/// `min_share`, a fraction such as 0.01, of `points`, and does not own them: at most half of the
/// points within `max_distance` of it, or fewer than [`OWNED_MIN_POINTS`]); and how many
/// components that is. The best-supported component is never
/// flagged (so the mesh is never emptied); `min_share ≤ 0` flags nothing.
pub fn floaters(
    mesh: &TriMesh,
    points: &[Point3],
    max_distance: f64,
    min_share: f64,
) -> (Vec<bool>, usize) {
    if min_share <= 0.0 || mesh.triangles.is_empty() {
        return (vec![false; mesh.triangles.len()], 0);
    }
    let components = triangle_components(mesh);
    if components.1.len() < 2 {
        // The one component is the best supported one: never a floater.
        return (vec![false; mesh.triangles.len()], 0);
    }
    let s = support_of(mesh, components, points, max_distance);
    let need = min_share * points.len() as f64;
    let best = (0..s.points.len()).fold(0, |b, c| if s.points[c] > s.points[b] { c } else { b });
    let candidate: Vec<bool> = (0..s.points.len())
        .map(|c| c != best && (s.points[c] as f64) < need)
        .collect();
    let near = points_near(mesh, &s.labels, &candidate, points, max_distance);
    let floater: Vec<bool> = (0..s.points.len())
        .map(|c| candidate[c] && (2 * s.points[c] <= near[c] || s.points[c] < OWNED_MIN_POINTS))
        .collect();
    let count = floater.iter().filter(|f| **f).count();
    (
        s.labels.iter().map(|&c| floater[c as usize]).collect(),
        count,
    )
}

/// Per component, how many `points` lie within `max_distance` of one of its vertices; counted for
/// the `candidate` components only (0 for the others).
fn points_near(
    mesh: &TriMesh,
    labels: &[u32],
    candidate: &[bool],
    points: &[Point3],
    max_distance: f64,
) -> Vec<usize> {
    let mut vertex_label = vec![u32::MAX; mesh.vertices.len()];
    for (t, &c) in mesh.triangles.iter().zip(labels) {
        if candidate[c as usize] {
            for &v in t {
                vertex_label[v as usize] = c;
            }
        }
    }
    let used: Vec<u32> = (0..mesh.vertices.len() as u32)
        .filter(|&v| vertex_label[v as usize] != u32::MAX)
        .collect();
    let positions: Vec<Point3> = used.iter().map(|&v| mesh.vertices[v as usize]).collect();
    let n = candidate.len();
    let Ok(tree) = KdTree::build(&positions) else {
        return vec![0; n];
    };
    if positions.is_empty() {
        return vec![0; n];
    }
    points
        .par_iter()
        .fold(
            || (vec![0usize; n], Vec::new(), Vec::new()),
            |(mut count, mut hits, mut seen): (Vec<usize>, Vec<u32>, Vec<u32>), p| {
                tree.within(p, max_distance, &mut hits);
                seen.clear();
                seen.extend(
                    hits.iter()
                        .map(|&i| vertex_label[used[i as usize] as usize]),
                );
                seen.sort_unstable();
                seen.dedup();
                for &c in &seen {
                    count[c as usize] += 1;
                }
                (count, hits, seen)
            },
        )
        .map(|(count, _, _)| count)
        .reduce(
            || vec![0; n],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    *x += y;
                }
                a
            },
        )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tetrahedron of edge ~`size` at `c`, as triangles over vertices starting at `first`.
    fn tet(mesh: &mut TriMesh, c: Point3, size: f64) {
        let f = mesh.vertices.len() as u32;
        for d in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ] {
            mesh.vertices.push([0, 1, 2].map(|k| c[k] + size * d[k]));
        }
        for t in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
            mesh.triangles.push(t.map(|v| f + v));
        }
    }

    #[test]
    fn pieces_without_data_are_floaters_and_carried_pieces_stay() {
        let mut mesh = TriMesh {
            vertices: vec![],
            normals: vec![],
            triangles: vec![],
            colors: Vec::new(),
        };
        tet(&mut mesh, [0.0; 3], 1.0); // carries 60 points
        tet(&mut mesh, [5.0, 0.0, 0.0], 1.0); // carries 40 points: a second object
        tet(&mut mesh, [0.0, 5.0, 0.0], 0.1); // no data near: a floater
        tet(&mut mesh, [1.2, 0.0, 0.0], 0.05); // next to the first, but its points are nearer it
        tet(&mut mesh, [0.0, -3.0, 0.0], 0.1); // a small real object: carries the 12 points near it
        tet(&mut mesh, [0.0, 0.0, -3.0], 0.1); // a blob around 3 outliers
        let mut points = Vec::new();
        for i in 0..60 {
            points.push([0.01 * (i % 7) as f64, 0.0, 0.01 * (i / 7) as f64]);
        }
        for i in 0..40 {
            points.push([5.0 + 0.01 * (i % 5) as f64, 0.0, 0.01 * (i / 5) as f64]);
        }
        points.push([20.0, 20.0, 20.0]); // far from everything: counts for nobody
        // Near the 4th piece (0.12 from it) but nearer to the first piece's vertex (1, 0, 0).
        points.push([1.08, 0.0, 0.0]);
        for k in 0..12 {
            points.push([0.005 * k as f64, -3.0, 0.0]);
        }
        for k in 0..3 {
            points.push([0.01 * k as f64, 0.0, -3.0]);
        }
        // 117 points, all pieces but the first two below 12 %.
        let s = component_support(&mesh, &points, 0.2);
        assert_eq!(s.points, vec![61, 40, 0, 0, 12, 3]);
        assert_eq!(s.triangles, vec![4; 6]);
        let (flag, n) = floaters(&mesh, &points, 0.2, 0.12);
        assert_eq!(n, 3);
        let expect: Vec<bool> = [false, false, true, true, false, true]
            .iter()
            .flat_map(|&f| [f; 4])
            .collect();
        assert_eq!(flag, expect);
        // At 1 % (1.17 points) the 3-outlier blob is above the share and stays.
        assert_eq!(floaters(&mesh, &points, 0.2, 0.01).1, 2);
        // A share above the second object's 40 / 117 makes it a candidate; it owns its points, so
        // it stays; 0 drops nothing.
        assert_eq!(floaters(&mesh, &points, 0.2, 0.5).1, 3);
        assert_eq!(floaters(&mesh, &points, 0.2, 0.0).1, 0);
        // No point near any piece: the mesh is never emptied.
        let (flag, n) = floaters(&mesh, &[[50.0; 3]], 0.2, 0.01);
        assert_eq!((n, flag.iter().filter(|f| !**f).count()), (5, 4));
    }
}
