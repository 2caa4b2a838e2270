//! Out-of-core reconstruction as a task graph: the path for clouds whose in-memory reconstruction
//! would not fit the memory budget.
//!
//! ```text
//! prepare (streams the input) ──► fit block b (one task per block) ──► polygonize region r ──► merge ──► post
//!   survey pass: count, box,        points/{b} ─► spline/{b}             points within the        weld pieces by
//!   subsample; partition pass:                                            region's halo + the      position (seams
//!   spill files; estimates on                                             splines that reach it    are bit-identical)
//!   patches; write points/{b}                                             ─► piece/{r}
//! ```
//!
//! Prepare's survey and partition passes run as one task per byte range of the input when its
//! format splits ([`InputSplit`], [`ranges`]), with the single passes' result.
//!
//! Each task is a pure function of what it reads from the [`StoreKind`] store (in memory or a
//! temporary directory) and writes one keyed result, so the executor is free to run tasks in any
//! order, in parallel, again, or elsewhere. The local executor runs the block fits and the regions
//! on a rayon pool of `concurrency` threads (chosen from the memory budget, see [`estimate`]), so at
//! most that many block systems are alive at once. The block size depends on the budget only,
//! never on the executor's concurrency, so every executor makes the same plan. Both stores give the same mesh, whatever the
//! region size (tested).
//!
//! Differences from the in-memory pipeline (documented in docs/large-scans.md): the surface is
//! closed (`--boundary auto` is taken as closed; `trim` and `--outliers` are refused); the local
//! carrier's far field is the winding number of a subsample of at most
//! [`prepare::SAMPLE_POINTS`] points, which also counts the floaters' support and plans the
//! blocks; the support and noise are measured on a few full-density blocks; inputs need
//! consistent normals for the local carrier (no global reorientation); no vertex colours and no
//! `--save-field`.

#[cfg(feature = "nats")]
pub(crate) mod codec;
pub(crate) mod graph;
mod merge;
mod patches;
#[cfg(feature = "nats")]
pub(crate) mod phases;
pub(crate) mod prepare;
mod ranges;
mod route;
pub(crate) mod store;
mod survey;
mod tasks;

pub use ranges::{DEFAULT_RANGE_BYTES, InputSplit};
pub use store::StoreKind;
pub use survey::TiledInput;

use crate::error::{ReconError, StoreError};
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
    /// How prepare reads the input: by byte ranges of 64 MiB by default ([`InputSplit`]).
    pub split: InputSplit,
}

impl Default for TiledOptions {
    fn default() -> Self {
        TiledOptions {
            store: StoreKind::TempDir(None),
            block_points: None,
            region_cells: 32,
            concurrency: None,
            worker: format!("local-{}", std::process::id()),
            split: InputSplit::default(),
        }
    }
}

/// What an out-of-core run of `points` points costs, from the memory model below.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutOfCoreEstimate {
    /// Peak of prepare (the subsample, the partition's buffers, the patches, one block clean-up
    /// per thread), MiB; bounded whatever the cloud's size.
    pub prepare_mib: f64,
    /// Core points per block: from the budget only, the same for every executor.
    pub block_points: usize,
    /// Blocks fitted at once on this executor.
    pub concurrency: usize,
    /// Peak of the block and region tasks, MiB.
    pub tasks_mib: f64,
    /// The larger of the two, MiB.
    pub peak_mib: f64,
}

/// Fixed cost, MiB: the process, the subsample (at most 400,000 points) and its k-d tree, the
/// winding grid, the welded mesh.
const FIXED_MIB: f64 = 100.0;
/// Bytes per point of the patches the support and noise are measured on (spilled records 52,
/// positions and normals 48, the k-d tree ~40, flags), at most [`prepare::PATCH_POINTS`] points.
const PATCH_BYTES: f64 = 160.0;
/// Bytes per spilled point held in the partition's buffers (a record with normals), at most
/// [`route::SPILL_BUFFER_BYTES`] in all.
const SPILL_RECORD_BYTES: f64 = 52.0;
/// Bytes per core point of turning a spill file into a block's point set: the records of its
/// core and margin (~2.5 per core point, 52 B each), their k-d tree and the encoded set.
const CONVERT_BYTES: f64 = 600.0;
/// Bytes per planned core point of a block task: its point set with halo and overlap, the
/// carrier's copies and trees, the system of its members. Measured at 10⁷ points with the
/// streamed prepare: blocks planned at 235,000 core points (the largest had 208,987 members),
/// two at once, peaked at 1,797 MiB — 3,786 B per planned core point above the fixed cost.
const TASK_BYTES: f64 = 4000.0;
/// Most core points per block (the in-memory block size).
const MAX_BLOCK_POINTS: usize = 250_000;
/// Fewest core points per block.
const MIN_BLOCK_POINTS: usize = 1000;
/// Blocks are sized for two at once while each can still hold this many core points.
const PARALLEL_BLOCK_POINTS: usize = 100_000;
/// Blocks the plan sizes for when the budget allows [`PARALLEL_BLOCK_POINTS`] each.
const PLAN_CONCURRENCY: f64 = 2.0;

const MIB: f64 = (1u64 << 20) as f64;

/// The out-of-core cost of `points` points within `budget_mib`, on an executor of `threads`
/// threads. The block size is a function of the budget alone: as large as lets two blocks fit
/// at once if each then holds at least 100,000 core points, else as large as one block fits (at
/// most 250,000 core points). `threads` decides only how many blocks run at once (as many as
/// fit, at most `threads`).
pub fn estimate(points: u64, budget_mib: u64, threads: usize) -> OutOfCoreEstimate {
    let n = points as f64;
    let room = (budget_mib as f64 - FIXED_MIB).max(0.0) * MIB;
    let sized = |c: f64| room / (c * TASK_BYTES);
    let block = if sized(PLAN_CONCURRENCY) >= PARALLEL_BLOCK_POINTS as f64 {
        sized(PLAN_CONCURRENCY)
    } else {
        sized(1.0)
    };
    let block_points = (block as usize).clamp(MIN_BLOCK_POINTS, MAX_BLOCK_POINTS);
    let concurrency =
        ((room / (block_points as f64 * TASK_BYTES)) as usize).clamp(1, threads.max(1));
    let blocks_at_once = concurrency as f64 * block_points as f64;
    let spill = (n * SPILL_RECORD_BYTES).min(route::SPILL_BUFFER_BYTES as f64);
    let patch = n.min(prepare::PATCH_POINTS as f64) * PATCH_BYTES;
    let prepare_mib = FIXED_MIB + (spill + patch + blocks_at_once * CONVERT_BYTES) / MIB;
    let tasks_mib = FIXED_MIB + blocks_at_once * TASK_BYTES / MIB;
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

/// Reconstruct `cloud` through the task graph (see [`reconstruct_tiled_from`]; the cloud is
/// read like a stream, chunk by chunk, and dropped before the blocks are fitted).
pub fn reconstruct_tiled(
    cloud: PointCloud,
    params: &ReconParams,
    options: &TiledOptions,
    progress: &dyn Progress,
) -> Result<super::Reconstruction, ReconError> {
    reconstruct_tiled_from(&TiledInput::Cloud(&cloud), params, options, progress)
}

/// Reconstruct the points of `input` through the task graph without holding them: prepare
/// streams the input (twice, or three times when the partition needs a wider margin) and
/// writes the blocks' point sets to the store. The report has `blocks[]`; `timings_s.read` /
/// `write` are left for the caller (`timings_s.clean` includes the reading).
pub fn reconstruct_tiled_from(
    input: &TiledInput<'_>,
    params: &ReconParams,
    options: &TiledOptions,
    progress: &dyn Progress,
) -> Result<super::Reconstruction, ReconError> {
    let start = Instant::now();
    params.validate()?;
    // A stream's size is not known here: its caller checks the estimate against the budget
    // with the count from the file's header ([`super::plan_execution`]); the block size and
    // the concurrency do not depend on it.
    let n = match input {
        TiledInput::Cloud(c) => Some(c.points.len() as u64),
        TiledInput::Stream(..) => None,
    };
    let threads = options
        .concurrency
        .unwrap_or_else(rayon::current_num_threads);
    let est = estimate(n.unwrap_or(0), params.max_memory_mib, threads);
    if let Some(n) = n.filter(|_| est.peak_mib > params.max_memory_mib as f64) {
        return Err(ReconError::OutOfCoreOverBudget {
            points: n,
            mib: est.peak_mib,
            budget_mib: params.max_memory_mib,
        });
    }
    let block_points = options.block_points.unwrap_or(est.block_points);
    let concurrency = options.concurrency.unwrap_or(est.concurrency).max(1);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(concurrency)
        .build()
        .map_err(|e| {
            ReconError::Store(StoreError::Io {
                path: "rayon pool".into(),
                source: std::io::Error::other(e.to_string()),
            })
        })?;
    let store = Store::open(&options.store)?;
    let mut timings = Timings::default();
    let t = Instant::now();
    let (plan, prepare_tasks) =
        pool.install(|| prepare::prepare(input, params, options, block_points, &store, progress))?;
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
    let mut recon = finish(
        &plan,
        mesh,
        poly,
        residual,
        block_reports,
        matrix,
        timings,
        start,
    )?;
    recon.report.tasks = prepare_tasks;
    Ok(recon)
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
        tasks: Vec::new(),
        critical_path: None,
    };
    Ok(super::Reconstruction { mesh, report })
}

/// Floaters (support counted on the subsample), small pieces, small handles, back to input units,
/// GPU order.
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
    super::surface::cut_small_handles(&mut mesh, params, plan.support.radius, s);
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
        local_fit: (plan.carrier_kind == crate::rbf::CarrierKind::Local)
            .then(|| p.carrier.fit.name()),
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
    fn the_plan_depends_on_the_budget_not_the_executor_and_fits_it() {
        for budget in [512, 1000, 1536, 8192] {
            let one = estimate(10_000_000, budget, 1);
            for threads in [2, 3, 8] {
                let e = estimate(10_000_000, budget, threads);
                assert_eq!(
                    e.block_points, one.block_points,
                    "{budget} MiB, {threads} threads"
                );
                assert!(
                    e.concurrency <= threads && e.peak_mib <= budget as f64,
                    "{e:?}"
                );
            }
        }
        let e = estimate(10_000_000, 1536, 2);
        assert_eq!(e.concurrency, 2, "{e:?}");
        assert!((150_000..=250_000).contains(&e.block_points), "{e:?}");
        // Far below the cloud (10⁷ points with normals are 458 MiB): one block at a time.
        let e = estimate(10_000_000, 512, 2);
        assert_eq!(e.concurrency, 1, "{e:?}");
        assert!(e.peak_mib <= 512.0 && e.block_points > 100_000, "{e:?}");
        // Prepare does not grow with the cloud.
        let big = estimate(1_000_000_000, 1536, 2);
        assert!((big.prepare_mib - e.prepare_mib).abs() < 200.0 && big.peak_mib <= 1536.0);
        // The distributed test's small budget: blocks of ~2,600 core points, within it.
        let e = estimate(30_000, 110, 2);
        assert!(e.peak_mib <= 110.0 && e.block_points > 2000, "{e:?}");
        // A budget that leaves no room for a block is refused.
        assert!(estimate(10_000_000, 100, 2).peak_mib > 100.0);
    }
}
