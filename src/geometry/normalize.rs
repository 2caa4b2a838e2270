//! The similarity transform between input units and normalised units (the unit cube).

use super::{Aabb, Point3};

/// `x_norm = (x_input − offset) · scale`: translates the input's bounding box to start at the origin
/// and scales its longest edge to 1. Uniform, so normals and angles are unchanged.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalization {
    /// Input-units point that maps to the origin (the bbox minimum).
    pub offset: Point3,
    /// Normalised units per input unit (1 / longest bbox edge).
    pub scale: f64,
}

impl Normalization {
    /// The transform that maps `bbox` into `[0,1]³` with its longest edge spanning `[0,1]`.
    /// A degenerate (single-point) box gets scale 1.
    pub fn from_aabb(bbox: &Aabb) -> Self {
        let e = bbox.extent();
        let longest = e[0].max(e[1]).max(e[2]);
        let scale = if longest > 0.0 && longest.is_finite() {
            1.0 / longest
        } else {
            1.0
        };
        Normalization {
            offset: bbox.min,
            scale,
        }
    }

    /// Input units → normalised units.
    #[inline]
    pub fn forward(&self, p: &Point3) -> Point3 {
        [
            (p[0] - self.offset[0]) * self.scale,
            (p[1] - self.offset[1]) * self.scale,
            (p[2] - self.offset[2]) * self.scale,
        ]
    }

    /// Normalised units → input units.
    #[inline]
    pub fn inverse(&self, p: &Point3) -> Point3 {
        [
            p[0] / self.scale + self.offset[0],
            p[1] / self.scale + self.offset[1],
            p[2] / self.scale + self.offset[2],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalization_round_trips_far_from_origin() {
        let pts = [[1e6, 1e6 + 2.0, -1e6], [1e6 + 4.0, 1e6, -1e6 + 1.0]];
        let n = Normalization::from_aabb(&Aabb::from_points(&pts));
        assert_eq!(n.scale, 0.25);
        for p in &pts {
            let q = n.forward(p);
            assert!(q.iter().all(|v| (0.0..=1.0).contains(v)));
            let r = n.inverse(&q);
            for k in 0..3 {
                assert!((r[k] - p[k]).abs() < 1e-9);
            }
        }
    }
}
