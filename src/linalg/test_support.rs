//! Test helpers shared by the linalg tests: a seeded RNG, Wendland test matrices and dense
//! reference solvers (Cholesky and Gaussian elimination with partial pivoting), O(n³).

use sprs::{CsMat, TriMat};

/// splitmix64 (Steele, Lea & Flood 2014): a tiny seeded generator.
pub(crate) struct SplitMix64(pub u64);

impl SplitMix64 {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    pub(crate) fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in 0..n.
    pub(crate) fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}

/// `n` random points in the unit cube.
pub(crate) fn random_points(n: usize, seed: u64) -> Vec<[f64; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64()])
        .collect()
}

/// Wendland C2 kernel φ(r) = (1 − r)⁴₊ (4r + 1).
pub(crate) fn wendland(r: f64) -> f64 {
    if r >= 1.0 {
        0.0
    } else {
        (1.0 - r).powi(4) * (4.0 * r + 1.0)
    }
}

/// Full symmetric CSC matrix A_ij = φ(|p_i − p_j| / radius) (brute force O(n²)).
pub(crate) fn wendland_matrix(points: &[[f64; 3]], radius: f64) -> CsMat<f64> {
    let n = points.len();
    let mut t = TriMat::new((n, n));
    for i in 0..n {
        for j in 0..n {
            let d = (0..3)
                .map(|k| (points[i][k] - points[j][k]).powi(2))
                .sum::<f64>()
                .sqrt();
            let v = wendland(d / radius);
            if v > 0.0 {
                t.add_triplet(i, j, v);
            }
        }
    }
    t.to_csc()
}

/// Support radius giving about `k` neighbours for `n` uniform points in the unit cube.
pub(crate) fn radius_for(n: usize, k: f64) -> f64 {
    (3.0 * k / (4.0 * std::f64::consts::PI * n as f64)).cbrt()
}

/// Wendland test matrix on `n` random points with ~`k` neighbours.
pub(crate) fn test_matrix(n: usize, k: f64, seed: u64) -> (Vec<[f64; 3]>, CsMat<f64>) {
    let pts = random_points(n, seed);
    let a = wendland_matrix(&pts, radius_for(n, k));
    (pts, a)
}

/// Dense row-major copy of a sparse matrix.
pub(crate) fn to_dense(a: &CsMat<f64>) -> Vec<Vec<f64>> {
    let mut d = vec![vec![0.0; a.cols()]; a.rows()];
    for (v, (i, j)) in a.iter() {
        d[i][j] = *v;
    }
    d
}

/// Dense Cholesky solve of an SPD system; `None` if a pivot is not positive.
#[allow(clippy::needless_range_loop)] // index loops mirror the matrix formulas
pub(crate) fn dense_cholesky_solve(a: &[Vec<f64>], b: &[f64]) -> Option<Vec<f64>> {
    let n = a.len();
    let mut l = vec![vec![0.0; n]; n];
    for j in 0..n {
        let mut d = a[j][j];
        for k in 0..j {
            d -= l[j][k] * l[j][k];
        }
        if d <= 0.0 {
            return None;
        }
        l[j][j] = d.sqrt();
        for i in j + 1..n {
            let mut s = a[i][j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s / l[j][j];
        }
    }
    let mut y = b.to_vec();
    for i in 0..n {
        for k in 0..i {
            y[i] -= l[i][k] * y[k];
        }
        y[i] /= l[i][i];
    }
    for i in (0..n).rev() {
        for k in i + 1..n {
            y[i] -= l[k][i] * y[k];
        }
        y[i] /= l[i][i];
    }
    Some(y)
}

/// Dense Gaussian elimination with partial pivoting (any non-singular system).
#[allow(clippy::needless_range_loop)] // index loops mirror the matrix formulas
pub(crate) fn dense_lu_solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let n = a.len();
    for c in 0..n {
        let p = (c..n)
            .max_by(|&x, &y| a[x][c].abs().total_cmp(&a[y][c].abs()))
            .expect("non-empty");
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            if f != 0.0 {
                for k in c..n {
                    a[r][k] -= f * a[c][k];
                }
                b[r] -= f * b[c];
            }
        }
    }
    for r in (0..n).rev() {
        for k in r + 1..n {
            b[r] -= a[r][k] * b[k];
        }
        b[r] /= a[r][r];
    }
    b
}

/// Random permutation of 0..n (Fisher–Yates).
pub(crate) fn random_perm(n: usize, seed: u64) -> Vec<usize> {
    let mut rng = SplitMix64(seed);
    let mut p: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        p.swap(i, rng.below(i + 1));
    }
    p
}

/// The three orderings every solver is tested with: identity, reversed, random.
pub(crate) fn orderings(n: usize) -> Vec<(&'static str, Option<Vec<usize>>)> {
    vec![
        ("identity", None),
        ("reversed", Some((0..n).rev().collect())),
        ("random", Some(random_perm(n, 7))),
    ]
}

/// max |x − y| / max |y|.
pub(crate) fn rel_diff(x: &[f64], y: &[f64]) -> f64 {
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-300);
    x.iter()
        .zip(y)
        .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()))
        / scale
}

/// A right-hand side with varied entries.
pub(crate) fn test_rhs(n: usize) -> Vec<f64> {
    (0..n)
        .map(|i| 1.0 + (i % 7) as f64 - 0.3 * (i % 3) as f64)
        .collect()
}
