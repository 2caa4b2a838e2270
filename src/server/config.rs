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
    /// A running job is stopped and failed after this long (default 600 s).
    pub job_timeout: Duration,
    /// Finished jobs (and their files) are deleted this long after they finished; `None` keeps them.
    pub expire_after: Option<Duration>,
    /// Bearer token required on mutating endpoints (POST, DELETE); `None` leaves them open.
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
            job_timeout: Duration::from_secs(600),
            expire_after: Some(Duration::from_secs(7 * 24 * 3600)),
            token: None,
            cors_origins: Vec::new(),
            max_wait: Duration::from_secs(600),
        }
    }
}
