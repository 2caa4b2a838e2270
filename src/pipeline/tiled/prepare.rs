//! The task graph's first step, run once over the whole cloud: clean (non-finite points,
//! duplicates), normalise, choose the support and the smoothing, orient the carrier, plan the
//! blocks and regions, and write every block's point set (its outer box and halo) to the store in
//! one pass. What it keeps for later tasks is small: the plan, the boxes and a bounded subsample.
//!
//! Memory: the cloud (48 bytes per point with normals, cleaned and normalised in place) plus one
//! k-d tree over it (~40 bytes per point) while the support, the noise and the duplicates are
//! measured; both are freed before any block is fitted. The global decisions are therefore the
//! same as the in-memory pipeline's (same support estimate, noise estimate, duplicate rule).

use super::store::{PointSet, Store};
use super::tasks::{GridPlan, block_key};
use super::{TiledError, TiledOptions};
use crate::clean::{CleanStats, InputError, check_degenerate};
use crate::error::ReconError;
use crate::geometry::{Aabb, Normalization, Point3, PointCloud, normalized};
use crate::params::{Boundary, ReconParams, Smoothing};
use crate::progress::{Progress, Stage};
use crate::rbf::winding::WindingGrid;
use crate::rbf::{
    Carrier, CarrierKind, NoiseEstimate, SupportEstimate, estimate_noise, estimate_support,
    plan_blocks,
};
use crate::spatial::{IndexKind, SpatialIndex, build_index};
use rayon::prelude::*;
use std::sync::Arc;

/// Most points of the subsample that builds the winding far field and counts the floaters'
/// support (every `⌈n / SAMPLE_POINTS⌉`-th cleaned point).
pub(crate) const SAMPLE_POINTS: usize = 400_000;

/// Share of opposed neighbour normals above which the normals count as inconsistent (as in the
/// in-memory pipeline, which then reorients them; that needs the whole cloud, so here it refuses).
const INCONSISTENT_NORMALS: f64 = 0.05;

/// Local thickness above which the points fill a volume (as in the in-memory pipeline).
const MAX_SURFACE_THICKNESS: f64 = 0.12;

/// The carrier every task rebuilds over its own points.
pub(crate) enum CarrierPlan {
    /// A global analytic carrier, fitted once.
    Sphere { center: Point3, radius: f64 },
    /// A global PCA ellipsoid, fitted once.
    Ellipsoid {
        center: Point3,
        axes: [Point3; 3],
        semi_axes: [f64; 3],
    },
    /// Tangent planes of the task's points; the far field is the winding number of the
    /// subsample, shared by every task.
    Local { winding: Option<Arc<WindingGrid>> },
}

/// A partition-of-unity block: its boxes and how many points it fits and stores.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct BlockBox {
    /// Weight 1 inside, normalised units.
    pub core: Aabb,
    /// Weight 0 outside, normalised units.
    pub outer: Aabb,
    /// Points inside `outer` (the block's system size).
    pub members: usize,
}

/// Everything the tasks share, decided once over the whole cloud.
pub(crate) struct Plan {
    pub normalization: Normalization,
    pub support: SupportEstimate,
    pub noise: NoiseEstimate,
    /// The parameters with the smoothing resolved.
    pub params: ReconParams,
    pub blocks: Vec<BlockBox>,
    /// Extra reach of every stored point set beyond its box (the carrier's neighbourhoods).
    pub halo: f64,
    pub carrier: CarrierPlan,
    pub grid: GridPlan,
    /// Every `step`-th cleaned point (normalised units), at most [`SAMPLE_POINTS`].
    pub sample: Vec<Point3>,
    /// Their normals (outwards, after any flip), when the input has normals: with the sample
    /// they rebuild the local carrier's far field wherever the plan is decoded.
    #[cfg_attr(not(feature = "nats"), allow(dead_code))]
    pub sample_normals: Option<Vec<Point3>>,
    pub clean: CleanStats,
    pub normals_flipped: bool,
    pub carrier_kind: CarrierKind,
}

/// Refuse what the task graph cannot do before any work.
pub(crate) fn check_supported(params: &ReconParams) -> Result<(), TiledError> {
    if params.method != crate::params::Method::Csrbf {
        return Err(TiledError::Unsupported("--method other than csrbf"));
    }
    if params.boundary == Boundary::Trim {
        return Err(TiledError::Unsupported("--boundary trim"));
    }
    if params.outliers.is_some() {
        return Err(TiledError::Unsupported("--outliers"));
    }
    Ok(())
}

/// Clean and normalise `cloud` in place: drop non-finite points, make normals unit (zero where
/// unusable). Returns the statistics so far and the transform.
fn clean_in_place(cloud: &mut PointCloud) -> Result<(CleanStats, Normalization), ReconError> {
    let total = cloud.points.len();
    if total == 0 {
        return Err(InputError::Empty.into());
    }
    cloud.colors = None;
    cloud.intensity = None;
    if cloud.normals.as_ref().is_some_and(|n| n.len() != total) {
        cloud.normals = None;
    }
    let finite: Vec<bool> = (cloud.points.par_iter())
        .map(|p| p.iter().all(|v| v.is_finite()))
        .collect();
    let mut k = 0;
    cloud.points.retain(|_| {
        k += 1;
        finite[k - 1]
    });
    if let Some(n) = &mut cloud.normals {
        let mut k = 0;
        n.retain(|_| {
            k += 1;
            finite[k - 1]
        });
    }
    drop(finite);
    if cloud.points.is_empty() {
        return Err(InputError::NoFinitePoints { total }.into());
    }
    let mut invalid = 0;
    if let Some(n) = &mut cloud.normals {
        for v in n.iter_mut() {
            *v = normalized(*v).unwrap_or_else(|| {
                invalid += 1;
                [0.0; 3]
            });
        }
        if invalid == n.len() {
            cloud.normals = None;
        }
    }
    let normalization = Normalization::from_aabb(&Aabb::from_points(&cloud.points));
    let stats = CleanStats {
        points: total,
        used: cloud.points.len(),
        dropped_non_finite: total - cloud.points.len(),
        has_normals: cloud.normals.is_some(),
        invalid_normals: invalid,
        ..Default::default()
    };
    Ok((stats, normalization))
}

/// Drop every point with an earlier point within `tol` (the in-memory cleaning's rule).
/// Returns how many were dropped; `index` is rebuilt when any was.
fn merge_duplicates(
    cloud: &mut PointCloud,
    index: &mut Box<dyn SpatialIndex + Send>,
    tol: f64,
) -> Result<usize, ReconError> {
    let pts = &cloud.points;
    let keep: Vec<bool> = (0..pts.len())
        .into_par_iter()
        .map_init(Vec::new, |hits, i| {
            index.within(&pts[i], tol, hits);
            !hits.iter().any(|&h| (h as usize) < i)
        })
        .collect();
    let dropped = keep.iter().filter(|k| !**k).count();
    if dropped == 0 {
        return Ok(0);
    }
    let mut k = 0;
    cloud.points.retain(|_| {
        k += 1;
        keep[k - 1]
    });
    if let Some(n) = &mut cloud.normals {
        let mut k = 0;
        n.retain(|_| {
            k += 1;
            keep[k - 1]
        });
    }
    *index = build_index(&cloud.points, IndexKind::KdTree, 16)?;
    Ok(dropped)
}

/// The global checks and estimates that need the k-d tree: surface test, normals' consistency,
/// support and noise (the same functions as the in-memory pipeline, over all points).
fn survey(
    points: &[Point3],
    normals: Option<&[Point3]>,
    index: &dyn SpatialIndex,
    params: &ReconParams,
) -> Result<(SupportEstimate, NoiseEstimate), ReconError> {
    let knn = |p: &Point3, k: usize, out: &mut Vec<(u32, f64)>| index.nearest_k(p, k, out);
    let thickness = crate::geometry::pca::surface_thickness(points, knn);
    if thickness > MAX_SURFACE_THICKNESS {
        return Err(InputError::NotASurface {
            n: points.len(),
            thickness,
        }
        .into());
    }
    if let Some(n) = normals {
        let share = crate::normals::inconsistent_fraction(points, n, 8, knn);
        if share > INCONSISTENT_NORMALS {
            return Err(TiledError::InconsistentNormals { share }.into());
        }
    }
    let support = estimate_support(points, index, params.support)?;
    let noise = estimate_noise(points, support.spacing, knn);
    Ok((support, noise))
}

/// The carrier plan: analytic solids fitted to all points; the local carrier's far field from
/// the subsample, whose winding integral also decides whether the normals point inwards (they
/// are then flipped in `normals`). Returns the plan, the kind and whether it flipped.
fn plan_carrier(
    points: &[Point3],
    normals: Option<&mut Vec<Point3>>,
    step: usize,
    params: &ReconParams,
    radius: f64,
) -> Result<(CarrierPlan, CarrierKind, bool), ReconError> {
    let kind = match (params.carrier.kind, &normals) {
        (CarrierKind::Auto | CarrierKind::Local, Some(_)) => CarrierKind::Local,
        (CarrierKind::Auto | CarrierKind::Local, None) => {
            return Err(TiledError::NeedsNormals.into());
        }
        (k, _) => k,
    };
    match kind {
        CarrierKind::Sphere => match crate::rbf::carrier::fit_sphere(points) {
            Carrier::Sphere { center, radius } => {
                Ok((CarrierPlan::Sphere { center, radius }, kind, false))
            }
            _ => unreachable!("fit_sphere returns a sphere"),
        },
        CarrierKind::Ellipsoid => match crate::rbf::carrier::fit_ellipsoid(points)? {
            Carrier::Ellipsoid {
                center,
                axes,
                semi_axes,
            } => Ok((
                CarrierPlan::Ellipsoid {
                    center,
                    axes,
                    semi_axes,
                },
                kind,
                false,
            )),
            _ => unreachable!("fit_ellipsoid returns an ellipsoid"),
        },
        _ => {
            let normals = normals.ok_or(TiledError::NeedsNormals)?;
            let sp: Vec<Point3> = points.iter().step_by(step).copied().collect();
            let sn: Vec<Point3> = normals.iter().step_by(step).copied().collect();
            let mut grid = crate::rbf::carrier::build_winding_grid(&sp, &sn, radius);
            let inward = grid.as_ref().is_some_and(|w| {
                let (sum, abs) = w.sums();
                abs > 0.0 && sum.abs() > 0.05 * abs && sum < 0.0
            });
            if inward {
                normals
                    .par_iter_mut()
                    .for_each(|n| *n = [-n[0], -n[1], -n[2]]);
                if let Some(w) = &mut grid {
                    w.negate();
                }
            }
            let winding = grid.map(Arc::new);
            Ok((CarrierPlan::Local { winding }, kind, inward))
        }
    }
}

/// Run the first step over `cloud` (consumed): see the module doc. Writes `points/{b}` for every
/// block to `store`.
pub(crate) fn prepare(
    mut cloud: PointCloud,
    params: &ReconParams,
    options: &TiledOptions,
    block_points: usize,
    store: &Store,
    progress: &dyn Progress,
) -> Result<Plan, ReconError> {
    check_supported(params)?;
    progress.stage(Stage::Clean);
    let (mut clean, normalization) = clean_in_place(&mut cloud)?;
    let tol = params.clean.merge_tolerance
        * Aabb::from_points(&cloud.points).diagonal()
        * normalization.scale;
    cloud
        .points
        .par_iter_mut()
        .for_each(|p| *p = normalization.forward(p));
    super::super::check_cancel(progress)?;
    progress.stage(Stage::Index);
    let mut index = build_index(&cloud.points, IndexKind::KdTree, 16)?;
    if params.clean.merge_tolerance > 0.0 {
        clean.merged_duplicates =
            merge_duplicates(&mut cloud, &mut index, tol.max(f64::MIN_POSITIVE))?;
        clean.used = cloud.points.len();
    }
    check_degenerate(&cloud.points, cloud.normals.is_some())?;
    let (support, noise) = survey(
        &cloud.points,
        cloud.normals.as_deref(),
        index.as_ref(),
        params,
    )?;
    drop(index);
    super::super::check_cancel(progress)?;
    let resolved = ReconParams {
        smoothing: Smoothing::Lambda(match params.smoothing {
            Smoothing::Auto => noise.lambda,
            Smoothing::Lambda(l) => l,
        }),
        ..params.clone()
    };
    progress.stage(Stage::Carrier);
    let n = cloud.points.len();
    let step = n.div_ceil(SAMPLE_POINTS).max(1);
    let (carrier, carrier_kind, normals_flipped) = plan_carrier(
        &cloud.points,
        cloud.normals.as_mut(),
        step,
        &resolved,
        support.radius,
    )?;
    let resolution = params
        .resolution
        .unwrap_or_else(|| super::super::auto_resolution(support.spacing));
    let grid = GridPlan::new(
        &cloud.points,
        &carrier,
        support.radius,
        resolution,
        options.region_cells,
    )?;
    let halo = 3.0 * support.radius + 4.0 * grid.h;
    let blocks = partition(&cloud, &resolved, &support, block_points, halo, store)?;
    let sample = cloud.points.iter().step_by(step).copied().collect();
    let sample_normals =
        (cloud.normals.as_ref()).map(|n| n.iter().step_by(step).copied().collect());
    Ok(Plan {
        normalization,
        support,
        noise,
        params: resolved,
        blocks,
        halo,
        carrier,
        grid,
        sample,
        sample_normals,
        clean,
        normals_flipped,
        carrier_kind,
    })
}

/// Plan the blocks (octree leaves of at most `block_points` core points, overlap three coarsest
/// support radii as in the in-memory block fit) and write each block's point set: every point
/// within `halo` of its outer box, in global order.
fn partition(
    cloud: &PointCloud,
    params: &ReconParams,
    support: &SupportEstimate,
    block_points: usize,
    halo: f64,
    store: &Store,
) -> Result<Vec<BlockBox>, ReconError> {
    let levels = params.levels.max(1);
    let coarsest = support.radius * (1u64 << (levels - 1)) as f64;
    let plans = plan_blocks(&cloud.points, block_points, 3.0 * coarsest);
    let mut blocks = Vec::with_capacity(plans.len());
    for (b, plan) in plans.into_iter().enumerate() {
        let reach = plan.outer.inflated(halo);
        let ids: Vec<u32> = (0..cloud.points.len() as u32)
            .into_par_iter()
            .filter(|&i| reach.contains(&cloud.points[i as usize]))
            .collect();
        let set = PointSet {
            points: ids.iter().map(|&i| cloud.points[i as usize]).collect(),
            normals: (cloud.normals.as_ref()).map(|n| ids.iter().map(|&i| n[i as usize]).collect()),
            ids,
        };
        store
            .put(&block_key(b), set.encode())
            .map_err(TiledError::from)?;
        blocks.push(BlockBox {
            core: plan.core,
            outer: plan.outer,
            members: plan.members.len(),
        });
    }
    Ok(blocks)
}
