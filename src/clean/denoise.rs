//! Denoising of noisy scans by local quadric projection: each point is moved along its
//! neighbourhood's normal onto the least-squares height-field quadric of its
//! [`DENOISE_NEIGHBOURS`] nearest points (itself included), one pass, Jacobi style (every fit
//! sees the original positions, so the result does not depend on the order or the thread count).
//!
//! Why: a smoothing spline (λ > 0) averages the noise over the few points its support covers; a
//! quadric over `k` points leaves about `2σ/√k` of it at the centre of a uniform patch (the
//! constant term's variance of a quadric fit, 4σ²/k), without the spline's shrinkage of curved
//! parts, since a quadric follows curvature. The spline then fits the projected points with the
//! smoothing the noise estimate chose. The pipeline applies it only to clouds the noise estimate
//! calls noisy *and* smooth at the scale of 48 neighbours ([`crate::rbf::noise::SMOOTH_RATIO`]):
//! clean data are interpolated as they are, and on noisy statues, whose detail a quadric over 32
//! points flattens, it cost more than it gained (Chamfer of a 26k-point armadillo with noise of
//! 0.25 % of the diagonal 6.36e-4 → 6.94e-4; noisy 10⁶ torus 1.17e-4 → 8.8e-5 of the diagonal).
//! It keeps the points' order, count, normals and colours. `O(n k log n)`, parallel.

use crate::geometry::Point3;
use crate::rbf::noise::LocalQuadric;
use rayon::prelude::*;

/// Neighbours of each point's quadric fit (the point itself included).
pub const DENOISE_NEIGHBOURS: usize = 32;

/// A point moves at most this many noise levels σ.
pub const MAX_SHIFT: f64 = 4.0;

/// A neighbourhood whose quadric leaves an RMS residual above this many σ holds geometry a
/// quadric does not follow (fine detail, an edge, two sheets): its point stays.
pub const MAX_RESIDUAL: f64 = 1.5;

/// The points projected onto their neighbourhoods' quadrics (`nearest_k` finds neighbours, a
/// point its own first; `sigma` is the cloud's noise level). A point stays where it is when its
/// neighbourhood is degenerate, when the quadric does not describe it (RMS residual over
/// [`MAX_RESIDUAL`] σ), or when it would move farther than [`MAX_SHIFT`] σ (a point off its
/// neighbours' surface, which the stray filter leaves to the fit).
pub fn denoise(
    points: &[Point3],
    sigma: f64,
    nearest_k: impl Fn(&Point3, usize, &mut Vec<(u32, f64)>) + Sync,
) -> Vec<Point3> {
    let k = DENOISE_NEIGHBOURS;
    if points.len() <= 2 * k || sigma.is_nan() || sigma <= 0.0 {
        return points.to_vec();
    }
    let max_shift = MAX_SHIFT * sigma;
    points
        .par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(knn, nb): &mut (Vec<(u32, f64)>, Vec<Point3>), p| {
                nearest_k(p, k, knn);
                nb.clear();
                nb.extend(knn.iter().map(|&(j, _)| points[j as usize]));
                let Some(q) = LocalQuadric::fit(nb) else {
                    return *p;
                };
                if q.rms_residual(nb) > MAX_RESIDUAL * sigma {
                    return *p;
                }
                let moved = q.project(*p);
                if crate::geometry::dist2(moved, *p) <= max_shift * max_shift {
                    moved
                } else {
                    *p
                }
            },
        )
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::SplitMix64;
    use crate::spatial::{IndexKind, build_index};

    /// Points of a sphere (radius 0.3 about 0.5) on a Fibonacci lattice, pushed radially by
    /// Gaussian noise of `sigma`; returns the noisy points.
    fn noisy_sphere(n: usize, sigma: f64) -> Vec<Point3> {
        let mut rng = SplitMix64(7);
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let t = golden * i as f64;
                let s = 0.3 + sigma * rng.next_gaussian();
                [0.5 + s * r * t.cos(), 0.5 + s * r * t.sin(), 0.5 + s * z]
            })
            .collect()
    }

    fn rms_off_sphere(points: &[Point3]) -> f64 {
        let ss: f64 = points
            .iter()
            .map(|p| {
                let d = crate::geometry::norm(crate::geometry::sub(*p, [0.5; 3])) - 0.3;
                d * d
            })
            .sum();
        (ss / points.len() as f64).sqrt()
    }

    #[test]
    fn noise_drops_by_the_quadrics_averaging_and_clean_points_stay() {
        let sigma = 0.002;
        let noisy = noisy_sphere(20000, sigma);
        let idx = build_index(&noisy, IndexKind::KdTree, 16).unwrap();
        let out = denoise(&noisy, sigma, |p, k, o| idx.nearest_k(p, k, o));
        let (before, after) = (rms_off_sphere(&noisy), rms_off_sphere(&out));
        // A quadric over 32 points leaves about 2σ/√32 ≈ 0.35 σ at a patch's centre.
        assert!((before / sigma - 1.0).abs() < 0.05, "{before}");
        assert!(after < 0.45 * before, "{before} → {after}");
        // Order and count are kept: each point moves by less than the noise allows.
        assert_eq!(out.len(), noisy.len());
        let most = (noisy.iter().zip(&out))
            .map(|(a, b)| crate::geometry::dist2(*a, *b).sqrt())
            .fold(0.0, f64::max);
        assert!(most < 6.0 * sigma, "{most}");

        // Exact sphere points: the quadric's bias at this spacing is far below the noise.
        let clean = noisy_sphere(20000, 0.0);
        let idx = build_index(&clean, IndexKind::KdTree, 16).unwrap();
        let out = denoise(&clean, 1e-3, |p, k, o| idx.nearest_k(p, k, o));
        assert!(rms_off_sphere(&out) < 1e-5, "{}", rms_off_sphere(&out));
    }

    #[test]
    fn a_point_that_would_move_too_far_stays() {
        let mut pts = noisy_sphere(5000, 0.0);
        pts[10] = [0.5, 0.5, 0.5 + 0.3 + 0.05];
        let idx = build_index(&pts, IndexKind::KdTree, 16).unwrap();
        let out = denoise(&pts, 0.0025, |p, k, o| idx.nearest_k(p, k, o));
        assert_eq!(out[10], pts[10]);
    }
}
