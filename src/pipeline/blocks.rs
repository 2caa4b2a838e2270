//! The block-decomposed CSRBF fit ([`crate::rbf::pou`]): plan octree blocks with overlap, then fit
//! each block's (single- or multi-level) spline to its points' carrier offsets, in waves of
//! [`concurrent_blocks`] blocks (one per thread, at most [`MAX_CONCURRENT`]; one when the memory
//! budget cannot hold two), so only that many blocks' matrices and factors are alive at a time
//! (memory bounded by the largest blocks, not by `n`) and one block's serial steps (its index, its
//! ordering) overlap another's parallel ones. Each block is an independent unit of work: (points,
//! offsets, parameters) in, spline out; the splines do not depend on the wave size.

use super::check_cancel;
use super::csrbf::fit_levels;
use crate::error::ReconError;
use crate::geometry::Point3;
use crate::params::ReconParams;
use crate::progress::Progress;
use crate::rbf::{PouBlock, SupportEstimate, plan_blocks, plan_levels};
use crate::report::{LevelReport, MatrixReport, Timings};
use crate::spatial::{SpatialIndex, build_index};
use rayon::prelude::*;
use std::sync::Arc;

/// Most blocks fitted at once.
const MAX_CONCURRENT: usize = 2;

/// Blocks fitted at once on the current thread pool: one per thread, at most [`MAX_CONCURRENT`].
pub(crate) fn concurrent_blocks() -> usize {
    rayon::current_num_threads().clamp(1, MAX_CONCURRENT)
}

/// Forwards cancellation only: a block's inner stages would reset the outer stage's fraction.
struct Quiet<'a>(&'a dyn Progress);

impl Progress for Quiet<'_> {
    fn stage(&self, _stage: crate::progress::Stage) {}
    fn fraction(&self, _done: f64) {}
    fn cancelled(&self) -> bool {
        self.0.cancelled()
    }
}

/// Fit `levels` levels in blocks of at most `max_points` core points, `wave` blocks at a time
/// (normalised units; `rhs` are the carrier offsets `−g(P_i)`); the blocks' stage times are summed
/// (with waves of two they can add up to more than the stage's wall time). The overlap is three
/// coarsest support radii: at least one for a continuous blend (see [`crate::rbf::pou`]), the rest
/// so the truncation of a block's system at its outer box has decayed where its weight is large.
/// Stage `blocks`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit_blocks(
    points: &[Point3],
    rhs: &[f64],
    support: &SupportEstimate,
    levels: usize,
    (max_points, wave): (usize, usize),
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<(Vec<PouBlock>, MatrixReport), ReconError> {
    let coarsest = support.radius * (1u64 << (levels.max(1) - 1)) as f64;
    let overlap = 3.0 * coarsest;
    let plans = plan_blocks(points, max_points, overlap);
    progress.stage(crate::progress::Stage::Blocks);
    let quiet = Quiet(progress);
    let mut blocks = Vec::with_capacity(plans.len());
    let mut report = MatrixReport::default();
    let wave = wave.max(1);
    for (w, group) in plans.chunks(wave).enumerate() {
        check_cancel(progress)?;
        let fitted: Vec<Result<(PouBlock, MatrixReport, Timings), ReconError>> = group
            .par_iter()
            .map(|plan| fit_block(points, rhs, support, levels, plan, params, &quiet))
            .collect();
        for f in fitted {
            let (block, r, t) = f?;
            merge_report(&mut report, r);
            for (total, part) in [
                (&mut timings.assemble, t.assemble),
                (&mut timings.order, t.order),
                (&mut timings.factor, t.factor),
                (&mut timings.solve, t.solve),
            ] {
                *total += part;
            }
            blocks.push(block);
        }
        progress.fraction(((w * wave + group.len()) as f64 / plans.len() as f64).min(1.0));
    }
    report.blocks = blocks.len();
    Ok((blocks, report))
}

/// Fit one planned block; its stage times in the returned [`Timings`].
fn fit_block(
    points: &[Point3],
    rhs: &[f64],
    support: &SupportEstimate,
    levels: usize,
    plan: &crate::rbf::BlockPlan,
    params: &ReconParams,
    quiet: &Quiet,
) -> Result<(PouBlock, MatrixReport, Timings), ReconError> {
    let pts: Vec<Point3> = plan.members.iter().map(|&i| points[i as usize]).collect();
    let target: Vec<f64> = plan.members.iter().map(|&i| rhs[i as usize]).collect();
    let index: Arc<dyn SpatialIndex + Send> =
        Arc::from(build_index(&pts, params.index, params.leaf_size)?);
    let level_plans = plan_levels(
        &pts,
        index.as_ref(),
        support.radius,
        support.mean_neighbours,
        levels,
    );
    let mut timings = Timings::default();
    let (spline, r) = fit_levels(
        &pts,
        &index,
        &level_plans,
        target,
        params,
        quiet,
        &mut timings,
    )?;
    let block = PouBlock {
        core: plan.core,
        outer: plan.outer,
        spline,
    };
    Ok((block, r, timings))
}

/// Sum a block's systems into the total: sizes add up, bandwidth is the largest, levels merge by
/// position (RMS of the right-hand sides weighted by size, iterations the largest).
pub(super) fn merge_report(total: &mut MatrixReport, block: MatrixReport) {
    total.n += block.n;
    total.nnz += block.nnz;
    total.bandwidth = total.bandwidth.max(block.bandwidth);
    total.profile_values += block.profile_values;
    total.dense_values += block.dense_values;
    total.factor_values += block.factor_values;
    total.solver_used.merge(&block.solver_used);
    for (k, l) in block.levels.into_iter().enumerate() {
        if k == total.levels.len() {
            total.levels.push(LevelReport {
                rhs_rms: 0.0,
                ..l.clone()
            });
            total.levels[k].n = 0;
            total.levels[k].nnz = 0;
            total.levels[k].factor_values = 0;
        }
        let t = &mut total.levels[k];
        let n = (t.n + l.n).max(1) as f64;
        t.rhs_rms = ((t.rhs_rms.powi(2) * t.n as f64 + l.rhs_rms.powi(2) * l.n as f64) / n).sqrt();
        t.n += l.n;
        t.nnz += l.nnz;
        t.factor_values += l.factor_values;
        t.iterations = match (t.iterations, l.iterations) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
    }
}
