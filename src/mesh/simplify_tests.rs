//! Tests of [`super`]: topology kept, tolerance honoured, pieces and seams, flat triangles.
use super::*;
use crate::geometry::{Point3, norm};

/// Splits vertex `v` of a closed mesh into `v` and a new vertex at the same position (as two
/// grid vertices 1e-9 apart are in `f32`): half of its fan moves to the new vertex, two
/// sliver triangles join the halves. Returns the slivers.
fn split_vertex(mesh: &mut TriMesh, v: u32) -> [[u32; 3]; 2] {
    let w = mesh.vertices.len() as u32;
    mesh.vertices.push(mesh.vertices[v as usize]);
    // The fan around v in cyclic order: next[a] = (b, triangle) for each triangle [v, a, b].
    let mut next = HashMap::new();
    for (i, t) in mesh.triangles.iter().enumerate() {
        if let Some(k) = t.iter().position(|&x| x == v) {
            next.insert(t[(k + 1) % 3], (t[(k + 2) % 3], i));
        }
    }
    let first = *next.keys().min().unwrap();
    let (mut a, mut fan) = (first, Vec::new());
    loop {
        let (b, i) = next[&a];
        fan.push((a, i));
        a = b;
        if a == first {
            break;
        }
    }
    let half = fan.len() / 2;
    for &(_, i) in &fan[..half] {
        let t = &mut mesh.triangles[i];
        *t = t.map(|x| if x == v { w } else { x });
    }
    let slivers = [[v, fan[0].0, w], [w, fan[half].0, v]];
    mesh.triangles.extend(slivers);
    slivers
}

#[test]
fn triangles_with_corners_at_one_f32_position_survive_simplification() {
    let mut mesh = sphere(1.0, 24);
    let before_split = analyze(&mesh);
    let slivers = split_vertex(&mut mesh, 300);
    let before = analyze(&mesh);
    assert!(
        before.watertight && before.manifold && before.oriented,
        "{before:?}"
    );
    assert_eq!(before.genus, before_split.genus);
    let n = mesh.triangles.len();
    let stats = simplify_to_tolerance(&mut mesh, 0.01);
    assert!(stats.triangles_after < n * 3 / 4, "{stats:?}");
    assert_eq!(signature(&analyze(&mesh)), signature(&before));
    for s in slivers {
        assert!(mesh.triangles.contains(&s), "sliver {s:?} kept");
    }
}

/// A closed triangulated sphere (latitude–longitude) of radius `r`.
fn sphere(r: f64, n: usize) -> TriMesh {
    let mut vertices: Vec<Point3> = vec![[0.0, 0.0, r], [0.0, 0.0, -r]];
    for i in 1..n {
        let th = std::f64::consts::PI * i as f64 / n as f64;
        for j in 0..2 * n {
            let ph = std::f64::consts::PI * j as f64 / n as f64;
            vertices.push([
                r * th.sin() * ph.cos(),
                r * th.sin() * ph.sin(),
                r * th.cos(),
            ]);
        }
    }
    let ring = |i: usize, j: usize| (2 + (i - 1) * 2 * n + j % (2 * n)) as u32;
    let mut triangles = Vec::new();
    for j in 0..2 * n {
        triangles.push([0, ring(1, j), ring(1, j + 1)]);
        triangles.push([1, ring(n - 1, j + 1), ring(n - 1, j)]);
    }
    for i in 1..n - 1 {
        for j in 0..2 * n {
            triangles.push([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
            triangles.push([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
        }
    }
    TriMesh {
        vertices,
        triangles,
        ..Default::default()
    }
}

#[test]
fn fewer_triangles_same_topology_vertices_unmoved_and_error_within_tolerance() {
    let mut mesh = sphere(1.0, 40);
    let original = mesh.clone();
    let before = analyze(&mesh);
    assert!(before.watertight && before.genus == Some(0));
    let tol = 0.01;
    let stats = simplify_to_tolerance(&mut mesh, tol);
    assert!(
        stats.triangles_after * 3 < stats.triangles_before,
        "{stats:?}"
    );
    assert_eq!(stats.triangles_after, mesh.triangles.len());
    assert_eq!(signature(&analyze(&mesh)), signature(&before));
    assert!(stats.error <= tol && stats.tolerance_used > 0.0);
    assert_eq!(mesh.vertices, original.vertices);
    // Independent check: every triangle's centroid is within about the tolerance (plus the
    // chord of the original tessellation, 1 − cos(π / 40) ≈ 3e-3) of the sphere. The quadric
    // error is an estimate, not a bound: measured 1.4 × the tolerance at worst here.
    let worst = (mesh.triangles.iter())
        .map(|t| {
            let c = [0, 1, 2]
                .map(|k| t.iter().map(|&v| mesh.vertices[v as usize][k]).sum::<f64>() / 3.0);
            1.0 - norm(c)
        })
        .fold(0.0, f64::max);
    assert!(worst < 1.5 * tol + 3.1e-3, "{worst}");
    // A tighter tolerance keeps more triangles.
    let mut fine = original.clone();
    let s2 = simplify_to_tolerance(&mut fine, tol / 10.0);
    assert!(s2.triangles_after > stats.triangles_after);
    // No tolerance: nothing changes.
    let mut same = original.clone();
    simplify_to_tolerance(&mut same, 0.0);
    assert_eq!(same, original);
}

#[test]
fn open_borders_stay_where_they_are() {
    let mut mesh = sphere(1.0, 30);
    // Cut the cap above z = 0.5 away: one boundary loop.
    mesh.triangles
        .retain(|t| t.iter().all(|&v| mesh.vertices[v as usize][2] < 0.5));
    let border = |m: &TriMesh| {
        let mut count = std::collections::HashMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let mut e: Vec<(u32, u32)> = count
            .into_iter()
            .filter(|(_, n)| *n == 1)
            .map(|(e, _)| e)
            .collect();
        e.sort_unstable();
        e
    };
    let before = border(&mesh);
    let stats = simplify_to_tolerance(&mut mesh, 0.02);
    assert!(stats.triangles_after < stats.triangles_before);
    assert_eq!(border(&mesh), before);
    assert_eq!(analyze(&mesh).boundary_loops, 1);
}
