//! Defects of real scans applied to a clean synthetic sample, deterministically for a seed:
//! a range-image cut (only the side facing a viewer), holes, Gaussian noise and gross outliers.
//!
//! Applied in that order. Lengths are relative to the bounding-box diagonal `D` of the sample as it
//! enters (after the cut). Cost `O(N · holes)` plus `O(N)`.

use super::SplitMix64;
use crate::geometry::{Aabb, Point3, PointCloud, dist2, dot};
use thiserror::Error;

/// Which part of the surface the scan sees.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Coverage {
    /// All of it (a merged multi-view scan).
    #[default]
    Full,
    /// One range image: the points whose true normal faces `view` (`n · view > 0`, `view` pointing
    /// from the surface to the scanner). Self-occlusion is not modelled. Needs normals.
    RangeImage {
        /// Direction towards the scanner (any length > 0).
        view: Point3,
    },
}

/// The defects to apply (all off by default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Defects {
    /// Range-image cut, applied first.
    pub coverage: Coverage,
    /// Number of holes: centres are random sample points; every point within `hole_radius_rel · D`
    /// of a centre is removed.
    pub holes: usize,
    /// Hole radius relative to `D` (default 0.08).
    pub hole_radius_rel: f64,
    /// Noise: every point moves by `g · σ` along a uniformly random direction, `g` standard normal,
    /// `σ = noise_rel · D` (so the RMS displacement is `σ`). Normals keep their true values.
    pub noise_rel: f64,
    /// Fraction in `[0, 1]` of the points (after holes) replaced by points uniform in the bounding box
    /// grown by 10% per axis (5% on each side), with uniformly random unit normals.
    pub outlier_fraction: f64,
}

impl Default for Defects {
    fn default() -> Self {
        Defects {
            coverage: Coverage::Full,
            holes: 0,
            hole_radius_rel: 0.08,
            noise_rel: 0.0,
            outlier_fraction: 0.0,
        }
    }
}

/// What [`apply_defects`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DefectStats {
    /// Points dropped by the range-image cut.
    pub cut: usize,
    /// Points removed by the holes.
    pub in_holes: usize,
    /// Points replaced by outliers.
    pub outliers: usize,
}

/// Defect parameters that cannot be applied.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum DefectError {
    /// A relative length or fraction is negative, not finite or (for a fraction) above 1.
    #[error("{name} = {value} is out of range: use a finite value in {range}")]
    OutOfRange {
        /// Parameter name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// The accepted range.
        range: &'static str,
    },
    /// A range image needs the true normals and a non-zero view direction.
    #[error("a range image needs a sample with normals and a non-zero, finite view direction")]
    RangeImage,
}

fn check(name: &'static str, value: f64, max: f64, range: &'static str) -> Result<(), DefectError> {
    if value.is_finite() && (0.0..=max).contains(&value) {
        Ok(())
    } else {
        Err(DefectError::OutOfRange { name, value, range })
    }
}

/// Applies `d` to `cloud` in place (order: cut, holes, noise, outliers); the same `seed` gives the
/// same result.
pub fn apply_defects(
    cloud: &mut PointCloud,
    d: &Defects,
    seed: u64,
) -> Result<DefectStats, DefectError> {
    check("noise", d.noise_rel, 1.0, "[0, 1]")?;
    check("hole radius", d.hole_radius_rel, 1.0, "[0, 1]")?;
    check("outlier fraction", d.outlier_fraction, 1.0, "[0, 1]")?;
    let mut rng = SplitMix64(seed ^ 0xDEFE_C7ED_5CA1_AB1E);
    let mut stats = DefectStats::default();
    if let Coverage::RangeImage { view } = d.coverage {
        let n = cloud.normals.as_ref().ok_or(DefectError::RangeImage)?;
        if !view.iter().all(|v| v.is_finite()) || dot(view, view) == 0.0 {
            return Err(DefectError::RangeImage);
        }
        let keep: Vec<bool> = n.iter().map(|n| dot(*n, view) > 0.0).collect();
        stats.cut = retain(cloud, &keep);
    }
    let diagonal = Aabb::from_points(&cloud.points).diagonal();
    if d.holes > 0 && !cloud.points.is_empty() {
        let r2 = (d.hole_radius_rel * diagonal).powi(2);
        let centres: Vec<Point3> = (0..d.holes)
            .map(|_| cloud.points[(rng.next_u64() % cloud.points.len() as u64) as usize])
            .collect();
        let keep: Vec<bool> = cloud
            .points
            .iter()
            .map(|p| centres.iter().all(|c| dist2(*p, *c) > r2))
            .collect();
        stats.in_holes = retain(cloud, &keep);
    }
    if d.noise_rel > 0.0 {
        let sigma = d.noise_rel * diagonal;
        for p in &mut cloud.points {
            let g = sigma * rng.next_gaussian();
            let u = rng.next_unit_vector();
            for k in 0..3 {
                p[k] += g * u[k];
            }
        }
    }
    stats.outliers = replace_with_outliers(cloud, d.outlier_fraction, &mut rng);
    Ok(stats)
}

/// Keeps the points (and normals) whose flag is set; returns how many were dropped.
fn retain(cloud: &mut PointCloud, keep: &[bool]) -> usize {
    let before = cloud.points.len();
    let mut it = keep.iter();
    cloud.points.retain(|_| *it.next().unwrap_or(&true));
    if let Some(n) = cloud.normals.as_mut() {
        let mut it = keep.iter();
        n.retain(|_| *it.next().unwrap_or(&true));
    }
    before - cloud.points.len()
}

/// Replaces `round(fraction · N)` distinct random points by uniform points in the bounding box grown
/// by 10% per axis (random unit normals); returns the count.
fn replace_with_outliers(cloud: &mut PointCloud, fraction: f64, rng: &mut SplitMix64) -> usize {
    let n = cloud.points.len();
    let count = ((fraction * n as f64).round() as usize).min(n);
    if count == 0 {
        return 0;
    }
    let bb = Aabb::from_points(&cloud.points);
    let ext = bb.extent();
    let lo: Point3 = std::array::from_fn(|k| bb.min[k] - 0.05 * ext[k]);
    // Partial Fisher–Yates: the first `count` entries of `order` are a uniform random subset.
    let mut order: Vec<usize> = (0..n).collect();
    for i in 0..count {
        let j = i + (rng.next_u64() % (n - i) as u64) as usize;
        order.swap(i, j);
        let idx = order[i];
        cloud.points[idx] = std::array::from_fn(|k| lo[k] + 1.1 * ext[k] * rng.next_f64());
        let normal = rng.next_unit_vector();
        if let Some(nr) = cloud.normals.as_mut() {
            nr[idx] = normal;
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::super::Shape;
    use super::*;

    #[test]
    fn noise_has_the_requested_rms_and_keeps_true_normals() {
        let s = Shape::by_name("sphere").unwrap();
        let clean = s.sample(20_000, 5);
        let mut noisy = clean.clone();
        let d = Defects {
            noise_rel: 0.005,
            ..Default::default()
        };
        apply_defects(&mut noisy, &d, 1).unwrap();
        let sigma = 0.005 * Aabb::from_points(&clean.points).diagonal();
        let rms = (clean
            .points
            .iter()
            .zip(&noisy.points)
            .map(|(a, b)| dist2(*a, *b))
            .sum::<f64>()
            / 20_000.0)
            .sqrt();
        assert!((rms / sigma - 1.0).abs() < 0.03, "rms {rms} vs σ {sigma}");
        // Normal component of a random direction: RMS σ/√3.
        let rms_n = (noisy
            .points
            .iter()
            .map(|p| s.signed_distance(p).powi(2))
            .sum::<f64>()
            / 20_000.0)
            .sqrt();
        assert!((rms_n * 3f64.sqrt() / sigma - 1.0).abs() < 0.05, "{rms_n}");
        assert_eq!(noisy.normals, clean.normals);
    }

    #[test]
    fn outliers_holes_and_cut_do_what_they_say_deterministically() {
        let s = Shape::by_name("sphere").unwrap();
        let clean = s.sample(10_000, 2);
        let d = Defects {
            outlier_fraction: 0.05,
            holes: 3,
            coverage: Coverage::RangeImage {
                view: [0.0, 0.0, 2.0],
            },
            ..Default::default()
        };
        let mut a = clean.clone();
        let st = apply_defects(&mut a, &d, 7).unwrap();
        let mut b = clean.clone();
        assert_eq!(apply_defects(&mut b, &d, 7).unwrap(), st);
        assert_eq!(a, b);
        // Half the sphere faces +z.
        assert!((st.cut as f64 - 5000.0).abs() < 200.0, "{st:?}");
        // The hemisphere's box is 0.8 × 0.8 × 0.4 (D = 1.2), so a hole is a cap of radius
        // ρ = 0.096 and area π ρ², 2.9% of the hemisphere's 2π R²; at most 3 of them, at least
        // half of one.
        let kept = 10_000 - st.cut;
        let cap = std::f64::consts::PI * 0.096f64.powi(2) / (std::f64::consts::TAU * 0.16);
        let frac = st.in_holes as f64 / kept as f64;
        assert!(
            frac > 0.5 * cap && frac < 3.0 * cap + 0.01,
            "{st:?}, cap {cap}"
        );
        assert_eq!(
            st.outliers,
            ((kept - st.in_holes) as f64 * 0.05).round() as usize
        );
        let off = a
            .points
            .iter()
            .filter(|p| s.signed_distance(p).abs() > 1e-9)
            .count();
        assert_eq!(off, st.outliers);
        let nrm = a.normals.as_ref().unwrap();
        assert!(
            nrm.iter()
                .all(|n| (crate::geometry::norm(*n) - 1.0).abs() < 1e-12)
        );
        let on: Vec<&Point3> = a
            .points
            .iter()
            .filter(|p| s.signed_distance(p).abs() < 1e-9)
            .collect();
        assert!(on.iter().all(|p| p[2] > 0.5 - 1e-12));
        let mut c = clean.clone();
        apply_defects(&mut c, &d, 8).unwrap();
        assert_ne!(a, c);
    }

    #[test]
    fn bad_parameters_are_refused() {
        let mut c = Shape::by_name("sphere").unwrap().sample(100, 1);
        for d in [
            Defects {
                noise_rel: -0.1,
                ..Default::default()
            },
            Defects {
                outlier_fraction: 1.5,
                ..Default::default()
            },
            Defects {
                noise_rel: f64::NAN,
                ..Default::default()
            },
            Defects {
                coverage: Coverage::RangeImage { view: [0.0; 3] },
                ..Default::default()
            },
        ] {
            assert!(apply_defects(&mut c, &d, 1).is_err(), "{d:?}");
        }
        c.normals = None;
        let d = Defects {
            coverage: Coverage::RangeImage {
                view: [0.0, 0.0, 1.0],
            },
            ..Default::default()
        };
        assert_eq!(apply_defects(&mut c, &d, 1), Err(DefectError::RangeImage));
    }
}
