//! Receiving an upload: the media type, the body (bounded in size, in idle time and in rate, so a
//! stalled or trickling client cannot hold a receive slot), multipart parts, and the parse plus
//! feasibility check on the blocking pool (linear time; the degeneracy checks run in the job).

use super::Pairs;
use crate::io::{PointFormat, ReadLimits, parse_point_cloud};
use crate::job::ServerConfig;
use crate::server::AppState;
use crate::server::error::ApiError;
use axum::body::Body;
use axum::extract::{FromRequest, Multipart, Request};
use axum::http::{HeaderMap, StatusCode, header};
use futures_util::StreamExt;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// How the upload's bytes are to be read.
pub enum BodyKind {
    /// A raw point file of this format (`None`: sniff the content).
    Raw(Option<PointFormat>),
    /// `multipart/form-data` with a `file` part and parameter fields.
    Multipart,
}

/// The body kind from `Content-Type` (415 for anything that is not a point format or multipart).
pub fn classify(headers: &HeaderMap) -> Result<BodyKind, ApiError> {
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

/// 413 for an upload over `limit` bytes.
pub fn too_large(limit: u64) -> ApiError {
    ApiError::too_large(format!(
        "the upload is larger than this server's limit of {limit} bytes; subsample the cloud or ask for a larger --max-upload-mib"
    ))
}

/// Why a guarded body stopped early (set by the guard, read by the handler).
pub type Stall = Arc<Mutex<Option<ApiError>>>;

/// Wraps a request body so that it fails when no byte arrives for `cfg.idle_timeout`, or when,
/// after that grace period, fewer than `cfg.min_upload_rate` bytes per second arrived on average
/// since the body started. The reason is left in the returned [`Stall`] (408 `upload_too_slow`).
pub fn guard_body(body: Body, cfg: &ServerConfig) -> (Body, Stall) {
    let stall: Stall = Arc::new(Mutex::new(None));
    let (idle, rate) = (cfg.idle_timeout, cfg.min_upload_rate);
    let start = Instant::now();
    let state = (body.into_data_stream(), 0u64, stall.clone());
    let stream = futures_util::stream::unfold(state, move |(mut s, seen, stall)| async move {
        let fail = |msg: String| -> std::io::Error {
            let e = ApiError::new(StatusCode::REQUEST_TIMEOUT, "upload_too_slow", msg.clone());
            *stall.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
            std::io::Error::new(std::io::ErrorKind::TimedOut, msg)
        };
        match tokio::time::timeout(idle, s.next()).await {
            Err(_) => Some((
                Err(fail(format!(
                    "no byte of the body arrived for {} s; the connection is closed (send the whole file at once)",
                    idle.as_secs()
                ))),
                (s, seen, stall),
            )),
            Ok(None) => None,
            Ok(Some(Err(e))) => Some((Err(std::io::Error::other(e)), (s, seen, stall))),
            Ok(Some(Ok(chunk))) => {
                let seen = seen + chunk.len() as u64;
                let secs = start.elapsed().as_secs_f64();
                if secs > idle.as_secs_f64() && (seen as f64) < rate as f64 * secs {
                    let msg = format!(
                        "the body arrives at {:.0} bytes/s, below this server's minimum of {rate} bytes/s; send it faster",
                        seen as f64 / secs
                    );
                    return Some((Err(fail(msg)), (s, seen, stall)));
                }
                Some((Ok(chunk), (s, seen, stall)))
            }
        }
    });
    (Body::from_stream(stream), stall)
}

fn stalled(stall: &Stall) -> Option<ApiError> {
    stall.lock().unwrap_or_else(|p| p.into_inner()).take()
}

/// Reads the raw body, stopping with 413 as soon as it exceeds `limit` bytes (408 when the guard
/// stopped it, 400 when the client broke off).
pub async fn read_limited(body: Body, limit: u64, stall: &Stall) -> Result<Vec<u8>, ApiError> {
    let mut stream = body.into_data_stream();
    let mut buf = Vec::new();
    while let Some(chunk) = stream.next().await {
        let chunk = chunk.map_err(|e| {
            stalled(stall).unwrap_or_else(|| {
                ApiError::new(
                    StatusCode::BAD_REQUEST,
                    "incomplete_body",
                    format!(
                        "the request body could not be read completely ({e}); send the whole file again"
                    ),
                )
            })
        })?;
        if (buf.len() + chunk.len()) as u64 > limit {
            return Err(too_large(limit));
        }
        buf.extend_from_slice(&chunk);
    }
    Ok(buf)
}

/// The file part (bytes, format hint) and the text fields of a multipart upload: exactly one
/// file part (400 `bad_multipart` for none or two), fields added to `pairs`.
pub async fn read_multipart(
    req: Request,
    st: &AppState,
    pairs: &mut Pairs,
    stall: &Stall,
) -> Result<(Vec<u8>, Option<PointFormat>), ApiError> {
    let limit = st.jobs.config().max_upload_bytes;
    let mp_err = |e: axum::extract::multipart::MultipartError| {
        if let Some(e) = stalled(stall) {
            return e;
        }
        match e.status() {
            StatusCode::PAYLOAD_TOO_LARGE => too_large(limit),
            _ => ApiError::new(
                StatusCode::BAD_REQUEST,
                "bad_multipart",
                format!("malformed multipart body: {}", e.body_text()),
            ),
        }
    };
    let mut mp = Multipart::from_request(req, st).await.map_err(|e| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            "bad_multipart",
            format!("{} (multipart/form-data needs a boundary)", e.body_text()),
        )
    })?;
    let mut file = None;
    while let Some(field) = mp.next_field().await.map_err(mp_err)? {
        let name = field.name().unwrap_or("").to_string();
        if name == "file" || field.file_name().is_some() {
            if file.is_some() {
                return Err(ApiError::new(
                    StatusCode::BAD_REQUEST,
                    "bad_multipart",
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
    file.ok_or_else(|| {
        ApiError::new(
            StatusCode::BAD_REQUEST,
            "bad_multipart",
            "multipart upload without a `file` part; send the point file as a part named `file`",
        )
    })
}

/// Parses the points (linear time, on the blocking pool) and checks that the job is feasible
/// within its limits ([`crate::server::feasibility`]). Cleaning and the degeneracy checks run in
/// the job, under its time limit and cancel.
pub async fn check_cloud(
    st: &AppState,
    bytes: Vec<u8>,
    hint: Option<PointFormat>,
    params: &crate::ReconParams,
) -> Result<(Vec<u8>, PointFormat, usize, crate::job::InputAttributes), ApiError> {
    let cfg = st.jobs.config();
    let limits = ReadLimits {
        max_points: cfg.max_points,
        max_bytes: cfg.max_upload_bytes,
        max_memory_mib: params.max_memory_mib,
    };
    let params = params.clone();
    // A NATS-backed node runs a job over the in-memory budget as the out-of-core task graph.
    let graph = st.jobs.is_remote();
    tokio::task::spawn_blocking(move || {
        let format = match hint {
            Some(PointFormat::Xyz) | None => PointFormat::sniff(&bytes)
                .ok_or_else(|| unsupported("binary content that is not PLY, LAS/LAZ or E57"))?,
            Some(f) => f,
        };
        let cloud = parse_point_cloud(&bytes, format, &limits)?;
        let n = cloud.points.len() as u64;
        let out_of_core = || {
            matches!(
                crate::pipeline::plan_execution(n, &params),
                Ok(crate::pipeline::Execution::OutOfCore(_))
            )
        };
        match crate::server::feasibility::check_cloud(&cloud, &params) {
            Err(_) if graph && out_of_core() => {}
            r => r?,
        }
        let attributes = crate::job::InputAttributes::of(&cloud);
        Ok((bytes, format, cloud.points.len(), attributes))
    })
    .await
    .map_err(|e| ApiError::internal(format!("upload check failed: {e}")))?
}
