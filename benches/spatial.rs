//! Octree vs kiddo k-d tree: build time and the time for every point's radius query
//! (37,706 points uniform on a sphere of radius 0.5 in the unit cube, r ≈ 30 neighbours).
//! Run: `cargo bench --bench spatial -- --warm-up-time 1 --measurement-time 3`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use rbfsurf::geometry::Point3;
use rbfsurf::spatial::{KdTree, Octree, OctreeParams, SpatialIndex};

const N: usize = 37_706;

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn unit(s: &mut u64) -> f64 {
    (splitmix64(s) >> 11) as f64 / (1u64 << 53) as f64
}

fn sphere_points(n: usize) -> Vec<Point3> {
    let mut s = 2024;
    (0..n)
        .map(|_| {
            let z = 2.0 * unit(&mut s) - 1.0;
            let phi = std::f64::consts::TAU * unit(&mut s);
            let rho = (1.0 - z * z).sqrt();
            [
                0.5 + 0.5 * rho * phi.cos(),
                0.5 + 0.5 * rho * phi.sin(),
                0.5 + 0.5 * z,
            ]
        })
        .collect()
}

/// Sum of hits over one `within` query per point (sequential, one thread).
fn all_within(index: &dyn SpatialIndex, pts: &[Point3], r: f64) -> usize {
    let mut buf = Vec::new();
    let mut total = 0;
    for q in pts {
        index.within(q, r, &mut buf);
        total += buf.len();
    }
    total
}

fn bench(c: &mut Criterion) {
    let pts = sphere_points(N);
    // Sphere area π, so a disc of radius r holds about N r² points.
    let r = (30.0 / N as f64).sqrt();
    let kd = KdTree::build(&pts).unwrap();
    eprintln!(
        "r = {r:.5}, mean neighbours = {:.1}",
        all_within(&kd, &pts, r) as f64 / N as f64
    );

    let mut g = c.benchmark_group("build");
    for k in [8, 16, 32] {
        g.bench_function(format!("octree_k{k}"), |b| {
            b.iter(|| Octree::build(black_box(&pts), &OctreeParams { leaf_size: k }).unwrap())
        });
    }
    g.bench_function("kdtree", |b| {
        b.iter(|| KdTree::build(black_box(&pts)).unwrap())
    });
    g.finish();

    let mut g = c.benchmark_group("within_all");
    for k in [8, 16, 32] {
        let tree = Octree::build(&pts, &OctreeParams { leaf_size: k }).unwrap();
        eprintln!("octree K={k}: {:?}", tree.stats());
        g.bench_function(format!("octree_k{k}"), |b| {
            b.iter(|| all_within(&tree, black_box(&pts), r))
        });
    }
    g.bench_function("kdtree", |b| b.iter(|| all_within(&kd, black_box(&pts), r)));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
