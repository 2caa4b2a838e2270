//! Jobs: a bounded queue, a fixed pool of worker threads (off the async reactor), per-job progress
//! (a `tokio::sync::watch` channel feeding status, `?wait` and server-sent events), cancellation,
//! time limits, persistence through [`Store`], restart recovery and expiry.
//!
//! Restart policy: jobs stored as `queued` are re-queued (their input and options are on disk);
//! jobs stored as `running` (the server died mid-job) are marked `failed` with code `interrupted`.
//! A graceful shutdown stops running jobs and stores them as `queued` again, so they run after
//! the restart. Queue operations are O(1); a scan at start-up is O(stored jobs).

use super::config::ServerConfig;
use super::error::ErrorBody;
use super::store::{Store, unfinished};
use crate::error::ErrorKind;
use crate::io::{MeshFormat, PointFormat, ReadLimits};
use crate::params::ReconParams;
use crate::pipeline::run::{PointSource, RunError, RunOutput, run};
use crate::progress::{Progress, Stage};
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, RwLock};
use std::time::{Duration, Instant};
use tokio::sync::watch;
use uuid::Uuid;

use super::model::unix_now_ms;
use super::model::{InputInfo, JobStatus, JobView, unix_now};

/// One job: its observable state plus the control flags the worker polls.
pub struct Job {
    /// Job id.
    pub id: Uuid,
    pub(super) tx: watch::Sender<JobView>,
    cancel: AtomicBool,
    /// Unix-epoch milliseconds after which the running job is stopped (0 = none).
    deadline_ms: AtomicU64,
}

impl Job {
    pub(super) fn new(view: JobView) -> Arc<Job> {
        Arc::new(Job {
            id: view.id,
            tx: watch::Sender::new(view),
            cancel: AtomicBool::new(false),
            deadline_ms: AtomicU64::new(0),
        })
    }

    /// A snapshot of the current state.
    pub fn view(&self) -> JobView {
        self.tx.borrow().clone()
    }

    /// A receiver that sees every state change (for `?wait` and server-sent events).
    pub fn subscribe(&self) -> watch::Receiver<JobView> {
        self.tx.subscribe()
    }

    fn timed_out(&self) -> bool {
        let d = self.deadline_ms.load(Ordering::Relaxed);
        d != 0 && unix_now_ms() >= d
    }
}

/// The [`Progress`] of a running job: publishes stage + fraction (throttled to steps of 1 %)
/// and answers `cancelled()` for a DELETE, a shutdown or the time limit.
struct JobProgress<'a> {
    job: &'a Job,
    shutdown: &'a AtomicBool,
    last_percent: AtomicU64,
    current: Mutex<Option<Stage>>,
}

impl Progress for JobProgress<'_> {
    fn stage(&self, stage: Stage) {
        *lock(&self.current) = Some(stage);
        self.last_percent.store(0, Ordering::Relaxed);
        self.job.tx.send_modify(|v| {
            v.stage = Some(stage.name().to_string());
            v.stage_progress = 0.0;
            if let Some(p) = stage.overall(0.0) {
                v.progress = v.progress.max(p);
            }
        });
    }

    fn fraction(&self, done: f64) {
        let pct = (done.clamp(0.0, 1.0) * 100.0) as u64;
        if self.last_percent.swap(pct, Ordering::Relaxed) == pct {
            return;
        }
        let current = *lock(&self.current);
        self.job.tx.send_modify(|v| {
            v.stage_progress = done.clamp(0.0, 1.0);
            if let Some(p) = current.and_then(|s| s.overall(done)) {
                v.progress = v.progress.max(p);
            }
        });
    }

    fn cancelled(&self) -> bool {
        self.job.cancel.load(Ordering::Relaxed)
            || self.shutdown.load(Ordering::Relaxed)
            || self.job.timed_out()
    }
}

/// Owns every job, the queue and the worker threads.
pub struct JobManager {
    pub(super) cfg: ServerConfig,
    pub(super) store: Store,
    pub(super) jobs: RwLock<HashMap<Uuid, Arc<Job>>>,
    /// Where jobs run when they do not run here (`serve --nats`); `None`: the embedded pool.
    pub(super) backend: Option<Arc<dyn super::remote::JobBackend>>,
    pub(super) queue: Mutex<VecDeque<Arc<Job>>>,
    pub(super) wake: Condvar,
    pub(super) shutdown: AtomicBool,
    pub(super) workers: Mutex<Vec<std::thread::JoinHandle<()>>>,
}

/// Why a submission was refused by the queue.
pub enum SubmitError {
    /// The queue holds `max_queue` jobs.
    QueueFull,
    /// The server is shutting down.
    ShuttingDown,
    /// The job could not be stored.
    Storage(crate::io::IoError),
    /// The job store (NATS) did not take the job.
    Backend(String),
}

impl JobManager {
    /// Opens the data directory, recovers stored jobs (see the module doc for the policy) and
    /// starts `cfg.workers` worker threads.
    pub fn start(cfg: ServerConfig) -> std::io::Result<Arc<JobManager>> {
        let store = Store::open(&cfg.data_dir)?;
        let mgr = Arc::new(JobManager {
            cfg,
            store,
            jobs: RwLock::new(HashMap::new()),
            queue: Mutex::new(VecDeque::new()),
            wake: Condvar::new(),
            shutdown: AtomicBool::new(false),
            workers: Mutex::new(Vec::new()),
            backend: None,
        });
        mgr.recover()?;
        let n = mgr.cfg.workers.max(1);
        let handles = (0..n)
            .map(|i| {
                let m = Arc::clone(&mgr);
                std::thread::Builder::new()
                    .name(format!("rbfsurf-worker-{i}"))
                    .spawn(move || m.worker_loop())
            })
            .collect::<std::io::Result<Vec<_>>>()?;
        *lock(&mgr.workers) = handles;
        Ok(mgr)
    }

    /// The configuration in force.
    pub fn config(&self) -> &ServerConfig {
        &self.cfg
    }

    /// The job store.
    pub fn store(&self) -> &Store {
        &self.store
    }

    fn recover(&self) -> std::io::Result<()> {
        let mut requeued = 0;
        let mut interrupted = 0;
        for mut view in self.store.scan()? {
            if unfinished(view.status) {
                if view.status == JobStatus::Running {
                    view.status = JobStatus::Failed;
                    view.finished_at = Some(unix_now());
                    view.error = Some(ErrorBody {
                        code: "interrupted".into(),
                        message: "the server stopped while this job was running; submit it again"
                            .into(),
                    });
                    interrupted += 1;
                } else {
                    requeued += 1;
                }
                if let Err(e) = self.store.save_status(&view) {
                    tracing::warn!(id = %view.id, error = %e, "cannot update recovered job");
                }
            }
            let job = Job::new(view);
            if job.view().status == JobStatus::Queued {
                lock(&self.queue).push_back(Arc::clone(&job));
            }
            write(&self.jobs).insert(job.id, job);
        }
        let total = read(&self.jobs).len();
        tracing::info!(total, requeued, interrupted, dir = %self.cfg.data_dir.display(), "job store opened");
        Ok(())
    }

    /// Stores a new job and queues it; refuses when the queue is full or the server stops.
    pub fn submit(
        &self,
        input: &[u8],
        info: InputInfo,
        options: &crate::params::ReconOptions,
    ) -> Result<Arc<Job>, SubmitError> {
        if self.shutdown.load(Ordering::SeqCst) {
            return Err(SubmitError::ShuttingDown);
        }
        if let Some(b) = &self.backend {
            return self.submit_remote(b.as_ref(), input, info, options);
        }
        let view = JobView::queued(info);
        let mut queue = lock(&self.queue);
        if queue.len() >= self.cfg.max_queue {
            return Err(SubmitError::QueueFull);
        }
        if let Err(e) = self.store.create(&view, input, options) {
            let _ = self.store.remove(view.id);
            return Err(SubmitError::Storage(e));
        }
        let job = Job::new(view);
        write(&self.jobs).insert(job.id, Arc::clone(&job));
        queue.push_back(Arc::clone(&job));
        drop(queue);
        self.wake.notify_one();
        Ok(job)
    }

    /// True when another job fits in the queue right now.
    pub fn has_room(&self) -> bool {
        lock(&self.queue).len() < self.cfg.max_queue
    }

    /// True once [`JobManager::shutdown`] was called.
    pub fn is_shutting_down(&self) -> bool {
        self.shutdown.load(Ordering::SeqCst)
    }

    /// The job with this id.
    pub fn get(&self, id: Uuid) -> Option<Arc<Job>> {
        read(&self.jobs).get(&id).cloned()
    }

    /// Every known job, oldest first.
    pub fn list(&self) -> Vec<JobView> {
        let mut v: Vec<JobView> = read(&self.jobs).values().map(|j| j.view()).collect();
        v.sort_by_key(|j| (j.created_at, j.id));
        v
    }

    /// Jobs waiting for a worker.
    pub fn queued(&self) -> usize {
        lock(&self.queue).len()
    }

    /// Cancels a queued or running job (a running one stops at its next progress poll, within
    /// about 20 ms in every long stage). Returns false when the job had already finished.
    ///
    /// The check and the flag are set under the job state's lock, and [`JobManager::finish`]
    /// decides under the same lock: a job this returns true for never ends `succeeded`.
    pub fn cancel(&self, job: &Arc<Job>) -> bool {
        let mut accepted = false;
        job.tx.send_if_modified(|v| {
            if !v.status.is_terminal() {
                job.cancel.store(true, Ordering::SeqCst);
                accepted = true;
            }
            false
        });
        if !accepted {
            return false;
        }
        if let Some(b) = &self.backend {
            b.cancel(job.id);
            return true;
        }
        let mut queue = lock(&self.queue);
        if let Some(pos) = queue.iter().position(|j| j.id == job.id) {
            queue.remove(pos);
            drop(queue);
            self.finish(job, JobStatus::Cancelled, Some(cancelled_error()), None);
        }
        true
    }

    /// Deletes a finished job and its files.
    pub fn delete(&self, id: Uuid) -> std::io::Result<()> {
        if let Some(b) = &self.backend {
            b.delete(id)?;
        }
        write(&self.jobs).remove(&id);
        self.store.remove(id)
    }

    /// Deletes finished jobs older than `expire_after`; returns how many this call deleted (on a
    /// NATS node: those it won the deletion of; the others were another node's).
    pub fn expire(&self) -> usize {
        let Some(age) = self.cfg.expire_after else {
            return 0;
        };
        let cutoff = unix_now().saturating_sub(age.as_secs());
        let old: Vec<Uuid> = read(&self.jobs)
            .values()
            .map(|j| j.view())
            .filter(|v| v.status.is_terminal() && v.finished_at.is_some_and(|t| t <= cutoff))
            .map(|v| v.id)
            .collect();
        let mut expired = 0;
        for id in &old {
            // On a NATS node the job's record decides, with compare-and-set: one node deletes it.
            let deleted = match &self.backend {
                Some(b) => b.expire(*id, cutoff).inspect(|_| {
                    write(&self.jobs).remove(id);
                    let _ = self.store.remove(*id);
                }),
                None => self.delete(*id).map(|()| true),
            };
            match deleted {
                Ok(mine) => expired += usize::from(mine),
                Err(e) => tracing::warn!(%id, error = %e, "cannot delete expired job"),
            }
        }
        if expired > 0 {
            tracing::info!(expired, "expired finished jobs");
        }
        expired
    }

    /// Stops accepting jobs, stops running ones (stored as `queued` again, so they run after a
    /// restart) and joins the workers.
    pub fn shutdown(&self) {
        self.shutdown.store(true, Ordering::SeqCst);
        self.wake.notify_all();
        let handles = std::mem::take(&mut *lock(&self.workers));
        for h in handles {
            let _ = h.join();
        }
    }

    fn worker_loop(&self) {
        loop {
            let job = {
                let mut queue = lock(&self.queue);
                loop {
                    if self.shutdown.load(Ordering::SeqCst) {
                        return;
                    }
                    if let Some(j) = queue.pop_front() {
                        break j;
                    }
                    queue = self
                        .wake
                        .wait_timeout(queue, Duration::from_millis(500))
                        .map_or_else(|e| e.into_inner().0, |r| r.0);
                }
            };
            let run = std::panic::AssertUnwindSafe(|| self.run_job(&job));
            if std::panic::catch_unwind(run).is_err() {
                tracing::error!(id = %job.id, "worker panicked; job failed, worker continues");
                let err = ErrorBody {
                    code: "internal".into(),
                    message: "internal error while reconstructing (a bug): please report it with the input".into(),
                };
                self.finish(&job, JobStatus::Failed, Some(err), None);
            }
        }
    }

    fn run_job(&self, job: &Arc<Job>) {
        if job.cancel.load(Ordering::SeqCst) {
            self.finish(job, JobStatus::Cancelled, Some(cancelled_error()), None);
            return;
        }
        let started = Instant::now();
        let deadline = unix_now_ms() + self.cfg.job_timeout.as_millis() as u64;
        job.deadline_ms.store(deadline.max(1), Ordering::Relaxed);
        job.tx.send_modify(|v| {
            v.status = JobStatus::Running;
            v.started_at = Some(unix_now());
        });
        self.persist(job);
        tracing::info!(id = %job.id, "job started");
        let progress = JobProgress {
            job,
            shutdown: &self.shutdown,
            last_percent: AtomicU64::new(0),
            current: Mutex::new(None),
        };
        match self.reconstruct_sampled(job, &progress) {
            Ok(triangles) => self.finish(job, JobStatus::Succeeded, None, Some(triangles)),
            Err(JobError::Stopped)
                if self.shutdown.load(Ordering::SeqCst) && !job.cancel.load(Ordering::SeqCst) =>
            {
                job.tx.send_modify(|v| {
                    v.status = JobStatus::Queued;
                    v.stage = None;
                    v.progress = 0.0;
                    v.stage_progress = 0.0;
                    v.started_at = None;
                });
                self.persist(job);
                tracing::info!(id = %job.id, "job stopped by shutdown; stored as queued");
            }
            Err(JobError::Stopped) if job.timed_out() && !job.cancel.load(Ordering::SeqCst) => {
                let err = ErrorBody {
                    code: "job_timeout".into(),
                    message: format!(
                        "the job exceeded the server's time limit of {} s; use fewer points, a smaller resolution, or ask for a longer --job-timeout-s",
                        self.cfg.job_timeout.as_secs()
                    ),
                };
                self.finish(job, JobStatus::Failed, Some(err), None);
            }
            Err(JobError::Stopped) => {
                self.finish(job, JobStatus::Cancelled, Some(cancelled_error()), None)
            }
            Err(JobError::Failed(err)) => self.finish(job, JobStatus::Failed, Some(err), None),
        }
        tracing::info!(id = %job.id, status = ?job.view().status, secs = started.elapsed().as_secs_f64(), "job ended");
    }

    /// [`JobManager::reconstruct_job`] with the job's own memory measured: a thread samples the
    /// resident set every 20 ms; the job's peak is the largest growth over the level at its start.
    fn reconstruct_sampled(&self, job: &Job, progress: &JobProgress) -> Result<usize, JobError> {
        let rss = || crate::report::current_rss_kib().unwrap_or(0);
        let base = rss();
        let peak = AtomicU64::new(base);
        let done = AtomicBool::new(false);
        std::thread::scope(|s| {
            s.spawn(|| {
                while !done.load(Ordering::Relaxed) {
                    peak.fetch_max(rss(), Ordering::Relaxed);
                    std::thread::sleep(Duration::from_millis(20));
                }
            });
            let job_mib = || {
                let p = peak.fetch_max(rss(), Ordering::Relaxed).max(rss());
                p.saturating_sub(base) as f64 / 1024.0
            };
            let result = self.reconstruct_job(job, progress, &job_mib);
            done.store(true, Ordering::Relaxed);
            result
        })
    }

    /// Reads the stored input, reconstructs, writes `mesh.glb` and `report.json`
    /// ([`crate::pipeline::run`]).
    fn reconstruct_job(
        &self,
        job: &Job,
        progress: &JobProgress,
        job_mib: &(dyn Fn() -> f64 + Sync),
    ) -> Result<usize, JobError> {
        let view = job.view();
        if [super::volume::COMPOSITION, super::volume::MORPH].contains(&view.input.format.as_str())
        {
            return super::volume::run_volume_job(&self.store, job.id, progress).map_err(|e| {
                if progress.cancelled() || e.code == ErrorKind::Cancelled.code() {
                    JobError::Stopped
                } else {
                    JobError::Failed(e)
                }
            });
        }
        let options = self
            .store
            .load_options(job.id)
            .map_err(JobError::internal)?;
        let params = ReconParams::try_from(&options).map_err(|e| {
            JobError::Failed(ErrorBody {
                code: ErrorKind::BadParameter.code().into(),
                message: e.to_string(),
            })
        })?;
        let data = std::fs::read(self.store.file(job.id, &view.input.file))
            .map_err(|e| JobError::internal(format!("stored input unreadable: {e}")))?;
        let format = PointFormat::from_path(std::path::Path::new(&view.input.file))
            .ok_or_else(|| JobError::internal("stored input has an unknown extension"))?;
        let limits = ReadLimits {
            max_points: self.cfg.max_points,
            max_bytes: self.cfg.max_upload_bytes,
            max_memory_mib: params.max_memory_mib,
        };
        let mesh = self.store.file(job.id, "mesh.glb");
        let report = self.store.file(job.id, "report.json");
        // The fitted field too (`GET …/field`), when the method has a saved form.
        let field = self.store.file(job.id, "fitted.field");
        let output = RunOutput {
            mesh: &mesh,
            format: MeshFormat::Glb(options.glb()),
            report: Some(&report),
            field: (params.method == crate::params::Method::Csrbf).then_some(field.as_path()),
            job_memory_mib: Some(job_mib),
        };
        let source = PointSource::Bytes {
            data: &data,
            format,
        };
        match run(source, &params, &limits, &output, progress) {
            Ok(summary) => Ok(summary.triangles),
            // Stages report a stop through their own error types: when a stop was requested,
            // that is the cause.
            Err(e) if e.kind() == ErrorKind::Cancelled || progress.cancelled() => {
                Err(JobError::Stopped)
            }
            Err(RunError::Write(e)) if super::error::io_storage_full(&e) => Err(JobError::Failed(
                super::error::storage_body(&format!("job {}: {e}", job.id)),
            )),
            // The readers' and writers' messages name server paths: the client gets the generic
            // message, the log the details. (Numerical failures name none and keep theirs.)
            Err(e @ (RunError::Read(_) | RunError::Write(_)))
                if e.kind() == ErrorKind::Internal =>
            {
                Err(JobError::internal(format!("job {}: {e}", job.id)))
            }
            Err(e) => Err(JobError::Failed(ErrorBody {
                code: e.kind().code().into(),
                message: e.to_string(),
            })),
        }
    }

    /// Stores the terminal state first, then publishes it: whoever sees it (a `?wait`, a DELETE,
    /// expiry) finds the files complete. Decided under the job state's lock (see
    /// [`JobManager::cancel`]): a success that races a cancel ends `cancelled`, without results.
    fn finish(
        &self,
        job: &Job,
        status: JobStatus,
        error: Option<ErrorBody>,
        triangles: Option<usize>,
    ) {
        job.tx.send_if_modified(|v| {
            if v.status.is_terminal() {
                return false;
            }
            let cancelled = status == JobStatus::Succeeded && job.cancel.load(Ordering::SeqCst);
            let (status, error, triangles) = if cancelled {
                for name in ["mesh.glb", "report.json"] {
                    let _ = std::fs::remove_file(self.store.file(job.id, name));
                }
                (JobStatus::Cancelled, Some(cancelled_error()), None)
            } else {
                (status, error, triangles)
            };
            v.status = status;
            v.finished_at = Some(unix_now());
            v.error = error;
            v.triangles = triangles;
            if status == JobStatus::Succeeded {
                v.progress = 1.0;
                v.stage_progress = 1.0;
            }
            if let Err(e) = self.store.save_status(v) {
                tracing::error!(id = %job.id, error = %e, "cannot store job status");
            }
            true
        });
    }

    fn persist(&self, job: &Job) {
        if let Err(e) = self.store.save_status(&job.view()) {
            tracing::error!(id = %job.id, error = %e, "cannot store job status");
        }
    }
}

enum JobError {
    /// Cancelled, timed out or shut down (decided by the caller from the flags).
    Stopped,
    /// Failed with this error.
    Failed(ErrorBody),
}

impl JobError {
    fn internal(detail: impl Into<String>) -> JobError {
        JobError::Failed(super::error::internal_body(&detail.into()))
    }
}

fn cancelled_error() -> ErrorBody {
    ErrorBody {
        code: "cancelled".into(),
        message: "cancelled by a DELETE request".into(),
    }
}

pub(super) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

pub(super) fn read<T>(m: &RwLock<T>) -> std::sync::RwLockReadGuard<'_, T> {
    m.read().unwrap_or_else(|e| e.into_inner())
}

pub(super) fn write<T>(m: &RwLock<T>) -> std::sync::RwLockWriteGuard<'_, T> {
    m.write().unwrap_or_else(|e| e.into_inner())
}
