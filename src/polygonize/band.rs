//! The band the data support: the cells near a data point. Polygonizing only this band is what makes
//! open scans cheap (the carrier's sheet far from the data is never sampled, instead of being
//! polygonized and trimmed afterwards).
//!
//! Rule: a box is kept when the data point nearest to its centre is within `radius + ½ diagonal`
//! of that centre (so a box that holds a point within `radius` of the data is always kept). The rule
//! is monotone: for a box `b` inside a box `B`, `|c_b − c_B| + ½ diag(b) ≤ ½ diag(B)`, so by the
//! triangle inequality a rejected `B` has no kept `b`. One nearest-neighbour query per box,
//! `O(log n)`.

use super::Region;
use crate::geometry::{Aabb, Point3};
use crate::spatial::{KdTree, SpatialError};

/// Cells within `radius` of the data (normalised units); see the module doc for the exact rule.
pub struct DataBand {
    tree: KdTree,
    radius: f64,
}

impl DataBand {
    /// The band of width `radius` (same units as `points`) around `points`. An empty point set keeps
    /// nothing.
    ///
    /// # Errors
    /// [`SpatialError`] when the k-d tree refuses the points (too many).
    pub fn new(points: &[Point3], radius: f64) -> Result<Self, SpatialError> {
        Ok(DataBand {
            tree: KdTree::build(points)?,
            radius,
        })
    }
}

impl Region for DataBand {
    fn touches(&self, cell: &Aabb) -> bool {
        let reach = self.radius + 0.5 * cell.diagonal();
        self.tree
            .nearest_one(&cell.center())
            .is_some_and(|(_, d)| d <= reach)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube(c: Point3, half: f64) -> Aabb {
        Aabb {
            min: c.map(|x| x - half),
            max: c.map(|x| x + half),
        }
    }

    #[test]
    fn keeps_boxes_near_the_data_and_is_monotone() {
        let band = DataBand::new(&[[0.0, 0.0, 0.0]], 0.1).unwrap();
        // A small box 0.05 away is kept, one 0.5 away is not.
        assert!(band.touches(&cube([0.05, 0.0, 0.0], 0.01)));
        assert!(!band.touches(&cube([0.5, 0.0, 0.0], 0.01)));
        // A big box around the far one reaching the point is kept (its sub-box need not be).
        assert!(band.touches(&cube([0.5, 0.0, 0.0], 0.6)));
        // Monotone: every sub-box of a rejected box is rejected (brute force over a grid of sub-boxes).
        let big = cube([0.6, 0.3, 0.0], 0.2);
        assert!(!band.touches(&big));
        for i in 0..8 {
            for j in 0..8 {
                for k in 0..8 {
                    let c = [
                        0.45 + 0.05 * i as f64,
                        0.15 + 0.05 * j as f64,
                        -0.15 + 0.05 * k as f64,
                    ];
                    let sub = cube(c, 0.025);
                    assert!(!band.touches(&sub), "{c:?}");
                }
            }
        }
        let empty = DataBand::new(&[], 0.1).unwrap();
        assert!(!empty.touches(&cube([0.0; 3], 1.0)));
    }
}
