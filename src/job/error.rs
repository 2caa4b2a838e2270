//! The error of a job as stored and shown: a stable machine-readable `code` and a message that
//! tells the caller what to do. The HTTP layer renders it as `{"error": {"code": "...",
//! "message": "..."}}`; the job record keeps it as the job's `error`.

use serde::{Deserialize, Serialize};

/// The JSON error object (`error` member of every error response, and of a failed job).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ErrorBody {
    /// Stable identifier: `bad_parameter`, `bad_multipart`, `incomplete_body`, `upload_too_slow`,
    /// `unauthorized`, `not_found`, `not_ready`, `method_not_allowed`, `too_large`,
    /// `unsupported_media_type`, `invalid_input`, `unreconstructable`, `system_too_large`,
    /// `conflicting_parameters`, `unsuitable_parameter`, `invalid_expression`,
    /// `queue_full`, `busy`, `shutting_down`, `job_store_unavailable`, `job_timeout`,
    /// `interrupted`, `cancelled`, `reconstruction_failed`, `insufficient_storage`, `no_lod`,
    /// `no_field`, `internal`.
    pub code: String,
    /// Human-readable explanation with a hint.
    pub message: String,
}

/// A short random id that ties a client's error to the server log line with the details.
pub fn error_id() -> String {
    uuid::Uuid::new_v4().simple().to_string()[..12].to_string()
}

/// Logs `detail` under a new error id and returns the generic `internal` body naming that id.
pub fn internal_body(detail: &str) -> ErrorBody {
    let id = error_id();
    tracing::error!(error_id = %id, %detail, "internal error");
    ErrorBody {
        code: "internal".into(),
        message: format!(
            "internal server error (error id {id}; the operator finds the details in the server log)"
        ),
    }
}

/// Logs `detail` under a new error id and returns the `insufficient_storage` body.
pub fn storage_body(detail: &str) -> ErrorBody {
    let id = error_id();
    tracing::error!(error_id = %id, %detail, "storage full");
    ErrorBody {
        code: "insufficient_storage".into(),
        message: format!(
            "the server's storage is full; retry later or ask the operator to free space (error id {id})"
        ),
    }
}

/// True for "no space left on device" and "disk quota exceeded".
pub fn storage_full(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded
    ) || matches!(e.raw_os_error(), Some(28 | 122))
}

/// True when a library I/O error is the disk being full.
pub fn io_storage_full(e: &crate::io::IoError) -> bool {
    use crate::io::IoError as E;
    match e {
        E::Write { source, .. } | E::Read { source, .. } | E::Open { source, .. } => {
            storage_full(source)
        }
        _ => false,
    }
}
