//! Small dense symmetric positive definite systems (the doubly bordered system's 4 × 4 Schur
//! complement, the local carrier's 6 × 6 quadric fits), solved on the stack by Cholesky.

use super::LinalgError;

/// A pivot below this fraction of its diagonal entry counts as singular (in the bordered system:
/// the polynomial columns are numerically dependent, coplanar points).
pub const RELATIVE_PIVOT_TOL: f64 = 1e-10;

/// Solves the `N × N` SPD system `S x = g` by Cholesky (`S` read whole; symmetric) with a
/// relative pivot check: [`LinalgError::Singular`] when a pivot falls below
/// [`RELATIVE_PIVOT_TOL`] of its diagonal entry or is not finite.
#[allow(clippy::needless_range_loop)] // index loops mirror the matrix formulas
pub fn cholesky_solve<const N: usize>(
    s: &[[f64; N]; N],
    g: &[f64; N],
) -> Result<[f64; N], LinalgError> {
    let mut l = [[0.0f64; N]; N];
    for j in 0..N {
        let diag = s[j][j];
        let pivot = diag - (0..j).map(|k| l[j][k] * l[j][k]).sum::<f64>();
        let relative_pivot = if diag > 0.0 { pivot / diag } else { 0.0 };
        if !(relative_pivot > RELATIVE_PIVOT_TOL && pivot.is_finite()) {
            return Err(LinalgError::Singular {
                column: j,
                relative_pivot,
            });
        }
        let ljj = pivot.sqrt();
        l[j][j] = ljj;
        for i in j + 1..N {
            l[i][j] = (s[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>()) / ljj;
        }
    }
    let mut y = [0.0f64; N];
    for i in 0..N {
        y[i] = (g[i] - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
    }
    let mut x = [0.0f64; N];
    for i in (0..N).rev() {
        x[i] = (y[i] - (i + 1..N).map(|k| l[k][i] * x[k]).sum::<f64>()) / l[i][i];
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_6x6_spd_system_and_refuses_a_singular_one() {
        let mut m = [[0.0; 6]; 6];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = 1.0 / (1.0 + i as f64 + j as f64) + if i == j { 1.0 } else { 0.0 };
            }
        }
        let x = [1.0, -2.0, 3.0, 0.5, -0.25, 2.0];
        let b: [f64; 6] = std::array::from_fn(|i| (0..6).map(|j| m[i][j] * x[j]).sum());
        let y = cholesky_solve(&m, &b).unwrap();
        for i in 0..6 {
            assert!((x[i] - y[i]).abs() < 1e-12, "{i}: {} vs {}", x[i], y[i]);
        }
        let mut singular = m;
        singular[5] = singular[4];
        for row in singular.iter_mut() {
            row[5] = row[4];
        }
        assert!(matches!(
            cholesky_solve(&singular, &b),
            Err(LinalgError::Singular { column: 5, .. })
        ));
    }
}
