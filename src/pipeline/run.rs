//! Read → reconstruct → write as one stage: the single run-to-file path of the command line, the
//! HTTP service and any embedding program. It checks the scale before reading (from the header's
//! point count), reads the points, reconstructs, writes the mesh and the report atomically (a
//! temporary file renamed into place, so a failed or cancelled run leaves no partial output) and
//! fills the report's `read`, `write` and `total` timings and the peak memory, measured once here.

use crate::error::{ErrorKind, ReconError};
use crate::io::{
    IoError, MeshFormat, MeshMeta, PointFormat, ReadLimits, StreamInput, parse_point_cloud,
    peek_point_count, read_point_cloud, write_atomic, write_mesh_with,
};
use crate::params::ReconParams;
use crate::progress::{Progress, Stage};
use crate::report::{Report, peak_rss_mib};
use std::path::Path;
use std::time::Instant;

/// Where the points come from.
#[derive(Debug, Clone, Copy)]
pub enum PointSource<'a> {
    /// A point file; its format comes from its content and extension. Errors name the path.
    File(&'a Path),
    /// Points in memory (an upload) in a known format. Errors name the source `<input>`.
    Bytes {
        /// The file's bytes.
        data: &'a [u8],
        /// Their format.
        format: PointFormat,
    },
}

impl PointSource<'_> {
    /// How errors and the result line name this input.
    pub fn name(&self) -> String {
        match self {
            PointSource::File(p) => p.display().to_string(),
            PointSource::Bytes { .. } => "<input>".to_string(),
        }
    }
}

/// Where the results go.
#[derive(Clone, Copy)]
pub struct RunOutput<'a> {
    /// The mesh file.
    pub mesh: &'a Path,
    /// Its format.
    pub format: MeshFormat,
    /// The JSON report, when wanted.
    pub report: Option<&'a Path>,
    /// The fitted field in the `.field` format ([`crate::frep::format`]), when wanted (CSRBF only).
    pub field: Option<&'a Path>,
    /// The caller's own measure of this run's peak memory, MiB (a server running several jobs in
    /// one process); `None`: the process's high-water mark is the run's.
    pub job_memory_mib: Option<&'a (dyn Fn() -> f64 + Sync)>,
}

impl std::fmt::Debug for RunOutput<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunOutput")
            .field("mesh", &self.mesh)
            .field("format", &self.format)
            .field("report", &self.report)
            .field("field", &self.field)
            .field(
                "job_memory_mib",
                &self.job_memory_mib.map(|_| "caller's measure"),
            )
            .finish()
    }
}

/// What a finished run produced (the files are written).
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// The report as written (timings include reading and writing).
    pub report: Report,
    /// Triangles in the written mesh.
    pub triangles: usize,
}

/// Why a run stopped; nothing was left at the output paths.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Reading the input failed or it is over a limit.
    #[error(transparent)]
    Read(IoError),
    /// The reconstruction failed, was refused or was cancelled.
    #[error("{input}: {source}")]
    Reconstruct {
        /// The input's name.
        input: String,
        /// The stage error.
        source: ReconError,
    },
    /// Writing the mesh or the report failed.
    #[error(transparent)]
    Write(IoError),
}

impl RunError {
    /// Whose failure this is; the HTTP layer maps it to a status, the command line to its message.
    pub fn kind(&self) -> ErrorKind {
        match self {
            RunError::Read(e) => e.kind(),
            RunError::Reconstruct { source, .. } => source.kind(),
            RunError::Write(_) => ErrorKind::Internal,
        }
    }
}

/// The task graph over `source`, streamed (never read whole); a read error mid-stream is the
/// reader's own [`RunError::Read`].
fn out_of_core(
    source: PointSource<'_>,
    params: &ReconParams,
    limits: &ReadLimits,
    output: &RunOutput<'_>,
    progress: &dyn Progress,
) -> Result<super::Reconstruction, RunError> {
    use super::tiled::{TiledInput, TiledOptions, reconstruct_tiled_from};
    let recon_err = |e: ReconError| match e {
        ReconError::Read(io) => RunError::Read(io),
        e => RunError::Reconstruct {
            input: source.name(),
            source: e,
        },
    };
    if output.field.is_some() {
        return Err(recon_err(ReconError::OutOfCoreUnsupported("--save-field")));
    }
    let input = match source {
        PointSource::File(path) => StreamInput::File(path),
        PointSource::Bytes { data, format } => StreamInput::Bytes { data, format },
    };
    let input = TiledInput::Stream(input, limits);
    reconstruct_tiled_from(&input, params, &TiledOptions::default(), progress).map_err(recon_err)
}

/// Reconstruct the points of `source` with `params` under `limits` (the reader's point, byte and
/// memory limits; `params.max_memory_mib` also bounds the reconstruction) and write the mesh and
/// report to `output`. A cancellation noticed by any stage returns a [`RunError`] of kind
/// [`ErrorKind::Cancelled`] and writes nothing.
pub fn run(
    source: PointSource<'_>,
    params: &ReconParams,
    limits: &ReadLimits,
    output: &RunOutput<'_>,
    progress: &dyn Progress,
) -> Result<RunSummary, RunError> {
    run_as(source, params, limits, output, progress, Route::ByBudget)
}

/// [`run`] through the out-of-core task graph even when the cloud fits its budget in memory
/// (`rbfsurf reconstruct --out-of-core`): the plan is the one a cloud over the budget gets
/// (block size from `params.max_memory_mib`), so the mesh is what the distributed executor
/// makes of a job it splits over idle workers.
pub fn run_out_of_core(
    source: PointSource<'_>,
    params: &ReconParams,
    limits: &ReadLimits,
    output: &RunOutput<'_>,
    progress: &dyn Progress,
) -> Result<RunSummary, RunError> {
    run_as(source, params, limits, output, progress, Route::OutOfCore)
}

/// Which pipeline [`run_as`] takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Route {
    /// In memory when the cloud fits `params.max_memory_mib`, else the out-of-core task graph.
    ByBudget,
    /// Always the out-of-core task graph.
    OutOfCore,
}

fn run_as(
    source: PointSource<'_>,
    params: &ReconParams,
    limits: &ReadLimits,
    output: &RunOutput<'_>,
    progress: &dyn Progress,
    route: Route,
) -> Result<RunSummary, RunError> {
    let start = Instant::now();
    let input = source.name();
    let recon_err = |source: ReconError| RunError::Reconstruct {
        input: input.clone(),
        source,
    };
    params.validate().map_err(|e| recon_err(e.into()))?;
    progress.stage(Stage::Read);
    if output.field.is_some() && params.method != crate::params::Method::Csrbf {
        return Err(recon_err(ReconError::Params(crate::params::ParamError {
            name: "method",
            value: params.method.name().to_string(),
            expected:
                "csrbf when saving the field (--save-field): the global methods have no saved form"
                    .into(),
        })));
    }
    let cloud = match source {
        PointSource::File(path) => {
            // Decide from the header's count before reading: a scan over the budget is streamed
            // out of core and never read whole; one whose points alone cannot fit is refused.
            let hint = peek_point_count(path).map_err(RunError::Read)?;
            let execution = super::plan_execution(hint.points, params).map_err(recon_err)?;
            if route == Route::OutOfCore || matches!(execution, super::Execution::OutOfCore(_)) {
                None
            } else {
                hint.check_budget(limits, path).map_err(RunError::Read)?;
                Some(read_point_cloud(path, limits).map_err(RunError::Read)?)
            }
        }
        PointSource::Bytes { data, format } => {
            Some(parse_point_cloud(data, format, limits).map_err(RunError::Read)?)
        }
    };
    let read_s = start.elapsed().as_secs_f64();
    let in_memory = match &cloud {
        Some(_) if route == Route::OutOfCore => false,
        Some(c) => {
            super::plan_execution(c.points.len() as u64, params).map_err(recon_err)?
                == super::Execution::InMemory
        }
        None => false,
    };
    let (mut rec, field) = match cloud {
        Some(cloud) if in_memory => {
            let rec = super::reconstruct_keeping_field(&cloud, params, progress);
            drop(cloud);
            rec.map_err(recon_err)?
        }
        cloud => {
            // The points (if read) are dropped: the task graph streams the input again.
            drop(cloud);
            (out_of_core(source, params, limits, output, progress)?, None)
        }
    };
    super::check_cancel(progress).map_err(recon_err)?;
    progress.stage(Stage::Write);
    let t = Instant::now();
    if let (Some(path), Some(field)) = (output.field, &field) {
        let bytes = crate::frep::format::encode(field);
        write_atomic(path, &bytes).map_err(RunError::Write)?;
    }
    drop(field);
    let meta = MeshMeta {
        crs: rec.report.attributes.crs.clone(),
    };
    write_mesh_with(output.mesh, &rec.mesh, output.format, &meta).map_err(RunError::Write)?;
    rec.report.timings_s.read = read_s;
    rec.report.timings_s.write = t.elapsed().as_secs_f64();
    rec.report.timings_s.total = start.elapsed().as_secs_f64();
    let process = peak_rss_mib();
    rec.report.memory.peak_rss_mib = output.job_memory_mib.map_or(process, |f| f());
    rec.report.memory.process_peak_rss_mib = output.job_memory_mib.map(|_| process);
    if let Some(path) = output.report {
        let json = serde_json::to_vec_pretty(&rec.report).map_err(|e| {
            RunError::Write(IoError::Encode {
                format: "JSON report",
                message: e.to_string(),
            })
        })?;
        if let Err(e) = write_atomic(path, &json) {
            // The mesh without its report would be half a result: take it back.
            let _ = std::fs::remove_file(output.mesh);
            if let Some(f) = output.field {
                let _ = std::fs::remove_file(f);
            }
            return Err(RunError::Write(e));
        }
    }
    progress.fraction(1.0);
    Ok(RunSummary {
        triangles: rec.mesh.triangles.len(),
        report: rec.report,
    })
}
