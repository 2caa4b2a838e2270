//! Reverse Cuthill–McKee ordering of a symmetric sparsity pattern, via
//! `sprs::linalg::reverse_cuthill_mckee` (pseudo-peripheral start vertices).
//! Reference: Cuthill & McKee (1969); George & Liu (1981), "Computer Solution of Large Sparse
//! Positive Definite Systems", chapter 4. Cost `O(nnz · log(max degree))` plus an
//! `O(nnz · log(degree))` structural-symmetry check.
//!
//! Direction: sprs's `transform_mat_papt(a, ord.perm.view())` puts old row `ord.perm.vec()[k]` at
//! new position `k`, so `ord.perm.vec()` is exactly our `perm[new] = old` (checked by a test that
//! compares bandwidths both ways).

use sprs::CsMat;

use super::{OrderingError, Permutation};

/// RCM permutation of the square, structurally symmetric `pattern` (values ignored).
///
/// # Errors
/// [`OrderingError::DimensionMismatch`] for a non-square pattern,
/// [`OrderingError::NotSymmetric`] when some entry `(i, j)` has no `(j, i)`.
///
/// ```
/// use rbfsurf::ordering::rcm_order;
/// let mut t = sprs::TriMat::new((3, 3));
/// for (i, j) in [(0, 0), (1, 1), (2, 2), (0, 1), (1, 0)] {
///     t.add_triplet(i, j, 1.0);
/// }
/// let p = rcm_order(&t.to_csc()).unwrap();
/// assert!(p.validate().is_ok());
/// ```
pub fn rcm_order(pattern: &CsMat<f64>) -> Result<Permutation, OrderingError> {
    let (rows, cols) = (pattern.rows(), pattern.cols());
    if rows != cols {
        return Err(OrderingError::DimensionMismatch {
            points: rows,
            rows,
            cols,
        });
    }
    check_structurally_symmetric(pattern)?;
    // The structure view has `()` values, so sprs' (debug) symmetry check looks at the pattern only.
    let ord = sprs::linalg::reverse_cuthill_mckee(pattern.structure_view());
    Permutation::from_perm(ord.perm.vec())
}

/// Every stored `(i, j)` must have a stored `(j, i)`. sprs keeps inner indices sorted, so each
/// look-up is a binary search.
fn check_structurally_symmetric(pattern: &CsMat<f64>) -> Result<(), OrderingError> {
    for (outer, vec) in pattern.outer_iterator().enumerate() {
        for &inner in vec.indices() {
            let found = pattern
                .outer_view(inner)
                .is_some_and(|v| v.indices().binary_search(&outer).is_ok());
            if !found {
                let (row, col) = if pattern.is_csr() {
                    (outer, inner)
                } else {
                    (inner, outer)
                };
                return Err(OrderingError::NotSymmetric { row, col });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::test_support::{bandwidth_of, components, radius_pattern, shuffled_sphere};
    use super::*;

    /// A tridiagonal (path) matrix whose rows were scrambled by a known permutation.
    fn scrambled_path(n: usize, seed: u64) -> CsMat<f64> {
        let mut order: Vec<usize> = (0..n).collect();
        let mut s = seed;
        for i in (1..n).rev() {
            let j = (crate::spatial::test_clouds::splitmix64(&mut s) % (i as u64 + 1)) as usize;
            order.swap(i, j);
        }
        let mut t = sprs::TriMat::new((n, n));
        for k in 0..n {
            t.add_triplet(order[k], order[k], 2.0);
            if k + 1 < n {
                t.add_triplet(order[k], order[k + 1], 1.0);
                t.add_triplet(order[k + 1], order[k], 1.0);
            }
        }
        t.to_csc()
    }

    #[test]
    fn permutation_direction_matches_sprs_papt() {
        let a = scrambled_path(300, 9);
        let ord = sprs::linalg::reverse_cuthill_mckee(a.structure_view());
        let p = rcm_order(&a).unwrap();
        // Our reading: perm[new] = old. The path must come out with bandwidth 1.
        assert_eq!(bandwidth_of(&a, &p), 1);
        // The opposite reading (perm used as inv) leaves it scrambled.
        let flipped = Permutation::from_perm(p.inv.clone()).unwrap();
        assert!(bandwidth_of(&a, &flipped) > 10);
        // And sprs' own P A Pᵀ agrees with our reading.
        let papt = sprs::transform_mat_papt(a.view(), ord.perm.view());
        let band = papt
            .iter()
            .map(|(_, (i, j))| i.abs_diff(j))
            .max()
            .unwrap_or(0);
        assert_eq!(band, 1);
    }

    #[test]
    fn rcm_reduces_bandwidth_of_shuffled_sphere() {
        let pts = shuffled_sphere(1500, 4);
        let pattern = radius_pattern(&pts, 0.12);
        let p = rcm_order(&pattern).unwrap();
        p.validate().unwrap();
        let before = bandwidth_of(&pattern, &Permutation::identity(pts.len()));
        let after = bandwidth_of(&pattern, &p);
        assert!(after * 3 < before, "bandwidth {before} → {after}");
    }

    #[test]
    fn rcm_keeps_components_contiguous() {
        let mut pts = Vec::new();
        for (i, p) in shuffled_sphere(300, 8).iter().enumerate() {
            pts.push([p[0] + (i % 3) as f64 * 3.0, p[1], p[2]]);
        }
        let pattern = radius_pattern(&pts, 0.3);
        let comp = components(&pattern);
        let p = rcm_order(&pattern).unwrap();
        let labels: Vec<usize> = p.perm.iter().map(|&o| comp[o]).collect();
        let changes = labels.windows(2).filter(|w| w[0] != w[1]).count();
        assert_eq!(changes + 1, comp.iter().max().unwrap() + 1);
    }

    #[test]
    fn rcm_rejects_asymmetric_and_non_square() {
        let mut t = sprs::TriMat::new((3, 3));
        t.add_triplet(0, 0, 1.0);
        t.add_triplet(2, 0, 1.0);
        assert!(matches!(
            rcm_order(&t.to_csc()),
            Err(OrderingError::NotSymmetric { row: 2, col: 0 })
        ));
        assert!(matches!(
            rcm_order(&t.to_csr()),
            Err(OrderingError::NotSymmetric { row: 2, col: 0 })
        ));
        let rect = sprs::TriMat::<f64>::new((2, 3)).to_csc();
        assert!(rcm_order(&rect).is_err());
    }
}
