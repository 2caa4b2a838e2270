//! Server configuration: every limit the service enforces, with the defaults of `rbfsurf serve`.
//! Plain data; no I/O. Reference: the HTTP API section of the design notes.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

/// Everything `rbfsurf serve` can be told (see `rbfsurf serve --help` for the flags).
#[derive(Debug, Clone)]
pub struct ServerConfig {
    /// Listen address (default `127.0.0.1:8080`).
    pub addr: SocketAddr,
    /// Directory holding one sub-directory per job (`<uuid>/input.*`, `params.json`, `status.json`,
    /// `report.json`, `mesh.glb`). Created if missing.
    pub data_dir: PathBuf,
    /// Worker threads running reconstructions (default 1; each job uses the rayon pool inside).
    pub workers: usize,
    /// Jobs allowed to wait for a worker; one more is refused with 429 (default 16).
    pub max_queue: usize,
    /// Largest accepted upload body, bytes (default 256 MiB).
    pub max_upload_bytes: u64,
    /// Largest accepted point count per upload (default 5,000,000).
    pub max_points: usize,
    /// Memory budget of one job, MiB (default 8192). A request's `max-memory-mib` can only lower
    /// it; jobs whose estimate exceeds it are refused at submit with 422 `system_too_large`.
    pub max_memory_mib: u64,
    /// Largest marching-grid resolution a request may ask for (default 1024).
    pub max_resolution: usize,
    /// A connection that sends no byte for this long while the server waits for its request
    /// (headers or body) is closed (default 5 s).
    pub idle_timeout: Duration,
    /// After an answer given before the request body was read (a refusal from the headers or the
    /// query), the body is still read and discarded for at most this long, and at most twice
    /// `max_upload_bytes`, so that clients which send the whole body before reading get the
    /// answer; then the connection closes (default 5 s; the lingering close of the HTTP layer).
    pub linger: Duration,
    /// Slowest accepted upload, bytes per second averaged from the start of the body; slower
    /// uploads are refused with 408 (default 64 KiB/s; checked after the first `idle_timeout`).
    pub min_upload_rate: u64,
    /// How long an upload waits for a free receive slot before it is answered 429 `busy`
    /// (default 30 s).
    pub upload_slot_wait: Duration,
    /// A running job is stopped and failed after this long (default 600 s).
    pub job_timeout: Duration,
    /// Finished jobs (and their files) are deleted this long after they finished; `None` keeps them.
    pub expire_after: Option<Duration>,
    /// Bearer token required on POST, DELETE and the job list; `None` leaves them open.
    pub token: Option<String>,
    /// Origins allowed by CORS (`*` = any); empty = no CORS headers.
    pub cors_origins: Vec<String>,
    /// Longest `?wait=SECONDS` honoured (default 600 s).
    pub max_wait: Duration,
}

impl Default for ServerConfig {
    fn default() -> Self {
        ServerConfig {
            addr: SocketAddr::from(([127, 0, 0, 1], 8080)),
            data_dir: PathBuf::from("rbfsurf-data"),
            workers: 1,
            max_queue: 16,
            max_upload_bytes: 256 << 20,
            max_points: 5_000_000,
            max_memory_mib: 8192,
            max_resolution: 1024,
            idle_timeout: Duration::from_secs(5),
            linger: Duration::from_secs(5),
            min_upload_rate: 64 << 10,
            upload_slot_wait: Duration::from_secs(30),
            job_timeout: Duration::from_secs(600),
            expire_after: Some(Duration::from_secs(7 * 24 * 3600)),
            token: None,
            cors_origins: Vec::new(),
            max_wait: Duration::from_secs(600),
        }
    }
}
