//! Block elimination for the doubly bordered CSRBF system with a linear polynomial.
//!
//! Solves `[A P; Pᵀ 0] [λ; v] = [r; 0]` where `A` (n × n, SPD) is already factorised and `P` is the
//! n × 4 polynomial block with rows `[1, x, y, z]`. Following George & Liu (1981) as the seed paper
//! does (Kojekine et al., section 3.2):
//! `W = A⁻¹ P` (4 solves), `u = A⁻¹ r`, `S = Pᵀ W` (4 × 4, SPD when the points are not coplanar),
//! `v = S⁻¹ Pᵀ u`, `λ = u − W v`. Cost: 5 solves with the factor (run in parallel) plus O(n).

use rayon::prelude::*;

use super::{LinalgError, SpdFactor};

/// Solves the bordered system with the factor of `A`; returns `(λ, v)`.
///
/// `poly` holds the n rows `[1, x, y, z]` of `P` (normalised units), `rhs` the n values `r`.
/// The solution satisfies `A λ + P v = r` and `Pᵀ λ = 0`; `v = [c, a_x, a_y, a_z]` are the
/// coefficients of the polynomial `c + a·x`.
///
/// Errors: [`LinalgError::DimensionMismatch`] when `poly` or `rhs` do not have `factor.n()` rows;
/// [`LinalgError::Singular`] when the points are (nearly) coplanar or fewer than 4.
///
/// # Example
/// ```
/// use rbfsurf::linalg::{factorize, solve_bordered, SolverParams};
/// use rbfsurf::progress::NoProgress;
/// // A = identity on the 4 corners of a tetrahedron.
/// let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
/// let a: sprs::CsMat<f64> = sprs::CsMat::eye(4);
/// let (f, _) = factorize(&a, None, &SolverParams::default(), &NoProgress).unwrap();
/// let poly: Vec<[f64; 4]> = pts.iter().map(|p| [1.0, p[0], p[1], p[2]]).collect();
/// // r = 2 + 3x interpolated exactly by the polynomial alone: λ = 0.
/// let r: Vec<f64> = pts.iter().map(|p| 2.0 + 3.0 * p[0]).collect();
/// let (lambda, v) = solve_bordered(f.as_ref(), &poly, &r).unwrap();
/// assert!(lambda.iter().all(|l| l.abs() < 1e-12));
/// assert!((v[0] - 2.0).abs() < 1e-12 && (v[1] - 3.0).abs() < 1e-12);
/// ```
#[allow(clippy::needless_range_loop)] // index loops mirror the matrix formulas
pub fn solve_bordered(
    factor: &dyn SpdFactor,
    poly: &[[f64; 4]],
    rhs: &[f64],
) -> Result<(Vec<f64>, [f64; 4]), LinalgError> {
    let n = factor.n();
    if poly.len() != n {
        return Err(LinalgError::DimensionMismatch {
            what: "polynomial block rows",
            expected: n,
            got: poly.len(),
        });
    }
    if rhs.len() != n {
        return Err(LinalgError::DimensionMismatch {
            what: "right-hand side length",
            expected: n,
            got: rhs.len(),
        });
    }
    // Columns 0..4: W = A⁻¹ P; column 4: u = A⁻¹ r.
    let mut cols: Vec<Vec<f64>> = (0..5)
        .map(|c| {
            if c < 4 {
                poly.iter().map(|row| row[c]).collect()
            } else {
                rhs.to_vec()
            }
        })
        .collect();
    cols.par_iter_mut()
        .try_for_each(|col| factor.solve_checked(col))?;
    let (w, u) = cols.split_at(4);
    let u = &u[0];
    let mut s = [[0.0f64; 4]; 4];
    let mut g = [0.0f64; 4];
    for (row, p) in poly.iter().enumerate() {
        for a in 0..4 {
            for b in 0..4 {
                s[a][b] += p[a] * w[b][row];
            }
            g[a] += p[a] * u[row];
        }
    }
    // Symmetrise (S is symmetric in exact arithmetic).
    for a in 0..4 {
        for b in 0..a {
            let m = 0.5 * (s[a][b] + s[b][a]);
            s[a][b] = m;
            s[b][a] = m;
        }
    }
    let v = super::small::cholesky_solve(&s, &g)?;
    let lambda = (0..n)
        .map(|i| u[i] - (0..4).map(|c| w[c][i] * v[c]).sum::<f64>())
        .collect();
    Ok((lambda, v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::test_support::*;
    use crate::linalg::{SolverKind, SolverParams, factorize};
    use crate::progress::NoProgress;

    fn poly_of(points: &[[f64; 3]]) -> Vec<[f64; 4]> {
        points.iter().map(|p| [1.0, p[0], p[1], p[2]]).collect()
    }

    /// Dense (n + 4) × (n + 4) bordered matrix.
    fn dense_bordered(a: &sprs::CsMat<f64>, poly: &[[f64; 4]]) -> Vec<Vec<f64>> {
        let n = poly.len();
        let mut m = vec![vec![0.0; n + 4]; n + 4];
        for (i, row) in to_dense(a).into_iter().enumerate() {
            m[i][..n].copy_from_slice(&row);
        }
        for (i, p) in poly.iter().enumerate() {
            for c in 0..4 {
                m[i][n + c] = p[c];
                m[n + c][i] = p[c];
            }
        }
        m
    }

    #[test]
    fn bordered_solve_matches_dense_lu_for_every_solver() {
        let n = 90;
        let (pts, a) = test_matrix(n, 15.0, 21);
        let poly = poly_of(&pts);
        let r: Vec<f64> = pts
            .iter()
            .map(|p| (3.0 * p[0]).sin() + p[1] * p[2] - 0.2)
            .collect();
        let mut rhs = r.clone();
        rhs.extend([0.0; 4]);
        let reference = dense_lu_solve(dense_bordered(&a, &poly), rhs);
        for kind in SolverKind::ALL {
            let params = SolverParams {
                kind,
                cg_tolerance: 1e-14,
                ..Default::default()
            };
            let perm = random_perm(n, 3);
            let (f, _) = factorize(&a, Some(&perm), &params, &NoProgress).unwrap();
            let (lambda, v) = solve_bordered(f.as_ref(), &poly, &r).unwrap();
            let mut x = lambda.clone();
            x.extend(v);
            let err = rel_diff(&x, &reference);
            assert!(err < 1e-10, "{kind}: rel diff {err:e}");
            for c in 0..4 {
                let ptl: f64 = poly.iter().zip(&lambda).map(|(p, l)| p[c] * l).sum();
                assert!(ptl.abs() < 1e-10, "{kind}: (Pᵀλ)[{c}] = {ptl:e}");
            }
        }
    }

    #[test]
    fn coplanar_or_too_few_points_are_singular() {
        let n = 60;
        let mut pts = random_points(n, 22);
        for p in &mut pts {
            p[2] = 0.25 + 0.5 * p[0] - 0.3 * p[1];
        }
        let a = wendland_matrix(&pts, radius_for(n, 12.0));
        let (f, _) = factorize(&a, None, &SolverParams::default(), &NoProgress).unwrap();
        let r = test_rhs(n);
        let err = solve_bordered(f.as_ref(), &poly_of(&pts), &r).err();
        assert!(
            matches!(err, Some(LinalgError::Singular { column: 3, .. })),
            "{err:?}"
        );

        let few = random_points(3, 23);
        let a3 = wendland_matrix(&few, 0.5);
        let (f3, _) = factorize(&a3, None, &SolverParams::default(), &NoProgress).unwrap();
        let err = solve_bordered(f3.as_ref(), &poly_of(&few), &[1.0, 2.0, 3.0]).err();
        assert!(matches!(err, Some(LinalgError::Singular { .. })), "{err:?}");
    }

    #[test]
    fn wrong_lengths_are_dimension_errors() {
        let (pts, a) = test_matrix(20, 8.0, 24);
        let (f, _) = factorize(&a, None, &SolverParams::default(), &NoProgress).unwrap();
        let poly = poly_of(&pts);
        assert!(matches!(
            solve_bordered(f.as_ref(), &poly[..19], &[0.0; 20]),
            Err(LinalgError::DimensionMismatch { .. })
        ));
        assert!(matches!(
            solve_bordered(f.as_ref(), &poly, &[0.0; 21]),
            Err(LinalgError::DimensionMismatch { .. })
        ));
    }
}
