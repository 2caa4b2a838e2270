//! Factorisation benchmark: envelope (RCM) vs faer sparse (AMD) vs sprs-ldl (RCM) on Wendland C2
//! matrices from points on a sphere of radius 0.5 with about 30 neighbours per point
//! (N = 1487 as in the seed paper's Table 1, and N = 10,000).
//!
//! Run: `cargo bench --bench solvers -- --warm-up-time 1 --measurement-time 3`.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use rbfsurf::linalg::{SolverKind, SolverParams, factorize, residual};
use rbfsurf::progress::NoProgress;
use sprs::{CsMat, TriMat};

/// splitmix64 step.
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `n` points uniform on the sphere of radius 0.5 (seeded).
fn sphere_points(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut s = seed;
    let mut unit = || (splitmix64(&mut s) >> 11) as f64 / (1u64 << 53) as f64;
    (0..n)
        .map(|_| {
            let z = 2.0 * unit() - 1.0;
            let phi = 2.0 * std::f64::consts::PI * unit();
            let r = (1.0 - z * z).sqrt();
            [0.5 * r * phi.cos(), 0.5 * r * phi.sin(), 0.5 * z]
        })
        .collect()
}

/// Full symmetric Wendland C2 matrix; support R = sqrt(k / n) gives about k neighbours on the
/// sphere of area π. Points are bucketed along z so assembly is not O(n²) at 10k.
fn wendland_matrix(points: &[[f64; 3]], neighbours: f64) -> CsMat<f64> {
    let n = points.len();
    let radius = (neighbours / n as f64).sqrt();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| points[a][2].total_cmp(&points[b][2]));
    let mut t = TriMat::new((n, n));
    for (pos, &i) in order.iter().enumerate() {
        for &j in &order[pos..] {
            if points[j][2] - points[i][2] > radius {
                break;
            }
            let d = (0..3)
                .map(|k| (points[i][k] - points[j][k]).powi(2))
                .sum::<f64>()
                .sqrt();
            let r = d / radius;
            if r < 1.0 {
                let v = (1.0 - r).powi(4) * (4.0 * r + 1.0);
                t.add_triplet(i, j, v);
                if i != j {
                    t.add_triplet(j, i, v);
                }
            }
        }
    }
    t.to_csc()
}

fn bench_solvers(c: &mut Criterion) {
    let mut group = c.benchmark_group("factorize");
    group.sample_size(10);
    // (points, neighbours): the second case has an RCM envelope close to the seed's 426,811 values.
    for (n, k) in [(1487usize, 30.0), (1487, 95.0), (10_000, 30.0)] {
        let a = wendland_matrix(&sphere_points(n, 42), k);
        let rcm = sprs::linalg::reverse_cuthill_mckee(a.view()).perm.vec();
        let b: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64).collect();
        for kind in SolverKind::ALL {
            let params = SolverParams {
                kind,
                ..Default::default()
            };
            let perm = (kind != SolverKind::Sparse).then_some(rcm.as_slice());
            let (f, stats) = factorize(&a, perm, &params, &NoProgress).expect("SPD");
            let mut x = b.clone();
            f.solve_in_place(&mut x);
            let (rms, max) = residual(&a, &x, &b);
            eprintln!(
                "n {n} k {k} nnz(A) {} {kind}: factor values {} symbolic {:.4} s numeric {:.4} s residual rms {rms:.2e} max {max:.2e}",
                a.nnz(),
                stats.factor_values,
                stats.symbolic_s,
                stats.numeric_s
            );
            if kind == SolverKind::Ldl && stats.numeric_s > 10.0 {
                continue;
            }
            group.bench_with_input(
                BenchmarkId::new(kind.name(), format!("{n}/k{k}")),
                &n,
                |bch, _| {
                    bch.iter(|| factorize(black_box(&a), perm, &params, &NoProgress).expect("SPD"))
                },
            );
        }
    }
    group.finish();
}

criterion_group!(benches, bench_solvers);
criterion_main!(benches);
