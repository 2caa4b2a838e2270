//! The job manager of a stateless API node (`serve --nats`): jobs run elsewhere, behind a
//! [`JobBackend`]; this node keeps a mirror of every job's view (fed by the backend's watch of
//! the job records), so listing, `?wait`, server-sent events and downloads work as on the
//! embedded service. The data directory holds only results copied from the backend.

use super::config::ServerConfig;
use super::manager::{Job, JobManager, SubmitError, read, write};
use super::model::{InputInfo, JobView};
use super::store::Store;
use crate::params::ReconOptions;
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Condvar, Mutex, RwLock};
use uuid::Uuid;

/// Where a remote node's jobs live and run.
pub trait JobBackend: Send + Sync {
    /// Stores the input and the record of a new job and queues it (blocking).
    fn submit(
        &self,
        view: &JobView,
        input: &[u8],
        options: &ReconOptions,
        cfg: &ServerConfig,
    ) -> Result<(), String>;
    /// Asks for job `id` to stop (does not block).
    fn cancel(&self, id: Uuid);
    /// Deletes finished job `id`'s record and files (blocking).
    fn delete(&self, id: Uuid) -> std::io::Result<()>;
    /// Deletes finished job `id` when it finished at or before `cutoff` (Unix seconds), unless
    /// another node is deleting it (blocking). Returns whether this call deleted it: with several
    /// API nodes sweeping the same jobs, exactly one deletes each.
    fn expire(&self, id: Uuid, cutoff: u64) -> std::io::Result<bool>;
}

impl JobManager {
    /// A manager whose jobs run on `backend`; `cfg.data_dir` is the cache of results.
    pub fn start_remote(
        cfg: ServerConfig,
        backend: Arc<dyn JobBackend>,
    ) -> std::io::Result<Arc<JobManager>> {
        let store = Store::open(&cfg.data_dir)?;
        Ok(Arc::new(JobManager {
            cfg,
            store,
            jobs: RwLock::new(HashMap::new()),
            backend: Some(backend),
            queue: Mutex::new(VecDeque::new()),
            wake: Condvar::new(),
            shutdown: AtomicBool::new(false),
            workers: Mutex::new(Vec::new()),
        }))
    }

    pub(super) fn submit_remote(
        &self,
        backend: &dyn JobBackend,
        input: &[u8],
        info: InputInfo,
        options: &ReconOptions,
    ) -> Result<Arc<Job>, SubmitError> {
        let view = JobView::queued(info);
        backend
            .submit(&view, input, options, &self.cfg)
            .map_err(SubmitError::Backend)?;
        Ok(self.mirror(view))
    }

    /// Records `view` (from the backend) as the job's current state; returns the job.
    pub fn mirror(&self, view: JobView) -> Arc<Job> {
        if let Some(job) = read(&self.jobs).get(&view.id).cloned() {
            job.tx.send_if_modified(|v| {
                // A terminal state is final; a stale update never moves a job back.
                if v.status.is_terminal() || *v == view {
                    return false;
                }
                *v = view.clone();
                true
            });
            return job;
        }
        let mut jobs = write(&self.jobs);
        let job = jobs.entry(view.id).or_insert_with(|| Job::new(view));
        Arc::clone(job)
    }

    /// Whether jobs run on a backend (`serve --nats`) rather than in this process.
    pub fn is_remote(&self) -> bool {
        self.backend.is_some()
    }

    /// Forgets job `id` (its record is gone) and its cached files.
    pub fn forget(&self, id: Uuid) {
        write(&self.jobs).remove(&id);
        let _ = self.store.remove(id);
    }
}
