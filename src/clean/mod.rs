//! Stage "clean": drop non-finite points, merge duplicates, reject degenerate clouds, and
//! (optionally) remove statistical outliers ([`outliers`]). It sits above [`crate::spatial`],
//! whose index finds the duplicates and neighbours.
//!
//! Duplicates: a point is dropped when an earlier point (lower index) lies within `tolerance`
//! (relative to the bbox diagonal) — deterministic, parallel, `O(n log n)`. Degeneracy is judged
//! by PCA after cleaning: collinear clouds are refused; coplanar ones need normals.

use crate::geometry::pca::pca;
use crate::geometry::{Aabb, Point3, PointCloud, normalized};
use crate::spatial::{IndexKind, SpatialError, build_index};
use rayon::prelude::*;

pub(crate) mod denoise;
pub(crate) mod outliers;
pub(crate) mod strays;

pub use outliers::OutlierParams;

/// Cleaning parameters.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CleanParams {
    /// Points closer than this fraction of the bbox diagonal are merged (default 1e-6).
    pub merge_tolerance: f64,
}

impl Default for CleanParams {
    fn default() -> Self {
        CleanParams {
            merge_tolerance: 1e-6,
        }
    }
}

/// What cleaning did (report `input` section).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CleanStats {
    /// Points read.
    pub points: usize,
    /// Points kept.
    pub used: usize,
    /// Points with a NaN or infinite coordinate.
    pub dropped_non_finite: usize,
    /// Points merged into an earlier duplicate.
    pub merged_duplicates: usize,
    /// Whether normals are used.
    pub has_normals: bool,
    /// Points whose normal was zero or non-finite (kept as positions; their normal is ignored).
    pub invalid_normals: usize,
    /// Points removed by the statistical outlier filter.
    pub outliers_removed: usize,
    /// Points of a noisy cloud removed as strays off the surface ([`strays`]).
    #[serde(default)]
    pub strays_removed: usize,
    /// Points of a noisy cloud moved onto their neighbourhood's quadric ([`denoise`]).
    #[serde(default)]
    pub denoised: usize,
}

/// Why a cloud cannot be reconstructed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum InputError {
    /// No points at all.
    #[error("the input holds no points")]
    Empty,
    /// Every point had a NaN/inf coordinate.
    #[error("all {total} points have NaN or infinite coordinates; nothing is left to reconstruct")]
    NoFinitePoints {
        /// Points read.
        total: usize,
    },
    /// Fewer than 4 distinct points.
    #[error(
        "only {distinct} distinct point(s) after cleaning; a surface needs at least 4 points not in one plane"
    )]
    TooFewPoints {
        /// Distinct finite points.
        distinct: usize,
    },
    /// All points on a line.
    #[error(
        "all {n} points lie on a straight line: no surface passes through them; scan more than one line"
    )]
    Collinear {
        /// Point count.
        n: usize,
    },
    /// The neighbour index could not be built.
    #[error(transparent)]
    Index(#[from] SpatialError),
    /// All points in a plane and no normals.
    #[error(
        "all {n} points lie in one plane: without normals the inside and outside are undefined; give points with normals (PLY nx ny nz or 6-column XYZ)"
    )]
    Coplanar {
        /// Point count.
        n: usize,
    },
    /// The points lie along lines or curves: no surface through them.
    #[error(
        "the {n} points sample a curve, not a surface: their neighbourhoods are lines (median \
         second/total variance {breadth:.4} at {scale} neighbours; surfaces give > 0.3). Scan the \
         surface itself, not a line or a profile across it"
    )]
    NotASurfaceButACurve {
        /// Point count.
        n: usize,
        /// [`crate::geometry::pca::LocalShape::breadth`].
        breadth: f64,
        /// Neighbours at which it was measured.
        scale: usize,
    },
    /// The points fill a volume at every scale: pure noise, not a sampled surface.
    #[error(
        "the {n} points do not sample a surface: their neighbourhoods are as thick as they are wide at \
         every scale (median thinnest/total variance {thickness:.2} at 16, 64 and 256 neighbours; \
         surfaces, even noisy ones, give < 0.12). Is this pure noise or a volume? Check the input"
    )]
    NotASurface {
        /// Point count.
        n: usize,
        /// Smallest (over the scales) median share of the least local variance.
        thickness: f64,
    },
}

/// Clean `cloud`: returns the kept points (input units) in Morton order
/// ([`crate::spatial::morton_order`]), unit normals (zero vectors where invalid), the other
/// attributes alike, and statistics.
pub fn clean_cloud(
    cloud: &PointCloud,
    params: &CleanParams,
) -> Result<(PointCloud, CleanStats), InputError> {
    let total = cloud.points.len();
    if total == 0 {
        return Err(InputError::Empty);
    }
    let finite: Vec<usize> = (0..total)
        .filter(|&i| cloud.points[i].iter().all(|v| v.is_finite()))
        .collect();
    if finite.is_empty() {
        return Err(InputError::NoFinitePoints { total });
    }
    let pts: Vec<Point3> = finite.iter().map(|&i| cloud.points[i]).collect();
    // A collinear cloud is refused before the duplicate merge: one O(n) pass instead of a tree
    // over points that all lie on one line (merging cannot make a cloud less collinear).
    if pts.len() >= 4 && is_collinear(&pts) {
        return Err(InputError::Collinear { n: pts.len() });
    }
    // A zero diagonal (all points equal) still merges exact duplicates.
    let tol = (params.merge_tolerance * Aabb::from_points(&pts).diagonal()).max(f64::MIN_POSITIVE);
    let keep: Vec<bool> = if params.merge_tolerance > 0.0 {
        let tree = build_index(&pts, IndexKind::KdTree, 16)?;
        (0..pts.len())
            .into_par_iter()
            .map_init(Vec::new, |hits, i| {
                tree.within(&pts[i], tol, hits);
                !hits.iter().any(|&h| (h as usize) < i)
            })
            .collect()
    } else {
        vec![true; pts.len()]
    };
    // The kept points in Morton order: every later stage's neighbour accesses then stay in
    // cache (a file in random order cost twice the time, see `spatial::morton_order`).
    let mut kept: Vec<usize> = (0..pts.len()).filter(|&k| keep[k]).collect();
    crate::spatial::sort_by_morton(&pts, &mut kept);
    let points: Vec<Point3> = kept.iter().map(|&k| pts[k]).collect();
    let mut invalid_normals = 0;
    let normals = cloud
        .normals
        .as_ref()
        .filter(|n| n.len() == total)
        .map(|n| {
            kept.iter()
                .map(|&k| {
                    normalized(n[finite[k]]).unwrap_or_else(|| {
                        invalid_normals += 1;
                        [0.0; 3]
                    })
                })
                .collect::<Vec<_>>()
        });
    let normals = normals.filter(|_| invalid_normals < kept.len());
    let stats = CleanStats {
        points: total,
        used: points.len(),
        dropped_non_finite: total - finite.len(),
        merged_duplicates: finite.len() - points.len(),
        has_normals: normals.is_some(),
        invalid_normals: if normals.is_some() {
            invalid_normals
        } else {
            0
        },
        outliers_removed: 0,
        strays_removed: 0,
        denoised: 0,
    };
    check_degenerate(&points, normals.is_some())?;
    // Colours and intensity follow the kept points (a merged duplicate keeps the first's).
    let source: Vec<usize> = kept.iter().map(|&k| finite[k]).collect();
    let (colors, intensity) = cloud.attributes_at(&source);
    let crs = cloud.crs.clone();
    let kept_cloud = PointCloud {
        points,
        normals,
        colors,
        intensity,
        crs,
    };
    Ok((kept_cloud, stats))
}

/// True when the points span a line (or a single point counts as not collinear: the merge makes
/// it one point, refused as too few). Linear time.
fn is_collinear(points: &[Point3]) -> bool {
    let p = pca(points);
    let l0 = p.variances[0];
    l0 > 0.0 && p.variances[1].max(0.0).sqrt() <= 1e-7 * l0.sqrt()
}

/// Refuse clouds with fewer than 4 points, collinear clouds, and coplanar clouds without normals.
pub fn check_degenerate(points: &[Point3], has_normals: bool) -> Result<(), InputError> {
    let n = points.len();
    if n < 4 {
        return Err(InputError::TooFewPoints { distinct: n });
    }
    let p = pca(points);
    let l0 = p.variances[0].max(f64::MIN_POSITIVE);
    if p.variances[1].max(0.0).sqrt() <= 1e-7 * l0.sqrt() {
        return Err(InputError::Collinear { n });
    }
    if !has_normals && p.variances[2].max(0.0).sqrt() <= 1e-7 * l0.sqrt() {
        return Err(InputError::Coplanar { n });
    }
    Ok(())
}

/// Local thickness (see [`crate::geometry::pca::LocalShape`]) above which the points are taken
/// for noise filling a volume rather than a sampled surface.
const MAX_SURFACE_THICKNESS: f64 = 0.12;
/// Local breadth below which the points are taken for a curve: the second axis of their
/// neighbourhoods under a tenth of the first, where every scan of the real-scan suite measures
/// 0.31–0.47.
const MIN_SURFACE_BREADTH: f64 = 0.01;

/// Refuse a cloud that does not sample a surface: one that fills a volume at every scale (pure
/// noise), or whose neighbourhoods are lines (points along a curve; exactly collinear clouds are
/// refused earlier by [`check_degenerate`]). Neighbours come from `nearest_k`.
pub fn check_local_shape(
    points: &[Point3],
    nearest_k: impl Fn(&Point3, usize, &mut Vec<(u32, f64)>) + Sync,
) -> Result<(), InputError> {
    let shape = crate::geometry::pca::local_shape(points, nearest_k);
    let n = points.len();
    if shape.thickness > MAX_SURFACE_THICKNESS {
        return Err(InputError::NotASurface {
            n,
            thickness: shape.thickness,
        });
    }
    if shape.breadth < MIN_SURFACE_BREADTH {
        return Err(InputError::NotASurfaceButACurve {
            n,
            breadth: shape.breadth,
            scale: shape.scale,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(points: Vec<Point3>) -> PointCloud {
        PointCloud {
            points,
            normals: None,
            ..Default::default()
        }
    }

    #[test]
    fn non_finite_points_are_dropped_and_duplicates_merged() {
        let mut p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        p.push([f64::NAN, 0.0, 0.0]);
        p.push([1.0, 0.0, f64::INFINITY]);
        p.push([1.0, 0.0, 0.0]);
        p.push([1.0 + 1e-9, 0.0, 0.0]);
        let (c, s) = clean_cloud(&cloud(p), &CleanParams::default()).unwrap();
        assert_eq!(s.points, 8);
        assert_eq!(s.dropped_non_finite, 2);
        assert_eq!(s.merged_duplicates, 2);
        assert_eq!(c.points.len(), 4);
        assert_eq!(s.used, 4);
    }

    #[test]
    fn degenerate_clouds_are_refused_with_the_reason() {
        assert!(matches!(
            clean_cloud(&cloud(vec![]), &CleanParams::default()),
            Err(InputError::Empty)
        ));
        let nan = cloud(vec![[f64::NAN; 3]; 3]);
        assert!(matches!(
            clean_cloud(&nan, &CleanParams::default()),
            Err(InputError::NoFinitePoints { total: 3 })
        ));
        let dup = cloud(vec![[1.0; 3]; 10]);
        assert!(matches!(
            clean_cloud(&dup, &CleanParams::default()),
            Err(InputError::TooFewPoints { distinct: 1 })
        ));
        let line = cloud((0..20).map(|i| [i as f64, 2.0 * i as f64, 1.0]).collect());
        assert!(matches!(
            clean_cloud(&line, &CleanParams::default()),
            Err(InputError::Collinear { n: 20 })
        ));
        let plane: Vec<Point3> = (0..100)
            .map(|i| [(i % 10) as f64, (i / 10) as f64, 3.0])
            .collect();
        assert!(matches!(
            clean_cloud(&cloud(plane.clone()), &CleanParams::default()),
            Err(InputError::Coplanar { .. })
        ));
        let with_normals = PointCloud {
            normals: Some(vec![[0.0, 0.0, 1.0]; 100]),
            points: plane,
            ..Default::default()
        };
        assert!(clean_cloud(&with_normals, &CleanParams::default()).is_ok());
    }

    #[test]
    fn invalid_normals_are_counted() {
        let p = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        let n = vec![
            [0.0, 0.0, 2.0],
            [0.0; 3],
            [f64::NAN, 0.0, 0.0],
            [1.0, 0.0, 0.0],
        ];
        let (c, s) = clean_cloud(
            &PointCloud {
                points: p,
                normals: Some(n),
                ..Default::default()
            },
            &CleanParams::default(),
        )
        .unwrap();
        assert_eq!(s.invalid_normals, 2);
        assert_eq!(c.normals.unwrap()[0], [0.0, 0.0, 1.0]);
    }
}
