//! Spatial indexes: radius (`r`-sphere) and k-nearest-neighbour queries over a fixed point set.
//!
//! Stage "spatial index" of the pipeline (see `design.md`). Two interchangeable indexes implement
//! [`SpatialIndex`]:
//! - [`Octree`]: the variable-depth octal tree of Kojekine et al. (2002), section 3.1,
//!   Algorithm I (creation with leaf size `K`, single-child collapse) and Algorithm II
//!   (`r`-sphere search classifying nodes as inside / outside / partial). It also supports
//!   removing points while searching ([`Octree::take_within`]), which the ordering stage uses for
//!   Algorithm III.
//! - [`KdTree`]: a thin wrapper around kiddo's `ImmutableKdTree<f64, 3>`.
//!
//! [`brute_force`] is the linear-scan reference both are tested against. Indexes know nothing
//! about kernels or matrices. Building is `O(n log n)`; a radius query costs about
//! `O(log n + hits)` on well-spread data.

mod batch;
pub mod brute_force;
mod kdtree;
mod morton;
mod octree;
mod octree_removal;
mod octree_search;
#[cfg(test)]
pub(crate) mod test_clouds;

use std::fmt;
use std::str::FromStr;

use crate::geometry::Point3;

pub use batch::{NeighbourLists, within_batch};
pub use kdtree::KdTree;
pub use morton::{morton_order, sort_by_morton};
pub(crate) use octree::partition8;
pub use octree::{MAX_DEPTH, Octree, OctreeParams, OctreeStats};
pub use octree_removal::RemovalSet;

/// Errors of the spatial index stage.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SpatialError {
    /// Indices are stored as `u32`; the point set is larger than that.
    #[error("{points} points exceed the spatial index limit of {max} points; split the input")]
    TooManyPoints {
        /// Number of points passed in.
        points: usize,
        /// The largest supported number of points (`u32::MAX`).
        max: usize,
    },
    /// The octree leaf size must be at least 1.
    #[error(
        "octree leaf size {leaf_size} is invalid; use a leaf size of at least 1 (typical 8–32)"
    )]
    InvalidLeafSize {
        /// The leaf size passed in.
        leaf_size: usize,
    },
    /// The k-d tree library refused the point set.
    #[error("k-d tree construction failed: {message}; try the octree index instead")]
    KdTreeConstruction {
        /// kiddo's description of the failure.
        message: String,
    },
}

/// A read-only index over `n` points answering radius and k-nearest-neighbour queries.
///
/// Indices returned are positions in the slice the index was built from. Distances are
/// Euclidean, in the units of the points (normalised units inside the pipeline).
pub trait SpatialIndex: Sync {
    /// Indices of all points with `|p − q| ≤ r`, written to `out` (unsorted); `out` is cleared
    /// first. A negative or NaN `r` gives no points.
    fn within(&self, q: &Point3, r: f64, out: &mut Vec<u32>);
    /// The `k` nearest points as `(index, distance)` sorted by increasing distance, written to
    /// `out` (cleared first). Fewer than `k` when the index holds fewer points.
    fn nearest_k(&self, q: &Point3, k: usize, out: &mut Vec<(u32, f64)>);
    /// Number of indexed points.
    fn len(&self) -> usize;
    /// True when the index holds no points.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Which spatial index to build.
///
/// The default is [`IndexKind::Octree`], because the radius queries dominate the pipeline (one
/// build, then one query per data point for assembly and one per evaluated grid point) and the
/// octree answered them faster. Measured with `benches/spatial.rs` (criterion, 37,706 points on a
/// sphere of radius 0.5, r = 0.0282 ≈ 31 neighbours, one `within` per point, one thread, on a
/// shared 2-core machine, three runs): octree K = 8 took 29.0 / 31.8 / 32.0 ms against kiddo's
/// 32.0 / 34.5 / 34.6 ms (K = 16 and 32 were between equal and 1.5× slower). Building is the other
/// way round (octree K = 8 4.5 ms, K = 16 2.3 ms, kiddo 2.3–2.6 ms) but happens once. The
/// octree also supports the search-and-remove that the BFS ordering needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum IndexKind {
    /// The seed's octal tree ([`Octree`]); leaf size 8–10 measured best.
    #[default]
    Octree,
    /// kiddo's immutable k-d tree ([`KdTree`]); the leaf size argument is ignored.
    KdTree,
}

impl fmt::Display for IndexKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            IndexKind::Octree => "octree",
            IndexKind::KdTree => "kdtree",
        })
    }
}

/// The value is not one of the index names.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown spatial index '{given}'; use one of: octree, kdtree")]
pub struct ParseIndexKindError {
    /// The string that was given.
    pub given: String,
}

impl FromStr for IndexKind {
    type Err = ParseIndexKindError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "octree" => Ok(IndexKind::Octree),
            "kdtree" | "kd-tree" => Ok(IndexKind::KdTree),
            _ => Err(ParseIndexKindError {
                given: s.to_string(),
            }),
        }
    }
}

/// Build an index of `kind` over `points` (n points × 3). `leaf_size` is the octree's `K`
/// (maximum points per leaf, typical 8–32); the k-d tree ignores it.
///
/// # Errors
/// [`SpatialError::TooManyPoints`] beyond `u32::MAX` points, [`SpatialError::InvalidLeafSize`]
/// for an octree with `leaf_size == 0`.
///
/// ```
/// use rbfsurf::spatial::{IndexKind, build_index};
/// let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.1, 0.0, 0.0]];
/// let index = build_index(&pts, IndexKind::Octree, 8).unwrap();
/// let mut out = Vec::new();
/// index.within(&[0.0, 0.0, 0.0], 0.5, &mut out);
/// out.sort();
/// assert_eq!(out, vec![0, 2]);
/// ```
pub fn build_index(
    points: &[Point3],
    kind: IndexKind,
    leaf_size: usize,
) -> Result<Box<dyn SpatialIndex + Send>, SpatialError> {
    Ok(match kind {
        IndexKind::Octree => Box::new(Octree::build(points, &OctreeParams { leaf_size })?),
        IndexKind::KdTree => Box::new(KdTree::build(points)?),
    })
}

/// Check that `n` points can be indexed with `u32` indices.
fn check_count(n: usize) -> Result<(), SpatialError> {
    if n > u32::MAX as usize {
        return Err(SpatialError::TooManyPoints {
            points: n,
            max: u32::MAX as usize,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn index_kind_round_trips_through_strings() {
        for k in [IndexKind::Octree, IndexKind::KdTree] {
            assert_eq!(k.to_string().parse::<IndexKind>().unwrap(), k);
        }
        assert!("quadtree".parse::<IndexKind>().is_err());
    }

    #[test]
    fn build_index_rejects_zero_leaf_size() {
        let pts = [[0.0; 3]];
        assert!(matches!(
            build_index(&pts, IndexKind::Octree, 0),
            Err(SpatialError::InvalidLeafSize { leaf_size: 0 })
        ));
        assert_eq!(build_index(&pts, IndexKind::KdTree, 0).unwrap().len(), 1);
    }
}
