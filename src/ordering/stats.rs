//! Shape of the reordered matrix `P A Pᵀ`: bandwidth and Jennings envelope (profile) storage,
//! computed from the pattern of `A` and the permutation without forming `P A Pᵀ`, in `O(nnz + n)`.
//!
//! Reference: Jennings (1966), "A compact storage scheme for the solution of symmetric linear
//! simultaneous equations"; Kojekine et al. (2002), Table 1 ("memory requirement to store the
//! band diagonal sub-matrix", "if stored traditionally" = `n²`).

use sprs::CsMat;

use super::{OrderingError, Permutation};

/// Size figures of `P A Pᵀ` for a symmetric pattern `A` (`n × n`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub struct MatrixShape {
    /// Matrix order `n`.
    pub n: usize,
    /// Stored nonzeros of `A` (both triangles and the diagonal, as given).
    pub nnz: usize,
    /// `max |i − j|` over nonzeros of `P A Pᵀ` (0 for a diagonal or empty matrix).
    pub bandwidth: usize,
    /// Jennings envelope of the lower triangle including the diagonal: `Σ_i (i − f_i + 1)`,
    /// `f_i` = first column with a nonzero in row `i` (at most `i`).
    pub profile_values: usize,
    /// `n²`, the values of a dense ("traditionally stored") matrix.
    pub dense_values: usize,
}

/// Shape of `P A Pᵀ` for `pattern` = `A` (CSR or CSC; values ignored; an unsymmetric pattern is
/// treated as its symmetrisation `A + Aᵀ`) and `perm` (`perm[new] = old`).
///
/// # Errors
/// [`OrderingError::DimensionMismatch`] when `A` is not square or `perm` has another length.
///
/// ```
/// use rbfsurf::ordering::{Permutation, matrix_shape};
/// let mut t = sprs::TriMat::new((3, 3));
/// for (i, j) in [(0, 0), (1, 1), (2, 2), (0, 2), (2, 0)] {
///     t.add_triplet(i, j, 1.0);
/// }
/// let s = matrix_shape(&t.to_csc(), &Permutation::identity(3)).unwrap();
/// assert_eq!((s.bandwidth, s.profile_values, s.dense_values), (2, 1 + 1 + 3, 9));
/// ```
pub fn matrix_shape(
    pattern: &CsMat<f64>,
    perm: &Permutation,
) -> Result<MatrixShape, OrderingError> {
    let (rows, cols) = (pattern.rows(), pattern.cols());
    if rows != cols || perm.len() != rows || perm.inv.len() != rows {
        return Err(OrderingError::DimensionMismatch {
            points: perm.len(),
            rows,
            cols,
        });
    }
    let n = rows;
    // first[i]: first column of new row i in the lower triangle (the diagonal at the latest).
    let mut first: Vec<usize> = (0..n).collect();
    let mut bandwidth = 0usize;
    for (outer, vec) in pattern.outer_iterator().enumerate() {
        let a = perm.inv[outer];
        for &inner in vec.indices() {
            let b = perm.inv[inner];
            let (lo, hi) = if a < b { (a, b) } else { (b, a) };
            bandwidth = bandwidth.max(hi - lo);
            first[hi] = first[hi].min(lo);
        }
    }
    let profile_values = first.iter().enumerate().map(|(i, &f)| i - f + 1).sum();
    Ok(MatrixShape {
        n,
        nnz: pattern.nnz(),
        bandwidth,
        profile_values,
        dense_values: n * n,
    })
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{radius_pattern, shuffled_sphere};
    use super::*;
    use crate::spatial::test_clouds::splitmix64;

    /// Brute force: form the dense permuted matrix and scan it.
    fn dense_shape(pattern: &CsMat<f64>, perm: &Permutation) -> (usize, usize) {
        let n = pattern.rows();
        let mut dense = vec![vec![false; n]; n];
        for (_, (i, j)) in pattern.iter() {
            dense[i][j] = true;
            dense[j][i] = true;
        }
        let mut band = 0;
        let mut profile = 0;
        for new_i in 0..n {
            let mut f = new_i;
            for new_j in 0..n {
                if dense[perm.perm[new_i]][perm.perm[new_j]] {
                    band = band.max(new_i.abs_diff(new_j));
                    if new_j < f {
                        f = new_j;
                    }
                }
            }
            profile += new_i - f + 1;
        }
        (band, profile)
    }

    fn random_perm(n: usize, seed: u64) -> Permutation {
        let mut p: Vec<usize> = (0..n).collect();
        let mut s = seed;
        for i in (1..n).rev() {
            p.swap(i, (splitmix64(&mut s) % (i as u64 + 1)) as usize);
        }
        Permutation::from_perm(p).unwrap()
    }

    #[test]
    fn shape_equals_dense_brute_force() {
        for (n, r, seed) in [(60, 0.3, 1), (120, 0.2, 2), (90, 0.5, 3), (40, 0.05, 4)] {
            let pts = shuffled_sphere(n, seed);
            let pattern = radius_pattern(&pts, r);
            for p in [Permutation::identity(n), random_perm(n, seed + 10)] {
                let s = matrix_shape(&pattern, &p).unwrap();
                let (band, profile) = dense_shape(&pattern, &p);
                assert_eq!((s.bandwidth, s.profile_values), (band, profile));
                assert_eq!((s.n, s.nnz, s.dense_values), (n, pattern.nnz(), n * n));
                let csr = matrix_shape(&pattern.to_csr(), &p).unwrap();
                assert_eq!(csr, s);
            }
        }
    }

    #[test]
    fn diagonal_and_empty_matrices() {
        let mut t = sprs::TriMat::new((4, 4));
        for i in 0..4 {
            t.add_triplet(i, i, 1.0);
        }
        let s = matrix_shape(&t.to_csc(), &Permutation::identity(4)).unwrap();
        assert_eq!((s.bandwidth, s.profile_values, s.dense_values), (0, 4, 16));
        let e = sprs::TriMat::<f64>::new((0, 0)).to_csc();
        assert_eq!(
            matrix_shape(&e, &Permutation::identity(0)).unwrap(),
            MatrixShape::default()
        );
        assert!(matrix_shape(&t.to_csc(), &Permutation::identity(3)).is_err());
    }
}
