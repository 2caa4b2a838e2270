//! k-d tree index: a thin wrapper around kiddo 6's `ImmutableKdTree<f64, 3>`.
//!
//! kiddo takes and returns SQUARED distances; this wrapper converts, and recomputes k-NN
//! distances with [`crate::geometry::dist2`] so they match the other indexes bit for bit.
//! Building is `O(n log n)`; queries about `O(log n + hits)`. Reference: Bentley (1975),
//! "Multidimensional binary search trees used for associative searching".

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::geometry::{Point3, dist2};

use super::{SpatialError, SpatialIndex, check_count};

type Se = SquaredEuclidean<f64>;

/// kiddo's immutable k-d tree plus a copy of the points.
#[derive(Debug)]
pub struct KdTree {
    tree: Option<ImmutableKdTree<f64, 3>>,
    points: Vec<Point3>,
}

impl KdTree {
    /// Build over `points` (n points × 3). An empty slice gives an empty index.
    ///
    /// # Errors
    /// [`SpatialError::TooManyPoints`] beyond `u32::MAX` points;
    /// [`SpatialError::KdTreeConstruction`] if kiddo refuses the set.
    ///
    /// ```
    /// use rbfsurf::spatial::{KdTree, SpatialIndex};
    /// let tree = KdTree::build(&[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]).unwrap();
    /// let mut nn = Vec::new();
    /// tree.nearest_k(&[0.9, 0.9, 0.9], 1, &mut nn);
    /// assert_eq!(nn[0].0, 1);
    /// ```
    pub fn build(points: &[Point3]) -> Result<Self, SpatialError> {
        check_count(points.len())?;
        let tree = if points.is_empty() {
            None
        } else {
            Some(ImmutableKdTree::new_from_slice(points).map_err(|e| {
                SpatialError::KdTreeConstruction {
                    message: e.to_string(),
                }
            })?)
        };
        Ok(KdTree {
            tree,
            points: points.to_vec(),
        })
    }

    /// The nearest point as `(index, distance)`; `None` for an empty index. Cheaper than
    /// [`SpatialIndex::nearest_k`] with `k = 1` (no result vector).
    pub fn nearest_one(&self, q: &Point3) -> Option<(u32, f64)> {
        let hit = self.tree.as_ref()?.query(q).nearest_one::<Se>().execute();
        Some((hit.item, dist2(self.points[hit.item as usize], *q).sqrt()))
    }
}

impl SpatialIndex for KdTree {
    fn within(&self, q: &Point3, r: f64, out: &mut Vec<u32>) {
        out.clear();
        let Some(tree) = &self.tree else { return };
        if r.is_nan() || r < 0.0 {
            return;
        }
        tree.query(q)
            .within::<Se>(r * r)
            .unsorted()
            .visit(|it| out.push(it.item));
    }

    fn nearest_k(&self, q: &Point3, k: usize, out: &mut Vec<(u32, f64)>) {
        out.clear();
        let (Some(tree), Some(k)) = (&self.tree, NonZero::new(k)) else {
            return;
        };
        let hits = tree.query(q).nearest_n::<Se>(k).execute();
        out.extend(
            hits.iter()
                .map(|it| (it.item, dist2(self.points[it.item as usize], *q).sqrt())),
        );
        out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    }

    fn len(&self) -> usize {
        self.points.len()
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_clouds::{all_clouds, assert_matches_brute_force};
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn kdtree_matches_brute_force_on_all_clouds() {
        for (name, pts) in all_clouds(700, 43) {
            let tree = KdTree::build(&pts).unwrap();
            assert_matches_brute_force(&tree, &pts, name, 8);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn kdtree_equals_brute_force_on_random_clouds(
            pts in prop::collection::vec(prop::array::uniform3(-1.0f64..1.0), 0..120),
            q in prop::array::uniform3(-1.5f64..1.5),
            r in 0.0f64..2.0,
            k in 0usize..20,
        ) {
            let tree = KdTree::build(&pts).unwrap();
            let (mut got, mut want) = (Vec::new(), Vec::new());
            tree.within(&q, r, &mut got);
            got.sort_unstable();
            crate::spatial::brute_force::within(&pts, &q, r, &mut want);
            prop_assert_eq!(got, want);
            let (mut gk, mut wk) = (Vec::new(), Vec::new());
            tree.nearest_k(&q, k, &mut gk);
            crate::spatial::brute_force::nearest_k(&pts, &q, k, &mut wk);
            if let Some(&(_, d)) = wk.first() {
                prop_assert_eq!(tree.nearest_one(&q).map(|x| x.1), Some(d));
            }
            let gd: Vec<f64> = gk.iter().map(|x| x.1).collect();
            let wd: Vec<f64> = wk.iter().map(|x| x.1).collect();
            prop_assert_eq!(gd, wd);
        }
    }
}
