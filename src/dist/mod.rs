//! The distributed executor on NATS JetStream: `rbfsurf worker` processes run the task graph's
//! steps ([`crate::pipeline::tiled`]) and whole in-memory jobs; `rbfsurf serve --nats` nodes are
//! stateless API nodes over the same job records.
//!
//! ```text
//!  API node ── input ─► object store "rbfsurf-objects": <job>/input.<ext>/<k> (8 MiB segments),
//!     │                  prep/…, plan, points/<b>, spline/<b>, block/<b>, piece/<r>, region/<r>, result/<file>
//!     ├── record ─► key-value "rbfsurf-jobs": job.<id> (the job view + options), prep.<id>, dag.<id> (done bits)
//!     └── task  ─► work-queue stream "RBFSURF_TASKS", subjects rbfsurf.tasks.{start,survey,sample,route,
//!                    │                                   cleanup,block,region,merge,whole}
//!                    └─► durable pull consumer "rbfsurf-workers" (explicit ack, ack wait ≤ 30 s,
//!                        progress heartbeats while a task runs, at most 5 deliveries)
//! ```
//!
//! A job starts as one `start` task. When the in-memory estimate fits the job's memory budget
//! (and the job is not spread over idle workers, [`spread`]) its worker reads the input and
//! reconstructs the whole job there (the normal run stage, every feature). Otherwise the graph's
//! prepare step runs: over the workers, one task per byte range of the input and one clean-up
//! task per block ([`prepare`]), when the input's format splits into ranges; else in the `start`
//! task. It stores the plan and the blocks' point sets and publishes one `block` task per block. The worker whose block completes the set
//! (recorded with compare-and-set on `dag.<id>`) publishes the `region` tasks, and the one that
//! completes the regions the `merge` task, which welds, post-processes and stores the results.
//! Every task writes only keys named by its job and block or region, and every publish carries
//! a message id (JetStream drops duplicates), so a redelivered task repeats the same writes.

pub(crate) mod connect;
mod objects;
mod outcome;
mod prepare;
pub mod presence;
mod queue;
mod records;
pub(crate) mod remote;
mod spread;
mod steps;
pub(crate) mod worker;

pub use connect::NatsConfig;
pub use spread::SPREAD_POINTS;

/// What went wrong talking to NATS or running a task.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DistError {
    /// No connection to the server.
    #[error("cannot connect to NATS at {url}: {message}")]
    Connect {
        /// The URL without credentials.
        url: String,
        /// The client's message.
        message: String,
    },
    /// A JetStream request failed (the server may be restarting: callers retry).
    #[error("NATS {what}: {message}")]
    Nats {
        /// What was asked.
        what: String,
        /// The client's message.
        message: String,
    },
    /// A stored value is missing or does not decode.
    #[error("{what} of job {job} is missing or damaged: {message}")]
    Corrupt {
        /// The job.
        job: uuid::Uuid,
        /// Which value.
        what: String,
        /// Details.
        message: String,
    },
}

impl DistError {
    /// Maps a client error to [`DistError::Nats`] naming `what`.
    pub(crate) fn nats<E: std::fmt::Display>(what: &str) -> impl Fn(E) -> DistError + '_ {
        move |e| DistError::Nats {
            what: what.to_string(),
            message: e.to_string(),
        }
    }
}

/// This process's worker id: host name and process id (unique per process on a host).
pub fn worker_id() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "host".to_string());
    format!("{host}-{}", std::process::id())
}
