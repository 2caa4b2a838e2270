//! On-disk layout of the job store: one directory per job under the data directory, named by the
//! job's UUID (the only request-derived value that ever becomes part of a path):
//! `input.<ext>`, `params.json` (the reconstruction options), `status.json` (the job view),
//! `report.json` and `mesh.glb` (plus `mesh.ply` / `mesh.obj` converted on first download).
//! Every file is written atomically (temporary file + rename), so a crash leaves either the old or
//! the new version. Scanning is O(jobs).

use super::model::{JobStatus, JobView};
use crate::io::{IoError, PointFormat, write_atomic};
use crate::params::ReconOptions;
use std::path::{Path, PathBuf};
use uuid::Uuid;

/// File extension used for a stored input of this format.
pub fn input_ext(format: PointFormat) -> &'static str {
    match format {
        PointFormat::Ply => "ply",
        PointFormat::Xyz => "xyz",
        PointFormat::Pts => "pts",
        PointFormat::Csv => "csv",
        PointFormat::Obj => "obj",
        PointFormat::Las => "las",
        PointFormat::E57 => "e57",
    }
}

/// The job store rooted at the data directory.
#[derive(Debug, Clone)]
pub struct Store {
    root: PathBuf,
}

impl Store {
    /// Opens (creating if needed) the data directory.
    pub fn open(root: &Path) -> std::io::Result<Store> {
        std::fs::create_dir_all(root)?;
        Ok(Store {
            root: root.to_path_buf(),
        })
    }

    /// Directory of job `id` (a UUID, so no path tricks are possible).
    pub fn dir(&self, id: Uuid) -> PathBuf {
        self.root.join(id.hyphenated().to_string())
    }

    /// Path of a named file of job `id`.
    pub fn file(&self, id: Uuid, name: &str) -> PathBuf {
        self.dir(id).join(name)
    }

    /// Creates the job directory and writes the input, the options and the first status.
    pub fn create(
        &self,
        view: &JobView,
        input: &[u8],
        options: &ReconOptions,
    ) -> Result<(), IoError> {
        let dir = self.dir(view.id);
        std::fs::create_dir_all(&dir).map_err(|source| IoError::Write {
            path: dir.clone(),
            source,
        })?;
        write_atomic(&dir.join(&view.input.file), input)?;
        write_atomic(&dir.join("params.json"), &to_json(options))?;
        self.save_status(view)
    }

    /// Rewrites `status.json`.
    pub fn save_status(&self, view: &JobView) -> Result<(), IoError> {
        write_atomic(&self.file(view.id, "status.json"), &to_json(view))
    }

    /// Reads the stored options of job `id`.
    pub fn load_options(&self, id: Uuid) -> Result<ReconOptions, String> {
        let path = self.file(id, "params.json");
        let bytes = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        serde_json::from_slice(&bytes).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Removes every file of job `id`.
    pub fn remove(&self, id: Uuid) -> std::io::Result<()> {
        match std::fs::remove_dir_all(self.dir(id)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }

    /// Every stored job whose `status.json` parses (directories not named by a UUID are ignored,
    /// unreadable ones are logged and skipped).
    pub fn scan(&self) -> std::io::Result<Vec<JobView>> {
        let mut out = Vec::new();
        for entry in std::fs::read_dir(&self.root)? {
            let entry = entry?;
            let name = entry.file_name();
            let Some(id) = name.to_str().and_then(|s| Uuid::parse_str(s).ok()) else {
                continue;
            };
            let path = self.file(id, "status.json");
            match std::fs::read(&path)
                .map_err(|e| e.to_string())
                .and_then(|b| serde_json::from_slice::<JobView>(&b).map_err(|e| e.to_string()))
            {
                Ok(v) if v.id == id => out.push(v),
                Ok(_) => {
                    tracing::warn!(path = %path.display(), "status.json names another job; skipped")
                }
                Err(e) => {
                    tracing::warn!(path = %path.display(), error = %e, "unreadable job status; skipped")
                }
            }
        }
        out.sort_by_key(|v| (v.created_at, v.id));
        Ok(out)
    }
}

fn to_json<T: serde::Serialize>(v: &T) -> Vec<u8> {
    serde_json::to_vec_pretty(v)
        .unwrap_or_else(|e| format!("{{\"serialize_error\":\"{e}\"}}").into_bytes())
}

/// True when a stored job must be handled at start-up (it never finished).
pub fn unfinished(status: JobStatus) -> bool {
    matches!(status, JobStatus::Queued | JobStatus::Running)
}
