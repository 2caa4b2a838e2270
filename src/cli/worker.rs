//! `rbfsurf worker` and the NATS flags it shares with `serve --nats`: address, credentials
//! (flags, files or environment; never printed), TLS files, ack wait.

use crate::dist::NatsConfig;
use anyhow::{Context, Result, bail};
use std::path::PathBuf;
use std::time::Duration;

/// How to reach NATS (shared by `worker` and `serve`).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct NatsArgs {
    /// NATS server URL(s), comma-separated (nats://host:4222, tls://host:4222); for `worker` the
    /// NATS_URL environment variable is used when absent. For `serve`: run as a stateless API
    /// node over NATS JetStream instead of the embedded service [default: none].
    #[arg(long, value_name = "URL")]
    pub nats: Option<String>,
    /// NATS user name; the password comes from --nats-password-file or RBFSURF_NATS_PASSWORD
    /// [default: none].
    #[arg(long)]
    pub nats_user: Option<String>,
    /// File whose first line is the NATS password [default: none].
    #[arg(long)]
    pub nats_password_file: Option<PathBuf>,
    /// File whose first line is the NATS token; else RBFSURF_NATS_TOKEN [default: none].
    #[arg(long)]
    pub nats_token_file: Option<PathBuf>,
    /// CA certificate (PEM) to trust for TLS to NATS [default: the system's].
    #[arg(long)]
    pub nats_tls_ca: Option<PathBuf>,
    /// Client certificate (PEM) for mutual TLS; needs --nats-tls-key [default: none].
    #[arg(long, requires = "nats_tls_key")]
    pub nats_tls_cert: Option<PathBuf>,
    /// Client key (PEM) for mutual TLS [default: none].
    #[arg(long, requires = "nats_tls_cert")]
    pub nats_tls_key: Option<PathBuf>,
    /// Seconds a task may go without a heartbeat before NATS hands it to another worker, 1..=30;
    /// also RBFSURF_NATS_ACK_WAIT_S (the shared consumer keeps the value it was created with)
    /// [default: 30].
    #[arg(long)]
    pub ack_wait_s: Option<u64>,
}

fn first_line(path: &PathBuf, what: &str) -> Result<String> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("{what} {}", path.display()))?;
    let line = text.lines().next().unwrap_or("").trim().to_string();
    if line.is_empty() {
        bail!("{what} {}: the file is empty", path.display());
    }
    Ok(line)
}

fn env(name: &str) -> Option<String> {
    std::env::var(name)
        .ok()
        .map(|v| v.trim().to_string())
        .filter(|v| !v.is_empty())
}

impl NatsArgs {
    /// The connection these flags describe for `url`.
    pub fn config(&self, url: String) -> Result<NatsConfig> {
        let token = match &self.nats_token_file {
            Some(p) => Some(first_line(p, "--nats-token-file")?),
            None => env("RBFSURF_NATS_TOKEN"),
        };
        let user = match &self.nats_user {
            Some(u) => {
                let password = match &self.nats_password_file {
                    Some(p) => first_line(p, "--nats-password-file")?,
                    None => env("RBFSURF_NATS_PASSWORD").with_context(|| {
                        "--nats-user needs a password: --nats-password-file or RBFSURF_NATS_PASSWORD"
                    })?,
                };
                Some((u.clone(), password))
            }
            None => None,
        };
        let ack = match (self.ack_wait_s, env("RBFSURF_NATS_ACK_WAIT_S")) {
            (Some(s), _) => s,
            (None, Some(v)) => v
                .parse()
                .with_context(|| format!("RBFSURF_NATS_ACK_WAIT_S={v}: give whole seconds"))?,
            (None, None) => 30,
        };
        if !(1..=30).contains(&ack) {
            bail!("--ack-wait-s {ack}: use 1..=30 (a dead worker's task waits this long)");
        }
        Ok(NatsConfig {
            url,
            token,
            user,
            tls_ca: self.nats_tls_ca.clone(),
            tls_client: self.nats_tls_cert.clone().zip(self.nats_tls_key.clone()),
            require_tls: false,
            ack_wait: Duration::from_secs(ack),
        })
    }
}

/// Arguments of `worker`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct WorkerArgs {
    /// NATS connection.
    #[command(flatten)]
    pub nats: NatsArgs,
    /// Tasks run at once; the block size of a job this worker prepares is planned for it
    /// [default: the number of CPUs].
    #[arg(long)]
    pub concurrency: Option<usize>,
    /// Points from which a job that fits its memory budget is still split into block tasks when
    /// another worker is idle (docs/distributed.md, "Spreading a large job"); 0 never splits
    /// such a job [default: 500000].
    #[arg(long, value_name = "POINTS")]
    pub spread_points: Option<u64>,
    /// MiB per byte range of the input when this worker prepares a job's task graph: the survey
    /// and routing run one task per range for binary PLY, uncompressed LAS and XYZ/PTS/CSV text
    /// (docs/distributed.md, "Prepare by byte ranges"); 0 reads the input whole [default: 64].
    #[arg(long, value_name = "MIB")]
    pub range_mib: Option<f64>,
}

/// Runs the worker until it is stopped.
pub fn run(a: &WorkerArgs) -> Result<()> {
    let Some(url) = a.nats.nats.clone().or_else(|| env("NATS_URL")) else {
        bail!("worker needs --nats URL (or the NATS_URL environment variable)");
    };
    let nats = a.nats.config(url)?;
    let concurrency = a
        .concurrency
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    if !(1..=256).contains(&concurrency) {
        bail!("--concurrency {concurrency}: use 1..=256");
    }
    super::serve::init_logging();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let spread_points = match a.spread_points {
        Some(0) => u64::MAX,
        Some(n) => n,
        None => crate::dist::SPREAD_POINTS,
    };
    let split = match a.range_mib {
        Some(m) if m <= 0.0 => crate::pipeline::tiled::InputSplit::Whole,
        Some(m) => crate::pipeline::tiled::InputSplit::Bytes(((m * 1048576.0) as u64).max(1)),
        None => crate::pipeline::tiled::InputSplit::default(),
    };
    let params = crate::dist::worker::WorkerParams {
        nats,
        concurrency,
        spread_points,
        split,
    };
    rt.block_on(crate::dist::worker::run_worker(&params))
        .context("worker")
}
