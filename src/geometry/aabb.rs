//! Axis-aligned bounding boxes.

use super::Point3;

/// An axis-aligned box `[min, max]` (inclusive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Point3,
    /// Upper corner.
    pub max: Point3,
}

impl Aabb {
    /// The empty box (min = +inf, max = −inf); growing it by a point gives that point's box.
    pub fn empty() -> Self {
        Aabb {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        }
    }

    /// The smallest box holding every point (the empty box for no points).
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Point3>) -> Self {
        let mut b = Self::empty();
        for p in points {
            b.grow(p);
        }
        b
    }

    /// Extend the box to contain `p`.
    pub fn grow(&mut self, p: &Point3) {
        for ((lo, hi), v) in self.min.iter_mut().zip(self.max.iter_mut()).zip(p) {
            *lo = lo.min(*v);
            *hi = hi.max(*v);
        }
    }

    /// True when no point was added.
    pub fn is_empty(&self) -> bool {
        self.min[0] > self.max[0]
    }

    /// Edge lengths along x, y, z.
    pub fn extent(&self) -> Point3 {
        [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ]
    }

    /// Length of the diagonal.
    pub fn diagonal(&self) -> f64 {
        super::norm(self.extent())
    }

    /// Centre of the box.
    pub fn center(&self) -> Point3 {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
            0.5 * (self.min[2] + self.max[2]),
        ]
    }

    /// The box grown by `margin` on every side.
    pub fn inflated(&self, margin: f64) -> Self {
        Aabb {
            min: [
                self.min[0] - margin,
                self.min[1] - margin,
                self.min[2] - margin,
            ],
            max: [
                self.max[0] + margin,
                self.max[1] + margin,
                self.max[2] + margin,
            ],
        }
    }

    /// The 8 corners (bit 0 of the index selects max x, bit 1 max y, bit 2 max z).
    pub fn corners(&self) -> [Point3; 8] {
        std::array::from_fn(|c| {
            std::array::from_fn(|k| {
                if c >> k & 1 == 0 {
                    self.min[k]
                } else {
                    self.max[k]
                }
            })
        })
    }

    /// Squared distance from `p` to the box (0 inside).
    pub fn dist2_to(&self, p: &Point3) -> f64 {
        (0..3)
            .map(|k| {
                let d = (self.min[k] - p[k]).max(0.0).max(p[k] - self.max[k]);
                d * d
            })
            .sum()
    }

    /// Whether the two boxes share a point (touching counts).
    pub fn intersects(&self, other: &Aabb) -> bool {
        (0..3).all(|k| self.min[k] <= other.max[k] && other.min[k] <= self.max[k])
    }

    /// Whether `p` lies in the closed box.
    pub fn contains(&self, p: &Point3) -> bool {
        (0..3).all(|k| self.min[k] <= p[k] && p[k] <= self.max[k])
    }

    /// Squared distance from `p` to the farthest corner of the box.
    pub fn max_dist2_to(&self, p: &Point3) -> f64 {
        (0..3)
            .map(|k| {
                let d = (p[k] - self.min[k]).abs().max((self.max[k] - p[k]).abs());
                d * d
            })
            .sum()
    }
}
