//! The reconstruction pipeline: clean → normalise → index → carrier → assemble → order → factor →
//! solve → residual → polygonize → post. Stage calls only; each stage lives in its own module.

use crate::error::ReconError;
use crate::geometry::clean::{CleanStats, clean_cloud};
use crate::geometry::{Aabb, Normalization, Point3, PointCloud, TriMesh};
use crate::linalg::{SolverParams, factorize, solve_bordered};
use crate::ordering::{compute_ordering, matrix_shape};
use crate::params::{Polynomial, ReconParams};
use crate::polygonize::{PolygonizeParams, ScalarField, polygonize};
use crate::progress::Progress;
use crate::rbf::{
    Carrier, RbfError, RbfField, SupportEstimate, assemble_matrix, estimate_support, fit_carrier,
};
use crate::report::{
    MatrixReport, ParamsReport, PolygonizeReport, Report, ResidualReport, Timings, peak_rss_mib,
};
use crate::spatial::{SpatialIndex, build_index};
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

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
    pub field: RbfField,
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
    let fit = fit_field(cloud, params, progress, &mut timings)?;
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
    let (mut mesh, stats) = polygonize(&fit.field, &domain, &pp, progress)?;
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
    if let Some(c) = fit.field.carrier.zero_set_bounds() {
        b.grow(&c.min);
        b.grow(&c.max);
    }
    let longest = b.extent().iter().fold(0.0f64, |a, &x| a.max(x));
    b.inflated(fit.field.support + 3.0 * longest / resolution as f64)
}

fn params_report(params: &ReconParams, fit: &FittedField, resolution: usize) -> ParamsReport {
    ParamsReport {
        method: "csrbf",
        kernel: params.kernel.to_string(),
        support: fit.field.support,
        support_input_units: fit.field.support / fit.normalization.scale,
        neighbours: fit.support.mean_neighbours,
        carrier: fit.field.carrier.name().to_string(),
        ordering: params.ordering.to_string(),
        solver: params.solver.to_string(),
        polynomial: params.polynomial.to_string(),
        resolution,
        index: params.index.to_string(),
        normals_flipped: fit.normals_flipped,
    }
}

/// Clean, normalise and fit: everything up to the solved field and its residual.
pub fn fit_field(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<FittedField, ReconError> {
    progress.stage("clean");
    let t = Instant::now();
    let (clean, clean_stats) = clean_cloud(cloud, &params.clean)?;
    let normalization = Normalization::from_aabb(&Aabb::from_points(&clean.points));
    let points: Vec<Point3> = clean
        .points
        .iter()
        .map(|p| normalization.forward(p))
        .collect();
    timings.clean = t.elapsed().as_secs_f64();

    progress.stage("index");
    let t = Instant::now();
    let index: Arc<dyn SpatialIndex + Send> =
        Arc::from(build_index(&points, params.index, params.leaf_size)?);
    let support = estimate_support(&points, index.as_ref(), params.support)?;
    check_memory(&support, points.len(), params.max_memory_mib)?;
    timings.index = t.elapsed().as_secs_f64();

    progress.stage("carrier");
    let t = Instant::now();
    let (carrier, normals_flipped) = fit_oriented_carrier(
        &points,
        clean.normals.as_deref(),
        params,
        support.radius,
        &index,
    )?;
    let rhs: Vec<f64> = points.par_iter().map(|p| -carrier.value(p)).collect();
    timings.carrier = t.elapsed().as_secs_f64();
    check_cancel(progress)?;

    progress.stage("assemble");
    let t = Instant::now();
    let a = assemble_matrix(
        &points,
        index.as_ref(),
        params.kernel,
        support.radius,
        progress,
    )?;
    timings.assemble = t.elapsed().as_secs_f64();

    progress.stage("order");
    let t = Instant::now();
    let perm = compute_ordering(params.ordering, &points, support.radius, &a, None)?;
    let shape = matrix_shape(&a, &perm)?;
    timings.order = t.elapsed().as_secs_f64();
    check_cancel(progress)?;

    progress.stage("factor");
    let t = Instant::now();
    let budget_values =
        (params.max_memory_mib as usize * (1 << 20) / 8).saturating_sub(2 * a.nnz());
    let solver = SolverParams {
        kind: params.solver,
        max_factor_values: budget_values,
    };
    let (factor, fstats) = factorize(&a, Some(&perm.perm), &solver, progress)?;
    timings.factor = t.elapsed().as_secs_f64();

    progress.stage("solve");
    let t = Instant::now();
    let (weights, polynomial) = match params.polynomial {
        Polynomial::None => {
            let mut x = rhs.clone();
            factor.solve_in_place(&mut x);
            (x, None)
        }
        Polynomial::Linear => {
            let poly: Vec<[f64; 4]> = points.iter().map(|p| [1.0, p[0], p[1], p[2]]).collect();
            let (x, v) = solve_bordered(factor.as_ref(), &poly, &rhs)?;
            (x, Some(v))
        }
    };
    timings.solve = t.elapsed().as_secs_f64();
    let matrix = MatrixReport {
        n: shape.n,
        nnz: shape.nnz,
        bandwidth: shape.bandwidth,
        profile_values: shape.profile_values,
        dense_values: shape.dense_values,
        factor_values: fstats.factor_values,
    };
    drop(factor);
    drop(a);
    let field = RbfField {
        centres: points.clone(),
        weights,
        polynomial,
        kernel: params.kernel,
        support: support.radius,
        carrier,
        index,
    };
    let t = Instant::now();
    let residual = residual_at(&field, &points);
    timings.residual = t.elapsed().as_secs_f64();
    Ok(FittedField {
        field,
        normalization,
        points,
        clean: clean_stats,
        support,
        matrix,
        residual,
        normals_flipped,
    })
}

fn check_cancel(progress: &dyn Progress) -> Result<(), ReconError> {
    if progress.cancelled() {
        Err(ReconError::Cancelled)
    } else {
        Ok(())
    }
}

/// Refuse before assembly when the matrix alone (values + indices, twice during assembly) would not fit.
fn check_memory(s: &SupportEstimate, n: usize, budget_mib: u64) -> Result<(), RbfError> {
    let mib = s.estimated_nnz * 32.0 / (1u64 << 20) as f64;
    if mib > budget_mib as f64 {
        return Err(RbfError::TooLarge {
            support: s.radius,
            neighbours: s.mean_neighbours,
            n,
            nnz: s.estimated_nnz,
            mib,
            budget_mib,
        });
    }
    Ok(())
}

/// Fit the carrier; a local carrier whose normals point inwards (negative far outside) is flipped.
fn fit_oriented_carrier(
    points: &[Point3],
    normals: Option<&[Point3]>,
    params: &ReconParams,
    radius: f64,
    index: &Arc<dyn SpatialIndex + Send>,
) -> Result<(Carrier, bool), ReconError> {
    let mut carrier = fit_carrier(points, normals, &params.carrier, radius, index)?;
    let mut flipped = false;
    if let Carrier::Local(local) = &mut carrier {
        let outer = Aabb::from_points(points).inflated(0.25);
        let negatives = (0..8)
            .filter(|c| {
                let p = [
                    if c & 1 == 0 {
                        outer.min[0]
                    } else {
                        outer.max[0]
                    },
                    if c & 2 == 0 {
                        outer.min[1]
                    } else {
                        outer.max[1]
                    },
                    if c & 4 == 0 {
                        outer.min[2]
                    } else {
                        outer.max[2]
                    },
                ];
                local.value_gradient(&p).0 < 0.0
            })
            .count();
        if negatives > 4 {
            local.flip_normals();
            flipped = true;
        }
    }
    Ok((carrier, flipped))
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
