//! `POST /v1/compositions` and `POST /v1/morphs`: volume-modelling jobs over finished
//! reconstructions (their saved fields) and primitives. They run in the same queue, under the same
//! limits, with the same status, events, mesh and report URLs as reconstructions
//! (`/v1/reconstructions/{id}…`).

use super::{authorize, job_response};
use crate::job::volume::{
    COMPOSITION, CompositionRequest, MORPH, MorphRequest, REQUEST_FILE, VolumeRequest,
    VolumeRequestError,
};
use crate::job::{InputInfo, JobStatus};
use crate::server::AppState;
use crate::server::error::{ApiError, ErrorResponse};
use axum::Json;
use axum::body::Bytes;
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};

/// Largest request body (an expression, not data).
const MAX_BODY: usize = 64 * 1024;

async fn submit(
    st: &AppState,
    headers: &HeaderMap,
    req: VolumeRequest,
) -> Result<Response, ApiError> {
    let cfg = st.jobs.config();
    authorize(cfg.token.as_deref(), headers)?;
    if st.jobs.is_shutting_down() {
        return Err(crate::job::SubmitError::ShuttingDown.into());
    }
    let ids = req.validate().map_err(|e| match e {
        VolumeRequestError::Range(m) => ApiError::bad_parameter(m),
        VolumeRequestError::Expression(m) => {
            ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "invalid_expression", m)
        }
    })?;
    for id in &ids {
        let job = st
            .jobs
            .get(*id)
            .ok_or_else(|| ApiError::not_found("operand job"))?;
        let view = job.view();
        if view.status != JobStatus::Succeeded {
            return Err(ApiError::new(
                StatusCode::CONFLICT,
                "not_ready",
                format!(
                    "operand job {id} is {:?}; wait until it succeeds",
                    view.status
                )
                .to_lowercase(),
            ));
        }
        if !st.jobs.store().file(*id, "fitted.field").exists() {
            return Err(ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid_expression",
                format!(
                    "operand job {id} has no saved field (only csrbf reconstructions have one)"
                ),
            ));
        }
    }
    if !st.jobs.has_room() {
        return Err(crate::job::SubmitError::QueueFull.into());
    }
    let bytes = serde_json::to_vec_pretty(&req).map_err(|e| ApiError::internal(e.to_string()))?;
    let info = InputInfo {
        format: match req {
            VolumeRequest::Composition(_) => COMPOSITION,
            VolumeRequest::Morph(_) => MORPH,
        }
        .to_string(),
        file: REQUEST_FILE.to_string(),
        bytes: bytes.len() as u64,
        points: 0,
        attributes: None,
    };
    let jobs = st.jobs.clone();
    let options = crate::params::ReconOptions::default();
    let job = tokio::task::spawn_blocking(move || jobs.submit(&bytes, info, &options))
        .await
        .map_err(|e| ApiError::internal(e.to_string()))??;
    let resp = job_response(job.view(), None);
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, resp.status_url.clone())],
        Json(resp),
    )
        .into_response())
}

fn body<T: serde::de::DeserializeOwned>(bytes: &Bytes) -> Result<T, ApiError> {
    if bytes.len() > MAX_BODY {
        return Err(ApiError::too_large(format!(
            "the request body is over {MAX_BODY} bytes"
        )));
    }
    serde_json::from_slice(bytes).map_err(|e| ApiError::bad_parameter(format!("request body: {e}")))
}

/// Mesh an expression over finished reconstructions (operands are job ids) and primitives, as a
/// job (202 + the job; poll `status_url`, download `links.mesh`, `links.report`).
#[utoipa::path(post, path = "/v1/compositions", tag = "volume",
    request_body = CompositionRequest,
    responses((status = 202, description = "queued", body = crate::server::routes::JobResponse),
        (status = 400, description = "a malformed body, or `resolution` out of range", body = ErrorResponse), (status = 404, description = "an operand job does not exist", body = ErrorResponse),
        (status = 409, description = "an operand job has not finished", body = ErrorResponse),
        (status = 413, description = "a body over 64 KiB", body = ErrorResponse),
        (status = 422, description = "`invalid_expression`: the expression does not parse, calls an unknown operation or names an operand that is not a job id or has no saved field", body = ErrorResponse),
        (status = 429, body = ErrorResponse), (status = 503, description = "`shutting_down`, or `job_store_unavailable` (NATS-backed node)", body = ErrorResponse)),
    security((), ("bearer" = [])))]
pub async fn create_composition(
    State(st): State<AppState>,
    headers: HeaderMap,
    bytes: Bytes,
) -> Result<Response, ApiError> {
    let req: CompositionRequest = body(&bytes)?;
    submit(&st, &headers, VolumeRequest::Composition(req)).await
}

/// Metamorphosis between two expressions (job ids or primitives) as a job: its mesh is an animated
/// GLB (one node per frame, STEP animation), its report has the frames' topology.
#[utoipa::path(post, path = "/v1/morphs", tag = "volume",
    request_body = MorphRequest,
    responses((status = 202, description = "queued", body = crate::server::routes::JobResponse),
        (status = 400, description = "a malformed body, or `frames`, `resolution` or `align` out of range", body = ErrorResponse), (status = 404, description = "an operand job does not exist", body = ErrorResponse),
        (status = 409, description = "an operand job has not finished", body = ErrorResponse),
        (status = 413, description = "a body over 64 KiB", body = ErrorResponse),
        (status = 422, description = "`invalid_expression`: an expression does not parse, calls an unknown operation or names an operand that is not a job id or has no saved field", body = ErrorResponse),
        (status = 429, body = ErrorResponse), (status = 503, description = "`shutting_down`, or `job_store_unavailable` (NATS-backed node)", body = ErrorResponse)),
    security((), ("bearer" = [])))]
pub async fn create_morph(
    State(st): State<AppState>,
    headers: HeaderMap,
    bytes: Bytes,
) -> Result<Response, ApiError> {
    let req: MorphRequest = body(&bytes)?;
    submit(&st, &headers, VolumeRequest::Morph(req)).await
}
