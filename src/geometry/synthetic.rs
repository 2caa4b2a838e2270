//! Synthetic point sets with known surfaces, for tests and benchmarks: sphere, torus, two spheres,
//! ellipsoid. Deterministic for a seed (splitmix64); area-uniform where it matters.

use super::{Point3, PointCloud};

/// A shape with an analytic signed distance (negative inside).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// Sphere of `radius` about `center`.
    Sphere {
        /// Centre.
        center: Point3,
        /// Radius.
        radius: f64,
    },
    /// Torus about `center` with axis z, tube centre-line radius `major`, tube radius `minor`.
    Torus {
        /// Centre.
        center: Point3,
        /// Distance from the centre to the tube's centre line.
        major: f64,
        /// Tube radius.
        minor: f64,
    },
    /// Two disjoint spheres of equal `radius` whose centres are `gap + 2 radius` apart along x.
    TwoSpheres {
        /// Midpoint between the centres.
        center: Point3,
        /// Radius of each.
        radius: f64,
        /// Closest distance between the two surfaces.
        gap: f64,
    },
}

impl Shape {
    /// Parse a command-line name: `sphere`, `torus`, `two-spheres` (unit-cube-sized defaults).
    pub fn by_name(name: &str) -> Option<Shape> {
        match name {
            "sphere" => Some(Shape::Sphere {
                center: [0.5; 3],
                radius: 0.4,
            }),
            "torus" => Some(Shape::Torus {
                center: [0.5; 3],
                major: 0.3,
                minor: 0.12,
            }),
            "two-spheres" => Some(Shape::TwoSpheres {
                center: [0.5; 3],
                radius: 0.2,
                gap: 0.1,
            }),
            _ => None,
        }
    }

    /// Signed distance to the surface (negative inside).
    pub fn signed_distance(&self, p: &Point3) -> f64 {
        match *self {
            Shape::Sphere { center, radius } => super::norm(super::sub(*p, center)) - radius,
            Shape::Torus {
                center,
                major,
                minor,
            } => {
                let d = super::sub(*p, center);
                let q = (d[0] * d[0] + d[1] * d[1]).sqrt() - major;
                (q * q + d[2] * d[2]).sqrt() - minor
            }
            Shape::TwoSpheres {
                center,
                radius,
                gap,
            } => {
                let off = radius + 0.5 * gap;
                let a = Shape::Sphere {
                    center: [center[0] - off, center[1], center[2]],
                    radius,
                };
                let b = Shape::Sphere {
                    center: [center[0] + off, center[1], center[2]],
                    radius,
                };
                a.signed_distance(p).min(b.signed_distance(p))
            }
        }
    }

    /// Genus of the surface (sum over components).
    pub fn genus(&self) -> i64 {
        match self {
            Shape::Torus { .. } => 1,
            _ => 0,
        }
    }

    /// Number of connected components.
    pub fn components(&self) -> usize {
        match self {
            Shape::TwoSpheres { .. } => 2,
            _ => 1,
        }
    }

    /// `n` points sampled uniformly by area, with outward unit normals.
    pub fn sample(&self, n: usize, seed: u64) -> PointCloud {
        let mut rng = SplitMix64(seed);
        let mut points = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        while points.len() < n {
            let (p, nrm) = match *self {
                Shape::Sphere { center, radius } => sphere_point(&mut rng, center, radius),
                Shape::TwoSpheres {
                    center,
                    radius,
                    gap,
                } => {
                    let off = if rng.next_f64() < 0.5 { -1.0 } else { 1.0 } * (radius + 0.5 * gap);
                    sphere_point(&mut rng, [center[0] + off, center[1], center[2]], radius)
                }
                Shape::Torus {
                    center,
                    major,
                    minor,
                } => {
                    // Rejection sampling on the tube angle for area uniformity (area ∝ major + minor cos v).
                    let u = rng.next_f64() * std::f64::consts::TAU;
                    let v = rng.next_f64() * std::f64::consts::TAU;
                    if rng.next_f64() * (major + minor) > major + minor * v.cos() {
                        continue;
                    }
                    let n = [v.cos() * u.cos(), v.cos() * u.sin(), v.sin()];
                    let r = major + minor * v.cos();
                    (
                        [
                            center[0] + r * u.cos(),
                            center[1] + r * u.sin(),
                            center[2] + minor * v.sin(),
                        ],
                        n,
                    )
                }
            };
            points.push(p);
            normals.push(nrm);
        }
        PointCloud {
            points,
            normals: Some(normals),
        }
    }
}

fn sphere_point(rng: &mut SplitMix64, c: Point3, r: f64) -> (Point3, Point3) {
    let z = 2.0 * rng.next_f64() - 1.0;
    let t = rng.next_f64() * std::f64::consts::TAU;
    let s = (1.0 - z * z).max(0.0).sqrt();
    let n = [s * t.cos(), s * t.sin(), z];
    ([c[0] + r * n[0], c[1] + r * n[1], c[2] + r * n[2]], n)
}

/// The splitmix64 generator (Steele, Lea & Flood 2014): tiny, seedable, good enough for sampling.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_lie_on_their_surface_with_unit_normals() {
        for name in ["sphere", "torus", "two-spheres"] {
            let s = Shape::by_name(name).unwrap();
            let c = s.sample(2000, 7);
            for (p, n) in c.points.iter().zip(c.normals.as_ref().unwrap()) {
                assert!(s.signed_distance(p).abs() < 1e-12, "{name}");
                assert!((super::super::norm(*n) - 1.0).abs() < 1e-12);
                let out = [p[0] + 1e-4 * n[0], p[1] + 1e-4 * n[1], p[2] + 1e-4 * n[2]];
                assert!(
                    s.signed_distance(&out) > 0.0,
                    "{name}: normal must point outwards"
                );
            }
        }
    }
}
