//! Statistical outlier removal: a point whose mean distance to its k nearest neighbours exceeds the
//! median of that statistic over the cloud by more than `std_ratio` robust standard deviations
//! (1.4826 · median absolute deviation) is dropped — the PCL / Open3D filter with robust statistics,
//! so a few gross outliers cannot mask each other. `O(n k log n)`, parallel, deterministic.

use crate::geometry::{Point3, PointCloud};
use crate::spatial::{KdTree, SpatialIndex};
use rayon::prelude::*;

/// Parameters of the statistical filter.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct OutlierParams {
    /// Neighbours for the mean distance (default 16).
    pub neighbours: usize,
    /// Points beyond `median + std_ratio · 1.4826 · MAD` are outliers (default 3; smaller removes more).
    pub std_ratio: f64,
}

impl Default for OutlierParams {
    fn default() -> Self {
        OutlierParams {
            neighbours: 16,
            std_ratio: 3.0,
        }
    }
}

/// The cloud without its statistical outliers, and how many were removed.
pub fn remove_outliers(cloud: &PointCloud, params: &OutlierParams) -> (PointCloud, usize) {
    let n = cloud.points.len();
    let k = params.neighbours.min(n.saturating_sub(1));
    let Ok(tree) = KdTree::build(&cloud.points) else {
        return (cloud.clone(), 0);
    };
    if k == 0 {
        return (cloud.clone(), 0);
    }
    let mean_dist: Vec<f64> = cloud
        .points
        .par_iter()
        .map_init(Vec::new, |nn, p: &Point3| {
            tree.nearest_k(p, k + 1, nn);
            nn.iter().skip(1).map(|&(_, d)| d).sum::<f64>() / k as f64
        })
        .collect();
    // Robust centre and spread (median, 1.4826 · MAD = σ for a normal distribution): gross outliers
    // would inflate a plain mean/std and hide each other.
    let median = crate::geometry::median(&mut mean_dist.clone());
    let mad = crate::geometry::median(
        &mut (mean_dist.iter())
            .map(|d| (d - median).abs())
            .collect::<Vec<_>>(),
    );
    let limit = median + params.std_ratio * 1.4826 * mad.max(1e-12 * median);
    let keep: Vec<usize> = (0..n).filter(|&i| mean_dist[i] <= limit).collect();
    (cloud.select(&keep), n - keep.len())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::{Shape, SplitMix64};

    #[test]
    fn scattered_outliers_are_removed_and_surface_points_kept() {
        let mut cloud = Shape::by_name("sphere").unwrap().sample(5000, 3);
        let mut rng = SplitMix64(5);
        let normals = cloud.normals.as_mut().unwrap();
        let sphere = Shape::by_name("sphere").unwrap();
        let mut added = 0;
        while added < 250 {
            let q = [rng.next_f64(), rng.next_f64(), rng.next_f64()];
            if sphere.signed_distance(&q).abs() > 0.05 {
                cloud.points.push(q);
                normals.push([0.0, 0.0, 1.0]);
                added += 1;
            }
        }
        let (clean, removed) = remove_outliers(&cloud, &OutlierParams::default());
        let surviving_outliers = clean
            .points
            .iter()
            .filter(|p| sphere.signed_distance(p).abs() > 1e-9)
            .count();
        let lost_surface = 5000
            - clean
                .points
                .iter()
                .filter(|p| sphere.signed_distance(p).abs() <= 1e-9)
                .count();
        assert!(
            surviving_outliers == 0,
            "{surviving_outliers} of 250 outliers survive (removed {removed})"
        );
        assert!(lost_surface < 50, "{lost_surface} surface points removed");
        assert_eq!(clean.normals.unwrap().len(), clean.points.len());
    }
}
