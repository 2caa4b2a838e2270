//! Values in the object store, named `<job>/<key>`: the input, the plan, the graph's values
//! (`points/<b>`, `spline/<b>`, `block/<b>`, `piece/<r>`, `region/<r>`) and the results
//! (`result/<file>`). A task rewrites the same names with the same bytes when it runs again.
//!
//! Every operation is retried for about a minute while the server is unreachable (a restart),
//! except a read of a name that does not exist.

use super::DistError;
use super::connect::{OBJECT_BUCKET, Resources};
use crate::error::StoreError;
use crate::io::split::ByteRange;
use crate::pipeline::tiled::store::RemoteStore;
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

/// Retries `op` (one second apart, [`ATTEMPTS`] times) while it fails with a transient error
/// (`Err((true, message))`); `Err((false, message))` fails at once. After the last attempt the
/// error is the last message.
pub async fn retry<T, F, Fut>(what: &str, op: F) -> Result<T, DistError>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, (bool, String)>>,
{
    retry_n(what, ATTEMPTS, op).await
}

/// [`retry`] with at most `attempts` attempts.
pub async fn retry_n<T, F, Fut>(what: &str, attempts: u32, mut op: F) -> Result<T, DistError>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, (bool, String)>>,
{
    let mut last = String::new();
    for attempt in 0..attempts {
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

/// The bytes of `name`, `None` when there is no such object (or it was deleted).
pub async fn get_opt(os: &ObjectStore, name: &str) -> Result<Option<Vec<u8>>, DistError> {
    match os.info(name).await {
        Err(e) if e.kind() == object_store::InfoErrorKind::NotFound => return Ok(None),
        Ok(info) if info.deleted => return Ok(None),
        _ => {}
    }
    get(os, name).await.map(Some)
}

/// Removes the objects `keys` of job `job` entirely: the chunks, then the metadata, each by a
/// purge of its subject, so (unlike the client's `delete`) no deletion marker stays behind and
/// the store does not grow with deleted jobs. Missing objects are fine; a removal interrupted
/// half-way is completed by running it again. Names are always known (from the record and the
/// graph state): listing a bucket that other jobs are writing is avoided.
pub async fn remove(res: &Resources, job: Uuid, keys: &[String]) -> Result<(), DistError> {
    for k in keys {
        let n = name(job, k);
        retry(&format!("remove {n}"), || async {
            let info = match res.objects.info(&n).await {
                Ok(info) => info,
                Err(e) if e.kind() == object_store::InfoErrorKind::NotFound => return Ok(()),
                Err(e) => return Err((true, e.to_string())),
            };
            let chunks = format!("$O.{OBJECT_BUCKET}.C.{}", info.nuid);
            let meta = format!("$O.{OBJECT_BUCKET}.M.{}", base64_url(n.as_bytes()));
            for subject in [chunks, meta] {
                (res.object_stream.purge().filter(subject).await)
                    .map_err(|e| (true, e.to_string()))?;
            }
            Ok(())
        })
        .await?;
    }
    Ok(())
}

/// Base64 with the URL-safe alphabet and padding (RFC 4648 §5): how the object store names an
/// object's metadata subject.
fn base64_url(bytes: &[u8]) -> String {
    use base64::Engine;
    base64::engine::general_purpose::URL_SAFE.encode(bytes)
}

/// Bytes per stored segment of a job's input (the last one shorter).
pub const SEGMENT_BYTES: u64 = 8 << 20;

/// The segment keys of an input `file` of `bytes` bytes (one at least).
pub fn input_keys(file: &str, bytes: u64) -> Vec<String> {
    let n = bytes.div_ceil(SEGMENT_BYTES).max(1);
    (0..n).map(|k| format!("{file}/{k}")).collect()
}

/// Stores job `job`'s input `file` in segments.
pub async fn put_input(
    os: &ObjectStore,
    job: Uuid,
    file: &str,
    data: &[u8],
) -> Result<(), DistError> {
    for (k, key) in input_keys(file, data.len() as u64).iter().enumerate() {
        let a = (k as u64 * SEGMENT_BYTES) as usize;
        let b = (a + SEGMENT_BYTES as usize).min(data.len());
        put(os, &name(job, key), &data[a..b]).await?;
    }
    Ok(())
}

/// The bytes `range` of job `job`'s input `file` (`bytes` long), as a window: the segments that
/// hold them, and the offset of the first.
pub async fn get_input_range(
    os: &ObjectStore,
    job: Uuid,
    file: &str,
    bytes: u64,
    range: ByteRange,
) -> Result<(u64, Vec<u8>), DistError> {
    let keys = input_keys(file, bytes);
    let first = (range.start / SEGMENT_BYTES) as usize;
    let last = ((range.end.max(range.start + 1) - 1) / SEGMENT_BYTES) as usize;
    let mut out = Vec::new();
    for key in &keys[first.min(keys.len() - 1)..=last.min(keys.len() - 1)] {
        out.extend(get(os, &name(job, key)).await?);
    }
    Ok((first as u64 * SEGMENT_BYTES, out))
}

/// The whole input of job `job`.
pub async fn get_input(
    os: &ObjectStore,
    job: Uuid,
    file: &str,
    bytes: u64,
) -> Result<Vec<u8>, DistError> {
    let all = ByteRange {
        start: 0,
        end: bytes.max(1),
    };
    Ok(get_input_range(os, job, file, bytes, all).await?.1)
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
    /// Records every key put, when set (the prepare step: its values are removed when it fails,
    /// before any graph state names them).
    pub written: Option<std::sync::Arc<std::sync::Mutex<Vec<String>>>>,
}

impl RemoteStore for JobObjects {
    fn put(&self, key: &str, bytes: Vec<u8>) -> Result<(), StoreError> {
        if let Some(w) = &self.written {
            w.lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(key.to_string());
        }
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

#[cfg(test)]
mod tests {
    use super::base64_url;

    #[test]
    fn base64_url_matches_rfc_4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64_url(plain.as_bytes()), encoded, "{plain}");
        }
        // The URL-safe alphabet: 0xfb 0xff -> "-_8=" (standard base64 would give "+/8=").
        assert_eq!(base64_url(&[0xfb, 0xff]), "-_8=");
    }
}
