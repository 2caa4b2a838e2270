//! Records in the key-value bucket: `job.<id>` (the job as the API shows it, its options and
//! limits, the cancel flag) and `dag.<id>` (which blocks and regions are done). Every change is
//! a compare-and-set on the key's revision, retried on a conflict, so concurrent workers and API
//! nodes never lose each other's changes and a transition (all blocks done → regions) is seen
//! by exactly the update that made it.

use super::DistError;
use crate::job::JobView;
use crate::params::ReconOptions;
use async_nats::jetstream::kv;
use serde::{Deserialize, Serialize, de::DeserializeOwned};
use std::time::Duration;
use uuid::Uuid;

/// A job as stored in `job.<id>`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct JobRecord {
    /// What the API shows.
    pub view: JobView,
    /// The reconstruction options (with the server's limits applied).
    pub options: ReconOptions,
    /// The API node's point limit for the reader.
    pub max_points: usize,
    /// The API node's byte limit for the reader.
    pub max_bytes: u64,
    /// Set by a DELETE: workers stop the job at their next check.
    pub cancel: bool,
    /// Files of the results (`result/<file>` in the object store), set when the job succeeds.
    #[serde(default)]
    pub results: Vec<String>,
    /// Unix milliseconds when an API node claimed the finished job for deletion (expiry or a
    /// DELETE); 0: not claimed. A claim older than [`DELETE_CLAIM_STALE_MS`] (its node died
    /// mid-deletion) may be taken over. API nodes show a claimed job as gone.
    #[serde(default)]
    pub deleting_since_ms: u64,
}

/// After this long (ms) a deletion claim is considered abandoned and another node may take it.
pub const DELETE_CLAIM_STALE_MS: u64 = 5 * 60 * 1000;

/// The task graph's progress in `dag.<id>`.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct DagState {
    /// Done flag per block.
    pub blocks: Vec<bool>,
    /// Done flag per region.
    pub regions: Vec<bool>,
    /// Seconds of the prepare step.
    pub prepare_s: f64,
    /// Unix milliseconds when the region phase began (0: not yet).
    pub regions_started_ms: u64,
    /// The tasks done so far (report `tasks[]`), in the order they were recorded.
    #[serde(default)]
    pub tasks: Vec<crate::report::TaskReport>,
}

/// Key of job `id`'s record.
pub fn job_key(id: Uuid) -> String {
    format!("job.{id}")
}

/// Key of job `id`'s graph state.
pub fn dag_key(id: Uuid) -> String {
    format!("dag.{id}")
}

/// Key of job `id`'s spread prepare state ([`super::prepare::PrepState`]).
pub fn prep_key(id: Uuid) -> String {
    format!("prep.{id}")
}

/// Conflicts or failures tolerated by one update before it gives up.
const ATTEMPTS: u32 = 120;

/// The value under `key` and its revision; `None` when there is none (or it was deleted).
pub async fn load<T: DeserializeOwned>(
    kv: &kv::Store,
    key: &str,
) -> Result<Option<(T, u64)>, DistError> {
    super::objects::retry(&format!("read {key}"), || async {
        let entry = kv.entry(key).await.map_err(|e| (true, e.to_string()))?;
        match entry {
            Some(e) if e.operation == kv::Operation::Put => serde_json::from_slice(&e.value)
                .map(|v| Some((v, e.revision)))
                .map_err(|e| (false, e.to_string())),
            _ => Ok(None),
        }
    })
    .await
}

/// Stores a new value under `key`; an existing value is kept (a repeated create is a no-op).
pub async fn create<T: Serialize>(kv: &kv::Store, key: &str, value: &T) -> Result<(), DistError> {
    let bytes = serde_json::to_vec(value).unwrap_or_default();
    super::objects::retry(&format!("create {key}"), || async {
        match kv.create(key, bytes.clone().into()).await {
            Ok(_) => Ok(()),
            Err(e) if e.kind() == kv::CreateErrorKind::AlreadyExists => Ok(()),
            Err(e) => Err((true, e.to_string())),
        }
    })
    .await
}

/// Applies `change` to the value under `key` with compare-and-set (again on a conflict).
/// `change` returns whether it changed anything; nothing is written when not. Returns the value
/// as stored, `None` when there is no value.
pub async fn update<T, F>(kv: &kv::Store, key: &str, mut change: F) -> Result<Option<T>, DistError>
where
    T: Serialize + DeserializeOwned,
    F: FnMut(&mut T) -> bool,
{
    let mut last = String::new();
    for _ in 0..ATTEMPTS {
        let Some((mut value, revision)) = load::<T>(kv, key).await? else {
            return Ok(None);
        };
        if !change(&mut value) {
            return Ok(Some(value));
        }
        let bytes = serde_json::to_vec(&value).unwrap_or_default();
        match kv.update(key, bytes.into(), revision).await {
            Ok(_) => return Ok(Some(value)),
            Err(e) if e.kind() == kv::UpdateErrorKind::WrongLastRevision => continue,
            Err(e) => {
                last = e.to_string();
                tokio::time::sleep(Duration::from_millis(500)).await;
            }
        }
    }
    Err(DistError::Nats {
        what: format!("update {key}"),
        message: last,
    })
}

/// Removes `key` from the bucket entirely (a purge of its subject: no deletion marker stays, so
/// the bucket does not grow with deleted jobs). Watchers are not told: callers first store a
/// value that tells them (a deletion claim). Missing keys are fine.
pub async fn purge(res: &super::connect::Resources, key: &str) -> Result<(), DistError> {
    let subject = format!("$KV.{}.{key}", super::connect::JOB_BUCKET);
    super::objects::retry(&format!("purge {key}"), || async {
        (res.job_stream.purge().filter(subject.clone()).await)
            .map(|_| ())
            .map_err(|e| (true, e.to_string()))
    })
    .await
}
