//! The job API under `/v1/reconstructions`: upload (raw body or multipart), list, status (with
//! `?wait`), server-sent events, mesh download (glb/ply/obj), report, cancel/delete.
//! Uploads are bounded before they are read (Content-Length) and while they are read (streamed
//! count, idle time, rate: [`super::upload`]); parsing and the feasibility check run on the
//! blocking pool before a job is queued; cleaning and the degeneracy checks run in the job.

use super::upload::{
    BodyKind, check_cloud, classify, guard_body, read_limited, read_multipart, too_large,
};
use super::{JobResponse, WaitQuery, authorize, find_job, job_response, parse_params, query_pairs};
use crate::io::{MeshFormat, MeshMeta, decode_glb, glb_crs, write_mesh_with};
use crate::job::store::input_ext;
use crate::job::{ErrorBody, InputInfo, Job, JobStatus, JobView};
use crate::server::AppState;
use crate::server::error::{ApiError, ErrorResponse};
use axum::Json;
use axum::body::Body;
use axum::extract::{Path, RawQuery, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use std::convert::Infallible;
use std::time::Duration;

/// A point file's bytes (documentation type of the binary request bodies).
#[derive(utoipa::ToSchema)]
#[schema(value_type = String, format = Binary)]
pub struct PointFile(pub Vec<u8>);

/// A `multipart/form-data` upload: the point file in a part named `file`; parameters may come as
/// further text fields with the query's names.
#[derive(utoipa::ToSchema)]
pub struct MultipartUpload {
    /// The point file (PLY, XYZ/PTS, CSV, OBJ, LAS/LAZ or E57).
    #[schema(value_type = String, format = Binary)]
    pub file: Vec<u8>,
}

/// Submit a point cloud for reconstruction.
///
/// The body is the point file (Content-Type by format; `application/octet-stream` is sniffed) or
/// `multipart/form-data` with a `file` part and parameter fields. Parameters (query or fields)
/// have the command line's names and ranges.
#[utoipa::path(post, path = "/v1/reconstructions", tag = "reconstructions",
    params(crate::params::ReconOptions, WaitQuery),
    request_body(description = "point file: PLY (ascii/binary), XYZ/PTS text, CSV, OBJ vertices, LAS/LAZ 1.0–1.4, E57 (application/octet-stream, sniffed by its `ASTM-E57` signature; LAS/LAZ by `LASF`, PLY by `ply`); or multipart/form-data with `file`",
        content(
            (PointFile = "application/ply"), (String = "text/plain"), (String = "text/csv"),
            (String = "model/obj"), (PointFile = "application/vnd.las"), (PointFile = "application/vnd.laszip"),
            (PointFile = "application/octet-stream"), (MultipartUpload = "multipart/form-data"))),
    responses(
        (status = 202, description = "accepted and queued (or still running after `wait`)", body = JobResponse),
        (status = 200, description = "succeeded (or was cancelled) within `wait`", body = JobResponse),
        (status = 400, description = "bad parameter, malformed multipart or incomplete body", body = ErrorResponse),
        (status = 401, description = "missing or wrong bearer token", body = ErrorResponse),
        (status = 408, description = "the body stalled (no byte for 5 s) or arrived below the minimum rate", body = ErrorResponse),
        (status = 409, description = "with `wait`: the job was cancelled while waiting (`{error, job}`)", body = ErrorResponse),
        (status = 413, description = "upload or point count over the limit", body = ErrorResponse),
        (status = 415, description = "unknown format", body = ErrorResponse),
        (status = 422, description = "parses but cannot be reconstructed, does not fit the server's limits (`system_too_large` with the estimate), parameters that conflict (`conflicting_parameters`) or do not suit the cloud (`unsuitable_parameter`); with `wait`: the job failed so (`{error, job}`)", body = ErrorResponse),
        (status = 429, description = "queue full, or too many uploads at once (see Retry-After)", body = ErrorResponse),
        (status = 500, description = "internal error (generic message with an error id; with `wait`: `{error, job}`)", body = ErrorResponse),
        (status = 503, description = "shutting down (`shutting_down`), or on a NATS-backed node (`serve --nats`) the job store did not take the job (`job_store_unavailable`); both with Retry-After", body = ErrorResponse),
        (status = 507, description = "the server's storage is full", body = ErrorResponse)),
    security((), ("bearer" = [])))]
pub async fn create_job(
    State(st): State<AppState>,
    RawQuery(raw): RawQuery,
    req: Request,
) -> Result<Response, ApiError> {
    let cfg = st.jobs.config();
    authorize(cfg.token.as_deref(), req.headers())?;
    if st.jobs.is_shutting_down() {
        return Err(crate::job::SubmitError::ShuttingDown.into());
    }
    let mut pairs = query_pairs(raw.as_deref())?;
    let declared = req
        .headers()
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    if declared.is_some_and(|n| n > cfg.max_upload_bytes) {
        return Err(too_large(cfg.max_upload_bytes));
    }
    parse_params(&pairs, cfg)?;
    let kind = classify(req.headers())?;
    if !st.jobs.has_room() {
        return Err(crate::job::SubmitError::QueueFull.into());
    }
    // At most a few uploads are buffered and parsed at once; others wait briefly, then get 429.
    let permit = tokio::time::timeout(cfg.upload_slot_wait, st.uploads.clone().acquire_owned())
        .await
        .ok()
        .and_then(Result::ok)
        .ok_or_else(|| {
            ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "busy",
                "too many uploads are being received at once; retry after the Retry-After delay",
            )
            .retry_after(2)
        })?;
    // A stalled or trickling body is cut off (408), which frees its slot within seconds.
    let (parts, body) = req.into_parts();
    let (body, stall) = guard_body(body, cfg);
    let req = Request::from_parts(parts, body);
    let (bytes, hint) = match kind {
        BodyKind::Raw(hint) => (
            read_limited(req.into_body(), cfg.max_upload_bytes, &stall).await?,
            hint,
        ),
        BodyKind::Multipart => read_multipart(req, &st, &mut pairs, &stall).await?,
    };
    let (options, params, wait) = parse_params(&pairs, cfg)?;
    let size = bytes.len() as u64;
    let (bytes, format, points, attributes) = check_cloud(&st, bytes, hint, &params).await?;
    let info = InputInfo {
        format: format.name().to_string(),
        file: format!("input.{}", input_ext(format)),
        bytes: size,
        points,
        attributes: Some(attributes),
    };
    let jobs = st.jobs.clone();
    let job = tokio::task::spawn_blocking(move || jobs.submit(&bytes, info, &options))
        .await
        .map_err(|e| ApiError::internal(e.to_string()))??;
    drop(permit);
    tracing::info!(id = %job.id, points, format = format.name(), "job accepted");
    if wait > 0.0 {
        wait_for(&job, wait, cfg.max_wait).await;
    }
    let view = job.view();
    if !view.status.is_terminal() {
        let resp = job_response(view, None);
        return Ok((
            StatusCode::ACCEPTED,
            [(header::LOCATION, resp.status_url.clone())],
            Json(resp),
        )
            .into_response());
    }
    finished_answer(&st, view).await
}

/// Answer for a job that finished within `wait`: 200 + job, or the failure's status + error.
async fn finished_answer(st: &AppState, view: JobView) -> Result<Response, ApiError> {
    if view.status == JobStatus::Failed {
        let err = view.error.clone().unwrap_or(ErrorBody {
            code: "internal".into(),
            message: "failed without a message".into(),
        });
        let status = crate::server::error::status_of_code(&err.code);
        let body = serde_json::json!({ "error": err, "job": job_response(view, None) });
        return Ok((status, Json(body)).into_response());
    }
    let report = load_report(st, &view).await;
    Ok(Json(job_response(view, report)).into_response())
}

async fn wait_for(job: &Job, secs: f64, max: Duration) {
    let d = Duration::from_secs_f64(secs.min(max.as_secs_f64()));
    let mut rx = job.subscribe();
    let _ = tokio::time::timeout(d, rx.wait_for(|v| v.status.is_terminal())).await;
}

async fn load_report(st: &AppState, view: &JobView) -> Option<serde_json::Value> {
    if view.status != JobStatus::Succeeded {
        return None;
    }
    let bytes = tokio::fs::read(st.jobs.store().file(view.id, "report.json"))
        .await
        .ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// List every stored job (oldest first), including those recovered after a restart.
///
/// When the server has a token, listing requires it (the list holds every job id, and an id is
/// what grants reading a job and its mesh).
#[utoipa::path(get, path = "/v1/reconstructions", tag = "reconstructions",
    responses((status = 200, description = "all jobs", body = Vec<JobView>),
        (status = 401, description = "the server has a token and the request lacks it", body = ErrorResponse)),
    security((), ("bearer" = [])))]
pub async fn list_jobs(
    State(st): State<AppState>,
    headers: HeaderMap,
) -> Result<Json<Vec<JobView>>, ApiError> {
    authorize(st.jobs.config().token.as_deref(), &headers)?;
    Ok(Json(st.jobs.list()))
}

/// Job status, progress (stage + fraction), error, and the report once it succeeded.
#[utoipa::path(get, path = "/v1/reconstructions/{id}", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)"), WaitQuery),
    responses((status = 200, description = "the job", body = JobResponse),
        (status = 400, description = "bad `wait`", body = ErrorResponse),
        (status = 404, description = "unknown id", body = ErrorResponse)))]
pub async fn get_job(
    State(st): State<AppState>,
    Path(id): Path<String>,
    RawQuery(raw): RawQuery,
) -> Result<Json<JobResponse>, ApiError> {
    let job = find_job(&st, &id)?;
    let q: WaitQuery = serde_urlencoded::from_str(raw.as_deref().unwrap_or(""))
        .map_err(|e| ApiError::bad_parameter(format!("invalid query: {e} (only wait=SECONDS)")))?;
    if let Some(w) = q.wait {
        if !(w.is_finite() && w >= 0.0) {
            return Err(ApiError::bad_parameter(format!(
                "invalid parameter wait = {w}: seconds >= 0"
            )));
        }
        wait_for(&job, w, st.jobs.config().max_wait).await;
    }
    let view = job.view();
    let report = load_report(&st, &view).await;
    Ok(Json(job_response(view, report)))
}

/// Server-sent events: `progress` events with the job state while it runs, then one `done`
/// event (the final state) and the stream ends.
#[utoipa::path(get, path = "/v1/reconstructions/{id}/events", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, description = "server-sent events `progress` and `done`, each with the job (JobView) as JSON data", content_type = "text/event-stream", body = String),
        (status = 404, description = "unknown id", body = ErrorResponse)))]
pub async fn job_events(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let job = find_job(&st, &id)?;
    let rx = job.subscribe();
    let stream =
        futures_util::stream::unfold((rx, false, true), |(mut rx, done, first)| async move {
            if done || (!first && rx.changed().await.is_err()) {
                return None;
            }
            let v = rx.borrow_and_update().clone();
            let terminal = v.status.is_terminal();
            let name = if terminal { "done" } else { "progress" };
            let ev = Event::default()
                .event(name)
                .json_data(&v)
                .unwrap_or_else(|_| Event::default().event(name));
            Some((Ok::<_, Infallible>(ev), (rx, terminal, false)))
        });
    Ok(Sse::new(stream)
        .keep_alive(KeepAlive::default())
        .into_response())
}

async fn mesh_file(st: &AppState, id: &str, format: MeshFormat) -> Result<Response, ApiError> {
    let job = find_job(st, id)?;
    let view = job.view();
    if view.status != JobStatus::Succeeded {
        return Err(not_ready(&view));
    }
    let (name, ctype) = match format {
        MeshFormat::Glb(_) => ("mesh.glb", "model/gltf-binary"),
        MeshFormat::Ply => ("mesh.ply", "application/ply"),
        MeshFormat::Obj => ("mesh.obj", "model/obj"),
    };
    let path = st.jobs.store().file(view.id, name);
    if !matches!(format, MeshFormat::Glb(_)) && !path.exists() {
        let glb = st.jobs.store().file(view.id, "mesh.glb");
        let out = path.clone();
        tokio::task::spawn_blocking(move || -> Result<(), crate::io::IoError> {
            let bytes = std::fs::read(&glb).map_err(|source| crate::io::IoError::Read {
                path: glb.clone(),
                source,
            })?;
            let meta = MeshMeta {
                crs: glb_crs(&bytes),
            };
            write_mesh_with(&out, &decode_glb(&bytes)?, format, &meta)
        })
        .await
        .map_err(|e| ApiError::internal(e.to_string()))?
        .map_err(ApiError::from)?;
    }
    let file = tokio::fs::File::open(&path)
        .await
        .map_err(|e| ApiError::from_io("stored mesh unreadable", &e))?;
    let download = format!("rbfsurf-{}.{}", view.id, &name[5..]);
    send_file(file, ctype, &download).await
}

/// Streams a stored result file as an attachment named `download`.
async fn send_file(
    file: tokio::fs::File,
    ctype: &str,
    download: &str,
) -> Result<Response, ApiError> {
    let len = file
        .metadata()
        .await
        .map_err(|e| ApiError::from_io("stored mesh unreadable", &e))?
        .len();
    let disposition = format!("attachment; filename=\"{download}\"");
    let body = Body::from_stream(tokio_util::io::ReaderStream::new(file));
    Ok((
        [
            (header::CONTENT_TYPE, ctype.to_string()),
            (header::CONTENT_DISPOSITION, disposition),
            (header::CONTENT_LENGTH, len.to_string()),
        ],
        body,
    )
        .into_response())
}

fn not_ready(view: &JobView) -> ApiError {
    ApiError::new(
        StatusCode::CONFLICT,
        "not_ready",
        format!(
            "job {} is {:?}, no result to download; poll the job until it succeeds",
            view.id, view.status
        )
        .to_lowercase(),
    )
}

/// The mesh as binary glTF 2.0.
#[utoipa::path(get, path = "/v1/reconstructions/{id}/mesh.glb", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, description = "the mesh", content_type = "model/gltf-binary", body = Vec<u8>),
        (status = 404, description = "unknown id", body = ErrorResponse),
        (status = 409, description = "the job has no result (not finished, failed or cancelled)", body = ErrorResponse),
        (status = 500, description = "stored mesh unreadable (error id)", body = ErrorResponse)))]
pub async fn mesh_glb(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    mesh_file(&st, &id, MeshFormat::Glb(Default::default())).await
}

/// A simplified level of detail of the mesh, written when the job asked for `lods` (level 1: about a
/// quarter of the mesh's triangles, each further level a quarter of the previous one's; the
/// simplification error is in the file's `asset.extras.lod`). The viewer streams them coarse to
/// fine before the full mesh.
#[utoipa::path(get, path = "/v1/reconstructions/{id}/lods/{level}", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)"),
        ("level" = u32, Path, description = "level of detail, 1 (finest) to the job's `lods` (at most 8)")),
    responses((status = 200, description = "the simplified mesh (GLB stored as the job's glb-compression says)", content_type = "model/gltf-binary", body = Vec<u8>),
        (status = 404, description = "unknown id, or no such level (the job asked for fewer lods)", body = ErrorResponse),
        (status = 409, description = "the job has no result (not finished, failed or cancelled)", body = ErrorResponse),
        (status = 500, description = "stored mesh unreadable (error id)", body = ErrorResponse)))]
pub async fn mesh_lod(
    State(st): State<AppState>,
    Path((id, level)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let job = find_job(&st, &id)?;
    let view = job.view();
    if view.status != JobStatus::Succeeded {
        return Err(not_ready(&view));
    }
    let no_level = || {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "no_lod",
            format!(
                "job {} has no level of detail {level:?}; submit with lods=N (1..=8) to get levels 1..=N",
                view.id
            ),
        )
    };
    let k: usize = (level.parse().ok())
        .filter(|k| (1..=8).contains(k))
        .ok_or_else(no_level)?;
    let path = crate::io::lod_path(&st.jobs.store().file(view.id, "mesh.glb"), k);
    let file = tokio::fs::File::open(&path).await.map_err(|_| no_level())?;
    let download = format!("rbfsurf-{}.lod{k}.glb", view.id);
    send_file(file, "model/gltf-binary", &download).await
}

/// The mesh as binary PLY (converted on first request).
#[utoipa::path(get, path = "/v1/reconstructions/{id}/mesh.ply", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, description = "the mesh", content_type = "application/ply", body = Vec<u8>),
        (status = 404, description = "unknown id", body = ErrorResponse),
        (status = 409, description = "the job has no result (not finished, failed or cancelled)", body = ErrorResponse),
        (status = 500, description = "conversion failed (error id)", body = ErrorResponse),
        (status = 507, description = "no storage for the converted file", body = ErrorResponse)))]
pub async fn mesh_ply(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    mesh_file(&st, &id, MeshFormat::Ply).await
}

/// The mesh as Wavefront OBJ (converted on first request).
#[utoipa::path(get, path = "/v1/reconstructions/{id}/mesh.obj", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, description = "the mesh", content_type = "model/obj", body = String),
        (status = 404, description = "unknown id", body = ErrorResponse),
        (status = 409, description = "the job has no result (not finished, failed or cancelled)", body = ErrorResponse),
        (status = 500, description = "conversion failed (error id)", body = ErrorResponse),
        (status = 507, description = "no storage for the converted file", body = ErrorResponse)))]
pub async fn mesh_obj(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    mesh_file(&st, &id, MeshFormat::Obj).await
}

/// The fitted implicit function in the `.field` format (docs/volume-modelling.md): the operand of
/// `rbfsurf csg`, `morph` and `voxelize`. CSRBF jobs only (404 `no_field` for the global methods).
#[utoipa::path(get, path = "/v1/reconstructions/{id}/field", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, content_type = "application/octet-stream", body = Vec<u8>),
        (status = 404, body = ErrorResponse), (status = 409, body = ErrorResponse)))]
pub async fn job_field(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let job = find_job(&st, &id)?;
    let view = job.view();
    if view.status != JobStatus::Succeeded {
        return Err(not_ready(&view));
    }
    let path = st.jobs.store().file(view.id, "fitted.field");
    let Ok(file) = tokio::fs::File::open(&path).await else {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "no_field",
            format!(
                "job {} has no saved field (only the csrbf method saves one)",
                view.id
            ),
        ));
    };
    let len = file
        .metadata()
        .await
        .map_err(|e| ApiError::internal(format!("stored field unreadable: {e}")))?
        .len();
    let disposition = format!("attachment; filename=\"rbfsurf-{}.field\"", view.id);
    let body = Body::from_stream(tokio_util::io::ReaderStream::new(file));
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_string()),
            (header::CONTENT_DISPOSITION, disposition),
            (header::CONTENT_LENGTH, len.to_string()),
        ],
        body,
    )
        .into_response())
}

/// The reconstruction report (JSON contract: docs/report.md).
#[utoipa::path(get, path = "/v1/reconstructions/{id}/report", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, description = "the report", body = Object),
        (status = 404, description = "unknown id", body = ErrorResponse),
        (status = 409, description = "the job has no report (not finished, failed or cancelled)", body = ErrorResponse)))]
pub async fn job_report(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let job = find_job(&st, &id)?;
    let view = job.view();
    match load_report(&st, &view).await {
        Some(r) => Ok(Json(r).into_response()),
        None => Err(not_ready(&view)),
    }
}

/// Cancel a queued or running job (202 + the job), or delete a finished one and its files (204).
#[utoipa::path(delete, path = "/v1/reconstructions/{id}", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 202, description = "cancellation requested", body = JobResponse),
        (status = 204, description = "deleted"),
        (status = 401, description = "missing or wrong bearer token", body = ErrorResponse),
        (status = 404, description = "unknown id", body = ErrorResponse),
        (status = 500, description = "the files could not be deleted (error id)", body = ErrorResponse)),
    security((), ("bearer" = [])))]
pub async fn delete_job(
    State(st): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    authorize(st.jobs.config().token.as_deref(), &headers)?;
    let job = find_job(&st, &id)?;
    if st.jobs.cancel(&job) {
        tracing::info!(id = %job.id, "cancel requested");
        return Ok((StatusCode::ACCEPTED, Json(job_response(job.view(), None))).into_response());
    }
    let jobs = st.jobs.clone();
    let jid = job.id;
    tokio::task::spawn_blocking(move || jobs.delete(jid))
        .await
        .map_err(|e| ApiError::internal(e.to_string()))?
        .map_err(|e| ApiError::from_io("cannot delete the job's files", &e))?;
    tracing::info!(id = %jid, "job deleted");
    Ok(StatusCode::NO_CONTENT.into_response())
}
