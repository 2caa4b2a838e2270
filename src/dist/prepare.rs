//! Prepare spread over the workers: a task graph's survey, subsample and partition run as one
//! task per byte range of the input, and the blocks' clean-up as one task per block
//! ([`crate::pipeline::tiled::phases`]), so that no task reads the whole input. The input is
//! stored in segments of [`objects::SEGMENT_BYTES`]; a range task fetches the first segment (the header:
//! the split is planned from it) and the segments around its range.
//!
//! The phases' progress is the record `prep.<id>` (phase, generation, a done flag per task, the
//! timeline): a task marks itself done with compare-and-set, and the task whose mark completes
//! the phase runs the step between phases and publishes the next phase (again, idempotently,
//! when a redelivered task finds the phase complete but not advanced). After the clean-up the
//! plan is stored and the graph goes on as [`super::steps`] describes: blocks, regions, merge.
//!
//! A job within its memory budget that is spread over idle workers runs whole instead when the
//! graph refuses it (inconsistent normals, say): the prepare values are removed and a `whole`
//! task is published.

use super::DistError;
use super::connect::Resources;
use super::objects::{self, JobObjects};
use super::queue::{self, Task, TaskKind};
use super::records::{self, DagState, JobRecord, dag_key, prep_key};
use super::spread::{record, timing};
use super::steps::{Ctx, TaskError, TaskProgress, recon_error, set_stage};
use crate::error::{ErrorKind, ReconError};
use crate::io::split::{ByteRange, Split, Window, split_window};
use crate::io::{PointFormat, ReadLimits};
use crate::job::unix_now_ms;
use crate::params::ReconParams;
use crate::pipeline::tiled::phases::{self, AfterRoutes, RangeInput};
use crate::pipeline::tiled::store::Store;
use crate::pipeline::tiled::{self, TiledOptions};
use crate::pipeline::{Execution, plan_execution};
use crate::progress::Stage;
use crate::report::TaskReport;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use uuid::Uuid;

/// A phase of the spread prepare.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Phase {
    Survey,
    Sample,
    Route,
    CleanUp,
}

/// The spread prepare's state (`prep.<id>`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PrepState {
    pub phase: Phase,
    /// The partition's generation (route tasks of an older one are stale).
    pub generation: u32,
    /// Done flag per task of the phase.
    pub done: Vec<bool>,
    /// Byte ranges of the input.
    pub ranges: usize,
    /// Bytes per range the split was planned with (every worker plans the same split).
    pub range_bytes: u64,
    /// Core points per block.
    pub block_points: usize,
    /// Blocks cleaned up (0 before the clean-up phase).
    pub blocks: usize,
    /// The job fits its budget: a refusal of the graph runs it whole.
    pub spread: bool,
    /// When the start task began (Unix ms).
    pub started_ms: u64,
    /// The prepare tasks' timeline.
    pub tasks: Vec<TaskReport>,
}

fn store(ctx: &Ctx, job: Uuid) -> Store {
    Store::Remote(Box::new(JobObjects {
        os: ctx.res.objects.clone(),
        job,
        rt: ctx.rt.clone(),
        written: None,
    }))
}

pub(super) fn limits(rec: &JobRecord, params: &ReconParams) -> ReadLimits {
    ReadLimits {
        max_points: rec.max_points,
        max_bytes: rec.max_bytes,
        max_memory_mib: params.max_memory_mib,
    }
}

pub(super) fn format_of(rec: &JobRecord) -> Result<PointFormat, TaskError> {
    PointFormat::from_path(std::path::Path::new(&rec.view.input.file)).ok_or_else(|| {
        TaskError::Job(crate::job::error::internal_body(
            "stored input has an unknown extension",
        ))
    })
}

/// The input's first segment and the split planned from it (`None`: the format does not split,
/// or into one range only).
pub(super) fn plan_split(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    range_bytes: u64,
) -> Result<Option<(Vec<u8>, Split)>, TaskError> {
    let input = &rec.view.input;
    let first = ByteRange {
        start: 0,
        end: objects::SEGMENT_BYTES.min(input.bytes).max(1),
    };
    let (_, header) = ctx.block_on(objects::get_input_range(
        &ctx.res.objects,
        rec.view.id,
        &input.file,
        input.bytes,
        first,
    ))?;
    let w = Window {
        data: &header,
        base: 0,
        len: input.bytes,
        format: format_of(rec)?,
    };
    let split = split_window(w, &limits(rec, params), range_bytes)
        .map_err(|e| recon_error(ReconError::Read(e)))?;
    Ok(split.filter(|s| s.ranges().len() > 1).map(|s| (header, s)))
}

/// A job the task graph can run, whose input splits into byte ranges and whose record knows its
/// points and attributes: the prepare runs over the workers ([`super::prepare`]), and the start
/// task reads only the input's first segment. `None`: the start task goes on with the input.
pub(super) fn start_by_ranges(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    started_ms: u64,
) -> Result<Option<Result<(), TaskError>>, TaskError> {
    let input = &rec.view.input;
    let (tiled::InputSplit::Bytes(range_bytes), Some(attrs)) = (ctx.split, input.attributes) else {
        return Ok(None);
    };
    if input.bytes <= range_bytes {
        return Ok(None);
    }
    let n = input.points as u64;
    let spread = match plan_execution(n, params).map_err(recon_error)? {
        Execution::OutOfCore(_) => false,
        Execution::InMemory => {
            if super::spread::spread_over(ctx, n, params, attrs)?.is_none() {
                return Ok(None);
            }
            true
        }
    };
    let Some((_, split)) = plan_split(ctx, rec, params, range_bytes)? else {
        return Ok(None);
    };
    Ok(Some(start(
        ctx,
        rec,
        params,
        &split,
        range_bytes,
        spread,
        started_ms,
    )))
}

/// Starts the spread prepare of job `rec` over the ranges of `split`: the survey tasks.
pub(super) fn start(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    split: &Split,
    range_bytes: u64,
    spread: bool,
    started_ms: u64,
) -> Result<(), TaskError> {
    let job = rec.view.id;
    let n = rec.view.input.points as u64;
    let est = super::steps::graph_estimate(ctx, n, params)?;
    tiled::prepare::check_supported(params).map_err(recon_error)?;
    let ranges = split.ranges().len();
    let state = PrepState {
        phase: Phase::Survey,
        generation: 0,
        done: vec![false; ranges],
        ranges,
        range_bytes,
        block_points: est.block_points,
        blocks: 0,
        spread,
        started_ms,
        tasks: Vec::new(),
    };
    ctx.block_on(records::create(&ctx.res.jobs, &prep_key(job), &state))?;
    ctx.update_job(job, |r| set_stage(r, Stage::Clean, 0.0))?;
    if spread {
        tracing::info!(job = %job, points = n, "splitting the job into block tasks");
    }
    tracing::info!(job = %job, ranges, "prepare by byte ranges over the workers");
    publish(ctx, job, (0..ranges).map(TaskKind::Survey))
}

fn publish(ctx: &Ctx, job: Uuid, kinds: impl Iterator<Item = TaskKind>) -> Result<(), TaskError> {
    let tasks: Vec<Task> = kinds.map(|kind| Task { job, kind }).collect();
    Ok(ctx.block_on(queue::publish(&ctx.res.js, &tasks))?)
}

/// The phase, item and generation of a prepare task.
fn phase_of(kind: TaskKind) -> Option<(Phase, usize, Option<u32>)> {
    match kind {
        TaskKind::Survey(r) => Some((Phase::Survey, r, None)),
        TaskKind::Sample(r) => Some((Phase::Sample, r, None)),
        TaskKind::Route(r, g) => Some((Phase::Route, r, Some(g))),
        TaskKind::CleanUp(k) => Some((Phase::CleanUp, k, None)),
        _ => None,
    }
}

fn current(state: &PrepState, phase: Phase, generation: Option<u32>) -> bool {
    state.phase == phase && generation.is_none_or(|g| g == state.generation)
}

/// Runs prepare task `kind` of job `rec` (see the module doc).
pub(super) fn run(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    kind: TaskKind,
    progress: &TaskProgress,
) -> Result<(), TaskError> {
    let job = rec.view.id;
    let Some((phase, k, generation)) = phase_of(kind) else {
        return Ok(());
    };
    let loaded = ctx.block_on(records::load::<PrepState>(&ctx.res.jobs, &prep_key(job)))?;
    let Some((state, _)) = loaded else {
        return Ok(());
    };
    if !current(&state, phase, generation) || k >= state.done.len() {
        return Ok(()); // a stale redelivery: its phase is over
    }
    let outcome = if state.done[k] {
        Ok(Some(state))
    } else {
        run_item(ctx, rec, params, &state, phase, k, progress)
    };
    let state = match outcome {
        Ok(Some(s)) => s,
        Ok(None) => return Ok(()), // the job ended meanwhile
        Err(e) => return refuse(ctx, rec, &state_or(ctx, job)?, e),
    };
    if state.done.iter().all(|&d| d)
        && current(&state, phase, generation)
        && let Err(e) = advance(ctx, rec, params, &state)
    {
        return refuse(ctx, rec, &state, e);
    }
    Ok(())
}

fn state_or(ctx: &Ctx, job: Uuid) -> Result<PrepState, TaskError> {
    let loaded = ctx.block_on(records::load::<PrepState>(&ctx.res.jobs, &prep_key(job)))?;
    loaded
        .map(|(s, _)| s)
        .ok_or_else(|| TaskError::Retry(format!("job {job}: no prepare state")))
}

/// A failed prepare task: the job's error, or (a spread job the graph refused) the job run
/// whole.
fn refuse(ctx: &Ctx, rec: &JobRecord, state: &PrepState, e: TaskError) -> Result<(), TaskError> {
    let TaskError::Job(body) = &e else {
        return Err(e);
    };
    if !state.spread || body.code == ErrorKind::Cancelled.code() {
        return Err(e);
    }
    let job = rec.view.id;
    tracing::info!(job = %job, error = %body.message, "the task graph refused the job; running it whole");
    remove(&ctx.res, ctx, job)?;
    publish(ctx, job, std::iter::once(TaskKind::Whole))
}

/// Runs item `k` of `phase` and marks it done; returns the state after the mark (`None`: the
/// job ended while it ran, and what it wrote is removed).
fn run_item(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    state: &PrepState,
    phase: Phase,
    k: usize,
    progress: &TaskProgress,
) -> Result<Option<PrepState>, TaskError> {
    let job = rec.view.id;
    let started_ms = unix_now_ms();
    let st = store(ctx, job);
    let dir = tempfile::tempdir().map_err(|e| TaskError::Retry(e.to_string()))?;
    let label = match phase {
        Phase::Survey => format!("survey range {k}"),
        Phase::Sample => format!("sample range {k}"),
        Phase::Route => format!("route range {k}"),
        Phase::CleanUp => format!("clean-up {k}"),
    };
    let written = if phase == Phase::CleanUp {
        let (spills, written) = phases::clean_up(&st, k, dir.path()).map_err(recon_error)?;
        ctx.block_on(objects::remove(&ctx.res, job, &spills))?;
        written
    } else {
        let (header, split) = plan_split(ctx, rec, params, state.range_bytes)?
            .ok_or_else(|| TaskError::Retry("the input no longer splits".into()))?;
        let input = &rec.view.input;
        let bounds = split.window_bounds(k, objects::SEGMENT_BYTES);
        let (base, data) = if bounds.end <= objects::SEGMENT_BYTES {
            (0, header)
        } else {
            ctx.block_on(objects::get_input_range(
                &ctx.res.objects,
                job,
                &input.file,
                input.bytes,
                bounds,
            ))?
        };
        let window = Window {
            data: &data,
            base,
            len: input.bytes,
            format: format_of(rec)?,
        };
        let ri = RangeInput {
            split: &split,
            r: k,
            window,
        };
        match phase {
            Phase::Survey => phases::count(&ri, &st),
            Phase::Sample => phases::sample(&ri, &st),
            _ => phases::route(&ri, &st, dir.path()),
        }
        .map_err(recon_error)?
    };
    if super::outcome::ended(ctx, job)? {
        // Ended while this task ran: the end's removal may have passed these values already.
        super::outcome::discard(ctx, job, &written)?;
        return Ok(None);
    }
    if progress.cancel.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(recon_error(ReconError::Cancelled));
    }
    let t = timing(&label, &ctx.worker, started_ms);
    let updated = ctx.block_on(records::update::<PrepState, _>(
        &ctx.res.jobs,
        &prep_key(job),
        |s| {
            if s.phase != phase || k >= s.done.len() || s.done[k] {
                return false;
            }
            s.done[k] = true;
            record(&mut s.tasks, t.clone());
            true
        },
    ))?;
    let s = updated.ok_or_else(|| TaskError::Retry(format!("job {job}: no prepare state")))?;
    let done = s.done.iter().filter(|&&d| d).count();
    let stage = if phase == Phase::CleanUp {
        Stage::Index
    } else {
        Stage::Clean
    };
    ctx.update_job(job, |r| {
        set_stage(r, stage, done as f64 / s.done.len() as f64)
    })?;
    Ok(Some(s))
}

/// Moves `state`'s phase to `next` with `items` tasks (once: nothing when another task did),
/// recording the step between the phases as `t`.
#[allow(clippy::too_many_arguments)]
fn move_to(
    ctx: &Ctx,
    job: Uuid,
    state: &PrepState,
    next: Phase,
    generation: u32,
    items: usize,
    blocks: usize,
    t: TaskReport,
) -> Result<(), TaskError> {
    let (from, from_gen) = (state.phase, state.generation);
    ctx.block_on(records::update::<PrepState, _>(
        &ctx.res.jobs,
        &prep_key(job),
        |s| {
            if s.phase != from || s.generation != from_gen {
                return false;
            }
            s.phase = next;
            s.generation = generation;
            s.done = vec![false; items];
            s.blocks = blocks;
            record(&mut s.tasks, t.clone());
            true
        },
    ))?;
    Ok(())
}

/// The step after a complete phase, and the next phase's tasks.
fn advance(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    state: &PrepState,
) -> Result<(), TaskError> {
    let job = rec.view.id;
    let st = store(ctx, job);
    let options = TiledOptions {
        worker: ctx.worker.clone(),
        ..Default::default()
    };
    let nr = state.ranges;
    let started_ms = unix_now_ms();
    let step = |name: &str| timing(name, &ctx.worker, started_ms);
    match state.phase {
        Phase::Survey => {
            let (_, split) = plan_split(ctx, rec, params, state.range_bytes)?
                .ok_or_else(|| TaskError::Retry("the input no longer splits".into()))?;
            phases::gather_counts(&split, &limits(rec, params), &st).map_err(recon_error)?;
            let t = step("number ranges");
            move_to(ctx, job, state, Phase::Sample, 0, nr, 0, t)?;
            publish(ctx, job, (0..nr).map(TaskKind::Sample))
        }
        Phase::Sample => {
            phases::plan_partition(params, &options, state.block_points, &st)
                .map_err(recon_error)?;
            let t = step("plan blocks");
            move_to(ctx, job, state, Phase::Route, 0, nr, 0, t)?;
            publish(ctx, job, (0..nr).map(|r| TaskKind::Route(r, 0)))
        }
        Phase::Route => {
            let dir = tempfile::tempdir().map_err(|e| TaskError::Retry(e.to_string()))?;
            let after = phases::after_routes(params, &options, state.block_points, &st, dir.path())
                .map_err(recon_error)?;
            let t = step(&format!("estimates {}", state.generation));
            match after {
                AfterRoutes::Reroute(g) => {
                    let old = phases::spill_keys(&st, state.generation, nr);
                    ctx.block_on(objects::remove(&ctx.res, job, &old))?;
                    move_to(ctx, job, state, Phase::Route, g, nr, 0, t)?;
                    publish(ctx, job, (0..nr).map(|r| TaskKind::Route(r, g)))
                }
                AfterRoutes::CleanUp(n) => {
                    move_to(ctx, job, state, Phase::CleanUp, state.generation, n, n, t)?;
                    ctx.update_job(job, |r| set_stage(r, Stage::Index, 0.0))?;
                    publish(ctx, job, (0..n).map(TaskKind::CleanUp))
                }
            }
        }
        Phase::CleanUp => begin_blocks(ctx, job, params, state, &st, started_ms),
    }
}

/// After the clean-up: the plan, the graph state, the block tasks; the prepare values go.
fn begin_blocks(
    ctx: &Ctx,
    job: Uuid,
    params: &ReconParams,
    state: &PrepState,
    st: &Store,
    started_ms: u64,
) -> Result<(), TaskError> {
    let plan = phases::complete(st, params).map_err(recon_error)?;
    ctx.block_on(objects::put(
        &ctx.res.objects,
        &objects::name(job, "plan"),
        &plan.encode(),
    ))?;
    let elapsed = unix_now_ms().saturating_sub(state.started_ms) as f64 / 1000.0;
    let mut tasks = state.tasks.clone();
    record(&mut tasks, timing("complete plan", &ctx.worker, started_ms));
    record(&mut tasks, timing("prepare", &ctx.worker, state.started_ms));
    let dag = DagState {
        blocks: vec![false; plan.blocks.len()],
        regions: vec![false; plan.grid.regions.len()],
        prepare_s: elapsed,
        regions_started_ms: 0,
        tasks,
    };
    ctx.block_on(records::create(&ctx.res.jobs, &dag_key(job), &dag))?;
    let keys = phases::prep_keys(state.ranges, state.generation, state.blocks);
    ctx.block_on(objects::remove(&ctx.res, job, &keys))?;
    ctx.block_on(records::purge(&ctx.res, &prep_key(job)))?;
    if super::outcome::ended(ctx, job)? {
        return super::outcome::remove_intermediates(ctx, job);
    }
    ctx.update_job(job, |r| set_stage(r, Stage::Blocks, 0.0))?;
    publish(ctx, job, (0..plan.blocks.len()).map(TaskKind::Block))
}

/// Removes job `job`'s prepare values and state (a job that ended, or a refusal). Blocks
/// written by the clean-up are removed with them.
pub(super) fn remove(res: &Resources, ctx: &Ctx, job: Uuid) -> Result<(), TaskError> {
    Ok(ctx.block_on(remove_async(res, job, Arc::new(store(ctx, job))))?)
}

/// [`remove`] from async code; `st` reads the job's values.
pub async fn remove_async(res: &Resources, job: Uuid, st: Arc<Store>) -> Result<(), DistError> {
    let Some((state, _)) = records::load::<PrepState>(&res.jobs, &prep_key(job)).await? else {
        return Ok(());
    };
    let (ranges, generation) = (state.ranges, state.generation);
    let mut keys = tokio::task::spawn_blocking(move || {
        let mut keys = Vec::new();
        for g in 0..=generation {
            keys.extend(phases::spill_keys(&st, g, ranges));
        }
        keys
    })
    .await
    .unwrap_or_default();
    keys.extend(phases::prep_keys(
        state.ranges,
        state.generation,
        state.blocks,
    ));
    keys.extend((0..state.blocks).map(|k| format!("points/{k}")));
    keys.push("plan".into());
    objects::remove(res, job, &keys).await?;
    records::purge(res, &prep_key(job)).await
}
