//! The HTTP service (`rbfsurf serve`): the reconstruction library behind a REST API with a job
//! queue, server-sent progress, an embedded WebGL viewer and an OpenAPI document.
//!
//! Layout: [`error`] (HTTP errors), [`feasibility`] (submit-time checks), [`routes`] (handlers),
//! [`openapi`], [`linger`] (the answer to a request refused before its
//! body was read reaches clients that send the whole body first); the job model, queue, store and limits below it are [`crate::job`].
//! The server only calls the library (`io`, `params`, `reconstruct`); it adds no numerics.
//! Design: the HTTP API section of the design notes; the seed's online server with browser view.

pub(crate) mod error;
pub(crate) mod feasibility;
pub(crate) mod linger;
#[cfg(feature = "nats")]
pub mod nats;
pub mod openapi;
pub mod routes;

use crate::job::{JobManager, ServerConfig};
use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::http::{HeaderValue, Method, header};
use std::sync::Arc;
use std::time::Duration;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::trace::{DefaultMakeSpan, DefaultOnResponse, TraceLayer};
use tracing::Level;

/// Shared state of every handler.
#[derive(Clone)]
pub struct AppState {
    /// The job manager (queue, workers, store).
    pub jobs: Arc<JobManager>,
    /// Uploads being received and checked at once (each holds up to `max_upload_bytes` plus the
    /// parsed cloud): bounds the memory of concurrent uploads to `permits × (upload + cloud)`.
    pub uploads: Arc<tokio::sync::Semaphore>,
}

impl AppState {
    /// Opens the data directory, recovers stored jobs and starts the workers.
    pub fn start(cfg: ServerConfig) -> std::io::Result<AppState> {
        let permits = (2 * cfg.workers).max(2);
        Ok(AppState {
            jobs: JobManager::start(cfg)?,
            uploads: Arc::new(tokio::sync::Semaphore::new(permits)),
        })
    }
}

/// The complete application: documented routes, JSON fallbacks, body limit, CORS, request logs,
/// lingering close of refused bodies.
pub fn router(state: AppState) -> Router {
    let cfg = state.jobs.config().clone();
    let (api, _) = openapi::api_router().split_for_parts();
    // Multipart reads through axum's limit; raw bodies are counted by the upload handler.
    let limit =
        usize::try_from(cfg.max_upload_bytes.saturating_add(64 << 10)).unwrap_or(usize::MAX);
    let mut app = api
        .fallback(routes::meta::no_route)
        .method_not_allowed_fallback(routes::meta::wrong_method)
        .with_state(state)
        .layer(DefaultBodyLimit::max(limit));
    if let Some(cors) = cors_layer(&cfg.cors_origins) {
        app = app.layer(cors);
    }
    let bounds = linger::Linger {
        max_bytes: cfg.max_upload_bytes.saturating_mul(2),
        max_time: cfg.linger,
    };
    app.layer(
        TraceLayer::new_for_http()
            .make_span_with(DefaultMakeSpan::new().level(Level::INFO))
            .on_response(DefaultOnResponse::new().level(Level::INFO)),
    )
    .layer(axum::middleware::from_fn(
        move |req: axum::extract::Request, next: axum::middleware::Next| {
            linger::linger(bounds, req, next)
        },
    ))
}

fn cors_layer(origins: &[String]) -> Option<CorsLayer> {
    if origins.is_empty() {
        return None;
    }
    let allow = if origins.iter().any(|o| o == "*") {
        AllowOrigin::any()
    } else {
        AllowOrigin::list(origins.iter().filter_map(|o| HeaderValue::from_str(o).ok()))
    };
    Some(
        CorsLayer::new()
            .allow_origin(allow)
            .allow_methods([Method::GET, Method::POST, Method::DELETE])
            .allow_headers([header::CONTENT_TYPE, header::AUTHORIZATION]),
    )
}

/// Runs the server until Ctrl-C or SIGTERM, then stops accepting, lets in-flight requests end,
/// stops the workers (running jobs are stored as queued and resume after a restart).
pub async fn serve(cfg: ServerConfig) -> std::io::Result<()> {
    let listener = tokio::net::TcpListener::bind(cfg.addr).await?;
    let state = tokio::task::spawn_blocking(move || AppState::start(cfg))
        .await
        .map_err(std::io::Error::other)??;
    tracing::info!(addr = %listener.local_addr()?, "rbfsurf serve listening");
    serve_on(listener, state, shutdown_signal()).await
}

/// Serves `state` on an already bound listener until `stop` completes (used by `serve` and tests).
///
/// Connections are served by hyper (HTTP/1.1) with a header read timeout of
/// [`ServerConfig::idle_timeout`]: a client that has not sent a complete request head within it
/// (a trickle, or an idle keep-alive connection) is disconnected. Bodies are guarded by the
/// upload handler (no byte for `idle_timeout`, or slower than `min_upload_rate`: 408).
pub async fn serve_on(
    listener: tokio::net::TcpListener,
    state: AppState,
    stop: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let expiry = tokio::spawn(expire_loop(state.jobs.clone()));
    let jobs = state.jobs.clone();
    let idle = jobs.config().idle_timeout;
    let app = router(state);
    let graceful = hyper_util::server::graceful::GracefulShutdown::new();
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(hyper_util::rt::TokioTimer::new())
        .header_read_timeout(idle);
    tokio::pin!(stop);
    let result = loop {
        tokio::select! {
            accepted = listener.accept() => {
                let stream = match accepted {
                    Ok((stream, _)) => stream,
                    // Out of file descriptors and the like: keep serving the open connections.
                    Err(e) => {
                        tracing::warn!(error = %e, "accept failed");
                        tokio::time::sleep(Duration::from_millis(50)).await;
                        continue;
                    }
                };
                let _ = stream.set_nodelay(true);
                let io = hyper_util::rt::TokioIo::new(stream);
                let service = hyper_util::service::TowerToHyperService::new(app.clone());
                let conn = graceful.watch(builder.serve_connection(io, service));
                tokio::spawn(async move {
                    let _ = conn.await;
                });
            }
            () = &mut stop => break Ok(()),
        }
    };
    drop(listener);
    // In-flight requests end (a `?wait` is bounded by `max_wait`; give them a few seconds).
    let _ = tokio::time::timeout(Duration::from_secs(10), graceful.shutdown()).await;
    expiry.abort();
    tokio::task::spawn_blocking(move || jobs.shutdown())
        .await
        .map_err(std::io::Error::other)?;
    tracing::info!("rbfsurf serve stopped");
    result
}

async fn expire_loop(jobs: Arc<JobManager>) {
    let Some(age) = jobs.config().expire_after else {
        return;
    };
    let period = (age / 4).clamp(Duration::from_secs(1), Duration::from_secs(60));
    let mut tick = tokio::time::interval(period);
    loop {
        tick.tick().await;
        let j = jobs.clone();
        let _ = tokio::task::spawn_blocking(move || j.expire()).await;
    }
}

/// Resolves on Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = term => {},
    }
    tracing::info!("shutdown requested");
}
