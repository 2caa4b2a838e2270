//! Out-of-core reconstruction as a task graph: the path for clouds whose in-memory reconstruction
//! would not fit the memory budget.
//!
//! ```text
//! prepare (once, whole cloud) ──► fit block b (one task per block) ──► polygonize region r ──► merge ──► post
//!   clean, normalise, support,      points/{b} ─► spline/{b}             points within the        weld pieces by
//!   noise, carrier, plan blocks                                           region's halo + the      position (seams
//!   and regions, write points/{b}                                        splines that reach it    are bit-identical)
//!                                                                        ─► piece/{r}
//! ```
//!
//! Each task is a pure function of what it reads from the [`StoreKind`] store (in memory or a
//! temporary directory) and writes one keyed result, so the executor is free to run tasks in any
//! order, in parallel, again, or elsewhere. The local executor runs the block fits and the regions
//! on a rayon pool of `concurrency` threads (chosen from the memory budget, see [`estimate`]), so at
//! most that many block systems are alive at once. Both stores give the same mesh, whatever the
//! region size (tested).
//!
//! Differences from the in-memory pipeline (documented in docs/large-scans.md): the surface is
//! closed (`--boundary auto` is taken as closed; `trim` and `--outliers` are refused); the local
//! carrier's far field is the winding number of a subsample of at most
//! [`prepare::SAMPLE_POINTS`] points, which also counts the floaters' support; inputs need
//! consistent normals for the local carrier (no global reorientation); no vertex colours and no
//! `--save-field`.

#[cfg(feature = "nats")]
pub(crate) mod codec;
pub(crate) mod graph;
mod merge;
pub(crate) mod prepare;
pub mod store;
mod tasks;

pub use store::{StoreError, StoreKind};

use crate::error::{ErrorKind, ReconError};
use crate::geometry::{PointCloud, TriMesh};
use crate::params::ReconParams;
use crate::progress::{Progress, Stage};
use crate::report::{
    AttributesReport, BlockReport, MatrixReport, MemoryReport, ParamsReport, PolygonizeReport,
    Report, ResidualReport, Timings, peak_rss_mib,
};
use prepare::Plan;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;
use store::Store;

/// Why the task graph refused or failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TiledError {
    /// The local carrier needs normals and the input has none.
    #[error(
        "out-of-core reconstruction with the local carrier needs oriented normals in the input \
         (estimating them needs the whole cloud in memory); give points with normals, use \
         --carrier ellipsoid or sphere, or raise --max-memory-mib"
    )]
    NeedsNormals,
    /// The normals disagree between neighbours.
    #[error(
        "{:.0}% of neighbouring normals point in opposite directions; out-of-core reconstruction \
         cannot reorient them (that needs the whole cloud): orient the normals or raise --max-memory-mib",
        share * 100.0
    )]
    InconsistentNormals {
        /// Share of opposed neighbour pairs.
        share: f64,
    },
    /// An option the task graph does not implement.
    #[error(
        "{0} is not available for out-of-core reconstruction (the cloud is over the memory budget); \
         leave it out or raise --max-memory-mib"
    )]
    Unsupported(&'static str),
    /// Even out of core the cloud does not fit the budget.
    #[error(
        "{points} points need about {mib:.0} MiB even out of core (the cleaning pass holds the \
         cloud and one k-d tree, ~100 bytes per point), more than the memory budget of \
         {budget_mib} MiB; subsample the scan or raise --max-memory-mib"
    )]
    OverBudget {
        /// Points in the input.
        points: u64,
        /// Estimated out-of-core peak, MiB.
        mib: f64,
        /// The budget, MiB.
        budget_mib: u64,
    },
    /// The store of intermediate results failed.
    #[error(transparent)]
    Store(#[from] StoreError),
}

impl TiledError {
    /// Whose failure this is.
    pub fn kind(&self) -> ErrorKind {
        match self {
            TiledError::NeedsNormals | TiledError::InconsistentNormals { .. } => {
                ErrorKind::Unreconstructable
            }
            TiledError::Unsupported(_) => ErrorKind::BadParameter,
            TiledError::OverBudget { .. } => ErrorKind::OverBudget,
            TiledError::Store(_) => ErrorKind::Internal,
        }
    }
}

/// How the local executor runs the task graph.
#[derive(Debug, Clone, PartialEq)]
pub struct TiledOptions {
    /// Where intermediate results live.
    pub store: StoreKind,
    /// Core points per block (`None`: from the memory budget, see [`estimate`]).
    pub block_points: Option<usize>,
    /// Grid cells along a region's edge (rounded up to a multiple of 16); default 32.
    pub region_cells: usize,
    /// Tasks run at once (`None`: from the memory budget and the pool's threads).
    pub concurrency: Option<usize>,
    /// The id the report gives this process's blocks (`blocks[].worker`).
    pub worker: String,
}

impl Default for TiledOptions {
    fn default() -> Self {
        TiledOptions {
            store: StoreKind::TempDir(None),
            block_points: None,
            region_cells: 32,
            concurrency: None,
            worker: format!("local-{}", std::process::id()),
        }
    }
}

/// What an out-of-core run of `points` points costs, from the memory model below.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutOfCoreEstimate {
    /// Peak of the cleaning pass (cloud + one k-d tree), MiB.
    pub prepare_mib: f64,
    /// Core points per block.
    pub block_points: usize,
    /// Blocks fitted at once.
    pub concurrency: usize,
    /// Peak of the block and region tasks, MiB.
    pub tasks_mib: f64,
    /// The larger of the two, MiB.
    pub peak_mib: f64,
}

/// Fixed cost, MiB: the process, the subsample (at most 400,000 points), the winding grid.
const FIXED_MIB: f64 = 100.0;
/// Bytes per point of the cleaning pass: the cloud with normals (48), the k-d tree (~40), flags
/// and the block plan (~12).
const PREPARE_BYTES: f64 = 100.0;
/// Bytes per point that stay resident after the cleaning pass (the allocator keeps the cloud's
/// pages for reuse): measured at 10⁷ points, 565 MiB between block fits.
const RETAINED_BYTES: f64 = 48.0;
/// Bytes per core point of a block task: its point set with halo and overlap, the carrier's
/// copies and trees, the system of its members. Measured at 10⁷ points: two blocks of up to
/// 209,000 members at once rose ~1,040 MiB above the retained level (~2,500 B per member), and
/// a block has ~1.25 members per core point.
const TASK_BYTES: f64 = 3200.0;
/// Most core points per block (the in-memory block size).
const MAX_BLOCK_POINTS: usize = 250_000;
/// Fewest core points per block.
const MIN_BLOCK_POINTS: usize = 1000;
/// Blocks run at once only while each can still hold this many core points.
const PARALLEL_BLOCK_POINTS: usize = 100_000;

const MIB: f64 = (1u64 << 20) as f64;

/// The out-of-core cost of `points` points within `budget_mib`, on a pool of `threads` threads:
/// as many blocks at once (at most `threads`) as leave each at least 100,000 core points, each as
/// large as fits (at most 250,000 core points).
pub fn estimate(points: u64, budget_mib: u64, threads: usize) -> OutOfCoreEstimate {
    let n = points as f64;
    let prepare_mib = FIXED_MIB + n * PREPARE_BYTES / MIB;
    let base = FIXED_MIB + n * RETAINED_BYTES / MIB;
    let room = (budget_mib as f64 - base).max(0.0) * MIB;
    let fits = |c: usize| room / (c as f64 * TASK_BYTES);
    let concurrency = (1..=threads.max(1))
        .rev()
        .find(|&c| fits(c) >= PARALLEL_BLOCK_POINTS as f64)
        .unwrap_or(1);
    let block_points = (fits(concurrency) as usize)
        .clamp(MIN_BLOCK_POINTS, MAX_BLOCK_POINTS)
        .min((points as usize).max(MIN_BLOCK_POINTS));
    let tasks_mib = base + concurrency as f64 * block_points as f64 * TASK_BYTES / MIB;
    OutOfCoreEstimate {
        prepare_mib,
        block_points,
        concurrency,
        tasks_mib,
        peak_mib: prepare_mib.max(tasks_mib),
    }
}

/// Whether `params` can run out of core (CSRBF, closed surfaces, no outlier filter).
pub fn supports(params: &ReconParams) -> bool {
    prepare::check_supported(params).is_ok()
}

/// Reconstruct `cloud` (consumed: its memory is reused and freed early) through the task graph.
/// The report has `blocks[]`; `timings_s.read` / `write` are left for the caller.
pub fn reconstruct_tiled(
    cloud: PointCloud,
    params: &ReconParams,
    options: &TiledOptions,
    progress: &dyn Progress,
) -> Result<super::Reconstruction, ReconError> {
    let start = Instant::now();
    params.validate()?;
    let n = cloud.points.len() as u64;
    let threads = options
        .concurrency
        .unwrap_or_else(rayon::current_num_threads);
    let est = estimate(n, params.max_memory_mib, threads);
    if est.prepare_mib > params.max_memory_mib as f64 {
        return Err(TiledError::OverBudget {
            points: n,
            mib: est.peak_mib,
            budget_mib: params.max_memory_mib,
        }
        .into());
    }
    let block_points = options.block_points.unwrap_or(est.block_points);
    let concurrency = options.concurrency.unwrap_or(est.concurrency).max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(concurrency)
        .build()
        .map_err(|e| {
            TiledError::Store(StoreError::Io {
                path: "rayon pool".into(),
                source: std::io::Error::other(e.to_string()),
            })
        })?;
    let store = Store::open(&options.store).map_err(TiledError::from)?;
    let mut timings = Timings::default();
    let t = Instant::now();
    let plan = prepare::prepare(cloud, params, options, block_points, &store, progress)?;
    timings.clean = t.elapsed().as_secs_f64();
    let (block_reports, matrix) = fit_all(
        &plan,
        &store,
        &pool,
        &options.worker,
        progress,
        &mut timings,
    )?;
    progress.stage(Stage::Polygonize);
    let t = Instant::now();
    let (mesh, poly, residual) = polygonize_all(&plan, &store, &pool, progress)?;
    timings.polygonize = t.elapsed().as_secs_f64();
    drop(store);
    progress.stage(Stage::Post);
    finish(
        &plan,
        mesh,
        poly,
        residual,
        block_reports,
        matrix,
        timings,
        start,
    )
}

/// Run `task` for `0..n` on `pool`, results in order; the first error wins.
fn run_tasks<T: Send>(
    pool: &rayon::ThreadPool,
    n: usize,
    task: impl Fn(usize) -> Result<T, ReconError> + Sync + Send,
) -> Result<Vec<T>, ReconError> {
    pool.install(|| (0..n).into_par_iter().map(task).collect())
}

/// Fit every block (stage `blocks`) with [`graph::fit_step`].
fn fit_all(
    plan: &Plan,
    store: &Store,
    pool: &rayon::ThreadPool,
    worker: &str,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<(Vec<BlockReport>, MatrixReport), ReconError> {
    progress.stage(Stage::Blocks);
    let done = AtomicUsize::new(0);
    let nb = plan.blocks.len();
    let results = run_tasks(pool, nb, |b| {
        super::check_cancel(progress)?;
        let outcome = graph::fit_step(plan, store, b, worker, progress)?;
        progress.fraction((done.fetch_add(1, Ordering::Relaxed) + 1) as f64 / nb as f64);
        Ok(outcome)
    })?;
    Ok(graph::merge_blocks(results, timings))
}

/// Polygonize every region with points near it (stage `polygonize`, [`graph::region_step`]),
/// then weld the pieces in region order. Returns the mesh, the statistics and the residual.
fn polygonize_all(
    plan: &Plan,
    store: &Store,
    pool: &rayon::ThreadPool,
    progress: &dyn Progress,
) -> Result<(TriMesh, PolygonizeReport, ResidualReport), ReconError> {
    let nr = plan.grid.regions.len();
    let done = AtomicUsize::new(0);
    let results = run_tasks(pool, nr, |r| {
        super::check_cancel(progress)?;
        let out = graph::region_step(plan, store, r, progress)?;
        progress.fraction((done.fetch_add(1, Ordering::Relaxed) + 1) as f64 / nr as f64);
        Ok(out)
    })?;
    graph::weld_step(plan, store, &results)
}

/// The last step of either executor: post-process the welded mesh and write the report.
/// `timings` has the phases so far; `start` is when the run began.
#[allow(clippy::too_many_arguments)]
pub(crate) fn finish(
    plan: &Plan,
    mesh: TriMesh,
    mut poly: PolygonizeReport,
    residual: ResidualReport,
    blocks: Vec<BlockReport>,
    matrix: MatrixReport,
    mut timings: Timings,
    start: Instant,
) -> Result<super::Reconstruction, ReconError> {
    let t = Instant::now();
    let mesh = post(plan, mesh, &mut poly)?;
    let topology = crate::mesh::topology::analyze(&mesh);
    timings.post = t.elapsed().as_secs_f64();
    timings.total = start.elapsed().as_secs_f64();
    let report = Report {
        input: plan.clean,
        params: params_report(plan),
        matrix,
        residual,
        mesh: topology,
        timings_s: timings,
        memory: MemoryReport {
            peak_rss_mib: peak_rss_mib(),
            process_peak_rss_mib: None,
        },
        polygonize: poly,
        attributes: AttributesReport {
            color: "none",
            ..Default::default()
        },
        blocks,
    };
    Ok(super::Reconstruction { mesh, report })
}

/// Floaters (support counted on the subsample), small pieces, back to input units, GPU order.
fn post(plan: &Plan, mut mesh: TriMesh, s: &mut PolygonizeReport) -> Result<TriMesh, ReconError> {
    use crate::mesh::{floaters, trim};
    let params = &plan.params;
    let (drop, n) =
        floaters::floaters(&mesh, &plan.sample, plan.support.radius, params.min_support);
    s.floaters_removed = n;
    s.floater_triangles = trim::remove_triangles(&mut mesh, &drop);
    let (drop, n) = trim::small_components(&mesh, params.min_component);
    s.small_components_removed = n;
    s.small_component_triangles = trim::remove_triangles(&mut mesh, &drop);
    for v in &mut mesh.vertices {
        *v = plan.normalization.inverse(v);
    }
    crate::mesh::optimize::optimize_for_gpu(&mut mesh)?;
    Ok(mesh)
}

fn params_report(plan: &Plan) -> ParamsReport {
    let p = &plan.params;
    ParamsReport {
        method: p.method.name(),
        kernel: p.kernel.to_string(),
        support: plan.support.radius,
        support_input_units: plan.support.radius / plan.normalization.scale,
        neighbours: plan.support.mean_neighbours,
        carrier: plan.carrier_kind.name().to_string(),
        ordering: p.ordering.to_string(),
        solver: p.solver.to_string(),
        polynomial: p.polynomial.to_string(),
        resolution: plan.grid.resolution,
        index: p.index.to_string(),
        normals_flipped: plan.normals_flipped,
        smoothing: p.smoothing.lambda(),
        noise: plan.noise,
        boundary: "closed",
        normals_reoriented: 0,
        normals: if plan.clean.has_normals {
            "input"
        } else {
            "none"
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimate_fits_the_budget_and_uses_both_threads_when_blocks_stay_large() {
        let e = estimate(10_000_000, 1536, 2);
        assert_eq!(e.concurrency, 2, "{e:?}");
        assert!(
            e.block_points >= 100_000 && e.block_points <= 250_000,
            "{e:?}"
        );
        assert!(e.peak_mib <= 1536.0, "{e:?}");
        // A small budget: one block at a time, smaller blocks, still within it.
        let e = estimate(60_000, 130, 2);
        assert_eq!(e.concurrency, 1, "{e:?}");
        assert!(e.peak_mib <= 130.0 && e.block_points < 60_000, "{e:?}");
        // 10⁸ points: the cleaning pass alone is over 1.5 GiB.
        assert!(estimate(100_000_000, 1536, 2).prepare_mib > 1536.0);
    }
}
