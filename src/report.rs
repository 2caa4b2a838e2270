//! The JSON report of a reconstruction (keys are a contract, see docs/report.md).

use crate::clean::CleanStats;
use crate::mesh::topology::MeshTopology;
use serde::Serialize;

/// Full report of one reconstruction.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// What was read and kept.
    pub input: CleanStats,
    /// The parameters actually used (resolved defaults).
    pub params: ParamsReport,
    /// Size and shape of the linear system.
    pub matrix: MatrixReport,
    /// Residual of the final field at the data points, normalised units.
    pub residual: ResidualReport,
    /// Topology of the output mesh.
    pub mesh: MeshTopology,
    /// Wall-clock seconds per stage.
    pub timings_s: Timings,
    /// Memory use.
    pub memory: MemoryReport,
    /// Polygonization statistics (sparse grid).
    pub polygonize: PolygonizeReport,
    /// Vertex colours and georeference carried from the input.
    pub attributes: AttributesReport,
    /// One entry per partition-of-unity block of an out-of-core (task graph) run: who fitted it,
    /// how many points, how long and at what memory. Absent for in-memory runs.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub blocks: Vec<BlockReport>,
    /// Every task of a distributed task-graph run in the order they ended: which worker ran it,
    /// when, for how long. Absent for other runs.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tasks: Vec<TaskReport>,
    /// The longest chain of dependent tasks of `tasks[]` ([`critical_path`]). Absent for other
    /// runs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub critical_path: Option<CriticalPath>,
}

/// Unix time in milliseconds (the clock of [`TaskReport::start_ms`] and `end_ms`).
pub fn unix_now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// One task of a distributed task-graph run (report `tasks[]`).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct TaskReport {
    /// `prepare` (the span of the graph's prepare), `block <b>`, `region <r>`, `merge`, or one of
    /// prepare's tasks: `survey`, `route` (the input read whole), `survey range <r>`,
    /// `sample range <r>`, `route range <r>` (read by byte ranges), `clean-up` (in one process);
    /// spread over the workers also `clean-up <k>` per block and the steps between the phases,
    /// `number ranges`, `plan blocks`, `estimates <generation>`, `complete plan`.
    pub task: String,
    /// Id of the worker that ran it (the last delivery's, when it ran more than once).
    pub worker: String,
    /// Unix milliseconds when the task began on its worker.
    pub start_ms: u64,
    /// Unix milliseconds when its result was stored.
    pub end_ms: u64,
    /// Wall-clock seconds, `end_ms - start_ms`.
    pub seconds: f64,
}

/// The longest chain of dependent tasks of a task-graph run: prepare, then the slowest block
/// (every region waits for every block), the slowest region, then merge. With the prepare
/// spread over the workers, prepare is itself the chain of its phases' slowest tasks (survey
/// range, sample range, route range, clean-up) and the steps between them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CriticalPath {
    /// The chain's tasks, in order.
    pub tasks: Vec<String>,
    /// Sum of their wall-clock seconds: the job's time on unlimited idle workers.
    pub seconds: f64,
    /// Seconds from the first task's start to the last task's end (what the job took).
    pub wall_seconds: f64,
}

/// The critical path of `tasks` (see [`CriticalPath`]); `None` without tasks. A phase with no
/// task (no region touched the surface) adds nothing.
pub fn critical_path(tasks: &[TaskReport]) -> Option<CriticalPath> {
    let first = tasks.iter().map(|t| t.start_ms).min()?;
    let last = tasks.iter().map(|t| t.end_ms).max()?;
    let slowest = |prefix: &str| {
        tasks
            .iter()
            .filter(|t| t.task == prefix || t.task.starts_with(&format!("{prefix} ")))
            .max_by(|a, b| a.seconds.total_cmp(&b.seconds))
    };
    // A prepare spread over the workers (one clean-up task per block) is a chain of its own:
    // its phases' slowest tasks and the steps between them replace the `prepare` span.
    let spread = tasks.iter().any(|t| t.task.starts_with("clean-up "));
    let phases: &[&str] = if spread {
        &[
            "survey range",
            "number ranges",
            "sample range",
            "plan blocks",
            "route range",
            "estimates",
            "clean-up",
            "complete plan",
            "block",
            "region",
            "merge",
        ]
    } else {
        &["prepare", "block", "region", "merge"]
    };
    let chain: Vec<&TaskReport> = phases.iter().copied().filter_map(slowest).collect();
    Some(CriticalPath {
        tasks: chain.iter().map(|t| t.task.clone()).collect(),
        seconds: chain.iter().map(|t| t.seconds).sum(),
        wall_seconds: last.saturating_sub(first) as f64 / 1000.0,
    })
}

/// One block of a task-graph run (report `blocks[]`).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct BlockReport {
    /// Block number (the order of the plan).
    pub id: usize,
    /// Id of the worker that fitted it (`local-<pid>` for the local executor).
    pub worker: String,
    /// Points of its system (inside its outer box).
    pub points: usize,
    /// Wall-clock seconds of the fit, including loading its points.
    pub seconds: f64,
    /// Peak resident memory of the fitting process when the block finished, MiB (Linux VmHWM:
    /// with several blocks in one process, the process's high-water mark so far).
    pub peak_rss_mib: f64,
}

/// What the input carried besides positions and normals, and what the mesh got from it.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AttributesReport {
    /// Whether the input points had RGB colour.
    pub input_rgb: bool,
    /// Whether the input points had intensity.
    pub input_intensity: bool,
    /// Where the vertex colours come from: `rgb`, `intensity` or `none` (the `--color` mode, or
    /// `none` when the input lacks that attribute).
    pub color: &'static str,
    /// Coloured mesh vertices (0 without colour).
    pub colored_vertices: usize,
    /// The input's coordinate reference system, verbatim (LAS WKT or `EPSG:<code>` from GeoTIFF
    /// keys, E57 coordinate metadata); `null` when it declares none. Also written to GLB
    /// `asset.extras.crs` and a PLY `comment crs` line.
    pub crs: Option<String>,
}

/// Resolved parameters.
#[derive(Debug, Clone, Serialize)]
pub struct ParamsReport {
    /// Always `csrbf` for this pipeline.
    pub method: &'static str,
    /// Kernel name.
    pub kernel: String,
    /// Support radius, normalised units.
    pub support: f64,
    /// Support radius, input units.
    pub support_input_units: f64,
    /// Mean neighbours per point within the support.
    pub neighbours: f64,
    /// Carrier actually fitted (`auto` resolved).
    pub carrier: String,
    /// The local carrier's term per point, `plane` or `quadric` (`auto` resolved from the noise
    /// estimate); null with another carrier.
    pub local_fit: Option<&'static str>,
    /// Ordering name.
    pub ordering: String,
    /// Solver name.
    pub solver: String,
    /// Polynomial name.
    pub polynomial: String,
    /// Grid cells along the longest axis.
    pub resolution: usize,
    /// Spatial index name.
    pub index: String,
    /// Whether input normals were flipped because they pointed inwards.
    pub normals_flipped: bool,
    /// Smoothing λ on the diagonal actually used (0 = interpolation; chosen from `noise` by default).
    pub smoothing: f64,
    /// Measured noise level and the λ it chooses (see `rbf::noise`).
    pub noise: crate::rbf::NoiseEstimate,
    /// Unsupported surface handling actually applied: `trim` or `closed`.
    pub boundary: &'static str,
    /// Where the normals came from: `input`, `input-reoriented` (inconsistent input orientation made
    /// consistent by MST propagation), `estimated` (PCA + MST orientation) or `none`.
    pub normals: &'static str,
    /// Input normals flipped by that re-orientation.
    pub normals_reoriented: usize,
}

/// Linear system statistics (seed Table 1 columns).
#[derive(Debug, Clone, Default, Serialize)]
pub struct MatrixReport {
    /// Unknowns (points).
    pub n: usize,
    /// Stored non-zeros of the full symmetric matrix.
    pub nnz: usize,
    /// Bandwidth under the chosen ordering.
    pub bandwidth: usize,
    /// Envelope (profile) values of the lower triangle incl. diagonal under the chosen ordering.
    pub profile_values: usize,
    /// Values of a dense `n × n` matrix.
    pub dense_values: usize,
    /// Values stored by the factor actually computed (summed over levels).
    pub factor_values: usize,
    /// Solver that ran: `sparse`, `envelope`, `ldl`, `cg` (several joined by `+` across levels), or
    /// the dense solver of a global method.
    pub solver_used: SolversUsed,
    /// Per-level systems of a CSRBF fit, coarse to fine (one entry for a single-level fit; the
    /// other fields then describe the finest level, except `factor_values`, which sums all levels).
    pub levels: Vec<LevelReport>,
    /// Blocks of the partition of unity (1 = one global system); per-level entries then sum the
    /// blocks' systems (n, nnz, factor values) and take the largest iteration count.
    pub blocks: usize,
}

/// The distinct solvers that ran, in order of first use; written in the report as their names
/// joined by `+` (`sparse`, `sparse+cg`).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SolversUsed(Vec<&'static str>);

impl SolversUsed {
    /// One solver.
    pub fn one(name: &'static str) -> Self {
        SolversUsed(vec![name])
    }

    /// Record that `name` ran (kept once, in order of first use).
    pub fn add(&mut self, name: &'static str) {
        if !self.0.contains(&name) {
            self.0.push(name);
        }
    }

    /// Record every solver of `other`.
    pub fn merge(&mut self, other: &SolversUsed) {
        for &s in &other.0 {
            self.add(s);
        }
    }

    /// The names, in order of first use.
    pub fn names(&self) -> &[&'static str] {
        &self.0
    }
}

impl std::fmt::Display for SolversUsed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0.join("+"))
    }
}

impl Serialize for SolversUsed {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// One level of a multi-level CSRBF fit.
#[derive(Debug, Clone, Default, Serialize)]
pub struct LevelReport {
    /// Centres of the level.
    pub n: usize,
    /// Stored non-zeros of its matrix.
    pub nnz: usize,
    /// Support radius, normalised units.
    pub support: f64,
    /// Values stored by its factor (0 for conjugate gradients).
    pub factor_values: usize,
    /// Conjugate-gradient iterations, when that solver ran.
    pub iterations: Option<usize>,
    /// Solver that ran for this level.
    pub solver: &'static str,
    /// RMS of the level's right-hand side (what it had left to interpolate), normalised units.
    pub rhs_rms: f64,
}

/// RMS and maximum of `|f(P_i)|`.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ResidualReport {
    /// Root mean square, normalised units.
    pub rms: f64,
    /// Maximum absolute value, normalised units.
    pub max: f64,
}

/// Seconds per stage (`read` and `write` are filled by the caller that does the I/O).
#[derive(Debug, Clone, Copy, Default, Serialize, serde::Deserialize)]
pub struct Timings {
    /// Reading the input file.
    pub read: f64,
    /// Cleaning and normalising.
    pub clean: f64,
    /// Estimating and orienting normals when the input has none (0 when it has them).
    #[serde(default)]
    pub normals: f64,
    /// Building the spatial index and choosing the support.
    pub index: f64,
    /// Fitting the carrier and computing offsets.
    pub carrier: f64,
    /// Assembling the matrix.
    pub assemble: f64,
    /// Computing the ordering and matrix shape.
    pub order: f64,
    /// Factorising.
    pub factor: f64,
    /// Solving (and the polynomial border).
    pub solve: f64,
    /// Residual at the data points.
    pub residual: f64,
    /// Marching the grid.
    pub polygonize: f64,
    /// Topology analysis and GPU optimisation.
    pub post: f64,
    /// Writing the output.
    pub write: f64,
    /// Everything.
    pub total: f64,
}

/// Memory statistics.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct MemoryReport {
    /// Peak resident memory of this reconstruction, MiB (0 where unknown). On the command line the
    /// process's high-water mark (Linux VmHWM: the process is the run); in the service the job's
    /// own peak: the largest growth of the server's resident set over its level at the job's
    /// start, sampled every 20 ms while the job runs.
    pub peak_rss_mib: f64,
    /// The service only: the whole server process's high-water mark (VmHWM), MiB, which includes
    /// earlier and concurrent jobs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub process_peak_rss_mib: Option<f64>,
}

/// Sparse-grid statistics.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct PolygonizeReport {
    /// Cells of the full grid.
    pub cells_total: u64,
    /// Blocks of the full grid.
    pub blocks_total: usize,
    /// Blocks the field could cross zero in (the only ones evaluated).
    pub blocks_active: usize,
    /// Field evaluations.
    pub field_evaluations: u64,
    /// Share of the surface area farther than the support radius from the data, measured on a
    /// coarse pass to decide open or closed (`--boundary auto` with the local carrier, when the
    /// data do not surround their middle; else null).
    pub unsupported_share: Option<f64>,
    /// Widest cone of directions (half-angle, degrees) from the middle of the data that holds no
    /// point (`--boundary auto` with the local carrier; else null): below 25° the data surround
    /// the object and the surface is closed without the coarse pass.
    pub empty_cone_deg: Option<f64>,
    /// Of the space where the oriented data's winding number is clearly non-zero, the share where
    /// it says enclosed (`|w| ≥ ¼` / `w ≥ ¾`; `--boundary auto` with the local carrier when the data
    /// do not surround their middle, else null): from 0.15 the data enclose a volume and the
    /// surface is closed without the coarse pass.
    pub enclosed_share: Option<f64>,
    /// Triangles the polygonizer produced (open surfaces: only in the band the data support).
    pub triangles_polygonized: usize,
    /// Triangles dropped because no data point is within the support radius (open scans).
    pub trimmed_triangles: usize,
    /// Triangles dropped to make the trimmed border manifold (bow-tie vertices).
    pub border_triangles: usize,
    /// Triangles peeled off the trimmed border because they lie farther than `--border-reach`
    /// support radii from every point, where that keeps the pieces, holes and handles (open
    /// surfaces).
    pub peeled_triangles: usize,
    /// Components dropped as floaters: carried by fewer than `--min-support` of the data points.
    pub floaters_removed: usize,
    /// Triangles in those components.
    pub floater_triangles: usize,
    /// Pieces of an open surface dropped as fringes: no vertex more than 2 support radii inside
    /// their border (silhouette and grazing-view strips of range scans; `--min-support 0`
    /// keeps them).
    #[serde(default)]
    pub fringes_removed: usize,
    /// Triangles in those pieces.
    #[serde(default)]
    pub fringe_triangles: usize,
    /// Connected components dropped by `--min-component` (floaters).
    pub small_components_removed: usize,
    /// Triangles in those components.
    pub small_component_triangles: usize,
    /// Handles cut (`--max-handle-loop`): thin bridges and pinholes of a closed surface.
    pub handles_removed: usize,
    /// The longest cut loop, support radii (0 when none was cut).
    pub handle_loop_max: f64,
    /// Seconds spent finding and cutting handles (part of `timings_s.polygonize`; of
    /// `timings_s.post` out of core).
    pub handles_s: f64,
    /// Seconds spent extracting the zero set on the grid (part of `timings_s.polygonize`; 0 out
    /// of core, where the tiles' extraction is spread over the task graph).
    pub extract_s: f64,
    /// Seconds spent simplifying to the chord error and measuring it (part of
    /// `timings_s.polygonize`; 0 out of core).
    pub simplify_s: f64,
    /// Short non-separating loops found but left (the cut would not have given a closed
    /// manifold one genus lower).
    pub handles_kept: usize,
    /// Grid cell edge, normalised units.
    pub cell_size: f64,
    /// Triangles before the chord-error simplification.
    pub triangles_before_simplify: usize,
    /// Chord-error tolerance of the simplification, normalised units (`--chord-error` × the
    /// median point spacing); null with `--chord-error off`.
    pub chord_tolerance: Option<f64>,
    /// meshoptimizer's measure of the simplified mesh's deviation from the grid mesh, normalised
    /// units (0 when nothing was simplified).
    pub simplify_error: f64,
    /// Largest chord error measured on the output: `|f| / |∇f|` (first-order distance to the fitted
    /// surface) at triangle centroids (every k-th triangle, at most 20,000), normalised units.
    pub chord_error_max: f64,
    /// Mean of the same, normalised units.
    pub chord_error_mean: f64,
}

/// Peak resident set size of this process in MiB (reads `/proc/self/status`; 0 elsewhere).
pub fn peak_rss_mib() -> f64 {
    proc_status_kib("VmHWM:").map_or(0.0, |kb| kb as f64 / 1024.0)
}

/// Current resident set size of the process, KiB (Linux VmRSS; `None` where unknown).
pub fn current_rss_kib() -> Option<u64> {
    proc_status_kib("VmRSS:")
}

fn proc_status_kib(key: &str) -> Option<u64> {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(key))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<u64>().ok())
        })
}

#[cfg(test)]
mod critical_path_tests {
    use super::*;

    fn task(task: &str, start_ms: u64, end_ms: u64) -> TaskReport {
        TaskReport {
            task: task.into(),
            worker: "w".into(),
            start_ms,
            end_ms,
            seconds: (end_ms - start_ms) as f64 / 1000.0,
        }
    }

    #[test]
    fn the_critical_path_is_prepare_the_slowest_block_and_region_then_merge() {
        let tasks = [
            task("prepare", 1_000, 3_000),
            task("block 0", 3_100, 4_100),
            task("block 1", 3_100, 6_100),
            task("block 10", 4_200, 5_200),
            task("region 0", 6_200, 6_700),
            task("region 1", 6_200, 7_200),
            task("merge", 7_300, 7_800),
        ];
        let c = critical_path(&tasks).unwrap();
        assert_eq!(c.tasks, ["prepare", "block 1", "region 1", "merge"]);
        assert!((c.seconds - 6.5).abs() < 1e-12, "{c:?}");
        assert!((c.wall_seconds - 6.8).abs() < 1e-12, "{c:?}");
        assert!(critical_path(&[]).is_none());
    }
}
