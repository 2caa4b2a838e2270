use super::*;

use crate::mesh::test_meshes::{cube, merge, torus};
use crate::mesh::topology::analyze;

fn shifted(mut m: TriMesh, d: Point3) -> TriMesh {
    m.vertices.iter_mut().for_each(|p| *p = add(*p, d));
    m
}

#[test]
fn a_thin_handle_is_cut_along_its_shortest_loop() {
    // Tube radius 0.05: the meridian is 2π · 0.05 ≈ 0.31 (0.306 as a 12-gon).
    let mut m = torus(1.0, 0.05, 96, 12);
    assert_eq!(analyze(&m).genus, Some(1));
    let s = remove_small_handles(&mut m, 0.5);
    assert_eq!(s.removed, 1, "{s:?}");
    let t = analyze(&m);
    assert!(t.watertight && t.manifold && t.oriented, "{t:?}");
    assert_eq!((t.genus, t.components), (Some(0), 1), "{t:?}");
    let l = s.loop_lengths[0];
    assert!((0.30..0.32).contains(&l), "loop {l}");
    // The caps close the tube where the band was cut: the mesh stays within the torus.
    for p in &m.vertices {
        let rho = (p[0] * p[0] + p[1] * p[1]).sqrt();
        assert!(((rho - 1.0).powi(2) + p[2] * p[2]).sqrt() <= 0.05 + 1e-9);
    }
}

#[test]
fn handles_with_longer_loops_and_spheres_are_left_alone() {
    for (mut m, max_loop) in [
        (torus(1.0, 0.05, 96, 12), 0.25), // the meridian 0.306 is longer
        (torus(1.0, 0.4, 64, 24), 1.0),   // meridian 2.5, longitude 3.8
        (cube([0.0; 3], 1.0), 10.0),      // genus 0: nothing to cut
    ] {
        let before = m.clone();
        let s = remove_small_handles(&mut m, max_loop);
        assert_eq!((s.removed, s.kept), (0, 0), "{s:?}");
        assert_eq!(m.triangles, before.triangles);
        assert_eq!(m.vertices, before.vertices);
    }
}

#[test]
fn only_the_small_handle_of_two_is_cut_and_a_mesh_with_a_border_is_left_alone() {
    let thin = torus(1.0, 0.05, 96, 12);
    let fat = shifted(torus(1.0, 0.4, 64, 24), [5.0, 0.0, 0.0]);
    let mut m = merge(&thin, &fat);
    let s = remove_small_handles(&mut m, 0.5);
    assert_eq!(s.removed, 1);
    let t = analyze(&m);
    assert_eq!(
        (t.genus, t.components, t.watertight),
        (Some(1), 2, true),
        "{t:?}"
    );
    // Every triangle of the fat torus is still there.
    let shift = thin.vertices.len() as u32;
    for f in &fat.triangles {
        let f = [f[0] + shift, f[1] + shift, f[2] + shift];
        assert!(m.triangles.contains(&f));
    }
    let mut open = torus(1.0, 0.05, 96, 12);
    open.triangles.pop();
    let before = open.triangles.clone();
    assert_eq!(remove_small_handles(&mut open, 0.5), HandleStats::default());
    assert_eq!(open.triangles, before);
}

#[test]
fn the_cut_is_the_same_whatever_the_thread_count() {
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut m = merge(
            &torus(1.0, 0.05, 96, 12),
            &shifted(torus(0.5, 0.03, 64, 10), [3.0, 0.0, 0.0]),
        );
        let s = pool.install(|| remove_small_handles(&mut m, 0.5));
        (s, m.triangles, m.vertices)
    };
    let (a, b) = (run(1), run(3));
    assert_eq!(a.0.removed, 2);
    assert_eq!(a, b);
}

#[test]
fn the_region_around_several_sources_is_the_union_of_their_balls() {
    let m = torus(1.0, 0.3, 48, 16);
    let adj = Adjacency::new(&m).unwrap();
    let sources = [0u32, 5, 300, 301, 700];
    let radius = 0.45;
    let region = around(&m, &adj, &sources, radius);
    // Brute force: one Dijkstra per source, the union of what each reaches.
    let mut ball = Ball::new(m.vertices.len(), adj.tris.len());
    let mut union: Vec<u32> = Vec::new();
    for &s in &sources {
        ball.dijkstra(&m, &adj, s, radius);
        union.extend(&ball.inside);
    }
    union.sort_unstable();
    union.dedup();
    assert_eq!(region, union);
    assert!(region.len() > sources.len() && region.len() < m.vertices.len());
}

#[test]
fn thin_handles_side_by_side_are_all_cut() {
    // Five thin tori in a row, 0.17 apart at their closest (nearer than a ball's radius): one cut
    // each, checked together, and no later round undoes or repeats one.
    let mut m = torus(0.5, 0.04, 64, 10);
    for k in 1..5 {
        m = merge(
            &m,
            &shifted(torus(0.5, 0.04, 64, 10), [1.25 * k as f64, 0.0, 0.0]),
        );
    }
    assert_eq!(analyze(&m).genus, Some(5));
    let s = remove_small_handles(&mut m, 0.5);
    assert_eq!((s.removed, s.kept), (5, 0), "{s:?}");
    let t = analyze(&m);
    assert!(t.watertight && t.manifold && t.oriented, "{t:?}");
    assert_eq!((t.genus, t.components), (Some(0), 5), "{t:?}");
}
