//! How a job ends on NATS: its results uploaded, its end decided once (compare-and-set on the
//! record), and its intermediate values removed, also those a task still running elsewhere
//! writes after the end.

use super::objects;
use super::records::{self, DagState, JobRecord, dag_key, job_key};
use super::steps::{Ctx, TaskError};
use crate::job::{ErrorBody, JobStatus, unix_now};
use uuid::Uuid;

/// Uploads every file of `dir` as `result/<file>`; returns the file names.
pub(super) fn upload_results(
    ctx: &Ctx,
    job: Uuid,
    dir: &std::path::Path,
) -> Result<Vec<String>, TaskError> {
    let entries = std::fs::read_dir(dir).map_err(|e| TaskError::Retry(e.to_string()))?;
    let mut files = Vec::new();
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().to_string();
        let bytes = std::fs::read(entry.path()).map_err(|e| TaskError::Retry(e.to_string()))?;
        let name = objects::name(job, &format!("result/{file}"));
        ctx.block_on(objects::put(&ctx.res.objects, &name, &bytes))?;
        files.push(file);
    }
    Ok(files)
}

/// How a job ends.
pub enum Outcome {
    /// With a mesh of this many triangles and these result files.
    Succeeded {
        /// Triangles of the mesh.
        triangles: usize,
        /// Files under `result/`.
        results: Vec<String>,
    },
    /// With this error.
    Failed(ErrorBody),
}

/// Ends job `job` (unless it already ended; a success of a cancelled job ends `cancelled`): the
/// end is decided once, by compare-and-set on the record, and the call that decided it removes
/// the job's intermediate values (the plan, the blocks' points, splines and outcomes, the pieces).
/// Values a task still running elsewhere writes afterwards are removed with the job (expiry or
/// DELETE), whose names come from the same graph state.
pub fn finish_job(ctx: &Ctx, job: Uuid, outcome: Outcome) -> Result<(), TaskError> {
    let (status, error, triangles, results) = match outcome {
        Outcome::Succeeded { triangles, results } => {
            (JobStatus::Succeeded, None, Some(triangles), results)
        }
        Outcome::Failed(e) => (JobStatus::Failed, Some(e), None, Vec::new()),
    };
    let (mut ended, mut discard) = (false, false);
    ctx.block_on(records::update::<JobRecord, _>(
        &ctx.res.jobs,
        &job_key(job),
        |r| {
            ended = !r.view.status.is_terminal();
            if !ended {
                return false;
            }
            // A result that raced a cancel is discarded (its names stay in the record, so the
            // job's deletion removes what a crash here would leave).
            discard = r.cancel && !results.is_empty();
            r.results = results.clone();
            let (status, error, triangles) = if r.cancel {
                (JobStatus::Cancelled, Some(cancelled_error()), None)
            } else {
                (status, error.clone(), triangles)
            };
            r.view.status = status;
            r.view.error = error;
            r.view.triangles = triangles;
            r.view.finished_at = Some(unix_now());
            if status == JobStatus::Succeeded {
                r.view.progress = 1.0;
                r.view.stage_progress = 1.0;
            }
            true
        },
    ))?;
    if ended {
        remove_intermediates(ctx, job)?;
    }
    if ended && discard {
        let keys: Vec<String> = results.iter().map(|f| format!("result/{f}")).collect();
        ctx.block_on(objects::remove(&ctx.res, job, &keys))?;
    }
    Ok(())
}

/// Removes job `job`'s intermediate values (names from its graph state; none without one).
pub(super) fn remove_intermediates(ctx: &Ctx, job: Uuid) -> Result<(), TaskError> {
    super::prepare::remove(&ctx.res, ctx, job)?;
    let dag = ctx.block_on(records::load::<DagState>(&ctx.res.jobs, &dag_key(job)))?;
    if let Some((d, _)) = dag {
        let keys = objects::intermediates(d.blocks.len(), d.regions.len());
        ctx.block_on(objects::remove(&ctx.res, job, &keys))?;
    }
    Ok(())
}

/// Whether job `job` has ended (or is gone).
pub(super) fn ended(ctx: &Ctx, job: Uuid) -> Result<bool, TaskError> {
    Ok(ctx.record(job)?.is_none_or(|r| r.view.status.is_terminal()))
}

/// Removes values a task wrote after its job ended: the end's removal may have passed them
/// already. (Written before the end, they are the end's to remove: either way none is left.)
pub(super) fn discard(ctx: &Ctx, job: Uuid, keys: &[String]) -> Result<(), TaskError> {
    Ok(ctx.block_on(objects::remove(&ctx.res, job, keys))?)
}

pub(super) fn cancelled_error() -> ErrorBody {
    ErrorBody {
        code: "cancelled".into(),
        message: "cancelled by a DELETE request".into(),
    }
}
