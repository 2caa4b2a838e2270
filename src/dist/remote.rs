//! The API node's side (`serve --nats`): a [`JobBackend`] that stores a new job's input in the
//! object store and its record in the key-value bucket and queues its `start` task, and the
//! mirror that watches every job record (with history, so a new node learns every job) and
//! feeds the node's [`JobManager`]. A job's results are copied into the data directory before
//! the node shows it succeeded, so whoever sees `succeeded` can download them.

use super::DistError;
use super::connect::{self, NatsConfig, Resources};
use super::objects::{self, JobObjects};
use super::queue::{self, Task, TaskKind};
use super::records::{self, DELETE_CLAIM_STALE_MS, DagState, JobRecord, dag_key, job_key};
use crate::job::{ErrorBody, JobBackend, JobManager, JobStatus, JobView, ServerConfig};
use crate::job::{unix_now, unix_now_ms};
use crate::params::ReconOptions;
use crate::pipeline::tiled::store::Store;
use async_nats::jetstream::kv::Operation;
use futures_util::StreamExt;
use std::sync::Arc;
use std::time::Duration;
use uuid::Uuid;

/// The backend of a NATS-backed API node.
pub struct NatsJobs {
    res: Resources,
    rt: tokio::runtime::Handle,
}

/// Connects to NATS and opens the resources (creating them when missing).
pub async fn connect_backend(cfg: &NatsConfig) -> Result<Arc<NatsJobs>, DistError> {
    let client = connect::connect(cfg, "rbfsurf-serve").await?;
    let res = connect::open(client).await?;
    Ok(Arc::new(NatsJobs {
        res,
        rt: tokio::runtime::Handle::current(),
    }))
}

impl JobBackend for NatsJobs {
    fn submit(
        &self,
        view: &JobView,
        input: &[u8],
        options: &ReconOptions,
        cfg: &ServerConfig,
    ) -> Result<(), String> {
        let record = JobRecord {
            view: view.clone(),
            options: options.clone(),
            max_points: cfg.max_points,
            max_bytes: cfg.max_upload_bytes,
            cancel: false,
            results: Vec::new(),
            deleting_since_ms: 0,
        };
        let job = view.id;
        self.rt
            .block_on(async {
                objects::put_input(&self.res.objects, job, &view.input.file, input).await?;
                records::create(&self.res.jobs, &job_key(job), &record).await?;
                let start = Task {
                    job,
                    kind: TaskKind::Start,
                };
                queue::publish(&self.res.js, &[start]).await
            })
            .map_err(|e| e.to_string())
    }

    fn cancel(&self, id: Uuid) {
        let kv = self.res.jobs.clone();
        self.rt.spawn(async move {
            let key = job_key(id);
            let r = records::update::<JobRecord, _>(&kv, &key, |r| {
                if r.view.status.is_terminal() || r.cancel {
                    return false;
                }
                r.cancel = true;
                if r.view.status == JobStatus::Queued {
                    r.view.status = JobStatus::Cancelled;
                    r.view.finished_at = Some(unix_now());
                    r.view.error = Some(ErrorBody {
                        code: "cancelled".into(),
                        message: "cancelled by a DELETE request".into(),
                    });
                }
                true
            });
            if let Err(e) = r.await {
                tracing::warn!(%id, error = %e, "cannot record the cancellation");
            }
        });
    }

    fn delete(&self, id: Uuid) -> std::io::Result<()> {
        let purge = self.rt.block_on(purge(&self.res, id, None));
        purge.map(|_| ()).map_err(std::io::Error::other)
    }

    fn expire(&self, id: Uuid, cutoff: u64) -> std::io::Result<bool> {
        let purge = self.rt.block_on(purge(&self.res, id, Some(cutoff)));
        purge.map_err(std::io::Error::other)
    }
}

/// Deletes finished job `id` (when it finished at or before `cutoff`, Unix seconds, if given):
/// first claims it with a compare-and-set of its record (`deleting_since_ms`), so of several API
/// nodes sweeping at once exactly one goes on (an abandoned claim is taken over after
/// [`DELETE_CLAIM_STALE_MS`]); then removes its objects (input, plan, the graph's values,
/// results), then its graph state and record. Every API node shows a claimed job as gone.
/// Returns whether this call deleted the job.
async fn purge(res: &Resources, id: Uuid, cutoff: Option<u64>) -> Result<bool, DistError> {
    let now = unix_now_ms();
    let mut claimed = false;
    let rec = records::update::<JobRecord, _>(&res.jobs, &job_key(id), |r| {
        let due = cutoff.is_none_or(|c| r.view.finished_at.is_some_and(|t| t <= c));
        let free = r.deleting_since_ms == 0
            || now.saturating_sub(r.deleting_since_ms) >= DELETE_CLAIM_STALE_MS;
        claimed = r.view.status.is_terminal() && due && free;
        if claimed {
            r.deleting_since_ms = now;
        }
        claimed
    })
    .await?;
    let Some(rec) = rec.filter(|_| claimed) else {
        return Ok(false);
    };
    if let Some((d, _)) = records::load::<DagState>(&res.jobs, &dag_key(id)).await? {
        let keys = objects::intermediates(d.blocks.len(), d.regions.len());
        objects::remove(res, id, &keys).await?;
    }
    let mut keys: Vec<String> = (rec.results.iter())
        .map(|f| format!("result/{f}"))
        .collect();
    let input = &rec.view.input;
    keys.extend(objects::input_keys(&input.file, input.bytes));
    objects::remove(res, id, &keys).await?;
    let store = Store::Remote(Box::new(JobObjects {
        os: res.objects.clone(),
        job: id,
        rt: tokio::runtime::Handle::current(),
        written: None,
    }));
    super::prepare::remove_async(res, id, Arc::new(store)).await?;
    // The graph state first: while the record exists, a new claim can still find its names.
    for key in [dag_key(id), job_key(id)] {
        records::purge(res, &key).await?;
    }
    tracing::info!(%id, "job deleted with its objects");
    Ok(true)
}

/// Follows every job record for ever (re-watching after a lost connection) into `mgr`.
pub async fn mirror(backend: Arc<NatsJobs>, mgr: Arc<JobManager>) {
    loop {
        match backend.res.jobs.watch_with_history("job.>").await {
            Ok(mut watch) => {
                if let Err(e) = resync(&backend, &mgr).await {
                    tracing::warn!(error = %e, "cannot list the job records; stale entries stay until the next watch");
                }
                while let Some(entry) = watch.next().await {
                    match entry {
                        Ok(e) => apply(&backend, &mgr, &e.key, e.operation, &e.value).await,
                        Err(e) => {
                            tracing::warn!(error = %e, "job watch failed; watching again");
                            break;
                        }
                    }
                }
            }
            Err(e) => tracing::warn!(error = %e, "cannot watch the job records; retrying"),
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
}

/// Forgets finished jobs whose records are gone and cached results of jobs that no longer
/// exist: records are purged without a marker (see [`purge`]), so a node that was not watching
/// when a job went (restarted, or disconnected) learns it here, on every (re)watch.
async fn resync(backend: &NatsJobs, mgr: &Arc<JobManager>) -> Result<(), DistError> {
    let mut keys = (backend.res.jobs.keys().await).map_err(DistError::nats("list jobs"))?;
    let mut live = std::collections::HashSet::new();
    while let Some(key) = keys.next().await {
        let key = key.map_err(DistError::nats("list jobs"))?;
        if let Some(id) = key
            .strip_prefix("job.")
            .and_then(|s| Uuid::parse_str(s).ok())
        {
            live.insert(id);
        }
    }
    let mgr = Arc::clone(mgr);
    let prune = move || -> std::io::Result<usize> {
        let gone: Vec<Uuid> = (mgr.list().into_iter())
            .filter(|v| v.status.is_terminal() && !live.contains(&v.id))
            .map(|v| v.id)
            .collect();
        let mut n = gone.len();
        for id in gone {
            mgr.forget(id);
        }
        // Only finished jobs have cached files, and a finished job's record exists until it
        // is deleted: a directory of an id not listed is stale. (A directory with a
        // `status.json` is an embedded service's job, not a cache: never touched.)
        for entry in std::fs::read_dir(mgr.config().data_dir.as_path())?.flatten() {
            let name = entry.file_name();
            let id = name.to_str().and_then(|s| Uuid::parse_str(s).ok());
            let cache = !entry.path().join("status.json").exists();
            if let Some(id) = id.filter(|id| cache && !live.contains(id)) {
                mgr.forget(id);
                n += 1;
            }
        }
        Ok(n)
    };
    let pruned = tokio::task::spawn_blocking(prune)
        .await
        .map_err(DistError::nats("resync"))?
        .map_err(DistError::nats("resync"))?;
    if pruned > 0 {
        tracing::info!(
            pruned,
            "forgot jobs deleted while this node was not watching"
        );
    }
    Ok(())
}

async fn apply(backend: &NatsJobs, mgr: &Arc<JobManager>, key: &str, op: Operation, value: &[u8]) {
    let Some(id) = key
        .strip_prefix("job.")
        .and_then(|s| Uuid::parse_str(s).ok())
    else {
        return;
    };
    let rec = (op == Operation::Put)
        .then(|| serde_json::from_slice::<JobRecord>(value))
        .transpose();
    let Ok(rec) = rec else {
        tracing::warn!(%id, "a job record that does not parse; ignored");
        return;
    };
    // Deleted, or claimed for deletion by some API node: gone for every node.
    let Some(rec) = rec.filter(|r| r.deleting_since_ms == 0) else {
        let mgr = Arc::clone(mgr);
        let _ = tokio::task::spawn_blocking(move || mgr.forget(id)).await;
        return;
    };
    let view = rec.view;
    if view.status == JobStatus::Succeeded
        && let Err(e) = fetch_results(backend, mgr, id, &rec.results).await
    {
        tracing::warn!(%id, error = %e, "cannot copy the job's results; it shows as running until they can be copied");
        return;
    }
    let mgr = Arc::clone(mgr);
    let _ = tokio::task::spawn_blocking(move || mgr.mirror(view)).await;
}

/// Copies `result/*` of job `id` into its directory of the data dir (once).
async fn fetch_results(
    backend: &NatsJobs,
    mgr: &JobManager,
    id: Uuid,
    files: &[String],
) -> Result<(), DistError> {
    let dir = mgr.store().dir(id);
    if dir.join("report.json").exists() {
        return Ok(());
    }
    let mut files = files.to_vec();
    // The report last: its presence says the copy is complete.
    files.sort_by_key(|f| f == "report.json");
    let d = dir.clone();
    tokio::task::spawn_blocking(move || std::fs::create_dir_all(d))
        .await
        .map_err(DistError::nats("cache"))?
        .map_err(DistError::nats("cache"))?;
    for file in files {
        let name = objects::name(id, &format!("result/{file}"));
        let bytes = objects::get(&backend.res.objects, &name).await?;
        let path = dir.join(file.replace('/', "_"));
        let write = tokio::task::spawn_blocking(move || crate::io::write_atomic(&path, &bytes));
        write
            .await
            .map_err(DistError::nats("cache"))?
            .map_err(DistError::nats("cache"))?;
    }
    Ok(())
}
