//! The job record shared by the API, the store and the workers: status, progress, timestamps,
//! error, input description. Serialised as the job JSON of the API and as `status.json`.

use super::error::ErrorBody;
use serde::{Deserialize, Serialize};
use std::time::{SystemTime, UNIX_EPOCH};
use uuid::Uuid;

/// Life cycle of a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum JobStatus {
    /// Waiting for a worker.
    Queued,
    /// A worker is reconstructing it.
    Running,
    /// Finished; mesh and report are available.
    Succeeded,
    /// Finished with an error (see `error`).
    Failed,
    /// Cancelled by a DELETE.
    Cancelled,
}

impl JobStatus {
    /// True for succeeded, failed and cancelled.
    pub fn is_terminal(self) -> bool {
        !matches!(self, JobStatus::Queued | JobStatus::Running)
    }
}

/// What was uploaded.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct InputInfo {
    /// Detected point format (`PLY`, `XYZ`, `CSV`, `PTS`, `OBJ`).
    pub format: String,
    /// Stored file name inside the job directory (`input.ply`, ...).
    pub file: String,
    /// Upload size in bytes.
    pub bytes: u64,
    /// Points read (before cleaning).
    pub points: usize,
    /// What the points carry besides positions (absent for composition and morph requests).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attributes: Option<InputAttributes>,
}

/// What an input's points carry besides their positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct InputAttributes {
    /// Normals.
    pub normals: bool,
    /// RGB colours.
    pub colors: bool,
    /// Intensities.
    pub intensity: bool,
}

impl InputAttributes {
    /// The attributes of `cloud`.
    pub fn of(cloud: &crate::geometry::PointCloud) -> Self {
        InputAttributes {
            normals: cloud.normals.is_some(),
            colors: cloud.colors.is_some(),
            intensity: cloud.intensity.is_some(),
        }
    }
}

/// The state of one job as returned by the API and stored in `status.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct JobView {
    /// Job id (random UUID v4).
    pub id: Uuid,
    /// Life-cycle state.
    pub status: JobStatus,
    /// Current (or last) pipeline stage: read, clean, index, carrier, assemble, order, factor,
    /// solve, polygonize, post, write.
    pub stage: Option<String>,
    /// Overall progress estimate 0..1 (stage weights are fixed estimates).
    pub progress: f64,
    /// Progress 0..1 of the current stage.
    pub stage_progress: f64,
    /// Unix seconds when the job was accepted.
    pub created_at: u64,
    /// Unix seconds when a worker started it.
    pub started_at: Option<u64>,
    /// Unix seconds when it reached a terminal state.
    pub finished_at: Option<u64>,
    /// Why it failed (or was cancelled).
    pub error: Option<ErrorBody>,
    /// The upload.
    pub input: InputInfo,
    /// Triangles of the result (succeeded jobs).
    pub triangles: Option<usize>,
}

impl JobView {
    /// A job just accepted: a fresh id, queued, created now.
    pub fn queued(input: InputInfo) -> JobView {
        JobView {
            id: Uuid::new_v4(),
            status: JobStatus::Queued,
            stage: None,
            progress: 0.0,
            stage_progress: 0.0,
            created_at: unix_now(),
            started_at: None,
            finished_at: None,
            error: None,
            input,
            triangles: None,
        }
    }
}

/// Unix time in whole seconds.
pub fn unix_now() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

pub use crate::report::unix_now_ms;
