//! `rbfsurf worker`: pull tasks from the shared consumer, at most `concurrency` at once, each on
//! a blocking thread; while one runs, send an in-progress acknowledgement every
//! [`HEARTBEAT`] (so the ack wait only has to cover a dead worker, not a long task), publish a
//! whole job's progress and pick up its cancellation. A task that succeeded or was skipped is
//! acknowledged; one whose job failed ends the job and is acknowledged; one that failed outside
//! the job (NATS unreachable) is negatively acknowledged and runs again, until the last
//! delivery, which fails the job.

use super::DistError;
use super::connect::{self, MAX_DELIVER, NatsConfig};
use super::queue::{Task, TaskKind};
use super::records::{self, JobRecord, job_key};
use super::steps::{self, Ctx, TaskError, TaskProgress};
use async_nats::jetstream::{AckKind, Message};
use futures_util::StreamExt;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

/// Period of in-progress acknowledgements and progress updates of a running task.
pub const HEARTBEAT: Duration = Duration::from_secs(2);
/// Period at which a running task's job record is read for a cancellation (one direct get of
/// one key); the task's stages check the flag at their own granularity (milliseconds).
pub const CANCEL_POLL: Duration = Duration::from_millis(500);

/// How the worker runs.
#[derive(Debug, Clone)]
pub struct WorkerParams {
    /// The server and credentials.
    pub nats: NatsConfig,
    /// Tasks at once.
    pub concurrency: usize,
    /// Points from which a job within its memory budget is split into block tasks when another
    /// worker is idle ([`super::spread`]).
    pub spread_points: u64,
    /// How this worker's prepare reads a job's input (by byte ranges, or whole).
    pub split: crate::pipeline::tiled::InputSplit,
}

/// Runs the worker until the process is stopped.
pub async fn run_worker(p: &WorkerParams) -> Result<(), DistError> {
    let id = super::worker_id();
    tracing::info!(
        worker = %id,
        concurrency = p.concurrency,
        nats = %connect::redact_url(&p.nats.url),
        "rbfsurf worker {id} starting"
    );
    let client = connect::connect(&p.nats, &format!("rbfsurf-worker {id}")).await?;
    let res = connect::open(client).await?;
    let consumer = connect::worker_consumer(&res, &p.nats).await?;
    let mut ctx = Ctx::new(
        res,
        tokio::runtime::Handle::current(),
        id.clone(),
        p.concurrency.max(1),
    );
    ctx.spread_points = p.spread_points;
    ctx.split = p.split;
    let ctx = Arc::new(ctx);
    let slots = Arc::new(tokio::sync::Semaphore::new(p.concurrency.max(1)));
    let running = Arc::new(AtomicUsize::new(0));
    let changed = Arc::new(tokio::sync::Notify::new());
    tokio::spawn(super::presence::announce(
        ctx.res.workers.clone(),
        id.clone(),
        p.concurrency.max(1),
        {
            let running = Arc::clone(&running);
            move || running.load(Ordering::Relaxed)
        },
        Arc::clone(&changed),
    ));
    tracing::info!(worker = %id, "waiting for tasks");
    loop {
        let Ok(permit) = Arc::clone(&slots).acquire_owned().await else {
            return Ok(());
        };
        let batch = consumer
            .batch()
            .max_messages(1)
            .expires(Duration::from_secs(5))
            .messages()
            .await;
        let mut batch = match batch {
            Ok(b) => b,
            Err(e) => {
                tracing::warn!(error = %e, "cannot pull tasks; retrying");
                tokio::time::sleep(Duration::from_secs(1)).await;
                continue;
            }
        };
        match batch.next().await {
            Some(Ok(msg)) => {
                let ctx = Arc::clone(&ctx);
                let (running, changed) = (Arc::clone(&running), Arc::clone(&changed));
                running.fetch_add(1, Ordering::Relaxed);
                changed.notify_one();
                tokio::spawn(async move {
                    handle(ctx, msg).await;
                    running.fetch_sub(1, Ordering::Relaxed);
                    changed.notify_one();
                    drop(permit);
                });
            }
            Some(Err(e)) => {
                tracing::warn!(error = %e, "pulling tasks failed; retrying");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
            None => {}
        }
    }
}

/// Runs one task message to its acknowledgement.
async fn handle(ctx: Arc<Ctx>, msg: Message) {
    let Ok(task) = serde_json::from_slice::<Task>(&msg.payload) else {
        tracing::warn!("a task message that does not parse; dropped");
        let _ = msg.ack_with(AckKind::Term).await;
        return;
    };
    let delivered = msg.info().map_or(1, |i| i.delivered);
    let label = task.label();
    tracing::info!(job = %task.job, task = %label, delivery = delivered, worker = %ctx.worker, "task started");
    let started = std::time::Instant::now();
    let progress = Arc::new(TaskProgress::default());
    let mut run = {
        let (ctx, progress) = (Arc::clone(&ctx), Arc::clone(&progress));
        tokio::task::spawn_blocking(move || steps::run_task(&ctx, task, &progress))
    };
    let mut tick = tokio::time::interval(HEARTBEAT);
    tick.tick().await;
    let mut poll = tokio::time::interval(CANCEL_POLL);
    poll.tick().await;
    let result = loop {
        tokio::select! {
            r = &mut run => break r,
            _ = tick.tick() => heartbeat(&ctx, &msg, task, &progress).await,
            _ = poll.tick() => poll_cancel(&ctx, task, &progress).await,
        }
    };
    let secs = started.elapsed().as_secs_f64();
    let result = result.unwrap_or_else(|e| {
        Err(TaskError::Job(crate::job::error::internal_body(&format!(
            "task {label} of job {} panicked: {e}",
            task.job
        ))))
    });
    match result {
        Ok(ran) => {
            let _ = msg.double_ack().await;
            tracing::info!(job = %task.job, task = %label, seconds = secs, skipped = !ran, "task finished");
        }
        Err(TaskError::Job(body)) => {
            tracing::warn!(job = %task.job, task = %label, code = %body.code, error = %body.message, "task failed; job failed");
            fail(&ctx, task, body).await;
            let _ = msg.ack().await;
        }
        Err(TaskError::Retry(m)) if delivered >= MAX_DELIVER => {
            tracing::error!(job = %task.job, task = %label, error = %m, "task failed on its last delivery; job failed");
            let body = crate::job::error::internal_body(&m);
            fail(&ctx, task, body).await;
            let _ = msg.ack().await;
        }
        Err(TaskError::Retry(m)) => {
            tracing::warn!(job = %task.job, task = %label, error = %m, "task failed; it will run again");
            let _ = msg
                .ack_with(AckKind::Nak(Some(Duration::from_secs(2))))
                .await;
        }
    }
}

async fn fail(ctx: &Arc<Ctx>, task: Task, body: crate::job::error::ErrorBody) {
    let ctx = Arc::clone(ctx);
    let _ = tokio::task::spawn_blocking(move || {
        steps::finish_job(&ctx, task.job, steps::Outcome::Failed(body))
    })
    .await;
}

/// Sets the task's cancel flag when its job was cancelled, ended or deleted.
async fn poll_cancel(ctx: &Ctx, task: Task, progress: &TaskProgress) {
    if progress.cancel.load(Ordering::Relaxed) {
        return;
    }
    let entry = tokio::time::timeout(CANCEL_POLL, ctx.res.jobs.get(job_key(task.job))).await;
    let stop = match entry {
        Ok(Ok(Some(bytes))) => serde_json::from_slice::<JobRecord>(&bytes)
            .is_ok_and(|r| r.cancel || r.view.status.is_terminal()),
        Ok(Ok(None)) => true,
        // No answer in time or NATS unreachable: the next poll tries again.
        _ => false,
    };
    if stop {
        progress.cancel.store(true, Ordering::Relaxed);
    }
}

/// Keeps the task's message alive, publishes a whole job's progress, picks up a cancellation.
async fn heartbeat(ctx: &Ctx, msg: &Message, task: Task, progress: &TaskProgress) {
    let _ = msg.ack_with(AckKind::Progress).await;
    let key = job_key(task.job);
    let snapshot = (task.kind == TaskKind::Start)
        .then(|| progress.snapshot())
        .flatten();
    let update = records::update::<JobRecord, _>(&ctx.res.jobs, &key, |r| {
        if r.cancel {
            progress.cancel.store(true, Ordering::Relaxed);
        }
        let Some((stage, fraction)) = snapshot else {
            return false;
        };
        if r.view.status.is_terminal() {
            return false;
        }
        let before = (r.view.stage.clone(), r.view.progress, r.view.stage_progress);
        r.view.stage = Some(stage.name().into());
        r.view.stage_progress = fraction;
        if let Some(p) = stage.overall(fraction) {
            r.view.progress = r.view.progress.max(p);
        }
        (r.view.stage.clone(), r.view.progress, r.view.stage_progress) != before
    });
    if let Ok(Ok(Some(r))) = tokio::time::timeout(HEARTBEAT, update).await
        && (r.cancel || r.view.status.is_terminal())
    {
        progress.cancel.store(true, Ordering::Relaxed);
    }
}
