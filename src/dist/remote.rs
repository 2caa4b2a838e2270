//! The API node's side (`serve --nats`): a [`JobBackend`] that stores a new job's input in the
//! object store and its record in the key-value bucket and queues its `start` task, and the
//! mirror that watches every job record (with history, so a new node learns every job) and
//! feeds the node's [`JobManager`]. A job's results are copied into the data directory before
//! the node shows it succeeded, so whoever sees `succeeded` can download them.

use super::DistError;
use super::connect::{self, NatsConfig, Resources};
use super::objects;
use super::queue::{self, Task, TaskKind};
use super::records::{self, DagState, JobRecord, dag_key, job_key};
use crate::params::ReconOptions;
use crate::server::config::ServerConfig;
use crate::server::error::ErrorBody;
use crate::server::jobs::JobManager;
use crate::server::model::{JobStatus, JobView, unix_now};
use crate::server::remote::JobBackend;
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
        };
        let job = view.id;
        self.rt
            .block_on(async {
                objects::put(
                    &self.res.objects,
                    &objects::name(job, &view.input.file),
                    input,
                )
                .await?;
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
        self.rt
            .block_on(async {
                let (os, kv) = (&self.res.objects, &self.res.jobs);
                if let Some((d, _)) = records::load::<DagState>(kv, &dag_key(id)).await? {
                    objects::delete(
                        os,
                        id,
                        &objects::intermediates(d.blocks.len(), d.regions.len()),
                    )
                    .await;
                }
                if let Some((r, _)) = records::load::<JobRecord>(kv, &job_key(id)).await? {
                    let mut keys: Vec<String> =
                        (r.results.iter()).map(|f| format!("result/{f}")).collect();
                    keys.push(r.view.input.file.clone());
                    objects::delete(os, id, &keys).await;
                }
                for key in [job_key(id), dag_key(id)] {
                    let _ = kv.delete(&key).await;
                }
                Ok::<(), DistError>(())
            })
            .map_err(std::io::Error::other)
    }
}

/// Follows every job record for ever (re-watching after a lost connection) into `mgr`.
pub async fn mirror(backend: Arc<NatsJobs>, mgr: Arc<JobManager>) {
    loop {
        match backend.res.jobs.watch_with_history("job.>").await {
            Ok(mut watch) => {
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

async fn apply(backend: &NatsJobs, mgr: &Arc<JobManager>, key: &str, op: Operation, value: &[u8]) {
    let Some(id) = key
        .strip_prefix("job.")
        .and_then(|s| Uuid::parse_str(s).ok())
    else {
        return;
    };
    if op != Operation::Put {
        let mgr = Arc::clone(mgr);
        let _ = tokio::task::spawn_blocking(move || mgr.forget(id)).await;
        return;
    }
    let Ok(rec) = serde_json::from_slice::<JobRecord>(value) else {
        tracing::warn!(%id, "a job record that does not parse; ignored");
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

/// Runs a NATS-backed API node until Ctrl-C / SIGTERM.
pub async fn serve_nats(cfg: ServerConfig, nats: NatsConfig) -> std::io::Result<()> {
    let listener = tokio::net::TcpListener::bind(cfg.addr).await?;
    tracing::info!(nats = %connect::redact_url(&nats.url), "connecting to NATS");
    let backend = connect_backend(&nats)
        .await
        .map_err(std::io::Error::other)?;
    let permits = (2 * cfg.workers).max(2);
    let mgr = {
        let b: Arc<dyn JobBackend> = backend.clone();
        tokio::task::spawn_blocking(move || JobManager::start_remote(cfg, b))
            .await
            .map_err(std::io::Error::other)??
    };
    let watcher = tokio::spawn(mirror(backend, Arc::clone(&mgr)));
    let state = crate::server::AppState {
        jobs: mgr,
        uploads: Arc::new(tokio::sync::Semaphore::new(permits)),
    };
    tracing::info!(addr = %listener.local_addr()?, "rbfsurf serve listening (jobs on NATS)");
    let result = crate::server::serve_on(listener, state, crate::server::shutdown_signal()).await;
    watcher.abort();
    result
}
