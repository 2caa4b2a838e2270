//! The connection to NATS: address and credentials (never logged: [`NatsConfig`]'s `Debug`
//! shows only whether each is set), reconnection for ever, and the JetStream resources every
//! node opens or creates: the task stream, the job bucket and the object store.

use super::DistError;
use async_nats::jetstream::{self, consumer, kv, object_store, stream};

use std::path::PathBuf;
use std::time::Duration;

/// Task stream (work queue): one message per task, `rbfsurf.tasks.<kind>`.
pub const TASK_STREAM: &str = "RBFSURF_TASKS";
/// Subjects of the task stream.
pub const TASK_SUBJECTS: &str = "rbfsurf.tasks.>";
/// The durable pull consumer every worker shares.
pub const WORKER_CONSUMER: &str = "rbfsurf-workers";
/// Key-value bucket: `job.<id>` job records, `dag.<id>` task-graph progress.
pub const JOB_BUCKET: &str = "rbfsurf-jobs";
/// Key-value bucket of the workers' presence: `w.<worker id>`, rewritten by each worker every
/// [`super::presence::PERIOD`]; values older than the bucket's age limit expire.
pub const WORKER_BUCKET: &str = "rbfsurf-workers";
/// Object store: inputs, plans, block point sets, splines, pieces, results.
pub const OBJECT_BUCKET: &str = "rbfsurf-objects";
/// Deliveries of one task before the job fails.
pub const MAX_DELIVER: i64 = 5;

/// Where NATS is and how to log in.
#[derive(Clone, Default)]
pub struct NatsConfig {
    /// Server URL(s), comma-separated (`nats://host:4222`, `tls://…`).
    pub url: String,
    /// Token authentication.
    pub token: Option<String>,
    /// User and password authentication.
    pub user: Option<(String, String)>,
    /// CA certificate (PEM) to trust for TLS.
    pub tls_ca: Option<PathBuf>,
    /// Client certificate and key (PEM) for mutual TLS.
    pub tls_client: Option<(PathBuf, PathBuf)>,
    /// Require TLS even for a `nats://` URL.
    pub require_tls: bool,
    /// How long a task may go without an acknowledgement or heartbeat before it is redelivered
    /// (at most 30 s; the consumer keeps the value it was created with).
    pub ack_wait: Duration,
}

impl std::fmt::Debug for NatsConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NatsConfig")
            .field("url", &redact_url(&self.url))
            .field("token", &self.token.as_ref().map(|_| "<set>"))
            .field("user", &self.user.as_ref().map(|(u, _)| (u, "<password>")))
            .field("tls_ca", &self.tls_ca)
            .field("tls_client", &self.tls_client)
            .field("require_tls", &self.require_tls)
            .field("ack_wait", &self.ack_wait)
            .finish()
    }
}

/// The URL without any `user:password@` part (for logs and errors).
pub fn redact_url(url: &str) -> String {
    url.split(',')
        .map(|u| match (u.find("://"), u.rfind('@')) {
            (Some(s), Some(at)) if at > s => {
                format!("{}://<credentials>@{}", &u[..s], &u[at + 1..])
            }
            _ => u.to_string(),
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// Connects (retrying until the server answers, reconnecting for ever afterwards).
pub async fn connect(cfg: &NatsConfig, name: &str) -> Result<async_nats::Client, DistError> {
    let mut opts = async_nats::ConnectOptions::new()
        .name(name)
        .retry_on_initial_connect()
        .max_reconnects(None)
        .connection_timeout(Duration::from_secs(5))
        .require_tls(cfg.require_tls);
    if let Some(t) = &cfg.token {
        opts = opts.token(t.clone());
    }
    if let Some((u, p)) = &cfg.user {
        opts = opts.user_and_password(u.clone(), p.clone());
    }
    if let Some(ca) = &cfg.tls_ca {
        opts = opts.add_root_certificates(ca.clone());
    }
    if let Some((cert, key)) = &cfg.tls_client {
        opts = opts.add_client_certificate(cert.clone(), key.clone());
    }
    opts.connect(cfg.url.as_str())
        .await
        .map_err(|e| DistError::Connect {
            url: redact_url(&cfg.url),
            message: e.to_string(),
        })
}

/// The JetStream resources of a node.
#[derive(Clone)]
pub struct Resources {
    /// The JetStream context.
    pub js: jetstream::Context,
    /// Job records and task-graph progress.
    pub jobs: kv::Store,
    /// Inputs, intermediate values and results.
    pub objects: object_store::ObjectStore,
    /// The object store's stream (`OBJ_rbfsurf-objects`): deleting an object purges its subjects.
    pub object_stream: stream::Stream,
    /// The job bucket's stream (`KV_rbfsurf-jobs`): deleting a job purges its keys' subjects.
    pub job_stream: stream::Stream,
    /// The workers' presence ([`super::presence`]).
    pub workers: kv::Store,
}

/// Attempts at opening the resources (one second apart). Every step is get-or-create: when
/// several nodes start at once, each finds nothing and creates, and all but one are refused
/// ("subjects overlap with an existing stream", "already in use"); the next attempt finds what
/// the first created.
const OPEN_ATTEMPTS: u32 = 8;

/// `step` with [`OPEN_ATTEMPTS`] attempts ([`super::objects::retry_n`]).
async fn retried<T, Fut>(what: &str, mut step: impl FnMut() -> Fut) -> Result<T, DistError>
where
    Fut: std::future::Future<Output = Result<T, DistError>>,
{
    super::objects::retry_n(what, OPEN_ATTEMPTS, || {
        let f = step();
        async move { f.await.map_err(|e| (true, e.to_string())) }
    })
    .await
}

/// Opens (creating when missing) the task stream, the job bucket and the object store; retried
/// while other nodes create them at the same time.
pub async fn open(client: async_nats::Client) -> Result<Resources, DistError> {
    let js = jetstream::new(client);
    retried("JetStream resources", || open_once(js.clone())).await
}

async fn open_once(js: jetstream::Context) -> Result<Resources, DistError> {
    js.get_or_create_stream(stream::Config {
        name: TASK_STREAM.to_string(),
        subjects: vec![TASK_SUBJECTS.to_string()],
        retention: stream::RetentionPolicy::WorkQueue,
        storage: stream::StorageType::File,
        duplicate_window: Duration::from_secs(600),
        ..Default::default()
    })
    .await
    .map_err(DistError::nats("task stream"))?;
    // The bucket's stream as the client's `create_key_value` makes it, created directly: that
    // call first asks for the account's limits in a form nats-server 2.9 does not answer.
    js.get_or_create_stream(stream::Config {
        name: format!("KV_{JOB_BUCKET}"),
        subjects: vec![format!("$KV.{JOB_BUCKET}.>")],
        max_messages_per_subject: 1,
        storage: stream::StorageType::File,
        allow_rollup: true,
        deny_delete: true,
        allow_direct: true,
        discard: stream::DiscardPolicy::New,
        duplicate_window: Duration::from_secs(120),
        num_replicas: 1,
        ..Default::default()
    })
    .await
    .map_err(DistError::nats("job bucket"))?;
    js.get_or_create_stream(stream::Config {
        name: format!("KV_{WORKER_BUCKET}"),
        subjects: vec![format!("$KV.{WORKER_BUCKET}.>")],
        max_messages_per_subject: 1,
        max_age: super::presence::MAX_AGE,
        duplicate_window: super::presence::MAX_AGE,
        storage: stream::StorageType::File,
        allow_rollup: true,
        deny_delete: true,
        allow_direct: true,
        discard: stream::DiscardPolicy::New,
        num_replicas: 1,
        ..Default::default()
    })
    .await
    .map_err(DistError::nats("worker bucket"))?;
    let workers = js
        .get_key_value(WORKER_BUCKET)
        .await
        .map_err(DistError::nats("worker bucket"))?;
    let jobs = js
        .get_key_value(JOB_BUCKET)
        .await
        .map_err(DistError::nats("job bucket"))?;
    let objects = match js.get_object_store(OBJECT_BUCKET).await {
        Ok(os) => os,
        Err(_) => js
            .create_object_store(object_store::Config {
                bucket: OBJECT_BUCKET.to_string(),
                storage: stream::StorageType::File,
                ..Default::default()
            })
            .await
            .map_err(DistError::nats("object store"))?,
    };
    let object_stream = js
        .get_stream(format!("OBJ_{OBJECT_BUCKET}"))
        .await
        .map_err(DistError::nats("object store"))?;
    let job_stream = js
        .get_stream(format!("KV_{JOB_BUCKET}"))
        .await
        .map_err(DistError::nats("job bucket"))?;
    Ok(Resources {
        js,
        jobs,
        objects,
        object_stream,
        job_stream,
        workers,
    })
}

/// The workers' shared durable pull consumer (explicit acks, `ack_wait`, bounded deliveries).
pub async fn worker_consumer(
    res: &Resources,
    cfg: &NatsConfig,
) -> Result<consumer::PullConsumer, DistError> {
    let stream = res
        .js
        .get_stream(TASK_STREAM)
        .await
        .map_err(DistError::nats("task stream"))?;
    retried("worker consumer", || async {
        stream
            .get_or_create_consumer(
                WORKER_CONSUMER,
                consumer::pull::Config {
                    durable_name: Some(WORKER_CONSUMER.to_string()),
                    ack_policy: consumer::AckPolicy::Explicit,
                    ack_wait: cfg.ack_wait,
                    max_deliver: MAX_DELIVER,
                    ..Default::default()
                },
            )
            .await
            .map_err(DistError::nats("worker consumer"))
    })
    .await
}
