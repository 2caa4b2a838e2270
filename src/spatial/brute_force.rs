//! Reference linear-scan neighbour search, `O(n)` per query.
//!
//! The independent truth the octree and k-d tree are tested against (other modules' tests may use
//! it too). Distances use [`crate::geometry::dist2`], the same arithmetic as the indexes, so the
//! results match exactly, including points at distance exactly `r`.

use crate::geometry::{Point3, dist2};

use super::{SpatialError, SpatialIndex, check_count};

/// A "no index" index: every query scans all points.
#[derive(Debug, Clone, Default)]
pub struct BruteForce {
    points: Vec<Point3>,
}

impl BruteForce {
    /// Copy `points` (n points × 3).
    ///
    /// # Errors
    /// [`SpatialError::TooManyPoints`] beyond `u32::MAX` points.
    pub fn build(points: &[Point3]) -> Result<Self, SpatialError> {
        check_count(points.len())?;
        Ok(BruteForce {
            points: points.to_vec(),
        })
    }
}

impl SpatialIndex for BruteForce {
    fn within(&self, q: &Point3, r: f64, out: &mut Vec<u32>) {
        within(&self.points, q, r, out);
    }
    fn nearest_k(&self, q: &Point3, k: usize, out: &mut Vec<(u32, f64)>) {
        nearest_k(&self.points, q, k, out);
    }
    fn len(&self) -> usize {
        self.points.len()
    }
}

/// Indices (ascending) of all `points` with `|p − q| ≤ r`, written to `out` (cleared first).
pub fn within(points: &[Point3], q: &Point3, r: f64, out: &mut Vec<u32>) {
    out.clear();
    let r2 = r * r;
    if r.is_nan() || r < 0.0 {
        return;
    }
    out.extend(
        points
            .iter()
            .enumerate()
            .filter(|(_, p)| dist2(**p, *q) <= r2)
            .map(|(i, _)| i as u32),
    );
}

/// The `k` nearest `points` to `q` as `(index, distance)`, sorted by distance then index,
/// written to `out` (cleared first).
pub fn nearest_k(points: &[Point3], q: &Point3, k: usize, out: &mut Vec<(u32, f64)>) {
    out.clear();
    let mut all: Vec<(u32, f64)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| (i as u32, dist2(*p, *q)))
        .collect();
    all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    out.extend(all.into_iter().take(k).map(|(i, d2)| (i, d2.sqrt())));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_hand_checked_case() {
        let pts = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            [3.0, 0.0, 0.0],
        ];
        let mut out = Vec::new();
        within(&pts, &[0.0, 0.0, 0.0], 1.0, &mut out);
        assert_eq!(out, vec![0, 1]);
        within(&pts, &[0.0, 0.0, 0.0], -1.0, &mut out);
        assert!(out.is_empty());
        let mut nn = Vec::new();
        nearest_k(&pts, &[0.9, 0.0, 0.0], 2, &mut nn);
        assert_eq!(nn.iter().map(|x| x.0).collect::<Vec<_>>(), vec![1, 0]);
        assert!((nn[0].1 - 0.1).abs() < 1e-15 && (nn[1].1 - 0.9).abs() < 1e-15);
        nearest_k(&pts, &[0.0; 3], 10, &mut nn);
        assert_eq!(nn.len(), 4);
    }
}
