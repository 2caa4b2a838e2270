//! The job API under `/v1/reconstructions`: upload (raw body or multipart), list, status (with
//! `?wait`), server-sent events, mesh download (glb/ply/obj), report, cancel/delete.
//! Uploads are bounded before they are read (Content-Length) and while they are read (streamed
//! count); parsing and the degenerate-input check run on the blocking pool before a job is queued.

use super::{
    JobResponse, Pairs, WaitQuery, authorize, find_job, job_response, parse_params, query_pairs,
};
use crate::error::ErrorKind;
use crate::io::{
    MeshFormat, MeshMeta, PointFormat, ReadLimits, decode_glb, glb_crs, parse_point_cloud,
    write_mesh_with,
};
use crate::server::AppState;
use crate::server::error::{ApiError, ErrorBody, ErrorResponse};
use crate::server::jobs::{InputInfo, Job, JobStatus, JobView};
use crate::server::store::input_ext;
use axum::Json;
use axum::body::Body;
use axum::extract::{FromRequest, Multipart, Path, RawQuery, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::StreamExt;
use std::convert::Infallible;
use std::time::Duration;

/// How long an upload waits for a free receive slot before it is answered 429.
const UPLOAD_SLOT_WAIT: Duration = Duration::from_secs(30);

/// How the upload's bytes are to be read.
enum BodyKind {
    /// A raw point file of this format (`None`: sniff the content).
    Raw(Option<PointFormat>),
    /// `multipart/form-data` with a `file` part and parameter fields.
    Multipart,
}

fn classify(headers: &HeaderMap) -> Result<BodyKind, ApiError> {
    let Some(ct) = headers.get(header::CONTENT_TYPE) else {
        return Ok(BodyKind::Raw(None));
    };
    let essence = ct
        .to_str()
        .unwrap_or("")
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    match format_for_media_type(&essence) {
        Some(kind) => Ok(kind),
        None => Err(unsupported(&format!(
            "Content-Type {essence:?} is not a point format"
        ))),
    }
}

fn format_for_media_type(essence: &str) -> Option<BodyKind> {
    Some(match essence {
        "application/ply" | "application/x-ply" | "model/ply" | "model/x-ply" => {
            BodyKind::Raw(Some(PointFormat::Ply))
        }
        "text/csv" => BodyKind::Raw(Some(PointFormat::Csv)),
        "model/obj" | "text/x-obj" => BodyKind::Raw(Some(PointFormat::Obj)),
        "application/vnd.las" | "application/vnd.laszip" => BodyKind::Raw(Some(PointFormat::Las)),
        "text/plain" | "text/x-xyz" | "application/octet-stream" | "" => BodyKind::Raw(None),
        "multipart/form-data" => BodyKind::Multipart,
        _ => return None,
    })
}

fn unsupported(what: &str) -> ApiError {
    ApiError::new(
        StatusCode::UNSUPPORTED_MEDIA_TYPE,
        "unsupported_media_type",
        format!(
            "{what}; send PLY (application/ply), XYZ/PTS text (text/plain), CSV (text/csv), OBJ (model/obj), LAS (application/vnd.las), LAZ (application/vnd.laszip), application/octet-stream (sniffed by magic bytes: PLY, LAS/LAZ, E57, text) or multipart/form-data with a `file` part"
        ),
    )
}

fn too_large(limit: u64) -> ApiError {
    ApiError::too_large(format!(
        "the upload is larger than this server's limit of {limit} bytes; subsample the cloud or ask for a larger --max-upload-mib"
    ))
}

/// Reads the raw body, stopping with 413 as soon as it exceeds `limit` bytes.
async fn read_limited(body: Body, limit: u64) -> Result<Vec<u8>, ApiError> {
    let mut stream = body.into_data_stream();
    let mut buf = Vec::new();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| {
            ApiError::new(
                StatusCode::BAD_REQUEST,
                "incomplete_body",
                format!(
                    "the request body could not be read completely ({e}); send the whole file again"
                ),
            )
        })?;
        if (buf.len() + chunk.len()) as u64 > limit {
            return Err(too_large(limit));
        }
        buf.extend_from_slice(&chunk);
    }
    Ok(buf)
}

/// The file part (bytes, format hint) and the text fields of a multipart upload.
async fn read_multipart(
    req: Request,
    st: &AppState,
    pairs: &mut Pairs,
) -> Result<(Vec<u8>, Option<PointFormat>), ApiError> {
    let limit = st.jobs.config().max_upload_bytes;
    let mp_err = |e: axum::extract::multipart::MultipartError| match e.status() {
        StatusCode::PAYLOAD_TOO_LARGE => too_large(limit),
        s => ApiError::new(
            s,
            "bad_multipart",
            format!("malformed multipart body: {}", e.body_text()),
        ),
    };
    let mut mp = Multipart::from_request(req, st)
        .await
        .map_err(|e| ApiError::new(e.status(), "bad_multipart", e.body_text()))?;
    let mut file = None;
    while let Some(field) = mp.next_field().await.map_err(mp_err)? {
        let name = field.name().unwrap_or("").to_string();
        if name == "file" || field.file_name().is_some() {
            if file.is_some() {
                return Err(ApiError::bad_parameter(
                    "more than one file part; send one point file per job",
                ));
            }
            let hint = field
                .file_name()
                .and_then(|n| PointFormat::from_path(std::path::Path::new(n)))
                .or_else(|| match field.content_type().map(format_for_media_type) {
                    Some(Some(BodyKind::Raw(f))) => f,
                    _ => None,
                });
            let bytes = field.bytes().await.map_err(mp_err)?;
            if bytes.len() as u64 > limit {
                return Err(too_large(limit));
            }
            file = Some((bytes.to_vec(), hint));
        } else {
            let value = field.text().await.map_err(mp_err)?;
            if !value.is_empty() {
                pairs.push((name, value));
            }
        }
    }
    file.ok_or_else(|| ApiError::bad_parameter("multipart upload without a `file` part"))
}

/// Parses the points and refuses degenerate clouds (422) before anything is stored.
async fn check_cloud(
    st: &AppState,
    bytes: Vec<u8>,
    hint: Option<PointFormat>,
    params: &crate::ReconParams,
) -> Result<(Vec<u8>, PointFormat, usize), ApiError> {
    let cfg = st.jobs.config();
    let limits = ReadLimits {
        max_points: cfg.max_points,
        max_bytes: cfg.max_upload_bytes,
        max_memory_mib: params.max_memory_mib,
    };
    let clean = params.clean;
    tokio::task::spawn_blocking(move || {
        let format = match hint {
            Some(PointFormat::Xyz) | None => PointFormat::sniff(&bytes)
                .ok_or_else(|| unsupported("binary content that is not PLY, LAS/LAZ or E57"))?,
            Some(f) => f,
        };
        let cloud = parse_point_cloud(&bytes, format, &limits)?;
        crate::clean::clean_cloud(&cloud, &clean)?;
        Ok((bytes, format, cloud.points.len()))
    })
    .await
    .map_err(|e| ApiError::internal(format!("upload check failed: {e}")))?
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
            (Vec<u8> = "application/ply"), (String = "text/plain"), (String = "text/csv"),
            (String = "model/obj"), (Vec<u8> = "application/vnd.las"), (Vec<u8> = "application/vnd.laszip"),
            (Vec<u8> = "application/octet-stream"), (Vec<u8> = "multipart/form-data"))),
    responses(
        (status = 202, description = "accepted and queued", body = JobResponse),
        (status = 200, description = "finished within `wait`", body = JobResponse),
        (status = 400, description = "bad parameter or incomplete body", body = ErrorResponse),
        (status = 401, description = "missing or wrong bearer token", body = ErrorResponse),
        (status = 413, description = "upload or point count over the limit", body = ErrorResponse),
        (status = 415, description = "unknown format", body = ErrorResponse),
        (status = 422, description = "parses but cannot be reconstructed", body = ErrorResponse),
        (status = 429, description = "queue full, or too many uploads at once (see Retry-After)", body = ErrorResponse),
        (status = 503, description = "shutting down", body = ErrorResponse)),
    security((), ("bearer" = [])))]
pub async fn create_job(
    State(st): State<AppState>,
    RawQuery(raw): RawQuery,
    req: Request,
) -> Result<Response, ApiError> {
    let cfg = st.jobs.config();
    authorize(cfg.token.as_deref(), req.headers())?;
    if st.jobs.is_shutting_down() {
        return Err(crate::server::jobs::SubmitError::ShuttingDown.into());
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
    parse_params(&pairs)?;
    let kind = classify(req.headers())?;
    if !st.jobs.has_room() {
        return Err(crate::server::jobs::SubmitError::QueueFull.into());
    }
    // At most a few uploads are buffered and parsed at once; others wait briefly, then get 429.
    let permit = tokio::time::timeout(UPLOAD_SLOT_WAIT, st.uploads.clone().acquire_owned())
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
    let (bytes, hint) = match kind {
        BodyKind::Raw(hint) => (
            read_limited(req.into_body(), cfg.max_upload_bytes).await?,
            hint,
        ),
        BodyKind::Multipart => read_multipart(req, &st, &mut pairs).await?,
    };
    let (options, params, wait) = parse_params(&pairs)?;
    let size = bytes.len() as u64;
    let (bytes, format, points) = check_cloud(&st, bytes, hint, &params).await?;
    let info = InputInfo {
        format: format.name().to_string(),
        file: format!("input.{}", input_ext(format)),
        bytes: size,
        points,
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
        // Failures the job record names by a stage's code (timeouts, interruptions, storage) are 500s.
        let status = ErrorKind::from_code(&err.code).map_or(
            StatusCode::INTERNAL_SERVER_ERROR,
            crate::server::error::status_of,
        );
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
#[utoipa::path(get, path = "/v1/reconstructions", tag = "reconstructions",
    responses((status = 200, description = "all jobs", body = Vec<JobView>)))]
pub async fn list_jobs(State(st): State<AppState>) -> Json<Vec<JobView>> {
    Json(st.jobs.list())
}

/// Job status, progress (stage + fraction), error, and the report once it succeeded.
#[utoipa::path(get, path = "/v1/reconstructions/{id}", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)"), WaitQuery),
    responses((status = 200, body = JobResponse), (status = 400, body = ErrorResponse),
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
    responses((status = 200, description = "text/event-stream of JobView JSON", content_type = "text/event-stream", body = String),
        (status = 404, body = ErrorResponse)))]
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
        MeshFormat::Glb => ("mesh.glb", "model/gltf-binary"),
        MeshFormat::Ply => ("mesh.ply", "application/ply"),
        MeshFormat::Obj => ("mesh.obj", "model/obj"),
    };
    let path = st.jobs.store().file(view.id, name);
    if format != MeshFormat::Glb && !path.exists() {
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
        .map_err(|e| ApiError::internal(e.to_string()))?;
    }
    let file = tokio::fs::File::open(&path)
        .await
        .map_err(|e| ApiError::internal(format!("stored mesh unreadable: {e}")))?;
    let len = file
        .metadata()
        .await
        .map_err(|e| ApiError::internal(format!("stored mesh unreadable: {e}")))?
        .len();
    let disposition = format!(
        "attachment; filename=\"rbfsurf-{}.{}\"",
        view.id,
        &name[5..]
    );
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
    responses((status = 200, content_type = "model/gltf-binary", body = Vec<u8>),
        (status = 404, body = ErrorResponse), (status = 409, description = "not finished", body = ErrorResponse)))]
pub async fn mesh_glb(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    mesh_file(&st, &id, MeshFormat::Glb).await
}

/// The mesh as binary PLY (converted on first request).
#[utoipa::path(get, path = "/v1/reconstructions/{id}/mesh.ply", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, content_type = "application/ply", body = Vec<u8>),
        (status = 404, body = ErrorResponse), (status = 409, body = ErrorResponse)))]
pub async fn mesh_ply(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    mesh_file(&st, &id, MeshFormat::Ply).await
}

/// The mesh as Wavefront OBJ (converted on first request).
#[utoipa::path(get, path = "/v1/reconstructions/{id}/mesh.obj", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, content_type = "model/obj", body = String),
        (status = 404, body = ErrorResponse), (status = 409, body = ErrorResponse)))]
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

/// The reconstruction report (JSON contract of the README).
#[utoipa::path(get, path = "/v1/reconstructions/{id}/report", tag = "reconstructions",
    params(("id" = String, Path, description = "job id (UUID)")),
    responses((status = 200, body = Object), (status = 404, body = ErrorResponse), (status = 409, body = ErrorResponse)))]
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
        (status = 204, description = "deleted"), (status = 401, body = ErrorResponse), (status = 404, body = ErrorResponse)),
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
        .map_err(|e| ApiError::internal(format!("cannot delete the job's files: {e}")))?;
    tracing::info!(id = %jid, "job deleted");
    Ok(StatusCode::NO_CONTENT.into_response())
}
