//! The API's one error type: an HTTP status plus a stable machine-readable `code` and a message
//! that tells the caller what to do. Rendered as `{"error": {"code": "...", "message": "..."}}`.

use crate::error::ErrorKind;
use crate::job::SubmitError;
use crate::job::error::{ErrorBody, internal_body, io_storage_full, storage_body, storage_full};
use axum::Json;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};

/// Envelope of every error response.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ErrorResponse {
    /// The error.
    pub error: ErrorBody,
}

/// An error answer: status, code, message and an optional `Retry-After` (seconds).
#[derive(Debug, Clone)]
pub struct ApiError {
    /// HTTP status.
    pub status: StatusCode,
    /// Body.
    pub body: ErrorBody,
    /// `Retry-After` header value in seconds (429/503).
    pub retry_after: Option<u64>,
}

impl ApiError {
    /// An error with this status, code and message.
    pub fn new(status: StatusCode, code: &str, message: impl Into<String>) -> Self {
        ApiError {
            status,
            body: ErrorBody {
                code: code.to_string(),
                message: message.into(),
            },
            retry_after: None,
        }
    }

    /// 400 `bad_parameter`.
    pub fn bad_parameter(message: impl Into<String>) -> Self {
        Self::new(StatusCode::BAD_REQUEST, "bad_parameter", message)
    }

    /// 404 `not_found` for a job id.
    pub fn not_found(what: &str) -> Self {
        Self::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!(
                "{what} not found; it may have expired or been deleted (list ids from the POST answers)"
            ),
        )
    }

    /// 413 `too_large`.
    pub fn too_large(message: impl Into<String>) -> Self {
        Self::new(StatusCode::PAYLOAD_TOO_LARGE, "too_large", message)
    }

    /// 500 `internal`: the detail (which may name server paths) goes to the server log under a
    /// fresh error id; the client gets a generic message with that id.
    pub fn internal(detail: impl Into<String>) -> Self {
        let body = internal_body(&detail.into());
        Self::new(StatusCode::INTERNAL_SERVER_ERROR, &body.code, body.message)
    }

    /// 507 `insufficient_storage` (the data directory's disk or quota is full); the detail is
    /// logged under an error id, as for [`ApiError::internal`].
    pub fn insufficient_storage(detail: impl Into<String>) -> Self {
        let body = storage_body(&detail.into());
        Self::new(StatusCode::INSUFFICIENT_STORAGE, &body.code, body.message).retry_after(60)
    }

    /// A file-system failure of the server: 507 when the disk is full, else 500.
    pub fn from_io(context: &str, e: &std::io::Error) -> Self {
        if storage_full(e) {
            Self::insufficient_storage(format!("{context}: {e}"))
        } else {
            Self::internal(format!("{context}: {e}"))
        }
    }

    /// Adds `Retry-After: secs`.
    pub fn retry_after(mut self, secs: u64) -> Self {
        self.retry_after = Some(secs);
        self
    }
}

impl std::fmt::Display for ApiError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}: {}",
            self.status, self.body.code, self.body.message
        )
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let mut resp = (
            self.status,
            Json(ErrorResponse {
                error: self.body.clone(),
            }),
        )
            .into_response();
        if self.status == StatusCode::UNAUTHORIZED {
            resp.headers_mut()
                .insert(header::WWW_AUTHENTICATE, HeaderValue::from_static("Bearer"));
        }
        if let Some(s) = self.retry_after {
            resp.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        resp
    }
}

/// The HTTP status of a stored job's error code (the answer of `POST ?wait` for a failed job):
/// 4xx for the input, the parameters and the limits (`job_timeout` is 422 like any other limit),
/// 409 cancelled, 507 a full disk, 500 the server's fault (`internal`, `reconstruction_failed`,
/// `interrupted` and unknown codes).
pub fn status_of_code(code: &str) -> StatusCode {
    match code {
        "job_timeout" => StatusCode::UNPROCESSABLE_ENTITY,
        "insufficient_storage" => StatusCode::INSUFFICIENT_STORAGE,
        _ => ErrorKind::from_code(code).map_or(StatusCode::INTERNAL_SERVER_ERROR, status_of),
    }
}

/// The HTTP status of a failure of this kind: 400 parameters, 415 format, 413 size, 422 data that
/// cannot be reconstructed or would not fit the budget, 409 cancelled, 500 the machine's fault.
pub fn status_of(kind: ErrorKind) -> StatusCode {
    match kind {
        ErrorKind::BadParameter => StatusCode::BAD_REQUEST,
        ErrorKind::UnsupportedFormat => StatusCode::UNSUPPORTED_MEDIA_TYPE,
        ErrorKind::TooLarge => StatusCode::PAYLOAD_TOO_LARGE,
        ErrorKind::InvalidInput | ErrorKind::Unreconstructable | ErrorKind::OverBudget => {
            StatusCode::UNPROCESSABLE_ENTITY
        }
        ErrorKind::Cancelled => StatusCode::CONFLICT,
        ErrorKind::Internal => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

impl From<crate::io::IoError> for ApiError {
    /// Reader errors: unknown format → 415, over a limit → 413, over the memory budget → 422
    /// `system_too_large`, anything else about the bytes → 422; open/read failures → 500.
    fn from(e: crate::io::IoError) -> Self {
        match e.kind() {
            ErrorKind::Internal if io_storage_full(&e) => {
                ApiError::insufficient_storage(e.to_string())
            }
            ErrorKind::Internal => ApiError::internal(e.to_string()),
            kind => ApiError::new(status_of(kind), kind.code(), e.to_string()),
        }
    }
}

impl From<crate::params::ParamError> for ApiError {
    fn from(e: crate::params::ParamError) -> Self {
        ApiError::bad_parameter(e.to_string())
    }
}

impl From<crate::clean::InputError> for ApiError {
    fn from(e: crate::clean::InputError) -> Self {
        ApiError::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "unreconstructable",
            e.to_string(),
        )
    }
}

impl From<SubmitError> for ApiError {
    fn from(e: SubmitError) -> Self {
        match e {
            SubmitError::QueueFull => ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                "queue_full",
                "the job queue is full; retry after the Retry-After delay",
            )
            .retry_after(5),
            SubmitError::ShuttingDown => ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "shutting_down",
                "the server is shutting down; retry against the restarted server",
            )
            .retry_after(10),
            SubmitError::Storage(e) => ApiError::from(e),
            SubmitError::Backend(detail) => {
                tracing::error!(%detail, "the job store did not take the job");
                ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "job_store_unavailable",
                    "the job store is unavailable; retry after the Retry-After delay",
                )
                .retry_after(5)
            }
        }
    }
}
