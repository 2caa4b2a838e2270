//! The job model shared by the HTTP service (`server`) and the distributed executor
//! (`dist`): the job record ([`model`]), its error ([`error`]), the service limits
//! ([`config`]), the files of a job under the data directory ([`store`]), composition and morph
//! jobs ([`volume`]), and the [`JobManager`] that queues and runs jobs in this process or on a
//! [`JobBackend`] ([`remote`]). Nothing here speaks HTTP; the server and the NATS executor both
//! build on it.

pub(crate) mod config;
pub(crate) mod error;
pub(crate) mod manager;
pub(crate) mod model;
pub(crate) mod remote;
pub(crate) mod store;
pub(crate) mod volume;

pub use config::ServerConfig;
pub use error::ErrorBody;
pub use manager::{Job, JobManager, SubmitError};
pub use model::{InputAttributes, InputInfo, JobStatus, JobView, unix_now, unix_now_ms};
pub use remote::JobBackend;
