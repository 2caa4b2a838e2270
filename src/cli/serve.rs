//! `rbfsurf serve` and `rbfsurf openapi`: flags → [`ServerConfig`], a tokio runtime, the server.

use crate::job::ServerConfig;
use anyhow::{Context, Result, bail};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Arguments of `serve`; every limit defaults to [`ServerConfig::default`].
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ServeArgs {
    /// Listen address [default: 127.0.0.1:8080].
    #[arg(long)]
    pub addr: Option<SocketAddr>,
    /// Directory for jobs (inputs, parameters, status, reports, meshes) [default: ./rbfsurf-data].
    #[arg(long)]
    pub data_dir: Option<PathBuf>,
    /// Worker threads running reconstructions [default: 1].
    #[arg(long)]
    pub workers: Option<usize>,
    /// Jobs allowed to wait for a worker; more are refused with 429 [default: 16].
    #[arg(long)]
    pub max_queue: Option<usize>,
    /// Largest upload in MiB; larger ones get 413 [default: 256].
    #[arg(long)]
    pub max_upload_mib: Option<u64>,
    /// Largest point count per upload [default: 5000000].
    #[arg(long)]
    pub max_points: Option<usize>,
    /// Memory budget of one job in MiB; a request's max-memory-mib can only lower it, and jobs
    /// estimated above it are refused with 422 at submit [default: 8192].
    #[arg(long)]
    pub max_memory_mib: Option<u64>,
    /// Largest resolution a request may ask for [default: 1024].
    #[arg(long)]
    pub max_resolution: Option<usize>,
    /// Slowest accepted upload in KiB/s (after the first 5 s); connections idle for 5 s are closed [default: 64].
    #[arg(long)]
    pub min_upload_kib_s: Option<u64>,
    /// A running job fails after this many seconds [default: 600].
    #[arg(long)]
    pub job_timeout_s: Option<u64>,
    /// Delete finished jobs this many hours after they finished; 0 keeps them [default: 168].
    #[arg(long)]
    pub expire_hours: Option<u64>,
    /// Bearer token required on POST, DELETE and the job list (visible in the process list:
    /// prefer --token-file or the RBFSURF_TOKEN environment variable) [default: none].
    #[arg(long, conflicts_with = "token_file")]
    pub token: Option<String>,
    /// Read the bearer token from this file (its first line) [default: none].
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Allow cross-origin requests from this origin (repeatable; `*` = any) [default: none].
    #[arg(long = "cors-origin")]
    pub cors_origins: Vec<String>,
    /// With --nats URL: a stateless API node over NATS JetStream (jobs run on `rbfsurf worker`
    /// processes; the data directory only caches results).
    #[cfg(feature = "nats")]
    #[command(flatten)]
    pub nats: super::worker::NatsArgs,
}

impl ServeArgs {
    /// The server configuration these flags describe.
    pub fn config(&self) -> Result<ServerConfig> {
        let d = ServerConfig::default();
        let workers = self.workers.unwrap_or(d.workers);
        if !(1..=256).contains(&workers) {
            bail!("--workers {workers}: use 1..=256");
        }
        let mib = self.max_upload_mib.unwrap_or(d.max_upload_bytes >> 20);
        if !(1..=1 << 20).contains(&mib) {
            bail!("--max-upload-mib {mib}: use 1..=1048576");
        }
        let timeout = self.job_timeout_s.unwrap_or(d.job_timeout.as_secs());
        if timeout == 0 {
            bail!("--job-timeout-s 0: give a positive number of seconds");
        }
        let max_queue = self.max_queue.unwrap_or(d.max_queue);
        if max_queue == 0 {
            bail!("--max-queue 0 would refuse every job: use 1 or more");
        }
        let max_memory_mib = self.max_memory_mib.unwrap_or(d.max_memory_mib);
        if !(16..=1 << 22).contains(&max_memory_mib) {
            bail!("--max-memory-mib {max_memory_mib}: use 16..=4194304");
        }
        let max_resolution = self.max_resolution.unwrap_or(d.max_resolution);
        if !(8..=4096).contains(&max_resolution) {
            bail!("--max-resolution {max_resolution}: use 8..=4096");
        }
        let min_rate = self.min_upload_kib_s.unwrap_or(d.min_upload_rate >> 10);
        if min_rate == 0 {
            bail!(
                "--min-upload-kib-s 0: give a positive rate (slow uploads hold memory and slots)"
            );
        }
        let token = self.token()?;
        Ok(ServerConfig {
            addr: self.addr.unwrap_or(d.addr),
            data_dir: self.data_dir.clone().unwrap_or(d.data_dir),
            workers,
            max_queue,
            max_upload_bytes: mib << 20,
            max_points: self.max_points.unwrap_or(d.max_points),
            max_memory_mib,
            max_resolution,
            idle_timeout: d.idle_timeout,
            linger: d.linger,
            min_upload_rate: min_rate << 10,
            upload_slot_wait: d.upload_slot_wait,
            job_timeout: Duration::from_secs(timeout),
            expire_after: match self.expire_hours {
                Some(0) => None,
                Some(h) => Some(Duration::from_secs(h.saturating_mul(3600))),
                None => d.expire_after,
            },
            token,
            cors_origins: self.cors_origins.clone(),
            max_wait: d.max_wait,
        })
    }
}

impl ServeArgs {
    /// The token from --token, --token-file or RBFSURF_TOKEN (in that order); empty = none.
    fn token(&self) -> Result<Option<String>> {
        let token = match (&self.token, &self.token_file) {
            (Some(t), _) => Some(t.clone()),
            (None, Some(path)) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("--token-file {}", path.display()))?;
                let line = text.lines().next().unwrap_or("").trim().to_string();
                if line.is_empty() {
                    bail!("--token-file {}: the file is empty", path.display());
                }
                Some(line)
            }
            (None, None) => std::env::var("RBFSURF_TOKEN").ok(),
        };
        Ok(token
            .map(|t| t.trim().to_string())
            .filter(|t| !t.is_empty()))
    }
}

/// Logs to stderr (`RUST_LOG`, default `info`).
pub(super) fn init_logging() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .try_init();
}

/// Runs the server until Ctrl-C / SIGTERM.
pub fn run(a: &ServeArgs) -> Result<()> {
    let cfg = a.config()?;
    #[cfg(feature = "nats")]
    let nats = match &a.nats.nats {
        Some(url) => Some(a.nats.config(url.clone())?),
        None => None,
    };
    init_logging();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let addr = cfg.addr;
    let dir = cfg.data_dir.display().to_string();
    #[cfg(feature = "nats")]
    if let Some(nats) = nats {
        return rt
            .block_on(crate::server::nats::serve_nats(cfg, nats))
            .with_context(|| format!("serving on {addr} (jobs on NATS)"));
    }
    rt.block_on(crate::server::serve(cfg))
        .with_context(|| format!("serving on {addr} with data directory {dir}"))
}

/// Arguments of `openapi`.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct OpenApiArgs {
    /// Write the document here (atomically) instead of stdout.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

/// Prints (or writes) the OpenAPI document of the HTTP API.
pub fn run_openapi(a: &OpenApiArgs) -> Result<()> {
    let json = crate::server::openapi::openapi_json();
    match &a.output {
        Some(p) => crate::io::write_atomic(p, json.as_bytes())?,
        None => print!("{json}"),
    }
    Ok(())
}
