//! The CSRBF fit (the seed's method): index → support → carrier → assemble → order → factor → solve.

use super::{FittedField, check_cancel, clean_and_normalize, residual_at};
use crate::error::ReconError;
use crate::geometry::{Aabb, Point3, PointCloud};
use crate::linalg::{SolverParams, factorize, solve_bordered};
use crate::normals::{NormalParams, estimate_oriented_normals};
use crate::ordering::{MatrixShape, Permutation, compute_ordering, matrix_shape};
use crate::params::{Polynomial, ReconParams};
use crate::progress::Progress;
use crate::rbf::{
    Carrier, CarrierKind, RbfError, RbfField, SupportEstimate, assemble_matrix, estimate_support,
    fit_carrier,
};
use crate::report::{MatrixReport, Timings};
use crate::spatial::{SpatialIndex, build_index};
use rayon::prelude::*;
use sprs::CsMat;
use std::sync::Arc;
use std::time::Instant;

/// Clean, normalise and fit: everything up to the solved field and its residual.
pub fn fit_field(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<FittedField, ReconError> {
    let (mut clean, clean_stats, normalization, points) =
        clean_and_normalize(cloud, params, progress, timings)?;
    let normals_estimated = estimate_missing_normals(&mut clean, &points, params, progress);

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

    let (a, perm, shape) = assemble_and_order(
        &points,
        index.as_ref(),
        support.radius,
        params,
        progress,
        timings,
    )?;
    let (weights, polynomial, factor_values) =
        solve_weights(&a, &perm.perm, &rhs, &points, params, progress, timings)?;
    let matrix = MatrixReport {
        n: shape.n,
        nnz: shape.nnz,
        bandwidth: shape.bandwidth,
        profile_values: shape.profile_values,
        dense_values: shape.dense_values,
        factor_values,
    };
    drop(a);
    let carrier_name = carrier.name();
    let carrier_bounds = carrier.zero_set_bounds();
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
        field: Box::new(field),
        method: "csrbf",
        support_radius: support.radius,
        carrier: carrier_name,
        carrier_bounds,
        normalization,
        points,
        clean: clean_stats,
        support,
        matrix,
        residual,
        normals_flipped,
        normals_estimated,
    })
}

/// Assemble `A (+ λI)` and compute the ordering and the matrix shape under it (stages `assemble`, `order`).
fn assemble_and_order(
    points: &[Point3],
    index: &dyn SpatialIndex,
    radius: f64,
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<(CsMat<f64>, Permutation, MatrixShape), ReconError> {
    progress.stage("assemble");
    let t = Instant::now();
    let a = assemble_matrix(
        points,
        index,
        params.kernel,
        radius,
        params.smoothing,
        progress,
    )?;
    timings.assemble = t.elapsed().as_secs_f64();
    progress.stage("order");
    let t = Instant::now();
    let perm = compute_ordering(params.ordering, points, radius, &a, None)?;
    let shape = matrix_shape(&a, &perm)?;
    timings.order = t.elapsed().as_secs_f64();
    check_cancel(progress)?;
    Ok((a, perm, shape))
}

/// Spline weights, the linear polynomial when fitted, and the factor's stored values.
type Solved = (Vec<f64>, Option<[f64; 4]>, usize);

/// Factorise `A` and solve for the weights (and the linear polynomial through the bordered system),
/// within the memory budget (stages `factor`, `solve`). Returns (weights, polynomial, factor values).
fn solve_weights(
    a: &CsMat<f64>,
    perm: &[usize],
    rhs: &[f64],
    points: &[Point3],
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<Solved, ReconError> {
    progress.stage("factor");
    let t = Instant::now();
    let budget_values =
        (params.max_memory_mib as usize * (1 << 20) / 8).saturating_sub(2 * a.nnz());
    let solver = SolverParams {
        kind: params.solver,
        max_factor_values: budget_values,
    };
    let (factor, fstats) = factorize(a, Some(perm), &solver, progress)?;
    timings.factor = t.elapsed().as_secs_f64();
    progress.stage("solve");
    let t = Instant::now();
    let solved = match params.polynomial {
        Polynomial::None => {
            let mut x = rhs.to_vec();
            factor.solve_in_place(&mut x);
            (x, None, fstats.factor_values)
        }
        Polynomial::Linear => {
            let poly: Vec<[f64; 4]> = points.iter().map(|p| [1.0, p[0], p[1], p[2]]).collect();
            let (x, v) = solve_bordered(factor.as_ref(), &poly, rhs)?;
            (x, Some(v), fstats.factor_values)
        }
    };
    timings.solve = t.elapsed().as_secs_f64();
    Ok(solved)
}

/// Estimate oriented normals (PCA + MST propagation) when the input has none and the carrier is
/// `auto` or `local`, so the local carrier can be used. Returns whether it did.
fn estimate_missing_normals(
    clean: &mut PointCloud,
    points: &[Point3],
    params: &ReconParams,
    progress: &dyn Progress,
) -> bool {
    let wants_local = matches!(params.carrier.kind, CarrierKind::Auto | CarrierKind::Local);
    if clean.normals.is_some() || !wants_local {
        return false;
    }
    progress.stage("normals");
    clean.normals = Some(estimate_oriented_normals(points, &NormalParams::default()));
    true
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
        let negatives = outer
            .corners()
            .iter()
            .filter(|p| local.value_gradient(p).0 < 0.0)
            .count();
        if negatives > 4 {
            local.flip_normals();
            flipped = true;
        }
    }
    Ok((carrier, flipped))
}
