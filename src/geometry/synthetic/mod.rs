//! Synthetic point sets with known surfaces, for tests and benchmarks: sphere, torus, two spheres,
//! trefoil-knot tube, bumpy sphere. Deterministic for a seed (splitmix64) and area-uniform; each shape
//! also gives a closed, outward-oriented truth mesh ([`Shape::truth_mesh`]) and the defects of real
//! scans can be applied to a sample ([`apply_defects`]: range-image cut, holes, noise, outliers).

mod bumpy;
mod defects;
mod knot;
mod truth;

pub use defects::{Coverage, DefectError, DefectStats, Defects, apply_defects};

use super::{Point3, PointCloud};

/// The names [`Shape::by_name`] accepts.
pub const SHAPE_NAMES: [&str; 5] = ["sphere", "torus", "two-spheres", "knot", "bumpy-sphere"];

/// A shape with a known surface and signed distance (negative inside; see each variant for how exact).
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
    /// Tube of radius `tube` around the trefoil `center + scale · c(t)`,
    /// `c(t) = (sin t + 2 sin 2t, cos t − 2 cos 2t, −sin 3t)` centred on its bounding box (genus 1).
    /// The tube must stay below `0.6 · scale` to avoid self-intersection. Its signed distance is the
    /// distance to the centre line (coarse search refined by golden section) minus `tube`: exact
    /// within the tube's reach, approximate far from it.
    Knot {
        /// Centre of the centre line's bounding box.
        center: Point3,
        /// Scale factor from trefoil units (the centre line spans 5.47 × 5.06 × 2) to output units.
        scale: f64,
        /// Tube radius, output units.
        tube: f64,
    },
    /// Star-shaped `r(u) = radius (1 + amplitude · Y(u))` over unit directions `u` with a smooth
    /// low-frequency bump `|Y| ≤ 1` (genus 0). Its signed distance is only the first-order
    /// approximation `F / |∇F|` (exact sign, exact zero set).
    BumpySphere {
        /// Centre.
        center: Point3,
        /// Mean radius `R`.
        radius: f64,
        /// Relative bump amplitude `a` (keep `|a| < 0.5`).
        amplitude: f64,
    },
}

impl Shape {
    /// Parse a command-line name (one of [`SHAPE_NAMES`]; unit-cube-sized defaults centred at 0.5).
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
            "knot" => Some(Shape::Knot {
                center: [0.5; 3],
                scale: 0.14,
                tube: 0.35 * 0.14,
            }),
            "bumpy-sphere" => Some(Shape::BumpySphere {
                center: [0.5; 3],
                radius: 0.35,
                amplitude: 0.1,
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
            Shape::Knot {
                center,
                scale,
                tube,
            } => knot::distance_to_centre_line(p, center, scale) - tube,
            Shape::BumpySphere {
                center,
                radius,
                amplitude,
            } => bumpy::signed_distance(p, center, radius, amplitude),
        }
    }

    /// Genus of the surface (sum over components).
    pub fn genus(&self) -> i64 {
        match self {
            Shape::Torus { .. } | Shape::Knot { .. } => 1,
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

    /// `n` points sampled uniformly by area (rejection sampling on the area element where it is not
    /// constant), with outward unit normals; the same `seed` gives the same points.
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
                Shape::Knot {
                    center,
                    scale,
                    tube,
                } => knot::sample(&mut rng, center, scale, tube),
                Shape::BumpySphere {
                    center,
                    radius,
                    amplitude,
                } => bumpy::sample(&mut rng, center, radius, amplitude),
            };
            points.push(p);
            normals.push(nrm);
        }
        PointCloud {
            points,
            normals: Some(normals),
            ..Default::default()
        }
    }
}

fn sphere_point(rng: &mut SplitMix64, c: Point3, r: f64) -> (Point3, Point3) {
    let n = rng.next_unit_vector();
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

    /// Standard normal deviate (Box–Muller, one of the pair).
    pub fn next_gaussian(&mut self) -> f64 {
        let u1 = 1.0 - self.next_f64(); // (0, 1], so the logarithm is finite
        let u2 = self.next_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    /// Uniformly distributed unit vector (Archimedes: uniform z, uniform azimuth).
    pub fn next_unit_vector(&mut self) -> Point3 {
        let z = 2.0 * self.next_f64() - 1.0;
        let t = self.next_f64() * std::f64::consts::TAU;
        let s = (1.0 - z * z).max(0.0).sqrt();
        [s * t.cos(), s * t.sin(), z]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_lie_on_their_surface_with_unit_normals() {
        for name in SHAPE_NAMES {
            let s = Shape::by_name(name).unwrap();
            let c = s.sample(2000, 7);
            for (p, n) in c.points.iter().zip(c.normals.as_ref().unwrap()) {
                assert!(
                    s.signed_distance(p).abs() < 1e-12,
                    "{name}: {}",
                    s.signed_distance(p)
                );
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
