//! Which workers are alive and idle: every worker rewrites `w.<worker id>` in the
//! [`super::connect::WORKER_BUCKET`] key-value bucket every [`PERIOD`] and whenever one of its
//! tasks starts or ends, with its concurrency and the tasks it is running. A value older than
//! [`STALE_MS`] is a worker that died (`kill -9`, a lost connection); the bucket's stream drops
//! values after [`MAX_AGE`], so the dead leave nothing behind. The `start` task of a large job
//! reads the bucket to decide whether to split the job over the idle workers
//! ([`super::spread`]).

use super::DistError;
use async_nats::jetstream::kv;
use futures_util::TryStreamExt;
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Duration;

/// Period of a worker's presence updates.
pub const PERIOD: Duration = Duration::from_secs(2);
/// A presence older than this (ms, three periods) is a dead worker's.
pub const STALE_MS: u64 = 6_000;
/// Age after which the bucket's stream drops a value.
pub const MAX_AGE: Duration = Duration::from_secs(30);

/// One worker's presence (`w.<worker id>`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Presence {
    /// The worker id (`blocks[].worker`).
    pub worker: String,
    /// Tasks it runs at once.
    pub concurrency: usize,
    /// Tasks it is running.
    pub running: usize,
    /// Unix milliseconds of this value.
    pub at_ms: u64,
}

impl Presence {
    /// Whether this worker could take a task now (`now_ms`: the reader's clock).
    pub fn idle(&self, now_ms: u64) -> bool {
        self.running < self.concurrency && now_ms.saturating_sub(self.at_ms) <= STALE_MS
    }
}

/// Unix milliseconds now.
pub fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

fn key(worker: &str) -> String {
    let safe: String = worker
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("w.{safe}")
}

/// Rewrites this worker's presence every [`PERIOD`] and whenever `changed` is notified, with
/// `running()` tasks; runs until the process ends. A failed write is retried at the next period.
pub async fn announce(
    kv: kv::Store,
    worker: String,
    concurrency: usize,
    running: impl Fn() -> usize,
    changed: Arc<tokio::sync::Notify>,
) {
    let key = key(&worker);
    let mut tick = tokio::time::interval(PERIOD);
    loop {
        let p = Presence {
            worker: worker.clone(),
            concurrency,
            running: running(),
            at_ms: now_ms(),
        };
        let bytes = serde_json::to_vec(&p).unwrap_or_default();
        if let Err(e) = tokio::time::timeout(PERIOD, kv.put(&key, bytes.into())).await {
            tracing::debug!(error = %e, "presence update timed out");
        }
        tokio::select! {
            _ = tick.tick() => {}
            _ = changed.notified() => {}
        }
    }
}

/// The presences in the bucket now (values that do not decode are skipped).
pub async fn list(kv: &kv::Store) -> Result<Vec<Presence>, DistError> {
    let keys: Vec<String> = (kv.keys().await.map_err(DistError::nats("worker bucket"))?)
        .try_collect()
        .await
        .map_err(DistError::nats("worker bucket"))?;
    let mut out = Vec::with_capacity(keys.len());
    for k in keys {
        let v = kv.get(&k).await.map_err(DistError::nats("worker bucket"))?;
        if let Some(p) = v.and_then(|b| serde_json::from_slice::<Presence>(&b).ok()) {
            out.push(p);
        }
    }
    Ok(out)
}

/// Workers other than `me` that are alive and have a free slot now.
pub async fn idle_others(kv: &kv::Store, me: &str) -> Result<Vec<String>, DistError> {
    let now = now_ms();
    Ok(list(kv)
        .await?
        .into_iter()
        .filter(|p| p.worker != me && p.idle(now))
        .map(|p| p.worker)
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_worker_is_idle_while_it_has_a_free_slot_and_its_presence_is_fresh() {
        let p = |running, at_ms| Presence {
            worker: "h-1".into(),
            concurrency: 2,
            running,
            at_ms,
        };
        assert!(p(0, 10_000).idle(10_000));
        assert!(p(1, 10_000).idle(10_000 + STALE_MS));
        assert!(!p(2, 10_000).idle(10_000), "both slots busy");
        assert!(!p(0, 10_000).idle(10_001 + STALE_MS), "stale: dead worker");
        assert_eq!(key("host.a-12"), "w.host_a-12");
    }
}
