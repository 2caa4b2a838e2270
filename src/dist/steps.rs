//! The bodies of the tasks, run on blocking threads: start (whole job, or prepare and publish
//! the blocks), block, region, merge. Each calls the task graph's own step functions
//! ([`crate::pipeline::tiled`]) over the object store, records what it did with compare-and-set,
//! and publishes the next phase when its update completed the current one.

use super::objects::{self, JobObjects};
pub use super::outcome::{Outcome, finish_job};
use super::outcome::{cancelled_error, discard, ended, remove_intermediates, upload_results};
use super::queue::{self, Task, TaskKind};
use super::records::{self, DagState, JobRecord, dag_key, job_key};
use super::spread::{record, timing};
use super::{DistError, connect::Resources};
use crate::error::{ErrorKind, ReconError};
use crate::io::{MeshFormat, ReadLimits};
use crate::job::{ErrorBody, JobStatus, unix_now, unix_now_ms};
use crate::params::ReconParams;
use crate::pipeline::tiled::codec::{decode_region, encode_region};
use crate::pipeline::tiled::graph::{self, BlockOutcome};
use crate::pipeline::tiled::prepare::{self, Plan};
use crate::pipeline::tiled::store::Store;
use crate::pipeline::tiled::{self, TiledOptions};
use crate::pipeline::{Execution, PointSource, RunError, RunOutput, plan_execution, run};
use crate::progress::{Progress, Stage};
use crate::report::{TaskReport, Timings};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use uuid::Uuid;

/// Why a task did not complete.
#[derive(Debug)]
pub enum TaskError {
    /// The job cannot succeed (bad input, over a limit, a bug): it fails with this error.
    Job(ErrorBody),
    /// Something outside the job failed (NATS unreachable): run the task again.
    Retry(String),
}

impl From<DistError> for TaskError {
    fn from(e: DistError) -> Self {
        TaskError::Retry(e.to_string())
    }
}

/// A reconstruction error as the job's error (a stop requested by a DELETE included).
pub(super) fn recon_error(e: ReconError) -> TaskError {
    match e {
        ReconError::Store(s) => TaskError::Retry(s.to_string()),
        e => TaskError::Job(ErrorBody {
            code: e.kind().code().into(),
            message: e.to_string(),
        }),
    }
}

/// What every task of this process shares.
pub struct Ctx {
    /// NATS resources.
    pub res: Resources,
    /// The runtime blocking threads call into.
    pub rt: tokio::runtime::Handle,
    /// This worker's id (`blocks[].worker`).
    pub worker: String,
    /// Tasks run at once (also the concurrency the block size is planned for).
    pub concurrency: usize,
    /// Points from which a job within its budget is split when another worker is idle
    /// ([`super::spread`]; `u64::MAX`: never).
    pub spread_points: u64,
    /// How prepare reads a job's input: by byte ranges (the default), or whole.
    pub split: tiled::InputSplit,
    /// The last plans decoded, by job (a plan rebuilds the far field: worth keeping).
    plans: Mutex<VecDeque<(Uuid, Arc<Plan>)>>,
}

impl Ctx {
    /// A context over `res`.
    pub fn new(
        res: Resources,
        rt: tokio::runtime::Handle,
        worker: String,
        concurrency: usize,
    ) -> Ctx {
        Ctx {
            res,
            rt,
            worker,
            concurrency,
            spread_points: super::spread::SPREAD_POINTS,
            split: tiled::InputSplit::default(),
            plans: Mutex::new(VecDeque::new()),
        }
    }

    pub(super) fn block_on<F: std::future::Future>(&self, f: F) -> F::Output {
        self.rt.block_on(f)
    }

    fn store(&self, job: Uuid) -> Store {
        self.recording_store(job, None)
    }

    fn recording_store(&self, job: Uuid, written: Option<Arc<Mutex<Vec<String>>>>) -> Store {
        Store::Remote(Box::new(JobObjects {
            os: self.res.objects.clone(),
            job,
            rt: self.rt.clone(),
            written,
        }))
    }

    pub(super) fn record(&self, job: Uuid) -> Result<Option<JobRecord>, TaskError> {
        let r = self.block_on(records::load::<JobRecord>(&self.res.jobs, &job_key(job)))?;
        Ok(r.map(|(v, _)| v))
    }

    /// Changes job `job`'s record (compare-and-set) unless it is terminal.
    pub fn update_job(
        &self,
        job: Uuid,
        mut f: impl FnMut(&mut JobRecord),
    ) -> Result<(), TaskError> {
        self.block_on(records::update::<JobRecord, _>(
            &self.res.jobs,
            &job_key(job),
            |r| {
                if r.view.status.is_terminal() {
                    return false;
                }
                let before = serde_json::to_vec(&r.view).unwrap_or_default();
                f(r);
                serde_json::to_vec(&r.view).unwrap_or_default() != before
            },
        ))?;
        Ok(())
    }

    fn plan(&self, job: Uuid, params: &ReconParams) -> Result<Arc<Plan>, TaskError> {
        let mut plans = self.plans.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, p)) = plans.iter().find(|(j, _)| *j == job) {
            return Ok(Arc::clone(p));
        }
        drop(plans);
        let name = objects::name(job, "plan");
        let bytes = self.block_on(objects::get(&self.res.objects, &name))?;
        let plan =
            Plan::decode(&bytes, &name, params).map_err(|e| TaskError::Retry(e.to_string()))?;
        let plan = Arc::new(plan);
        plans = self.plans.lock().unwrap_or_else(|e| e.into_inner());
        plans.push_front((job, Arc::clone(&plan)));
        plans.truncate(2);
        Ok(plan)
    }
}

/// Progress of the running task: the stage and fraction (published by the worker loop) and the
/// cancel flag (set by the worker loop from the job record).
#[derive(Default)]
pub struct TaskProgress {
    /// Set when the job was cancelled.
    pub cancel: AtomicBool,
    stage: Mutex<Option<Stage>>,
    fraction: AtomicU64,
}

impl TaskProgress {
    /// The job's overall progress so far, with its stage (whole-job tasks only).
    pub fn snapshot(&self) -> Option<(Stage, f64)> {
        let stage = (*self.stage.lock().unwrap_or_else(|e| e.into_inner()))?;
        Some((stage, f64::from_bits(self.fraction.load(Ordering::Relaxed))))
    }
}

impl Progress for TaskProgress {
    fn stage(&self, stage: Stage) {
        *self.stage.lock().unwrap_or_else(|e| e.into_inner()) = Some(stage);
        self.fraction.store(0f64.to_bits(), Ordering::Relaxed);
    }
    fn fraction(&self, done: f64) {
        self.fraction
            .store(done.clamp(0.0, 1.0).to_bits(), Ordering::Relaxed);
    }
    fn cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }
}

/// Runs `task`. `Ok(false)`: skipped (the job is finished, cancelled or gone).
pub fn run_task(ctx: &Ctx, task: Task, progress: &TaskProgress) -> Result<bool, TaskError> {
    let Some(rec) = ctx.record(task.job)? else {
        return Ok(false);
    };
    if rec.view.status.is_terminal() {
        return Ok(false);
    }
    if rec.cancel {
        // Cancelled between tasks: the first task to see it ends the job (the others skip).
        finish_job(ctx, task.job, Outcome::Failed(cancelled_error()))?;
        return Ok(false);
    }
    let params = ReconParams::try_from(&rec.options).map_err(|e| {
        TaskError::Job(ErrorBody {
            code: ErrorKind::BadParameter.code().into(),
            message: e.to_string(),
        })
    })?;
    match task.kind {
        TaskKind::Start => start(ctx, &rec, &params, progress),
        TaskKind::Block(b) => block(ctx, task.job, &params, b, progress),
        TaskKind::Region(r) => region(ctx, task.job, &params, r, progress),
        TaskKind::Merge => merge(ctx, &rec, &params),
        TaskKind::Whole => whole_from_store(ctx, &rec, &params, progress),
        k => super::prepare::run(ctx, &rec, &params, k, progress),
    }
    .map(|()| true)
}

fn start(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    progress: &TaskProgress,
) -> Result<(), TaskError> {
    let job = rec.view.id;
    let started_ms = unix_now_ms();
    ctx.update_job(job, |r| {
        if r.view.status == JobStatus::Queued {
            r.view.status = JobStatus::Running;
            r.view.started_at = Some(unix_now());
            r.view.stage = Some(Stage::Read.name().into());
        }
    })?;
    if [crate::job::volume::COMPOSITION, crate::job::volume::MORPH]
        .contains(&rec.view.input.format.as_str())
    {
        return volume(ctx, rec, progress);
    }
    if let Some(r) = super::prepare::start_by_ranges(ctx, rec, params, started_ms)? {
        return r;
    }
    let input = &rec.view.input;
    let data = ctx.block_on(objects::get_input(
        &ctx.res.objects,
        job,
        &input.file,
        input.bytes,
    ))?;
    let format = super::prepare::format_of(rec)?;
    let limits = super::prepare::limits(rec, params);
    let cloud = crate::io::parse_point_cloud(&data, format, &limits)
        .map_err(|e| run_error(RunError::Read(e)))?;
    let n = cloud.points.len() as u64;
    let stream = || {
        let input = crate::io::StreamInput::Bytes {
            data: &data,
            format,
        };
        tiled::TiledInput::Stream(input, &limits)
    };
    match plan_execution(n, params).map_err(recon_error)? {
        Execution::InMemory => {
            let attrs = crate::job::model::InputAttributes::of(&cloud);
            let spread = super::spread::spread_over(ctx, n, params, attrs)?;
            drop(cloud);
            if let Some(idle) = spread {
                tracing::info!(job = %job, points = n, idle = ?idle, "splitting the job into block tasks");
                match prepare_graph(ctx, job, params, &stream(), n, started_ms, progress) {
                    Err(TaskError::Job(e)) if e.code != ErrorKind::Cancelled.code() => {
                        tracing::info!(job = %job, error = %e.message, "the task graph refused the job; running it whole");
                    }
                    r => return r,
                }
            }
            whole(
                ctx,
                rec,
                params,
                PointSource::Bytes {
                    data: &data,
                    format,
                },
                &limits,
                progress,
            )
        }
        Execution::OutOfCore(_) => {
            drop(cloud);
            prepare_graph(ctx, job, params, &stream(), n, started_ms, progress)
        }
    }
}

/// A spread job the task graph refused, run whole on this worker.
fn whole_from_store(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    progress: &TaskProgress,
) -> Result<(), TaskError> {
    let input = &rec.view.input;
    let data = ctx.block_on(objects::get_input(
        &ctx.res.objects,
        rec.view.id,
        &input.file,
        input.bytes,
    ))?;
    let format = super::prepare::format_of(rec)?;
    let limits = super::prepare::limits(rec, params);
    let source = PointSource::Bytes {
        data: &data,
        format,
    };
    whole(ctx, rec, params, source, &limits, progress)
}

/// The error of a failed run as the job's error (as the embedded service words it).
fn run_error(e: RunError) -> TaskError {
    match e {
        RunError::Reconstruct {
            source: ReconError::Store(s),
            ..
        } => TaskError::Retry(s.to_string()),
        e @ (RunError::Read(_) | RunError::Write(_)) if e.kind() == ErrorKind::Internal => {
            TaskError::Job(crate::job::error::internal_body(&e.to_string()))
        }
        e => TaskError::Job(ErrorBody {
            code: e.kind().code().into(),
            message: e.to_string(),
        }),
    }
}

/// The whole job on this worker: the run stage into a temporary directory, then the results.
fn whole(
    ctx: &Ctx,
    rec: &JobRecord,
    params: &ReconParams,
    source: PointSource<'_>,
    limits: &ReadLimits,
    progress: &TaskProgress,
) -> Result<(), TaskError> {
    let dir = tempfile::tempdir().map_err(|e| TaskError::Retry(e.to_string()))?;
    let mesh = dir.path().join("mesh.glb");
    let report = dir.path().join("report.json");
    let field = dir.path().join("fitted.field");
    let output = RunOutput {
        mesh: &mesh,
        format: MeshFormat::Glb(rec.options.glb()),
        report: Some(&report),
        field: (params.method == crate::params::Method::Csrbf).then_some(field.as_path()),
        job_memory_mib: None,
    };
    let summary = run(source, params, limits, &output, progress).map_err(run_error)?;
    let results = upload_results(ctx, rec.view.id, dir.path())?;
    let done = Outcome::Succeeded {
        triangles: summary.triangles,
        results,
    };
    finish_job(ctx, rec.view.id, done)
}

/// A composition or morph job, whole on this worker (it is not block-parallel): the operands'
/// saved fields come from their jobs' results in the object store, the mesh and report go to
/// this job's results, as for a reconstruction.
fn volume(ctx: &Ctx, rec: &JobRecord, progress: &TaskProgress) -> Result<(), TaskError> {
    use crate::job::volume::{VolumeRequest, run_volume};
    let job = rec.view.id;
    let input = &rec.view.input;
    let bytes = ctx.block_on(objects::get_input(
        &ctx.res.objects,
        job,
        &input.file,
        input.bytes,
    ))?;
    let req = VolumeRequest::decode(&bytes).map_err(TaskError::Job)?;
    let ids = req.validate().map_err(|e| {
        TaskError::Job(ErrorBody {
            code: e.code().into(),
            message: e.to_string(),
        })
    })?;
    let mut fields = std::collections::HashMap::new();
    for op in ids {
        let name = objects::name(op, "result/fitted.field");
        if let Some(bytes) = ctx.block_on(objects::get_opt(&ctx.res.objects, &name))? {
            fields.insert(op, (bytes, name));
        }
    }
    let dir = tempfile::tempdir().map_err(|e| TaskError::Retry(e.to_string()))?;
    let (mesh, report) = (dir.path().join("mesh.glb"), dir.path().join("report.json"));
    let mut load = |op: Uuid| {
        let (bytes, name) = fields.get(&op)?;
        crate::frep::format::decode(bytes, name).ok()
    };
    let triangles =
        run_volume(&req, &mut load, &mesh, &report, progress).map_err(TaskError::Job)?;
    let results = upload_results(ctx, job, dir.path())?;
    finish_job(ctx, job, Outcome::Succeeded { triangles, results })
}

fn prepare_graph(
    ctx: &Ctx,
    job: Uuid,
    params: &ReconParams,
    input: &tiled::TiledInput<'_>,
    n: u64,
    started_ms: u64,
    progress: &TaskProgress,
) -> Result<(), TaskError> {
    let t = Instant::now();
    let est = graph_estimate(ctx, n, params)?;
    let options = TiledOptions {
        worker: ctx.worker.clone(),
        split: ctx.split,
        ..Default::default()
    };
    let written = Arc::new(Mutex::new(Vec::new()));
    let store = ctx.recording_store(job, Some(Arc::clone(&written)));
    let prepared = prepare::prepare(input, params, &options, est.block_points, &store, progress);
    let (plan, prepare_tasks) = match prepared {
        Ok(prepared) => prepared,
        Err(e) => {
            // Cancelled or failed half-way: no graph state names these values yet.
            let keys = std::mem::take(&mut *written.lock().unwrap_or_else(|e| e.into_inner()));
            ctx.block_on(objects::remove(&ctx.res, job, &keys))?;
            return Err(recon_error(e));
        }
    };
    let blob = plan.encode();
    ctx.block_on(objects::put(
        &ctx.res.objects,
        &objects::name(job, "plan"),
        &blob,
    ))?;
    let dag = DagState {
        blocks: vec![false; plan.blocks.len()],
        regions: vec![false; plan.grid.regions.len()],
        prepare_s: t.elapsed().as_secs_f64(),
        regions_started_ms: 0,
        tasks: (prepare_tasks.into_iter())
            .chain([timing("prepare", &ctx.worker, started_ms)])
            .collect(),
    };
    ctx.block_on(records::create(&ctx.res.jobs, &dag_key(job), &dag))?;
    if ended(ctx, job)? {
        // Ended (cancelled) while preparing: the end's removal may have run before the graph
        // state named these values.
        return remove_intermediates(ctx, job);
    }
    ctx.update_job(job, |r| set_stage(r, Stage::Blocks, 0.0))?;
    let tasks: Vec<Task> = (0..plan.blocks.len())
        .map(|b| Task {
            job,
            kind: TaskKind::Block(b),
        })
        .collect();
    ctx.block_on(queue::publish(&ctx.res.js, &tasks))?;
    Ok(())
}

/// The task graph's estimate for a job of `n` points, refused when over its budget or when its
/// parameters are invalid.
pub(super) fn graph_estimate(
    ctx: &Ctx,
    n: u64,
    params: &ReconParams,
) -> Result<tiled::OutOfCoreEstimate, TaskError> {
    let est = tiled::estimate(n, params.max_memory_mib, ctx.concurrency);
    if est.peak_mib > params.max_memory_mib as f64 {
        let e = ReconError::OutOfCoreOverBudget {
            points: n,
            mib: est.peak_mib,
            budget_mib: params.max_memory_mib,
        };
        return Err(recon_error(e));
    }
    params.validate().map_err(|e| recon_error(e.into()))?;
    Ok(est)
}

pub(super) fn set_stage(r: &mut JobRecord, stage: Stage, fraction: f64) {
    r.view.stage = Some(stage.name().into());
    r.view.stage_progress = fraction;
    if let Some(p) = stage.overall(fraction) {
        r.view.progress = r.view.progress.max(p);
    }
}

/// Marks item `k` of the phase done and records its timeline entry `t`; returns (done, total)
/// after the update.
fn mark_done(
    ctx: &Ctx,
    job: Uuid,
    k: usize,
    regions: bool,
    t: TaskReport,
) -> Result<(usize, usize), TaskError> {
    let dag = ctx.block_on(records::update::<DagState, _>(
        &ctx.res.jobs,
        &dag_key(job),
        |d| {
            let flags = if regions {
                &mut d.regions
            } else {
                &mut d.blocks
            };
            if k >= flags.len() || flags[k] {
                return false;
            }
            flags[k] = true;
            record(&mut d.tasks, t.clone());
            if !regions && d.blocks.iter().all(|&x| x) {
                d.regions_started_ms = unix_now_ms();
            }
            true
        },
    ))?;
    let dag = dag.ok_or_else(|| TaskError::Retry(format!("job {job}: no graph state")))?;
    let flags = if regions { &dag.regions } else { &dag.blocks };
    Ok((flags.iter().filter(|&&x| x).count(), flags.len()))
}

fn block(
    ctx: &Ctx,
    job: Uuid,
    params: &ReconParams,
    b: usize,
    progress: &TaskProgress,
) -> Result<(), TaskError> {
    let started_ms = unix_now_ms();
    let plan = ctx.plan(job, params)?;
    let store = ctx.store(job);
    let outcome = graph::fit_step(&plan, &store, b, &ctx.worker, progress).map_err(recon_error)?;
    let name = objects::name(job, &format!("block/{b}"));
    ctx.block_on(objects::put(&ctx.res.objects, &name, &outcome.encode()))?;
    if ended(ctx, job)? {
        return discard(ctx, job, &[format!("spline/{b}"), format!("block/{b}")]);
    }
    let t = timing(&format!("block {b}"), &ctx.worker, started_ms);
    let (done, total) = mark_done(ctx, job, b, false, t)?;
    if done < total {
        return ctx.update_job(job, |r| {
            set_stage(r, Stage::Blocks, done as f64 / total as f64)
        });
    }
    ctx.update_job(job, |r| set_stage(r, Stage::Polygonize, 0.0))?;
    let tasks: Vec<Task> = (0..plan.grid.regions.len())
        .map(|r| Task {
            job,
            kind: TaskKind::Region(r),
        })
        .collect();
    Ok(ctx.block_on(queue::publish(&ctx.res.js, &tasks))?)
}

fn region(
    ctx: &Ctx,
    job: Uuid,
    params: &ReconParams,
    r: usize,
    progress: &TaskProgress,
) -> Result<(), TaskError> {
    let started_ms = unix_now_ms();
    let plan = ctx.plan(job, params)?;
    let store = ctx.store(job);
    let outcome = graph::region_step(&plan, &store, r, progress).map_err(recon_error)?;
    let name = objects::name(job, &format!("region/{r}"));
    ctx.block_on(objects::put(
        &ctx.res.objects,
        &name,
        &encode_region(&outcome),
    ))?;
    if ended(ctx, job)? {
        return discard(ctx, job, &[format!("piece/{r}"), format!("region/{r}")]);
    }
    let t = timing(&format!("region {r}"), &ctx.worker, started_ms);
    let (done, total) = mark_done(ctx, job, r, true, t)?;
    if done < total {
        return ctx.update_job(job, |v| {
            set_stage(v, Stage::Polygonize, done as f64 / total as f64)
        });
    }
    ctx.update_job(job, |v| set_stage(v, Stage::Post, 0.0))?;
    Ok(ctx.block_on(queue::publish(
        &ctx.res.js,
        &[Task {
            job,
            kind: TaskKind::Merge,
        }],
    ))?)
}

fn merge(ctx: &Ctx, rec: &JobRecord, params: &ReconParams) -> Result<(), TaskError> {
    let started_ms = unix_now_ms();
    let job = rec.view.id;
    let plan = ctx.plan(job, params)?;
    let store = ctx.store(job);
    let dag = ctx.block_on(records::load::<DagState>(&ctx.res.jobs, &dag_key(job)))?;
    let (dag, _) = dag.ok_or_else(|| TaskError::Retry(format!("job {job}: no graph state")))?;
    let get = |key: String| {
        let name = objects::name(job, &key);
        ctx.block_on(objects::get(&ctx.res.objects, &name))
            .map(|b| (b, name))
    };
    let mut blocks = Vec::with_capacity(plan.blocks.len());
    for b in 0..plan.blocks.len() {
        let (bytes, name) = get(format!("block/{b}"))?;
        blocks.push(
            BlockOutcome::decode(&bytes, &name).map_err(|e| TaskError::Retry(e.to_string()))?,
        );
    }
    let mut regions = Vec::with_capacity(plan.grid.regions.len());
    for r in 0..plan.grid.regions.len() {
        let (bytes, name) = get(format!("region/{r}"))?;
        regions.push(decode_region(&bytes, &name).map_err(|e| TaskError::Retry(e.to_string()))?);
    }
    let blocks_peak = blocks
        .iter()
        .map(|b| b.report.peak_rss_mib)
        .fold(0.0, f64::max);
    let mut timings = Timings {
        clean: dag.prepare_s,
        polygonize: unix_now_ms().saturating_sub(dag.regions_started_ms) as f64 / 1000.0,
        ..Default::default()
    };
    let (reports, matrix) = graph::merge_blocks(blocks, &mut timings);
    let (mesh, poly, residual) = graph::weld_step(&plan, &store, &regions).map_err(recon_error)?;
    let age = unix_now().saturating_sub(rec.view.started_at.unwrap_or(rec.view.created_at));
    let start = Instant::now()
        .checked_sub(Duration::from_secs(age))
        .unwrap_or_else(Instant::now);
    let mut recon = tiled::finish(&plan, mesh, poly, residual, reports, matrix, timings, start)
        .map_err(recon_error)?;
    recon.report.memory.peak_rss_mib = recon.report.memory.peak_rss_mib.max(blocks_peak);
    let mut tasks = dag.tasks;
    record(&mut tasks, timing("merge", &ctx.worker, started_ms));
    recon.report.critical_path = crate::report::critical_path(&tasks);
    recon.report.tasks = tasks;
    let dir = tempfile::tempdir().map_err(|e| TaskError::Retry(e.to_string()))?;
    let meta = crate::io::MeshMeta::default();
    let glb = MeshFormat::Glb(rec.options.glb());
    crate::io::write_mesh_with(&dir.path().join("mesh.glb"), &recon.mesh, glb, &meta)
        .map_err(|e| run_error(RunError::Write(e)))?;
    let json = serde_json::to_vec_pretty(&recon.report).unwrap_or_default();
    crate::io::write_atomic(&dir.path().join("report.json"), &json)
        .map_err(|e| run_error(RunError::Write(e)))?;
    let results = upload_results(ctx, job, dir.path())?;
    let triangles = recon.mesh.triangles.len();
    finish_job(ctx, job, Outcome::Succeeded { triangles, results })
}
