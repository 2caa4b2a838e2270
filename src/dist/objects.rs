//! Values in the object store, named `<job>/<key>`: the input, the plan, the graph's values
//! (`points/<b>`, `spline/<b>`, `block/<b>`, `piece/<r>`, `region/<r>`) and the results
//! (`result/<file>`). A task rewrites the same names with the same bytes when it runs again.
//!
//! Every operation is retried for about a minute while the server is unreachable (a restart),
//! except a read of a name that does not exist.

use super::DistError;
use crate::pipeline::tiled::store::{RemoteStore, StoreError};
use async_nats::jetstream::object_store::{self, ObjectStore};
use std::time::Duration;
use tokio::io::AsyncReadExt;
use uuid::Uuid;

/// Attempts of one operation (one second apart).
const ATTEMPTS: u32 = 60;
/// Longest wait for one attempt (a request lost in a restart never answers).
const ATTEMPT_TIMEOUT: Duration = Duration::from_secs(30);

/// The object name of `key` of job `job`.
pub fn name(job: Uuid, key: &str) -> String {
    format!("{job}/{key}")
}

/// Retries `op` while it fails with a transient error (`Err(Some(e))`); `Err(None)` after the
/// last attempt is the last error.
pub async fn retry<T, F, Fut>(what: &str, mut op: F) -> Result<T, DistError>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, (bool, String)>>,
{
    let mut last = String::new();
    for attempt in 0..ATTEMPTS {
        let outcome = tokio::time::timeout(ATTEMPT_TIMEOUT, op())
            .await
            .unwrap_or_else(|_| Err((true, "no answer in time".to_string())));
        match outcome {
            Ok(v) => return Ok(v),
            Err((false, m)) => {
                return Err(DistError::Nats {
                    what: what.to_string(),
                    message: m,
                });
            }
            Err((true, m)) => {
                if attempt == 0 {
                    tracing::warn!(what, error = %m, "NATS operation failed; retrying");
                }
                last = m;
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
    Err(DistError::Nats {
        what: what.to_string(),
        message: last,
    })
}

/// Stores `bytes` as `name`.
pub async fn put(os: &ObjectStore, name: &str, bytes: &[u8]) -> Result<(), DistError> {
    retry(&format!("put {name}"), || async {
        let mut reader = bytes;
        os.put(name, &mut reader)
            .await
            .map(|_| ())
            .map_err(|e| (true, e.to_string()))
    })
    .await
}

/// The bytes of `name`.
pub async fn get(os: &ObjectStore, name: &str) -> Result<Vec<u8>, DistError> {
    retry(&format!("get {name}"), || async {
        let mut obj = os.get(name).await.map_err(|e| {
            let missing = e.kind() == object_store::GetErrorKind::NotFound;
            (!missing, e.to_string())
        })?;
        let mut out = Vec::new();
        obj.read_to_end(&mut out)
            .await
            .map_err(|e| (true, e.to_string()))?;
        Ok(out)
    })
    .await
}

/// Deletes the objects `keys` of job `job` (missing ones are fine). Names are always known
/// (from the record and the graph state): listing a bucket that other jobs are writing is
/// avoided.
pub async fn delete(os: &ObjectStore, job: Uuid, keys: &[String]) {
    for k in keys {
        let n = name(job, k);
        let _ = tokio::time::timeout(ATTEMPT_TIMEOUT, os.delete(&n)).await;
    }
}

/// The keys of the task graph's intermediate values of a graph with `blocks` blocks and
/// `regions` regions.
pub fn intermediates(blocks: usize, regions: usize) -> Vec<String> {
    let mut keys = vec!["plan".to_string()];
    for b in 0..blocks {
        keys.extend(["points", "spline", "block"].map(|k| format!("{k}/{b}")));
    }
    for r in 0..regions {
        keys.extend(["piece", "region"].map(|k| format!("{k}/{r}")));
    }
    keys
}

/// The object store as the task graph's [`RemoteStore`] for one job, from a blocking thread.
pub struct JobObjects {
    /// The store.
    pub os: ObjectStore,
    /// The job.
    pub job: Uuid,
    /// The runtime the calls block on.
    pub rt: tokio::runtime::Handle,
}

impl RemoteStore for JobObjects {
    fn put(&self, key: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        let n = name(self.job, key);
        (self.rt.block_on(put(&self.os, &n, &bytes))).map_err(|e| store_error(&n, e))
    }

    fn get(&self, key: &str) -> Result<Vec<u8>, StoreError> {
        let n = name(self.job, key);
        (self.rt.block_on(get(&self.os, &n))).map_err(|e| store_error(&n, e))
    }
}

fn store_error(name: &str, e: DistError) -> StoreError {
    StoreError::Io {
        path: name.into(),
        source: std::io::Error::other(e.to_string()),
    }
}
