//! The reconstruction pipeline: clean → normalise → index → carrier → assemble → order → factor →
//! solve → residual → polygonize → post. Stage calls only; each stage lives in its own module.

use crate::clean::{CleanStats, clean_cloud};
use crate::error::ReconError;
use crate::geometry::{Aabb, Normalization, Point3, PointCloud, TriMesh};
use crate::params::{Boundary, Method, ReconParams};
use crate::polygonize::ScalarField;
use crate::progress::Progress;
use crate::rbf::SupportEstimate;
use crate::report::{MatrixReport, ParamsReport, Report, ResidualReport, Timings, peak_rss_mib};
use rayon::prelude::*;
use std::time::Instant;

mod blocks;
mod csrbf;
mod global;
pub mod run;
mod surface;
pub mod tiled;

pub use csrbf::fit_field;
pub use run::{PointSource, RunError, RunOutput, RunSummary, run, run_out_of_core};

/// A reconstructed mesh (input units) with its report.
pub struct Reconstruction {
    /// The mesh, in the input's units and frame, outward normals.
    pub mesh: TriMesh,
    /// The report (`timings_s.read` / `write` are left for the caller).
    pub report: Report,
}

/// A solved field with everything measured on the way.
pub struct FittedField {
    /// The implicit field, normalised units.
    pub field: std::sync::Arc<dyn ScalarField + Send>,
    /// The same field as a CSRBF fit (what `--save-field` writes); `None` for the global methods.
    pub rbf: Option<std::sync::Arc<crate::rbf::RbfField>>,
    /// The fit that ran.
    pub method: Method,
    /// Support radius (CSRBF) or the margin scale of a global method, normalised units.
    pub support_radius: f64,
    /// The fitted carrier (`None` for the global methods, which have none).
    pub carrier: Option<crate::rbf::CarrierKind>,
    /// The local carrier's fit (`None` without a local carrier).
    pub local_fit: Option<crate::rbf::LocalFit>,
    /// Bounds of the carrier's own zero set, when it has a closed analytic one.
    pub carrier_bounds: Option<Aabb>,
    /// Input units ↔ normalised units.
    pub normalization: Normalization,
    /// Cleaned points, normalised units.
    pub points: Vec<Point3>,
    /// Cleaning statistics.
    pub clean: CleanStats,
    /// Resolved support.
    pub support: SupportEstimate,
    /// System statistics.
    pub matrix: MatrixReport,
    /// Residual at the data.
    pub residual: ResidualReport,
    /// Whether the input normals were flipped (they pointed inwards).
    pub normals_flipped: bool,
    /// Whether normals were estimated (the input had none).
    pub normals_estimated: bool,
    /// Input normals flipped to make an inconsistent orientation consistent (0 = none).
    pub normals_reoriented: usize,
    /// Measured noise (CSRBF; default for the global methods).
    pub noise: crate::rbf::NoiseEstimate,
    /// Smoothing λ used on the diagonal (0 = interpolation).
    pub smoothing: f64,
    /// Switch of the local carrier's winding-number far field (`None` without one): the surface
    /// stage turns it off for a surface it trims open, whose sheet the tangent planes continue.
    pub far_field: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
    /// Colour value of each point of `points` for the `--color` mode (RGB in [0, 1]), when the
    /// input has that attribute.
    pub point_colors: Option<Vec<[f32; 3]>>,
    /// The colour mode `point_colors` were taken for.
    pub color_mode: Option<crate::mesh::ColorMode>,
}

/// Reconstruct a closed mesh from `cloud` (any units).
/// A cancellation noticed by any stage comes back as [`ReconError::Cancelled`].
pub fn reconstruct(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
) -> Result<Reconstruction, ReconError> {
    reconstruct_keeping_field(cloud, params, progress).map(|(r, _)| r)
}

/// [`reconstruct`], also returning the fitted field as a [`crate::frep::FieldModel`] (input
/// units ↔ normalised units, data points, index settings) when the method is CSRBF: what
/// `--save-field` writes. The global methods give `None`.
pub fn reconstruct_keeping_field(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
) -> Result<(Reconstruction, Option<crate::frep::FieldModel>), ReconError> {
    reconstruct_inner(cloud, params, progress).map_err(|e| {
        if e.is_cancelled() {
            ReconError::Cancelled
        } else {
            e
        }
    })
}

/// Estimated peak resident memory (MiB) of a CSRBF reconstruction of `points` points with the
/// default parameters: 64 MiB of fixed cost (the mesh, bounded by the grid resolution cap), ~460 bytes per point for the points, normals,
/// indices, carrier and offsets, and ~1230 bytes per point of the largest system alive at once
/// (one block of at most 250,000 core points plus overlap). Calibrated on measured runs: 10⁶ torus
/// points peaked at 815–902 MiB (estimate 944), 10⁴ at 63–76 MiB (estimate 80).
pub fn estimated_peak_mib(points: u64) -> f64 {
    let alive = points.min(375_000);
    64.0 + (points as f64 * 460.0 + alive as f64 * 1230.0) / (1u64 << 20) as f64
}

/// How a reconstruction runs within its memory budget ([`plan_execution`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Execution {
    /// The whole cloud in memory ([`reconstruct`]).
    InMemory,
    /// The task graph with intermediate results on disk ([`tiled::reconstruct_tiled`]), at this
    /// estimated cost.
    OutOfCore(tiled::OutOfCoreEstimate),
}

/// Choose, before reading, how `points` points are reconstructed with `params`: in memory when
/// [`estimated_peak_mib`] fits the budget, else out of core when the parameters allow it
/// ([`tiled::supports`], blocks not `none`) and its [`tiled::estimate`] fits; otherwise the
/// refusal names the cost.
pub fn plan_execution(points: u64, params: &ReconParams) -> Result<Execution, ReconError> {
    let budget = params.max_memory_mib;
    let refusal = match check_scale(points, budget) {
        Ok(()) => return Ok(Execution::InMemory),
        Err(e) => e,
    };
    if !tiled::supports(params) || params.blocks == crate::rbf::Blocks::None {
        return Err(refusal);
    }
    let est = tiled::estimate(points, budget, rayon::current_num_threads());
    if est.peak_mib > budget as f64 {
        return Err(ReconError::OutOfCoreOverBudget {
            points,
            mib: est.peak_mib,
            budget_mib: budget,
        });
    }
    Ok(Execution::OutOfCore(est))
}

/// Refuse, before any work, a cloud whose reconstruction would not fit the budget.
pub fn check_scale(points: u64, budget_mib: u64) -> Result<(), ReconError> {
    let mib = estimated_peak_mib(points);
    if mib > budget_mib as f64 {
        return Err(ReconError::TooManyPoints {
            points,
            mib,
            budget_mib,
        });
    }
    Ok(())
}

fn reconstruct_inner(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
) -> Result<(Reconstruction, Option<crate::frep::FieldModel>), ReconError> {
    let start = Instant::now();
    params.validate()?;
    check_scale(cloud.points.len() as u64, params.max_memory_mib)?;
    let mut timings = Timings::default();
    let fit = match params.method {
        Method::Csrbf => fit_field(cloud, params, progress, &mut timings)?,
        Method::Variational | Method::Mls => {
            global::fit_global(cloud, params, progress, &mut timings)?
        }
    };
    let resolution = params
        .resolution
        .unwrap_or_else(|| auto_resolution(fit.support.spacing));
    let (domain, grid_resolution) = polygonize_domain(&fit, resolution, params.boundary);
    progress.stage(crate::progress::Stage::Polygonize);
    let t = Instant::now();
    let (mut mesh, open, polygonize) =
        surface::extract_surface(&fit, params, &domain, grid_resolution, progress)?;
    timings.polygonize = t.elapsed().as_secs_f64();
    progress.stage(crate::progress::Stage::Post);
    let t = Instant::now();
    for v in &mut mesh.vertices {
        *v = fit.normalization.inverse(v);
    }
    // The topology does not depend on the order of triangles and vertices: measured on a copy
    // while the mesh is reordered.
    let copy = TriMesh {
        vertices: mesh.vertices.clone(),
        triangles: mesh.triangles.clone(),
        ..TriMesh::default()
    };
    let (topology, optimized) = rayon::join(
        || crate::mesh::topology::analyze(&copy),
        || crate::mesh::optimize::optimize_for_gpu(&mut mesh),
    );
    optimized?;
    let attributes = color_mesh(&mut mesh, &fit, cloud)?;
    timings.post = t.elapsed().as_secs_f64();
    timings.total = start.elapsed().as_secs_f64();
    let report = Report {
        input: fit.clean,
        params: params_report(params, &fit, resolution, open),
        matrix: fit.matrix.clone(),
        residual: fit.residual,
        mesh: topology,
        timings_s: timings,
        memory: crate::report::MemoryReport {
            peak_rss_mib: peak_rss_mib(),
            process_peak_rss_mib: None,
        },
        polygonize,
        attributes,
        blocks: Vec::new(),
        tasks: Vec::new(),
        critical_path: None,
    };
    let field = fit.rbf.map(|rbf| crate::frep::FieldModel {
        rbf,
        normalization: fit.normalization,
        points: fit.points,
        index: params.index,
        leaf_size: params.leaf_size,
    });
    Ok((Reconstruction { mesh, report }, field))
}

/// Colours the vertices of `mesh` (input units) from the fitted points' colour values, blended
/// within the support radius in normalised units ([`crate::mesh::vertex_colors`]); reports what
/// the input carried.
fn color_mesh(
    mesh: &mut TriMesh,
    fit: &FittedField,
    cloud: &PointCloud,
) -> Result<crate::report::AttributesReport, ReconError> {
    let mut report = crate::report::AttributesReport {
        input_rgb: cloud.colors.is_some(),
        input_intensity: cloud.intensity.is_some(),
        color: "none",
        colored_vertices: 0,
        crs: cloud.crs.clone(),
    };
    let (Some(values), Some(mode)) = (&fit.point_colors, fit.color_mode) else {
        return Ok(report);
    };
    let local: Vec<Point3> = (mesh.vertices.iter())
        .map(|v| fit.normalization.forward(v))
        .collect();
    mesh.colors = crate::mesh::vertex_colors(&local, &fit.points, values, fit.support_radius)?;
    report.color = mode.name();
    report.colored_vertices = mesh.colors.len();
    Ok(report)
}

/// The colour values of the cleaned points for `params.color` (see [`FittedField::point_colors`]).
pub(crate) fn point_colors(clean: &PointCloud, params: &ReconParams) -> Option<Vec<[f32; 3]>> {
    crate::mesh::color::point_values(
        params.color,
        clean.colors.as_deref(),
        clean.intensity.as_deref(),
    )
}

/// Grid cells per point spacing of [`auto_resolution`]. Measured against 1 cell: at 0.75
/// the cells are 4/3 of the spacing and the real-scan statues (armadillo, camel, man, elephant,
/// bunny, 10⁴–2.6·10⁴ points, with and without normals) keep their topology and their Chamfer
/// distance to the truth (within ±1%, man 26k +7%) with 45% fewer triangles and about half the
/// polygonization time; at 0.6 the camel gained a handle. 0.7 measured with the chord
/// error 0.03: the clean bunny (37,706 points, vs `bunny00.off`)
/// is grid-limited, Chamfer 4.5e-5 at 0.75 and 5.1e-5 at 0.6 without simplification, 4.8e-5 at 0.7
/// with it; the 20 real-scan statues keep their topology and their Chamfer (geometric mean 0.98 ×
/// that of 0.75 with the chord error 0.05, none worse by more than 1%) at the same wall time.
const CELLS_PER_SPACING: f64 = 0.7;

/// Grid resolution from the median point spacing (normalised units): [`CELLS_PER_SPACING`] cells
/// per spacing, clamped to 64..=200. Measured against a cap of 320: at 10⁵–10⁶ points 200 cells gave equal or
/// lower Chamfer distance to the truth (torus 10⁵ 9.5e-6 vs 1.10e-5, bumpy sphere 6.3e-6 vs 7.7e-6,
/// torus 10⁶ 4.9e-6 vs 5.2e-6, bunny vs bunny00 4.9e-5 vs 5.2e-5) in about half the time.
pub fn auto_resolution(spacing: f64) -> usize {
    if !(spacing.is_finite() && spacing > 0.0) {
        return 128;
    }
    ((CELLS_PER_SPACING / spacing).ceil() as usize).clamp(64, 200)
}

/// The box the polygonizer marches: the points and the carrier's own zero set, with a margin of
/// one support radius plus two cells so the field is positive on its boundary; with
/// `--boundary closed` at least a quarter of the longest edge, room for the surface that closes a
/// hole to bulge beyond the data (the grid then gets more cells, so the cell size stays the
/// same). Returns the box and the number of cells along its longest edge.
fn polygonize_domain(fit: &FittedField, resolution: usize, boundary: Boundary) -> (Aabb, usize) {
    let mut b = Aabb::from_points(&fit.points);
    if let Some(c) = fit.carrier_bounds {
        b.grow(&c.min);
        b.grow(&c.max);
    }
    let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    let margin = fit.support_radius + 3.0 * longest / resolution as f64;
    if boundary != Boundary::Closed || margin >= 0.25 * longest {
        return (b.inflated(margin), resolution);
    }
    let closing = 0.25 * longest;
    let cells = (resolution as f64 * (longest + 2.0 * closing) / (longest + 2.0 * margin)).ceil();
    (b.inflated(closing), (cells as usize).min(4096))
}

fn params_report(
    params: &ReconParams,
    fit: &FittedField,
    resolution: usize,
    trim: bool,
) -> ParamsReport {
    ParamsReport {
        method: fit.method.name(),
        kernel: params.kernel.to_string(),
        support: fit.support_radius,
        support_input_units: fit.support_radius / fit.normalization.scale,
        neighbours: fit.support.mean_neighbours,
        carrier: fit.carrier.map_or("none", |c| c.name()).to_string(),
        local_fit: fit.local_fit.map(crate::rbf::LocalFit::name),
        ordering: params.ordering.to_string(),
        solver: params.solver.to_string(),
        polynomial: params.polynomial.to_string(),
        resolution,
        index: params.index.to_string(),
        normals_flipped: fit.normals_flipped,
        smoothing: fit.smoothing,
        noise: fit.noise,
        boundary: if trim { "trim" } else { "closed" },
        normals_reoriented: fit.normals_reoriented,
        normals: if fit.normals_estimated {
            "estimated"
        } else if fit.normals_reoriented > 0 {
            "input-reoriented"
        } else if fit.clean.has_normals {
            "input"
        } else {
            "none"
        },
    }
}

/// Clean the cloud and map it into the unit cube: (cleaned cloud in input units, stats, transform,
/// normalised points).
pub(crate) fn clean_and_normalize(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<(PointCloud, CleanStats, Normalization, Vec<Point3>), ReconError> {
    progress.stage(crate::progress::Stage::Clean);
    let t = Instant::now();
    let (mut clean, mut stats) = clean_cloud(cloud, &params.clean)?;
    if let Some(o) = &params.outliers {
        let (kept, removed) = crate::clean::outliers::remove_outliers(&clean, o);
        crate::clean::check_degenerate(&kept.points, kept.normals.is_some())?;
        clean = kept;
        stats.outliers_removed = removed;
        stats.used = clean.points.len();
    }
    let normalization = Normalization::from_aabb(&Aabb::from_points(&clean.points));
    let points: Vec<Point3> = clean
        .points
        .iter()
        .map(|p| normalization.forward(p))
        .collect();
    timings.clean = t.elapsed().as_secs_f64();
    Ok((clean, stats, normalization, points))
}

pub(crate) fn check_cancel(progress: &dyn Progress) -> Result<(), ReconError> {
    if progress.cancelled() {
        Err(ReconError::Cancelled)
    } else {
        Ok(())
    }
}

/// Points per bucket of [`residual_at`] (about; the buckets are cubes sized for a surface sample).
const RESIDUAL_BUCKET: usize = 64;

/// RMS and max of `|f(P_i)|` over the data points, evaluated in parallel (rayon) in spatial buckets
/// of about [`RESIDUAL_BUCKET`] points, one [`ScalarField::values_in`] call each (a field backed by
/// a spatial index gathers its candidates once per bucket instead of once per point); summed in
/// point order so the result does not depend on the thread schedule. Stops with
/// [`ReconError::Cancelled`] within one bucket of a cancel.
pub fn residual_at(
    field: &dyn ScalarField,
    points: &[Point3],
    progress: &dyn Progress,
) -> Result<ResidualReport, ReconError> {
    residual_in_buckets(points, progress, |_, pts, out| {
        field.values_in(&Aabb::from_points(pts), pts, out)
    })
}

/// [`residual_at`] for a CSRBF field whose carrier values at the points are known
/// (`carrier[i] = g(P_i)`, from the carrier stage): only the spline part is evaluated and the
/// carrier's value added, the same sum in the same order, so the same bits.
pub(crate) fn residual_with_carrier(
    field: &crate::rbf::RbfField,
    points: &[Point3],
    carrier: &[f64],
    progress: &dyn Progress,
) -> Result<ResidualReport, ReconError> {
    residual_in_buckets(points, progress, |ids, pts, out| {
        field.correction_values_in(&Aabb::from_points(pts), pts, out);
        for (o, &i) in out.iter_mut().zip(ids) {
            *o += carrier[i as usize];
        }
    })
}

/// RMS and max of `|f(P_i)|`, `eval(ids, points, out)` writing `f` of one bucket's points (see
/// [`residual_at`]); magnitudes summed in point order.
fn residual_in_buckets(
    points: &[Point3],
    progress: &dyn Progress,
    eval: impl Fn(&[u32], &[Point3], &mut [f64]) + Sync,
) -> Result<ResidualReport, ReconError> {
    let mut abs = per_bucket(points, RESIDUAL_BUCKET, |ids, pts| {
        let mut out = vec![0.0; pts.len()];
        if !progress.cancelled() {
            eval(ids, pts, &mut out);
        }
        out
    });
    check_cancel(progress)?;
    for v in &mut abs {
        *v = v.abs();
    }
    let sum2: f64 = abs.iter().map(|v| v * v).sum();
    Ok(ResidualReport {
        rms: (sum2 / points.len().max(1) as f64).sqrt(),
        max: abs.iter().fold(0.0f64, |m, &v| m.max(v)),
    })
}

/// `eval(ids, points)` of each bucket of about `per` nearby points ([`spatial_buckets`]), in
/// parallel, as one value per point in the input order: for evaluations that gather their data
/// once per small box.
pub(crate) fn per_bucket(
    points: &[Point3],
    per: usize,
    eval: impl Fn(&[u32], &[Point3]) -> Vec<f64> + Sync,
) -> Vec<f64> {
    let buckets = spatial_buckets(points, per);
    let values: Vec<Vec<f64>> = (buckets.par_iter())
        .map(|ids| {
            eval(
                ids,
                &ids.iter().map(|&i| points[i as usize]).collect::<Vec<_>>(),
            )
        })
        .collect();
    let mut out = vec![0.0; points.len()];
    for (ids, v) in buckets.iter().zip(values) {
        for (&i, v) in ids.iter().zip(v) {
            out[i as usize] = v;
        }
    }
    out
}

/// The points grouped by cubes of a grid sized so that a surface sample puts about `per` points in
/// a cube (edge `longest · √(per / n)`); cubes in lexicographic order, points ascending within a
/// cube (deterministic). `O(n log n)`.
fn spatial_buckets(points: &[Point3], per: usize) -> Vec<Vec<u32>> {
    let bbox = Aabb::from_points(points);
    let longest = bbox.extent().iter().fold(0.0f64, |a, &b| a.max(b));
    let cell = longest * (per as f64 / points.len().max(1) as f64).sqrt();
    if !(cell.is_finite() && cell > 0.0) {
        return vec![(0..points.len() as u32).collect()];
    }
    let key = |p: &Point3| [0, 1, 2].map(|k| ((p[k] - bbox.min[k]) / cell).floor() as i64);
    let mut keyed: Vec<([i64; 3], u32)> = (points.par_iter().enumerate())
        .map(|(i, p)| (key(p), i as u32))
        .collect();
    keyed.par_sort_unstable();
    keyed
        .chunk_by(|a, b| a.0 == b.0)
        .map(|c| c.iter().map(|&(_, i)| i).collect())
        .collect()
}
