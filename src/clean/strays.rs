//! Strays of noisy scans: points that lie off the surface their neighbours describe, farther than
//! the noise explains. Range scans leave them at their silhouettes (mixed pixels: samples between
//! the object's edge and the background, often in one-pixel streaks), and a merged multi-view
//! scan holds them inside the other views' surface, where their neighbour distances are ordinary
//! (so the statistical filter of [`super::outliers`] does not see them). A smoothing fit still
//! follows a streak of them: on the ten merged Stanford bunny views (362,272 points, x y z only)
//! they made a genus-22 surface, genus 0 once the 2,366 strays below are dropped.
//!
//! Test: the distance of the point to the least-squares plane of its [`STRAY_NEIGHBOURS`]
//! nearest other points, against [`STRAY_SIGMAS`] times the cloud's noise level σ (the median
//! quadric residual, [`crate::rbf::estimate_noise`]). The pipeline applies it only to clouds the
//! noise estimate calls noisy, before normals are estimated (a streak misleads their
//! orientation too): clean data keep every point (they are interpolated). Gaussian noise leaves
//! almost nothing beyond 5 σ (62 of 26,000 points of a noisy statue; 3 σ took 4 % of it and of
//! the merged bunny, and cost the statue 4 % of its Chamfer distance). `O(n k log n)`, parallel,
//! deterministic.

use crate::geometry::pca::pca;
use crate::geometry::{Point3, dot, sub};
use rayon::prelude::*;

/// Neighbours of the plane fit (the point itself excluded).
pub const STRAY_NEIGHBOURS: usize = 16;

/// A point farther than this many noise levels σ from its neighbours' plane is a stray.
pub const STRAY_SIGMAS: f64 = 5.0;

/// Per point, `true` when it lies farther than `STRAY_SIGMAS · sigma` from the plane of its
/// [`STRAY_NEIGHBOURS`] nearest other points (`nearest_k` finds neighbours, a point its own
/// first). `sigma ≤ 0` flags nothing.
pub fn strays(
    points: &[Point3],
    sigma: f64,
    nearest_k: impl Fn(&Point3, usize, &mut Vec<(u32, f64)>) + Sync,
) -> Vec<bool> {
    if sigma.is_nan() || sigma <= 0.0 || points.len() <= 2 * STRAY_NEIGHBOURS {
        return vec![false; points.len()];
    }
    let limit = STRAY_SIGMAS * sigma;
    (0..points.len())
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(knn, nb): &mut (Vec<(u32, f64)>, Vec<Point3>), i| {
                nearest_k(&points[i], STRAY_NEIGHBOURS + 1, knn);
                nb.clear();
                nb.extend(
                    (knn.iter())
                        .filter(|&&(j, _)| j as usize != i)
                        .take(STRAY_NEIGHBOURS)
                        .map(|&(j, _)| points[j as usize]),
                );
                if nb.len() < STRAY_NEIGHBOURS {
                    return false;
                }
                let p = pca(nb);
                dot(sub(points[i], p.centroid), p.axes[2]).abs() > limit
            },
        )
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::{Shape, SplitMix64};

    fn brute_knn(points: &[Point3]) -> impl Fn(&Point3, usize, &mut Vec<(u32, f64)>) + Sync + '_ {
        move |p, k, out| {
            out.clear();
            out.extend(
                (0..points.len() as u32)
                    .map(|j| (j, crate::geometry::dist2(*p, points[j as usize]).sqrt())),
            );
            out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            out.truncate(k);
        }
    }

    #[test]
    fn a_streak_off_a_noisy_sphere_is_flagged_and_its_noise_kept() {
        // A sphere of radius ~0.4 with Gaussian noise σ = 0.002 along the normal, and a streak of
        // 20 points 0.02 (10 σ) outside it, as a range scan's mixed pixels at a silhouette.
        let sphere = Shape::by_name("sphere").unwrap();
        let mut cloud = sphere.sample(3000, 4);
        let mut rng = SplitMix64(9);
        let sigma = 0.002;
        let normals = cloud.normals.clone().unwrap();
        for (p, n) in cloud.points.iter_mut().zip(&normals) {
            let e = sigma * rng.next_gaussian();
            *p = [0, 1, 2].map(|k| p[k] + e * n[k]);
        }
        let clean = cloud.points.len();
        for i in 0..20 {
            let (p, n) = (cloud.points[i * 7], normals[i * 7]);
            cloud
                .points
                .push([0, 1, 2].map(|k| p[k] + 10.0 * sigma * n[k]));
        }
        let flags = strays(&cloud.points, sigma, brute_knn(&cloud.points));
        let streak = flags[clean..].iter().filter(|f| **f).count();
        let noise = flags[..clean].iter().filter(|f| **f).count();
        assert!(streak >= 18, "{streak} of the 20 stray points flagged");
        // Gaussian noise beyond 5σ: none to speak of; the streak's neighbours lean a little.
        assert!(
            noise <= clean / 300,
            "{noise} of {clean} noisy surface points flagged"
        );
        // No noise level: nothing is flagged.
        assert!(!strays(&cloud.points, 0.0, brute_knn(&cloud.points)).contains(&true));
    }
}
