//! Spreading a large job over idle workers, and the task timeline of a task-graph job.
//!
//! A job whose in-memory estimate fits its memory budget runs whole on the worker that took its
//! `start` task, unless it has at least [`SPREAD_POINTS`] points (`rbfsurf worker
//! --spread-points`), the task graph can run it (the same conditions as out of core, see
//! [`crate::pipeline::tiled`], and no vertex colours wanted from the input), its plan has at
//! least two blocks, and at least one other worker is idle ([`super::presence`]). Then the
//! `start` task prepares the graph exactly as for a job over the budget, and the blocks and
//! regions go to every worker: the mesh is the local out-of-core run's at the same budget
//! (`rbfsurf reconstruct --out-of-core`).
//!
//! Every task of a graph job records its worker and wall-clock interval in `dag.<id>`
//! (the same compare-and-set that marks it done); the merge task puts them in the report's
//! `tasks[]` with the [`crate::report::critical_path`].

use super::presence;
use super::steps::{Ctx, TaskError};
use crate::job::model::InputAttributes;
use crate::mesh::ColorMode;
use crate::params::ReconParams;
use crate::pipeline::tiled;
use crate::report::TaskReport;

/// Default points from which a job within its budget is split when another worker is idle
/// (smaller jobs gain little next to the extra pass over the input that prepare makes).
pub const SPREAD_POINTS: u64 = 500_000;

/// Whether a job of `n` points with `attrs`, which fits its budget in memory, is split into block
/// tasks: see the module doc. Returns the idle workers seen (for the log) when it is.
pub(super) fn spread_over(
    ctx: &Ctx,
    n: u64,
    params: &ReconParams,
    attrs: InputAttributes,
) -> Result<Option<Vec<String>>, TaskError> {
    if n < ctx.spread_points || !graph_can_run(params, attrs) {
        return Ok(None);
    }
    let est = tiled::estimate(n, params.max_memory_mib, ctx.concurrency);
    if n < 2 * est.block_points as u64 || est.peak_mib > params.max_memory_mib as f64 {
        return Ok(None);
    }
    let idle = ctx.block_on(presence::idle_others(&ctx.res.workers, &ctx.worker))?;
    Ok((!idle.is_empty()).then_some(idle))
}

/// Whether the task graph gives this job what the whole job would: CSRBF with a closed surface
/// and no outlier filter, normals for the local carrier, no vertex colours from the input.
fn graph_can_run(params: &ReconParams, attrs: InputAttributes) -> bool {
    use crate::rbf::CarrierKind;
    let needs_normals = matches!(params.carrier.kind, CarrierKind::Auto | CarrierKind::Local);
    let colors = match params.color {
        ColorMode::Rgb => attrs.colors,
        ColorMode::Intensity => attrs.intensity,
        ColorMode::None => false,
    };
    tiled::supports(params)
        && params.blocks != crate::rbf::Blocks::None
        && (attrs.normals || !needs_normals)
        && !colors
}

/// The timeline entry of task `task` run by `worker` from `start_ms` until now.
pub(super) fn timing(task: &str, worker: &str, start_ms: u64) -> TaskReport {
    let end_ms = presence::now_ms().max(start_ms);
    TaskReport {
        task: task.to_string(),
        worker: worker.to_string(),
        start_ms,
        end_ms,
        seconds: (end_ms - start_ms) as f64 / 1000.0,
    }
}

/// Records `t` in a graph's timeline, replacing an earlier delivery's entry of the same task.
pub(super) fn record(tasks: &mut Vec<TaskReport>, t: TaskReport) {
    tasks.retain(|x| x.task != t.task);
    tasks.push(t);
}
