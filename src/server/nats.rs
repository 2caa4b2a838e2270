//! A stateless API node (`serve --nats`): the HTTP service over a job manager whose jobs run on
//! NATS workers ([`crate::dist`]); the backend and the mirror of the job records are the
//! executor's, this module wires them to the router.

use super::{AppState, serve_on, shutdown_signal};
use crate::dist::NatsConfig;
use crate::dist::remote::{connect_backend, mirror};
use crate::job::{JobBackend, JobManager, ServerConfig};
use std::sync::Arc;

/// A NATS-backed API node's state (its job manager over the backend, upload slots) and the
/// task that mirrors the job records into it (abort it when the node stops).
pub async fn start_node(
    cfg: ServerConfig,
    nats: &NatsConfig,
) -> std::io::Result<(AppState, tokio::task::JoinHandle<()>)> {
    tracing::info!(nats = %crate::dist::connect::redact_url(&nats.url), "connecting to NATS");
    let backend = connect_backend(nats).await.map_err(std::io::Error::other)?;
    let permits = (2 * cfg.workers).max(2);
    let mgr = {
        let b: Arc<dyn JobBackend> = backend.clone();
        tokio::task::spawn_blocking(move || JobManager::start_remote(cfg, b))
            .await
            .map_err(std::io::Error::other)??
    };
    let watcher = tokio::spawn(mirror(backend, Arc::clone(&mgr)));
    let state = AppState {
        jobs: mgr,
        uploads: Arc::new(tokio::sync::Semaphore::new(permits)),
    };
    Ok((state, watcher))
}

/// Runs a NATS-backed API node until Ctrl-C / SIGTERM.
pub async fn serve_nats(cfg: ServerConfig, nats: NatsConfig) -> std::io::Result<()> {
    let listener = tokio::net::TcpListener::bind(cfg.addr).await?;
    let (state, watcher) = start_node(cfg, &nats).await?;
    tracing::info!(addr = %listener.local_addr()?, "rbfsurf serve listening (jobs on NATS)");
    let result = serve_on(listener, state, shutdown_signal()).await;
    watcher.abort();
    result
}
