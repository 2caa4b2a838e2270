//! Service endpoints: health, the OpenAPI document, the embedded viewer page and its script,
//! and JSON answers for unknown routes and methods.

use crate::server::AppState;
use crate::server::error::{ApiError, ErrorResponse};
use axum::Json;
use axum::extract::State;
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

/// The viewer page (upload, parameters, progress, WebGL view), embedded in the binary.
const INDEX_HTML: &str = include_str!("../assets/index.html");
/// The viewer's script: GLB parsing, WebGL rendering, orbit/zoom, the upload flow.
const VIEWER_JS: &str = include_str!("../assets/viewer.js");
/// meshoptimizer's glTF buffer decoder (npm `meshoptimizer` 1.3.0, MIT, vendored unchanged; its
/// licence is `assets/meshopt_decoder.LICENSE.md`): the viewer decodes compact GLBs with it.
const MESHOPT_DECODER_JS: &str = include_str!("../assets/meshopt_decoder.mjs");
/// The decoder's licence text.
const MESHOPT_LICENSE: &str = include_str!("../assets/meshopt_decoder.LICENSE.md");

/// Answer of `/healthz`.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Health {
    /// Always `ok` (a stopping server answers 503 instead).
    pub status: String,
    /// Jobs waiting for a worker.
    pub queued: usize,
    /// Queue capacity.
    pub max_queue: usize,
    /// Worker threads.
    pub workers: usize,
    /// Jobs known (all states).
    pub jobs: usize,
    /// Crate version.
    pub version: String,
}

/// Liveness and queue state.
#[utoipa::path(get, path = "/healthz", tag = "service",
    responses((status = 200, body = Health), (status = 503, description = "shutting down", body = ErrorResponse)))]
pub async fn health(State(st): State<AppState>) -> Result<Json<Health>, ApiError> {
    if st.jobs.is_shutting_down() {
        return Err(crate::job::SubmitError::ShuttingDown.into());
    }
    let cfg = st.jobs.config();
    Ok(Json(Health {
        status: "ok".into(),
        queued: st.jobs.queued(),
        max_queue: cfg.max_queue,
        workers: cfg.workers,
        jobs: st.jobs.list().len(),
        version: env!("CARGO_PKG_VERSION").into(),
    }))
}

/// This API's OpenAPI 3.1 document (the same as proto/openapi.json).
#[utoipa::path(get, path = "/openapi.json", tag = "service",
    responses((status = 200, description = "OpenAPI document", body = Object)))]
pub async fn openapi_json() -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        crate::server::openapi::openapi_json(),
    )
        .into_response()
}

/// The viewer page.
#[utoipa::path(get, path = "/", tag = "service",
    responses((status = 200, description = "HTML viewer", content_type = "text/html", body = String)))]
pub async fn index() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        INDEX_HTML,
    )
        .into_response()
}

/// The viewer script.
#[utoipa::path(get, path = "/assets/viewer.js", tag = "service",
    responses((status = 200, description = "viewer script", content_type = "text/javascript", body = String)))]
pub async fn viewer_js() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/javascript; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        VIEWER_JS,
    )
        .into_response()
}

/// The meshoptimizer decoder module the viewer imports for `EXT_meshopt_compression`.
#[utoipa::path(get, path = "/assets/meshopt_decoder.mjs", tag = "service",
    responses((status = 200, description = "meshoptimizer decoder (ES module, MIT licence at /assets/meshopt_decoder.LICENSE.md)", content_type = "text/javascript", body = String)))]
pub async fn meshopt_decoder_js() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/javascript; charset=utf-8"),
            (header::CACHE_CONTROL, "public, max-age=86400"),
        ],
        MESHOPT_DECODER_JS,
    )
        .into_response()
}

/// The meshoptimizer decoder's licence (MIT).
#[utoipa::path(get, path = "/assets/meshopt_decoder.LICENSE.md", tag = "service",
    responses((status = 200, description = "licence of the vendored meshoptimizer decoder", content_type = "text/markdown", body = String)))]
pub async fn meshopt_license() -> Response {
    (
        [(header::CONTENT_TYPE, "text/markdown; charset=utf-8")],
        MESHOPT_LICENSE,
    )
        .into_response()
}

/// 404 for unknown routes.
pub async fn no_route() -> ApiError {
    ApiError::new(
        StatusCode::NOT_FOUND,
        "not_found",
        "no such endpoint; see /openapi.json",
    )
}

/// 405 for known routes with the wrong method.
pub async fn wrong_method() -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        "this endpoint does not accept that method; see /openapi.json",
    )
}
