//! Orderings of the points (rows/columns of the interpolation matrix) that shape the sparse
//! matrix: none, breadth-first octree sort (Kojekine et al. 2002, section 3.1, Algorithm III),
//! or reverse Cuthill–McKee (Cuthill & McKee 1969; George & Liu 1981), plus the envelope
//! statistics of the reordered matrix ([`matrix_shape`]).
//!
//! Stage "ordering" of the pipeline: input the points (normalised units), the support radius
//! and the symmetric sparsity pattern of the `n × n` RBF block; output a [`Permutation`].
//! BFS costs `n` octree searches; RCM `O(nnz · log(degree))`; the statistics `O(nnz)`.

mod bfs;
mod rcm;
mod stats;

use std::fmt;
use std::str::FromStr;

use crate::geometry::Point3;
use crate::spatial::{Octree, SpatialError};

pub use bfs::bfs_order;
pub use rcm::rcm_order;
pub use stats::{MatrixShape, matrix_shape};

/// Errors of the ordering stage.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum OrderingError {
    /// The pattern is not square or does not match the number of points.
    #[error(
        "matrix pattern is {rows}×{cols} but there are {points} points; pass the n×n block of the n points"
    )]
    DimensionMismatch {
        /// Number of points.
        points: usize,
        /// Pattern rows.
        rows: usize,
        /// Pattern columns.
        cols: usize,
    },
    /// The octree passed in was built over a different number of points.
    #[error(
        "octree holds {octree_points} points but {points} were given; build it from the same points"
    )]
    OctreeMismatch {
        /// Points in the octree.
        octree_points: usize,
        /// Points given.
        points: usize,
    },
    /// The neighbour radius is negative, zero, NaN or infinite.
    #[error("ordering radius {radius} is invalid; use the positive, finite support radius")]
    InvalidRadius {
        /// The radius given.
        radius: f64,
    },
    /// The pattern is not structurally symmetric.
    #[error(
        "matrix pattern has an entry at ({row}, {col}) but none at ({col}, {row}); pass a symmetric pattern"
    )]
    NotSymmetric {
        /// Row of the unmatched entry.
        row: usize,
        /// Column of the unmatched entry.
        col: usize,
    },
    /// A permutation is not a bijection of `0..n` or its inverse does not match.
    #[error("invalid permutation: {reason}")]
    InvalidPermutation {
        /// What is wrong with it.
        reason: String,
    },
    /// Building the octree failed.
    #[error(transparent)]
    Index(#[from] SpatialError),
}

/// Which ordering to compute.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum OrderingKind {
    /// Keep the input order (identity permutation).
    None,
    /// The seed's Algorithm III: breadth-first over `r`-neighbourhoods found with the octree.
    Bfs,
    /// Reverse Cuthill–McKee on the matrix pattern (sprs).
    #[default]
    Rcm,
}

impl fmt::Display for OrderingKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            OrderingKind::None => "none",
            OrderingKind::Bfs => "bfs",
            OrderingKind::Rcm => "rcm",
        })
    }
}

/// The value is not one of the ordering names.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown ordering '{given}'; use one of: none, bfs, rcm")]
pub struct ParseOrderingKindError {
    /// The string that was given.
    pub given: String,
}

impl FromStr for OrderingKind {
    type Err = ParseOrderingKindError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "none" => Ok(OrderingKind::None),
            "bfs" => Ok(OrderingKind::Bfs),
            "rcm" => Ok(OrderingKind::Rcm),
            _ => Err(ParseOrderingKindError {
                given: s.to_string(),
            }),
        }
    }
}

/// A permutation of `0..n`: `perm[new] = old` and `inv[old] = new`.
///
/// Row/column `new` of the reordered matrix `P A Pᵀ` is row/column `perm[new]` of `A`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Permutation {
    /// `perm[new] = old`.
    pub perm: Vec<usize>,
    /// `inv[old] = new`.
    pub inv: Vec<usize>,
}

impl Permutation {
    /// The identity on `0..n`.
    pub fn identity(n: usize) -> Self {
        Permutation {
            perm: (0..n).collect(),
            inv: (0..n).collect(),
        }
    }

    /// Build from `perm` (`perm[new] = old`), computing the inverse.
    ///
    /// # Errors
    /// [`OrderingError::InvalidPermutation`] when `perm` is not a bijection of `0..n`.
    pub fn from_perm(perm: Vec<usize>) -> Result<Self, OrderingError> {
        let n = perm.len();
        let mut inv = vec![usize::MAX; n];
        for (new, &old) in perm.iter().enumerate() {
            if old >= n || inv[old] != usize::MAX {
                return Err(OrderingError::InvalidPermutation {
                    reason: format!("entry {old} at position {new} is out of range or repeated"),
                });
            }
            inv[old] = new;
        }
        Ok(Permutation { perm, inv })
    }

    /// Number of elements permuted.
    pub fn len(&self) -> usize {
        self.perm.len()
    }

    /// True for the permutation of nothing.
    pub fn is_empty(&self) -> bool {
        self.perm.is_empty()
    }

    /// Check that `perm` is a bijection of `0..n` and `inv` its inverse.
    ///
    /// # Errors
    /// [`OrderingError::InvalidPermutation`] describing the first problem found.
    pub fn validate(&self) -> Result<(), OrderingError> {
        let n = self.perm.len();
        if self.inv.len() != n {
            return Err(OrderingError::InvalidPermutation {
                reason: format!("perm has {n} entries but inv has {}", self.inv.len()),
            });
        }
        for (new, &old) in self.perm.iter().enumerate() {
            if old >= n || self.inv[old] != new {
                return Err(OrderingError::InvalidPermutation {
                    reason: format!("perm[{new}] = {old} is out of range or inv[{old}] ≠ {new}"),
                });
            }
        }
        Ok(())
    }
}

/// Compute the ordering `kind` for `points` (n points × 3, normalised units).
///
/// `radius` is the neighbour radius (the RBF support) used by [`OrderingKind::Bfs`];
/// `pattern` is the symmetric `n × n` sparsity pattern of the RBF block, used by
/// [`OrderingKind::Rcm`] (values are ignored); `octree`, if given, must be built over `points`
/// and is reused by BFS (otherwise one with leaf size 10 is built).
///
/// # Errors
/// [`OrderingError::DimensionMismatch`] when the pattern is not `n × n`, plus the errors of
/// [`bfs_order`] and [`rcm_order`].
///
/// ```
/// use rbfsurf::ordering::{OrderingKind, compute_ordering};
/// let pts = [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.25, 0.0, 0.0]];
/// let mut t = sprs::TriMat::new((3, 3));
/// for (i, j) in [(0, 0), (1, 1), (2, 2), (0, 2), (2, 0), (1, 2), (2, 1)] {
///     t.add_triplet(i, j, 1.0);
/// }
/// let pattern = t.to_csc();
/// let p = compute_ordering(OrderingKind::Bfs, &pts, 0.3, &pattern, None).unwrap();
/// assert_eq!(p.perm, vec![0, 2, 1]);
/// ```
pub fn compute_ordering(
    kind: OrderingKind,
    points: &[Point3],
    radius: f64,
    pattern: &sprs::CsMat<f64>,
    octree: Option<&Octree>,
) -> Result<Permutation, OrderingError> {
    let n = points.len();
    if pattern.rows() != n || pattern.cols() != n {
        return Err(OrderingError::DimensionMismatch {
            points: n,
            rows: pattern.rows(),
            cols: pattern.cols(),
        });
    }
    match kind {
        OrderingKind::None => Ok(Permutation::identity(n)),
        OrderingKind::Bfs => bfs_order(points, radius, octree),
        OrderingKind::Rcm => rcm_order(pattern),
    }
}

#[cfg(test)]
pub(crate) mod test_support;

#[cfg(test)]
mod tests {
    use super::test_support::{radius_pattern, shuffled_sphere};
    use super::*;

    #[test]
    fn kind_round_trips_through_strings() {
        for k in [OrderingKind::None, OrderingKind::Bfs, OrderingKind::Rcm] {
            assert_eq!(k.to_string().parse::<OrderingKind>().unwrap(), k);
        }
        assert!("amdx".parse::<OrderingKind>().is_err());
    }

    #[test]
    fn permutation_validation() {
        assert!(Permutation::identity(5).validate().is_ok());
        assert!(
            Permutation::from_perm(vec![2, 0, 1])
                .unwrap()
                .validate()
                .is_ok()
        );
        assert!(Permutation::from_perm(vec![0, 0, 1]).is_err());
        assert!(Permutation::from_perm(vec![0, 3, 1]).is_err());
        let bad = Permutation {
            perm: vec![1, 0],
            inv: vec![0, 1],
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn none_is_identity_and_dimensions_are_checked() {
        let pts = shuffled_sphere(200, 3);
        let pattern = radius_pattern(&pts, 0.2);
        let p = compute_ordering(OrderingKind::None, &pts, 0.2, &pattern, None).unwrap();
        assert_eq!(p, Permutation::identity(200));
        let r = compute_ordering(OrderingKind::None, &pts[..199], 0.2, &pattern, None);
        assert!(matches!(r, Err(OrderingError::DimensionMismatch { .. })));
    }

    #[test]
    fn every_kind_handles_empty_and_single_point() {
        for kind in [OrderingKind::None, OrderingKind::Bfs, OrderingKind::Rcm] {
            let empty = radius_pattern(&[], 0.1);
            assert!(
                compute_ordering(kind, &[], 0.1, &empty, None)
                    .unwrap()
                    .is_empty()
            );
            let one = [[0.5; 3]];
            let pat = radius_pattern(&one, 0.1);
            let p = compute_ordering(kind, &one, 0.1, &pat, None).unwrap();
            assert_eq!(p.perm, vec![0]);
        }
    }
}
