//! Seeded test point clouds (splitmix64) and the brute-force comparison used by the index tests.

use crate::geometry::Point3;

use super::{SpatialIndex, brute_force};

/// splitmix64 step.
pub(crate) fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Uniform in `[0, 1)`.
pub(crate) fn unit(state: &mut u64) -> f64 {
    (splitmix64(state) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// `n` points uniform in the unit cube.
pub(crate) fn uniform_cube(n: usize, seed: u64) -> Vec<Point3> {
    let mut s = seed;
    (0..n)
        .map(|_| [unit(&mut s), unit(&mut s), unit(&mut s)])
        .collect()
}

/// `n` points uniform on the sphere of radius 0.5 centred at (0.5, 0.5, 0.5).
pub(crate) fn sphere_surface(n: usize, seed: u64) -> Vec<Point3> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            let z = 2.0 * unit(&mut s) - 1.0;
            let phi = std::f64::consts::TAU * unit(&mut s);
            let rho = (1.0 - z * z).max(0.0).sqrt();
            [
                0.5 + 0.5 * rho * phi.cos(),
                0.5 + 0.5 * rho * phi.sin(),
                0.5 + 0.5 * z,
            ]
        })
        .collect()
}

/// `n` points in a few tight clusters (spread 1e-3) at random centres.
pub(crate) fn clustered(n: usize, seed: u64) -> Vec<Point3> {
    let mut s = seed;
    let centres = uniform_cube(5, seed ^ 77);
    (0..n)
        .map(|i| {
            let c = centres[i % centres.len()];
            [
                c[0] + 1e-3 * unit(&mut s),
                c[1] + 1e-3 * unit(&mut s),
                c[2] + 1e-3 * unit(&mut s),
            ]
        })
        .collect()
}

/// `n` points drawn from only 7 distinct locations (heavy duplicates).
pub(crate) fn duplicates(n: usize, seed: u64) -> Vec<Point3> {
    let base = uniform_cube(7, seed);
    (0..n).map(|i| base[(i * 5) % 7]).collect()
}

/// `n` points on the plane z = 0.25 (x, y uniform).
pub(crate) fn planar(n: usize, seed: u64) -> Vec<Point3> {
    let mut s = seed;
    (0..n).map(|_| [unit(&mut s), unit(&mut s), 0.25]).collect()
}

/// `n` points on a line along x.
pub(crate) fn line(n: usize, seed: u64) -> Vec<Point3> {
    let mut s = seed;
    (0..n).map(|_| [unit(&mut s), 0.5, 0.5]).collect()
}

/// All the test clouds, named.
pub(crate) fn all_clouds(n: usize, seed: u64) -> Vec<(&'static str, Vec<Point3>)> {
    vec![
        ("uniform", uniform_cube(n, seed)),
        ("sphere", sphere_surface(n, seed)),
        ("clustered", clustered(n, seed)),
        ("duplicates", duplicates(n, seed)),
        ("planar", planar(n, seed)),
        ("line", line(n, seed)),
        ("identical", vec![[0.3, 0.6, 0.9]; n]),
        ("empty", Vec::new()),
        ("single", vec![[0.1, 0.2, 0.3]]),
    ]
}

/// Query points: some data points, some random points in and well outside the unit cube.
pub(crate) fn queries(pts: &[Point3], seed: u64) -> Vec<Point3> {
    let mut s = seed;
    let mut q: Vec<Point3> = pts
        .iter()
        .step_by(pts.len().max(1) / 8 + 1)
        .copied()
        .collect();
    for _ in 0..8 {
        q.push([unit(&mut s), unit(&mut s), unit(&mut s)]);
        q.push([3.0 * unit(&mut s) - 1.0, -0.7, 2.0 * unit(&mut s)]);
    }
    q
}

/// Compare `within` (as a set) and `nearest_k` (distances equal; every index at its distance)
/// of `index` with brute force over `pts`.
pub(crate) fn assert_matches_brute_force(
    index: &dyn SpatialIndex,
    pts: &[Point3],
    name: &str,
    seed: u64,
) {
    assert_eq!(index.len(), pts.len(), "{name}: len");
    let (mut got, mut want) = (Vec::new(), Vec::new());
    let (mut gk, mut wk) = (Vec::new(), Vec::new());
    for q in queries(pts, seed) {
        for r in [0.0, 1e-9, 1e-4, 0.01, 0.05, 0.2, 0.7, 3.0] {
            index.within(&q, r, &mut got);
            brute_force::within(pts, &q, r, &mut want);
            got.sort_unstable();
            assert_eq!(got, want, "{name}: within q={q:?} r={r}");
        }
        for k in [0, 1, 2, 7, 30, pts.len() + 3] {
            index.nearest_k(&q, k, &mut gk);
            brute_force::nearest_k(pts, &q, k, &mut wk);
            assert_eq!(gk.len(), wk.len(), "{name}: knn len q={q:?} k={k}");
            let mut seen = std::collections::HashSet::new();
            for (g, w) in gk.iter().zip(&wk) {
                assert_eq!(g.1, w.1, "{name}: knn distance q={q:?} k={k}");
                let p = pts[g.0 as usize];
                assert_eq!(
                    crate::geometry::dist2(p, q).sqrt(),
                    g.1,
                    "{name}: knn index"
                );
                assert!(seen.insert(g.0), "{name}: repeated index");
            }
        }
    }
}
