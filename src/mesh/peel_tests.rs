use super::*;
use crate::mesh::test_meshes::sheet;
use crate::mesh::topology::analyze;
use crate::mesh::trim;

/// Distance from each triangle's centroid to the nearest of `points`, by brute force.
fn centroid_distances(mesh: &TriMesh, points: &[Point3]) -> Vec<f64> {
    (mesh.triangles.iter())
        .map(|t| {
            let c = centroid(mesh, t);
            (points.iter())
                .map(|p| crate::geometry::dist2(*p, c).sqrt())
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

/// Points every 0.25 over the part of `[0, nx] × [0, ny]` where `inside` holds, in z = 0.
fn samples(nx: u32, ny: u32, inside: impl Fn(f64, f64) -> bool) -> Vec<Point3> {
    let mut p = Vec::new();
    for j in 0..=4 * ny {
        for i in 0..=4 * nx {
            let (x, y) = (i as f64 / 4.0, j as f64 / 4.0);
            if inside(x, y) {
                p.push([x, y, 0.0]);
            }
        }
    }
    p
}

/// Brute force: no triangle left that is farther than `max` from the points, with the points
/// within `radius` on one side, could still be collapsed.
fn nothing_left_to_peel(mesh: &TriMesh, points: &[Point3], max: f64, radius: f64) -> bool {
    let adj = neighbours(&mesh.triangles);
    let mut uses = vec![0; mesh.vertices.len()];
    let mut border = vec![false; mesh.vertices.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            uses[tri[k] as usize] += 1;
            if adj[t][k] == NONE {
                border[tri[k] as usize] = true;
                border[tri[(k + 1) % 3] as usize] = true;
            }
        }
    }
    mesh.triangles.iter().enumerate().all(|(t, tri)| {
        let edges: Vec<usize> = (0..3).filter(|&k| adj[t][k] == NONE).collect();
        let collapsible = match edges[..] {
            [k] => !border[tri[(k + 2) % 3] as usize],
            [_, _] => tri.iter().any(|&v| uses[v as usize] == 1),
            _ => false,
        };
        !collapsible || !overhang(mesh, tri, points, max, radius)
    })
}

/// Brute force over all points: the centroid of `tri` is farther than `max` from every point and
/// no point within `radius` lies 135° or more from the nearest one, as seen from the centroid.
fn overhang(mesh: &TriMesh, tri: &[u32; 3], points: &[Point3], max: f64, radius: f64) -> bool {
    let c: [f64; 3] = std::array::from_fn(|k| {
        tri.iter()
            .map(|&v| mesh.vertices[v as usize][k])
            .sum::<f64>()
            / 3.0
    });
    let rel: Vec<([f64; 3], f64)> = (points.iter())
        .map(|p| {
            let d: [f64; 3] = std::array::from_fn(|k| p[k] - c[k]);
            (d, (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
        })
        .collect();
    let Some(&(u, du)) = rel.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
        return true;
    };
    let opposite = rel.iter().any(|(v, l)| {
        *l <= radius && (v[0] * u[0] + v[1] * u[1] + v[2] * u[2]) / (du * l) <= -0.5f64.sqrt()
    });
    du > max && !opposite
}

#[test]
fn a_bridge_between_two_data_patches_thins_but_stays() {
    // Data on the two ends of a 30 × 10 sheet; the middle 14 units carry none.
    let mut mesh = sheet(30, 10, |_, _| true);
    let points = samples(30, 10, |x, _| !(8.0..=22.0).contains(&x));
    let before = analyze(&mesh);
    // Independent truth: the plain trim at the same distance cuts the sheet in two.
    let mut cut = mesh.clone();
    let drop = trim::unsupported_triangles(&cut, &points, 1.5);
    trim::remove_triangles(&mut cut, &drop);
    assert_eq!(analyze(&cut).components, 2);

    let removed = peel_border(&mut mesh, &points, 1.5, 2.0 * 1.5);
    let after = analyze(&mesh);
    assert!(removed > 100, "removed {removed}");
    assert_eq!(after.components, 1);
    assert_eq!(after.boundary_loops, 1);
    assert_eq!(after.euler, before.euler);
    assert_eq!(
        (after.non_manifold_vertices, after.non_manifold_edges),
        (0, 0)
    );
    assert!(nothing_left_to_peel(&mesh, &points, 1.5, 3.0));
    // What is left of the bridge is a thin strip: far fewer than the 280 triangles it had.
    let far = centroid_distances(&mesh, &points)
        .iter()
        .filter(|&&d| d > 1.5)
        .count();
    assert!(far < 60, "{far} triangles left beyond the data");
}

#[test]
fn a_gap_between_data_is_bridged_not_notched() {
    // Data on both sides of a 4-unit gap across a 30 × 10 sheet: its middle has points within the
    // radius 3 on both sides, so it is a gap, not an overhang, and is kept; only the ends of the
    // gap at the sheet's border, where the points lie on the inner side, may be peeled.
    let mut mesh = sheet(30, 10, |_, _| true);
    let points = samples(30, 10, |x, _| !(13.0..=17.0).contains(&x));
    let removed = peel_border(&mut mesh, &points, 1.5, 3.0);
    let after = analyze(&mesh);
    assert_eq!(
        (after.components, after.boundary_loops, after.euler),
        (1, 1, 1)
    );
    assert!(nothing_left_to_peel(&mesh, &points, 1.5, 3.0));
    // The middle of the gap (centroids 13.5 < x < 16.5, 3 < y < 7: 2 × 3 × 4 squares) is whole.
    let middle = |t: &[u32; 3]| {
        let c: [f64; 3] = std::array::from_fn(|k| {
            t.iter().map(|&v| mesh.vertices[v as usize][k]).sum::<f64>() / 3.0
        });
        c[0] > 13.5 && c[0] < 16.5 && c[1] > 3.0 && c[1] < 7.0
    };
    assert_eq!(
        mesh.triangles.iter().filter(|t| middle(t)).count(),
        24,
        "removed {removed}"
    );
}

#[test]
fn an_overhang_beyond_a_disk_of_data_is_peeled_off() {
    let mut mesh = sheet(20, 20, |_, _| true);
    let points = samples(20, 20, |x, y| (x - 10.0).hypot(y - 10.0) <= 5.0);
    let removed = peel_border(&mut mesh, &points, 1.0, 2.0 * 1.0);
    let after = analyze(&mesh);
    assert!(removed > 400, "removed {removed}");
    assert_eq!(
        (after.components, after.boundary_loops, after.euler),
        (1, 1, 1)
    );
    assert!(nothing_left_to_peel(&mesh, &points, 1.0, 2.0));
    let far = centroid_distances(&mesh, &points);
    assert!(
        far.iter().all(|&d| d <= 1.0),
        "max {:?}",
        far.iter().copied().fold(0.0, f64::max)
    );
}

#[test]
fn a_hole_stays_a_hole_while_the_outer_border_is_peeled() {
    // A 20 × 20 sheet with a 6 × 6 hole in the middle; no data within 3 units of the outer edge.
    let hole = |i: u32, j: u32| (7..13).contains(&i) && (7..13).contains(&j);
    let mut mesh = sheet(20, 20, |i, j| !hole(i, j));
    let points = samples(20, 20, |x, y| {
        (3.0..=17.0).contains(&x)
            && (3.0..=17.0).contains(&y)
            && !((7.0..=13.0).contains(&x) && (7.0..=13.0).contains(&y))
    });
    let before = analyze(&mesh);
    assert_eq!((before.boundary_loops, before.euler), (2, 0));
    let removed = peel_border(&mut mesh, &points, 1.0, 2.0 * 1.0);
    let after = analyze(&mesh);
    assert!(removed > 100, "removed {removed}");
    assert_eq!(
        (after.components, after.boundary_loops, after.euler),
        (1, 2, 0)
    );
    assert!(nothing_left_to_peel(&mesh, &points, 1.0, 2.0));
}

#[test]
fn a_closed_mesh_and_a_fin_are_left_alone() {
    let mut torus = crate::mesh::test_meshes::torus(1.0, 0.3, 12, 8);
    let far = [[10.0, 10.0, 10.0]];
    assert_eq!(peel_border(&mut torus, &far, 0.1, 2.0 * 0.1), 0);
    // Three triangles on one edge (non-manifold): none is peeled, nothing panics.
    let mut fin = crate::mesh::test_meshes::fin();
    assert_eq!(peel_border(&mut fin, &far, 0.1, 2.0 * 0.1), 0);
    // No points at all: every triangle is infinitely far, and a single sheet collapses only to
    // what cannot be collapsed further: one triangle is left (a piece never disappears).
    let mut lone = sheet(4, 4, |_, _| true);
    peel_border(&mut lone, &[], 1.0, 2.0);
    assert_eq!(lone.triangles.len(), 1);
}
