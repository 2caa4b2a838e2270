//! The task graph's first step, run once over the input without holding it: two streaming
//! passes and a clean-up per block.
//!
//! 1. **Survey** ([`super::survey`]): count, bounding box of the finite points, normals, and a
//!    bounded deterministic subsample (at most [`SAMPLE_POINTS`], every `step`-th finite point).
//!    From it: the normalisation, the duplicate tolerance, the block cores (the in-memory block
//!    plan's octree rule over the subsample, each point standing for `step`), and rough support
//!    and grid sizes (the subsample's spacing scaled to the full density) that give the margin
//!    the partition writes around each core.
//! 2. **Partition** ([`super::route`]): one more stream of the input appends every point to the
//!    spill file of each block whose core plus margin contains it (bounded buffers).
//! 3. **Estimates on full-density patches**: the points of a few blocks (at most
//!    [`PATCH_POINTS`], spread over the block order), duplicates merged, give the surface test,
//!    the normals' consistency, the support radius and the noise, with the in-memory pipeline's
//!    own functions. The winding far field (and the normals' orientation) comes from the
//!    subsample. Should the exact reach of a block (overlap, halo, tolerance) exceed the margin,
//!    the partition is written again with a wider one.
//! 4. **Blocks**: each spill file becomes the block's point set (duplicates merged by global id,
//!    the same decision in every block; on a cloud the noise estimate calls noisy, the strays of
//!    [`crate::clean::strays`] dropped too, tested against the whole file), written to the store,
//!    and is removed.
//!
//! Memory: the subsample and its tree, the spill buffers, one patch and one block per thread —
//! nothing proportional to the cloud.

use super::TiledOptions;
use super::patches;
use super::ranges::Scan;
use super::route::{self, Routing};
use super::store::Store;
use super::survey::{Survey, TiledInput};
use super::tasks::{GridPlan, block_key};
use crate::clean::{CleanStats, check_degenerate};
use crate::error::{ReconError, StoreError};
use crate::geometry::{Aabb, Normalization, Point3};
use crate::params::{Boundary, ReconParams};
use crate::progress::{Progress, Stage};
use crate::rbf::winding::WindingGrid;
use crate::rbf::{
    Carrier, CarrierKind, NoiseEstimate, SupportEstimate, estimate_support, plan_leaves,
};
use crate::report::TaskReport;
use crate::spatial::{IndexKind, build_index};
use rayon::prelude::*;
use std::sync::Arc;

/// Most points of the subsample that builds the winding far field, plans the blocks and counts
/// the floaters' support.
pub(crate) const SAMPLE_POINTS: usize = 400_000;

/// Most points (with their blocks' margins) of the patches the estimates are made on.
pub(crate) const PATCH_POINTS: usize = 1_000_000;

/// How much wider than the rough reach the partition's margin is.
const MARGIN_FACTOR: f64 = 1.25;

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

/// Everything the tasks share, decided once by prepare.
pub(crate) struct Plan {
    pub normalization: Normalization,
    pub support: SupportEstimate,
    pub noise: NoiseEstimate,
    /// The parameters with the smoothing and the local carrier's fit resolved.
    pub params: ReconParams,
    pub blocks: Vec<BlockBox>,
    /// Extra reach of every stored point set beyond its box (the carrier's neighbourhoods).
    pub halo: f64,
    pub carrier: CarrierPlan,
    pub grid: GridPlan,
    /// The survey's subsample (every `step`-th finite point, normalised units), at most
    /// [`SAMPLE_POINTS`].
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
pub(crate) fn check_supported(params: &ReconParams) -> Result<(), ReconError> {
    if params.method != crate::params::Method::Csrbf {
        return Err(ReconError::OutOfCoreUnsupported(
            "--method other than csrbf",
        ));
    }
    if params.boundary == Boundary::Trim {
        return Err(ReconError::OutOfCoreUnsupported("--boundary trim"));
    }
    if params.outliers.is_some() {
        return Err(ReconError::OutOfCoreUnsupported("--outliers"));
    }
    Ok(())
}

/// The carrier plan: analytic solids fitted to the subsample; the local carrier's far field from
/// the subsample, whose winding integral also decides whether the normals point inwards (they
/// are then flipped in `normals`). Returns the plan, the kind and whether it flipped.
fn plan_carrier(
    points: &[Point3],
    normals: Option<&mut Vec<Point3>>,
    params: &ReconParams,
    radius: f64,
) -> Result<(CarrierPlan, CarrierKind, bool), ReconError> {
    let kind = match (params.carrier.kind, &normals) {
        (CarrierKind::Auto | CarrierKind::Local, Some(_)) => CarrierKind::Local,
        (CarrierKind::Auto | CarrierKind::Local, None) => {
            return Err(ReconError::NeedsNormals);
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
            let normals = normals.ok_or(ReconError::NeedsNormals)?;
            let mut grid = crate::rbf::carrier::build_winding_grid(points, normals, radius);
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

/// The carrier the input allows: the local carrier (the default) needs normals.
fn carrier_kind(params: &ReconParams, has_normals: bool) -> Result<CarrierKind, ReconError> {
    match (params.carrier.kind, has_normals) {
        (CarrierKind::Auto | CarrierKind::Local, true) => Ok(CarrierKind::Local),
        (CarrierKind::Auto | CarrierKind::Local, false) => Err(ReconError::NeedsNormals),
        (k, _) => Ok(k),
    }
}

/// How far beyond its core a block's stored points must reach: the overlap (three coarsest
/// support radii), the halo (three support radii and four grid cells `h`) and the duplicate
/// tolerance `tol` (normalised units).
fn reach(params: &ReconParams, radius: f64, h: f64, tol: f64) -> f64 {
    3.0 * coarsest(params, radius) + 3.0 * radius + 4.0 * h + tol
}

/// The support radius of the coarsest level.
fn coarsest(params: &ReconParams, radius: f64) -> f64 {
    radius * (1u64 << (params.levels.max(1) - 1)) as f64
}

/// The support from the subsample, its radius (when chosen by neighbour count) and spacing
/// scaled to the full density of a surface (`1/√step`): only the partition's margin uses it.
fn rough_support(
    sample: &[Point3],
    step: usize,
    params: &ReconParams,
) -> Result<SupportEstimate, ReconError> {
    let index = build_index(sample, IndexKind::KdTree, 16)?;
    let mut s = estimate_support(sample, index.as_ref(), params.support)?;
    let scale = 1.0 / (step as f64).sqrt();
    if matches!(params.support, crate::rbf::Support::Neighbours(_)) {
        s.radius *= scale;
    }
    s.spacing *= scale;
    Ok(s)
}

/// The polygonizer's grid for a support estimate (the resolution from its spacing unless given).
fn grid_for(
    params: &ReconParams,
    options: &TiledOptions,
    bounds: &Aabb,
    carrier: &CarrierPlan,
    support: &SupportEstimate,
) -> Result<GridPlan, ReconError> {
    let resolution = params
        .resolution
        .unwrap_or_else(|| super::super::auto_resolution(support.spacing));
    GridPlan::from_bounds(
        *bounds,
        carrier,
        support.radius,
        resolution,
        options.region_cells,
    )
}

/// A fresh directory for the spill files (next to the store's, or in `TMPDIR`).
fn spill_dir(options: &TiledOptions) -> Result<tempfile::TempDir, ReconError> {
    let parent = match &options.store {
        super::StoreKind::TempDir(Some(p)) => p.clone(),
        _ => std::env::temp_dir(),
    };
    (tempfile::Builder::new().prefix("rbfsurf-spill-"))
        .tempdir_in(&parent)
        .map_err(|source| {
            ReconError::Store(StoreError::Io {
                path: parent,
                source,
            })
        })
}

/// What the survey decides before the partition: the normalisation, the duplicate tolerance,
/// the normalised subsample and bounds, an analytic carrier (fitted once), the block cores and
/// the partition's first margin (normalised units).
pub(crate) struct Routes {
    pub normalization: Normalization,
    pub tol: f64,
    pub sample: Vec<Point3>,
    pub bounds: Aabb,
    analytic: Option<CarrierPlan>,
    pub cores: Vec<Aabb>,
    pub margin: f64,
}

/// Step 1's decisions from the survey `s` (see the module doc); `block_points` bounds the core
/// points per block.
pub(crate) fn plan_routes(
    s: &Survey,
    params: &ReconParams,
    options: &TiledOptions,
    block_points: usize,
) -> Result<Routes, ReconError> {
    let kind = carrier_kind(params, s.has_normals)?;
    let normalization = Normalization::from_aabb(&s.bbox);
    let tol = if params.clean.merge_tolerance > 0.0 {
        (params.clean.merge_tolerance * s.bbox.diagonal() * normalization.scale)
            .max(f64::MIN_POSITIVE)
    } else {
        0.0
    };
    let sample: Vec<Point3> = s.points.iter().map(|p| normalization.forward(p)).collect();
    check_degenerate(&sample, s.has_normals)?;
    let bounds = Aabb {
        min: normalization.forward(&s.bbox.min),
        max: normalization.forward(&s.bbox.max),
    };
    // Analytic carriers do not depend on the support; the local one is built after the
    // partition.
    let analytic = match kind {
        CarrierKind::Sphere | CarrierKind::Ellipsoid => {
            Some(plan_carrier(&sample, None, params, 1.0)?.0)
        }
        _ => None,
    };
    let cores = plan_leaves(&sample, &bounds, (block_points / s.step).max(1), true);
    let mut routes = Routes {
        normalization,
        tol,
        sample,
        bounds,
        analytic,
        cores,
        margin: 0.0,
    };
    let rough = rough_support(&routes.sample, s.step, params)?;
    routes.margin = MARGIN_FACTOR * routes.exact_reach(params, options, &rough)?;
    Ok(routes)
}

impl Routes {
    /// How far beyond its core a block's stored points must reach for `support`.
    pub(crate) fn exact_reach(
        &self,
        params: &ReconParams,
        options: &TiledOptions,
        support: &SupportEstimate,
    ) -> Result<f64, ReconError> {
        let placeholder = CarrierPlan::Local { winding: None };
        let shape = self.analytic.as_ref().unwrap_or(&placeholder);
        let grid = grid_for(params, options, &self.bounds, shape, support)?;
        Ok(reach(params, support.radius, grid.h, self.tol))
    }

    /// The margin the partition must be written again with when `support` needs more than the
    /// current one (`None`: the current one suffices).
    pub(crate) fn wider_margin(
        &self,
        params: &ReconParams,
        options: &TiledOptions,
        support: &SupportEstimate,
    ) -> Result<Option<f64>, ReconError> {
        let needed = self.exact_reach(params, options, support)?;
        Ok((needed > self.margin).then_some(MARGIN_FACTOR * needed))
    }
}

/// How each block's point set is made from its spill (step 4), decided after the estimates.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct CleanSpec {
    /// Outer box of a block: its core inflated by this (normalised units).
    pub overlap: f64,
    /// Extra reach of every stored point set beyond its outer box.
    pub halo: f64,
    /// Duplicate tolerance.
    pub tol: f64,
    pub normals: bool,
    /// Negate the normals (they point inwards).
    pub flip: bool,
    /// The noise level σ when the noise estimate calls the cloud noisy: its strays are dropped.
    pub stray_sigma: Option<f64>,
}

/// Steps 3 (after the estimates) and 4's plan: the carrier, the grid, the halo; the plan has
/// no blocks yet and its clean-up counts are the survey's (see [`complete_plan`]).
pub(crate) fn plan_after_partition(
    s: &Survey,
    routes: Routes,
    support: SupportEstimate,
    noise: NoiseEstimate,
    params: &ReconParams,
    options: &TiledOptions,
) -> Result<(Plan, CleanSpec), ReconError> {
    let resolved = params.resolved_for(&noise);
    let mut sample_normals = s.has_normals.then(|| s.normals.clone());
    let (carrier, carrier_kind, normals_flipped) = plan_carrier(
        &routes.sample,
        sample_normals.as_mut(),
        &resolved,
        support.radius,
    )?;
    let grid = grid_for(params, options, &routes.bounds, &carrier, &support)?;
    let halo = 3.0 * support.radius + 4.0 * grid.h;
    let spec = CleanSpec {
        overlap: 3.0 * coarsest(params, support.radius),
        halo,
        tol: routes.tol,
        normals: s.has_normals,
        flip: normals_flipped,
        stray_sigma: noise.noisy.then_some(noise.sigma),
    };
    let plan = Plan {
        normalization: routes.normalization,
        support,
        noise,
        params: resolved,
        blocks: Vec::new(),
        halo,
        carrier,
        grid,
        sample: routes.sample,
        sample_normals,
        clean: clean_stats(s, &route::Dropped::default()),
        normals_flipped,
        carrier_kind,
    };
    Ok((plan, spec))
}

/// The plan with its blocks and what their clean-up dropped.
pub(crate) fn complete_plan(plan: &mut Plan, blocks: Vec<BlockBox>, dropped: &route::Dropped) {
    plan.blocks = blocks;
    plan.clean.used -= dropped.merged + dropped.strays;
    plan.clean.merged_duplicates = dropped.merged;
    plan.clean.strays_removed = dropped.strays;
}

/// The input's clean-up counts from the survey and what the blocks dropped.
fn clean_stats(s: &Survey, dropped: &route::Dropped) -> CleanStats {
    CleanStats {
        points: s.total,
        used: s.finite - dropped.merged - dropped.strays,
        dropped_non_finite: s.total - s.finite,
        merged_duplicates: dropped.merged,
        strays_removed: dropped.strays,
        has_normals: s.has_normals,
        invalid_normals: s.invalid_normals,
        ..Default::default()
    }
}

/// The partition, written again with a wider margin when the exact reach needs it.
struct Partition {
    dir: tempfile::TempDir,
    /// Provisional blocks with points in their cores, ascending.
    alive: Vec<usize>,
    support: SupportEstimate,
    noise: NoiseEstimate,
}

/// Steps 2 and 3 of the module doc.
fn partition(
    scan: &Scan<'_>,
    s: &Survey,
    routes: &mut Routes,
    params: &ReconParams,
    options: &TiledOptions,
) -> Result<Partition, ReconError> {
    // Route every point into a fresh spill folder with the given margin.
    let spill = |margin: f64| {
        let dir = spill_dir(options)?;
        let routing = Routing::new(
            &routes.cores,
            margin,
            &routes.normalization,
            s.has_normals,
            dir.path(),
        );
        let routed = scan.route(&routing, routes.cores.len())?;
        Ok::<_, ReconError>((dir, routed))
    };
    let (dir, routed) = spill(routes.margin)?;
    let alive = alive_blocks(&routed);
    let picks = patches::pick_patches(&alive, &routed.spilled);
    let (support, noise) = patches::estimate_on_patches(
        (dir.path(), scan.parts()),
        &picks,
        &routes.cores,
        s.has_normals,
        routes.tol,
        s.finite,
        params,
    )?;
    let Some(wider) = routes.wider_margin(params, options, &support)? else {
        return Ok(Partition {
            dir,
            alive,
            support,
            noise,
        });
    };
    drop(dir);
    let (dir, _) = spill(wider)?;
    routes.margin = wider;
    Ok(Partition {
        dir,
        alive,
        support,
        noise,
    })
}

/// The provisional blocks with points in their cores, ascending: the blocks of the plan.
pub(crate) fn alive_blocks(routed: &route::Routed) -> Vec<usize> {
    (0..routed.core_points.len())
        .filter(|&b| routed.core_points[b] > 0)
        .collect()
}

/// Run the first step over `input` (see the module doc); writes `points/{b}` for every block to
/// `store`. `block_points` bounds the core points per block.
pub(crate) fn prepare(
    input: &TiledInput<'_>,
    params: &ReconParams,
    options: &TiledOptions,
    block_points: usize,
    store: &Store,
    progress: &dyn Progress,
) -> Result<(Plan, Vec<TaskReport>), ReconError> {
    check_supported(params)?;
    progress.stage(Stage::Clean);
    let mut scan = Scan::new(input, options.split, &options.worker)?;
    let s = scan.survey(SAMPLE_POINTS)?;
    let mut routes = plan_routes(&s, params, options, block_points)?;
    super::super::check_cancel(progress)?;
    progress.stage(Stage::Index);
    let part = partition(&scan, &s, &mut routes, params, options)?;
    super::super::check_cancel(progress)?;
    progress.stage(Stage::Carrier);
    let cores = routes.cores.clone();
    let (mut plan, spec) =
        plan_after_partition(&s, routes, part.support, part.noise, params, options)?;
    let out = BlockOutput {
        dir: part.dir.path(),
        parts: scan.parts(),
        cores: &cores,
        spec,
    };
    let (blocks, dropped) = scan.timed("clean-up".into(), || {
        write_blocks(&out, &part.alive, store, progress)
    })?;
    complete_plan(&mut plan, blocks, &dropped);
    Ok((plan, scan.take_tasks()))
}

/// What turning spill files into block point sets needs.
pub(crate) struct BlockOutput<'a> {
    pub dir: &'a std::path::Path,
    /// Spill parts per block.
    pub parts: usize,
    /// The provisional cores (spill file `b` is core `b`'s).
    pub cores: &'a [Aabb],
    pub spec: CleanSpec,
}

/// Step 4 for one block: block `k` of the plan is provisional block `prov`; its point set is
/// every kept point within its outer box plus the halo, written to `store` as `points/{k}`; its
/// spill is removed. Returns the block and what was dropped.
pub(crate) fn write_block(
    out: &BlockOutput<'_>,
    k: usize,
    prov: usize,
    store: &Store,
) -> Result<(BlockBox, route::Dropped), ReconError> {
    let spec = &out.spec;
    let records = route::read_block_spill(out.dir, prov, out.parts, spec.normals)?;
    let core = out.cores[prov];
    let outer = core.inflated(spec.overlap);
    let reach = outer.inflated(spec.halo);
    let owns = |p: &Point3| out.cores.iter().position(|c| c.contains(p)) == Some(prov);
    let (set, dropped) = route::finish_block(
        &records,
        &reach,
        spec.tol,
        spec.normals,
        spec.flip,
        spec.stray_sigma,
        owns,
    )?;
    drop(records);
    route::remove_block_spill(out.dir, prov, out.parts);
    let members = set.points.iter().filter(|p| outer.contains(p)).count();
    store.put(&block_key(k), set.encode())?;
    let block = BlockBox {
        core,
        outer,
        members,
    };
    Ok((block, dropped))
}

/// Step 4: block `k` is the `k`-th of `alive`. Returns the blocks and what was dropped in all.
fn write_blocks(
    out: &BlockOutput<'_>,
    alive: &[usize],
    store: &Store,
    progress: &dyn Progress,
) -> Result<(Vec<BlockBox>, route::Dropped), ReconError> {
    let results: Vec<Result<(BlockBox, route::Dropped), ReconError>> =
        (alive.par_iter().enumerate())
            .map(|(k, &prov)| {
                super::super::check_cancel(progress)?;
                write_block(out, k, prov, store)
            })
            .collect();
    let mut blocks = Vec::with_capacity(results.len());
    let mut dropped = route::Dropped::default();
    for r in results {
        let (b, d) = r?;
        blocks.push(b);
        dropped.merged += d.merged;
        dropped.strays += d.strays;
    }
    Ok((blocks, dropped))
}

#[cfg(test)]
mod tests {
    use super::super::store::{PointSet, StoreKind};
    use super::*;
    use crate::geometry::PointCloud;
    use crate::progress::NoProgress;

    /// A torus with a NaN point and duplicates (copies within a tenth of the tolerance) spread
    /// over the cloud, so some fall in the blocks' overlaps.
    fn cloud_with_duplicates() -> PointCloud {
        let shape = crate::geometry::synthetic::Shape::by_name("torus").unwrap();
        let mut cloud = shape.sample(4000, 9);
        let normals = cloud.normals.as_mut().unwrap();
        cloud.points[100] = [f64::NAN, 0.0, 0.0];
        for i in (0..4000).step_by(37) {
            let p = cloud.points[i];
            cloud.points.push([p[0] + 1e-9, p[1], p[2] - 1e-9]);
            normals.push(normals[i]);
        }
        cloud
    }

    #[test]
    fn every_block_holds_exactly_the_kept_points_of_its_reach_and_duplicates_agree() {
        let cloud = cloud_with_duplicates();
        let params = ReconParams::default();
        let options = TiledOptions {
            store: StoreKind::Memory,
            ..Default::default()
        };
        let store = Store::open(&options.store).unwrap();
        let input = TiledInput::Cloud(&cloud);
        let (plan, _) = prepare(&input, &params, &options, 500, &store, &NoProgress).unwrap();
        assert!(plan.blocks.len() >= 8, "{} blocks", plan.blocks.len());
        // Brute force over the whole cloud: ids among the finite points, the same transform and
        // tolerance, and the in-memory rule (dropped when a lower id lies within the tolerance).
        let finite: Vec<(Point3, Point3)> =
            (cloud.points.iter().zip(cloud.normals.as_ref().unwrap()))
                .filter(|(p, _)| p.iter().all(|v| v.is_finite()))
                .map(|(p, n)| (plan.normalization.forward(p), *n))
                .collect();
        let bbox = Aabb::from_points(cloud.points.iter().filter(|p| p[0].is_finite()));
        let tol = params.clean.merge_tolerance * bbox.diagonal() * plan.normalization.scale;
        let d2 = |a: &Point3, b: &Point3| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>();
        let keep: Vec<bool> = (0..finite.len())
            .map(|i| !(0..i).any(|j| d2(&finite[j].0, &finite[i].0) <= tol * tol))
            .collect();
        let dropped = keep.iter().filter(|k| !**k).count();
        assert_eq!(dropped, 4000 / 37 + 1, "every copy is a duplicate");
        assert_eq!(plan.clean.merged_duplicates, dropped);
        assert_eq!(plan.clean.dropped_non_finite, 1);
        assert_eq!(plan.clean.used, finite.len() - dropped);
        let mut seen = vec![false; finite.len()];
        for (b, block) in plan.blocks.iter().enumerate() {
            let key = block_key(b);
            let set = PointSet::decode(&store.get(&key).unwrap(), &key).unwrap();
            let reach = block.outer.inflated(plan.halo);
            let want: Vec<u32> = (0..finite.len() as u32)
                .filter(|&i| keep[i as usize] && reach.contains(&finite[i as usize].0))
                .collect();
            assert_eq!(set.ids, want, "block {b}");
            for (k, &id) in set.ids.iter().enumerate() {
                let (p, n) = finite[id as usize];
                assert_eq!(set.points[k], p, "block {b}, point {id}");
                let unit = crate::geometry::normalized(n).unwrap();
                let n = set.normals.as_ref().unwrap()[k];
                let sign = if plan.normals_flipped { -1.0 } else { 1.0 };
                assert_eq!(n, unit.map(|v| sign * v), "block {b}, normal {id}");
                seen[id as usize] |= block.core.contains(&p);
            }
            let members = set
                .points
                .iter()
                .filter(|p| block.outer.contains(p))
                .count();
            assert_eq!(block.members, members);
        }
        // Every kept point lies in some block's core.
        assert!((0..finite.len()).all(|i| !keep[i] || seen[i]));
    }

    #[test]
    fn the_subsample_plans_the_same_leaves_as_the_in_memory_rule_when_it_is_the_whole_cloud() {
        let cloud = crate::geometry::synthetic::Shape::by_name("knot")
            .unwrap()
            .sample(6000, 4);
        let norm = Normalization::from_aabb(&Aabb::from_points(&cloud.points));
        let pts: Vec<Point3> = cloud.points.iter().map(|p| norm.forward(p)).collect();
        let in_memory: Vec<Aabb> = (crate::rbf::plan_blocks(&pts, 700, 0.01).into_iter())
            .map(|b| b.core)
            .collect();
        let leaves = plan_leaves(&pts, &Aabb::from_points(&pts), 700, true);
        let non_empty: Vec<Aabb> = (leaves.into_iter())
            .filter(|l| pts.iter().any(|p| l.contains(p)))
            .collect();
        assert_eq!(non_empty, in_memory);
    }
}
