//! The reconstruction pipeline: clean → normalise → index → carrier → assemble → order → factor →
//! solve → residual → polygonize → post. Stage calls only; each stage lives in its own module.

use crate::error::ReconError;
use crate::geometry::clean::{CleanStats, clean_cloud};
use crate::geometry::{Aabb, Normalization, Point3, PointCloud, TriMesh};
use crate::params::{Method, ReconParams};
use crate::polygonize::{PolygonizeParams, ScalarField, polygonize};
use crate::progress::Progress;
use crate::rbf::SupportEstimate;
use crate::report::{
    MatrixReport, ParamsReport, PolygonizeReport, Report, ResidualReport, Timings, peak_rss_mib,
};
use rayon::prelude::*;
use std::time::Instant;

mod csrbf;
mod global;

pub use csrbf::fit_field;

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
    pub field: Box<dyn ScalarField + Send>,
    /// Method name for the report.
    pub method: &'static str,
    /// Support radius (CSRBF) or the margin scale of a global method, normalised units.
    pub support_radius: f64,
    /// Carrier name for the report.
    pub carrier: &'static str,
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
}

/// Reconstruct a closed mesh from `cloud` (any units).
pub fn reconstruct(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
) -> Result<Reconstruction, ReconError> {
    let start = Instant::now();
    params.validate()?;
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
    let domain = polygonize_domain(&fit, resolution);
    progress.stage("polygonize");
    let t = Instant::now();
    let pp = PolygonizeParams {
        resolution,
        ..Default::default()
    };
    let (mut mesh, stats) = polygonize(fit.field.as_ref(), &domain, &pp, progress)?;
    timings.polygonize = t.elapsed().as_secs_f64();
    progress.stage("post");
    let t = Instant::now();
    for v in &mut mesh.vertices {
        *v = fit.normalization.inverse(v);
    }
    crate::mesh::optimize::optimize_for_gpu(&mut mesh)?;
    let topology = crate::mesh::topology::analyze(&mesh);
    timings.post = t.elapsed().as_secs_f64();
    timings.total = start.elapsed().as_secs_f64();
    let report = Report {
        input: fit.clean,
        params: params_report(params, &fit, resolution),
        matrix: fit.matrix.clone(),
        residual: fit.residual,
        mesh: topology,
        timings_s: timings,
        memory: crate::report::MemoryReport {
            peak_rss_mib: peak_rss_mib(),
        },
        polygonize: PolygonizeReport {
            cells_total: stats.cells_total,
            blocks_total: stats.blocks_total,
            blocks_active: stats.blocks_active,
            field_evaluations: stats.field_evaluations,
            cell_size: domain.extent().iter().fold(0.0f64, |a, &b| a.max(b)) / resolution as f64,
        },
    };
    Ok(Reconstruction { mesh, report })
}

/// Grid resolution from the median point spacing (normalised units): about one cell per spacing,
/// clamped to 64..=320.
pub fn auto_resolution(spacing: f64) -> usize {
    if !(spacing.is_finite() && spacing > 0.0) {
        return 128;
    }
    ((1.0 / spacing).ceil() as usize).clamp(64, 320)
}

/// The box the polygonizer marches: the points and the carrier's own zero set, with a margin of
/// one support radius plus two cells so the field is positive on its boundary.
fn polygonize_domain(fit: &FittedField, resolution: usize) -> Aabb {
    let mut b = Aabb::from_points(&fit.points);
    if let Some(c) = fit.carrier_bounds {
        b.grow(&c.min);
        b.grow(&c.max);
    }
    let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    b.inflated(fit.support_radius + 3.0 * longest / resolution as f64)
}

fn params_report(params: &ReconParams, fit: &FittedField, resolution: usize) -> ParamsReport {
    ParamsReport {
        method: fit.method,
        kernel: params.kernel.to_string(),
        support: fit.support_radius,
        support_input_units: fit.support_radius / fit.normalization.scale,
        neighbours: fit.support.mean_neighbours,
        carrier: fit.carrier.to_string(),
        ordering: params.ordering.to_string(),
        solver: params.solver.to_string(),
        polynomial: params.polynomial.to_string(),
        resolution,
        index: params.index.to_string(),
        normals_flipped: fit.normals_flipped,
        normals: if fit.normals_estimated {
            "estimated"
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
    progress.stage("clean");
    let t = Instant::now();
    let (clean, stats) = clean_cloud(cloud, &params.clean)?;
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

/// RMS and max of `|f(P_i)|` over the data points (parallel).
pub fn residual_at(field: &dyn ScalarField, points: &[Point3]) -> ResidualReport {
    let (sum2, max) = points
        .par_iter()
        .map(|p| field.value(p).abs())
        .fold(|| (0.0f64, 0.0f64), |(s, m), v| (s + v * v, m.max(v)))
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1.max(b.1)));
    ResidualReport {
        rms: (sum2 / points.len().max(1) as f64).sqrt(),
        max,
    }
}
