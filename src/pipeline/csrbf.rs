//! The CSRBF fit (the seed's method): index → support → carrier → assemble → order → factor → solve.

use super::{FittedField, check_cancel, clean_and_normalize};
use crate::error::ReconError;
use crate::geometry::{Aabb, Point3, PointCloud};
use crate::linalg::{SolverKind, SolverParams, factorize_owned, solve_bordered};
use crate::normals::{NormalParams, estimate_oriented_normals};
use crate::ordering::{MatrixShape, Permutation, compute_ordering, matrix_shape};
use crate::params::{Method, Polynomial, ReconParams};
use crate::progress::Progress;
use crate::rbf::{
    Carrier, CarrierKind, Correction, Kernel, LevelPlan, RbfError, RbfField, Spline, SplineLevel,
    SupportEstimate, assemble_matrix, estimate_support, fit_carrier, linear_poly, plan_levels,
};
use crate::report::{LevelReport, MatrixReport, Timings};
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
    let (mut clean, mut clean_stats, normalization, mut points) =
        clean_and_normalize(cloud, params, progress, timings)?;
    let mut point_colors = super::point_colors(&clean, params);

    progress.stage(crate::progress::Stage::Index);
    let t = Instant::now();
    let mut index: Arc<dyn SpatialIndex + Send> =
        Arc::from(build_index(&points, params.index, params.leaf_size)?);
    crate::clean::check_local_shape(&points, |p, k, out| index.nearest_k(p, k, out))?;
    let support = estimate_support(&points, index.as_ref(), params.support)?;
    let noise = crate::rbf::estimate_noise(&points, support.spacing, |p, k, out| {
        index.nearest_k(p, k, out)
    });
    if noise.noisy {
        let mut cloud = Cleaned {
            clean: &mut clean,
            stats: &mut clean_stats,
            points: &mut points,
            colors: &mut point_colors,
        };
        if let Some(rebuilt) = drop_strays(&mut cloud, index.as_ref(), noise.sigma, params)? {
            index = rebuilt;
        }
    }
    let mut index_s = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let normals_estimated = estimate_missing_normals(&mut clean, &points, params, progress);
    timings.normals = if normals_estimated {
        t.elapsed().as_secs_f64()
    } else {
        0.0
    };
    let t = Instant::now();
    let normals_reoriented = reorient_inconsistent_normals(&mut clean, &points, index.as_ref());
    // Denoised after the normals: they are estimated and oriented on the measured points.
    if noise.smooth && params.smoothing != crate::params::Smoothing::Lambda(0.0) {
        let moved = crate::clean::denoise::denoise(&points, noise.sigma, |p, k, out| {
            index.nearest_k(p, k, out)
        });
        clean_stats.denoised = (moved.iter().zip(&points)).filter(|(a, b)| a != b).count();
        points = moved;
        index = Arc::from(build_index(&points, params.index, params.leaf_size)?);
    }
    let resolved = params.resolved_for(&noise);
    let params = &resolved;
    let count = params.levels;
    let wave = block_wave(&support, points.len(), count, params)?;
    index_s += t.elapsed().as_secs_f64();
    timings.index = index_s;

    progress.stage(crate::progress::Stage::Carrier);
    let t = Instant::now();
    let (carrier, normals_flipped) = fit_oriented_carrier(
        &points,
        clean.normals.as_deref(),
        params,
        support.radius,
        &index,
    )?;
    let carrier_at = carrier_values(&carrier, &points);
    let rhs: Vec<f64> = carrier_at.iter().map(|v| -v).collect();
    timings.carrier = t.elapsed().as_secs_f64();
    check_cancel(progress)?;

    let (correction, matrix) = match params.blocks.max_points(points.len()) {
        None => {
            let plans = plan_levels(
                &points,
                index.as_ref(),
                support.radius,
                support.mean_neighbours,
                count,
            );
            let (spline, matrix) =
                fit_levels(&points, &index, &plans, rhs, params, progress, timings)?;
            (Correction::Global(spline), matrix)
        }
        Some(max_points) => {
            let (blocks, matrix) = super::blocks::fit_blocks(
                &points,
                &rhs,
                &support,
                count,
                (max_points, wave),
                params,
                progress,
                timings,
            )?;
            (Correction::Blocks(blocks), matrix)
        }
    };
    let far_field = match &carrier {
        Carrier::Local(l) => Some(l.far_field_switch()),
        _ => None,
    };
    let carrier_kind = carrier.kind();
    let local_fit = match &carrier {
        Carrier::Local(l) => Some(l.fit()),
        _ => None,
    };
    let carrier_bounds = carrier.zero_set_bounds();
    let field = Arc::new(RbfField {
        correction,
        kernel: params.kernel,
        carrier,
        carrier_index: index,
        carrier_radius: support.radius,
        finest_support: support.radius,
        // The floaters go when their share is positive (see `surface::extract_surface`).
        unsupported_dropped: params.min_support > 0.0,
    });
    let t = Instant::now();
    let residual = super::residual_with_carrier(field.as_ref(), &points, &carrier_at, progress)?;
    timings.residual = t.elapsed().as_secs_f64();
    Ok(FittedField {
        far_field,
        field: Arc::clone(&field) as Arc<dyn crate::polygonize::ScalarField + Send>,
        rbf: Some(field),
        method: Method::Csrbf,
        support_radius: support.radius,
        carrier: Some(carrier_kind),
        carrier_bounds,
        local_fit,
        normalization,
        points,
        clean: clean_stats,
        support,
        matrix,
        residual,
        normals_flipped,
        normals_estimated,
        normals_reoriented,
        noise,
        smoothing: params.smoothing.lambda(),
        color_mode: point_colors.as_ref().map(|_| params.color),
        point_colors,
    })
}

/// The cleaned cloud in its three parallel forms (input units with attributes, normalised
/// points, colour values), which a filter must keep in step.
struct Cleaned<'a> {
    clean: &'a mut PointCloud,
    stats: &'a mut crate::clean::CleanStats,
    points: &'a mut Vec<Point3>,
    colors: &'a mut Option<Vec<[f32; 3]>>,
}

/// Drops the strays of a noisy cloud ([`crate::clean::strays`], noise level `sigma`) from every
/// form of it and counts them in the report; returns the index of the points left, `None` when
/// nothing was dropped (the old index still holds).
fn drop_strays(
    cloud: &mut Cleaned,
    index: &dyn SpatialIndex,
    sigma: f64,
    params: &ReconParams,
) -> Result<Option<Arc<dyn SpatialIndex + Send>>, ReconError> {
    let points = &*cloud.points;
    let stray = crate::clean::strays::strays(points, sigma, |p, k, out| index.nearest_k(p, k, out));
    let keep: Vec<usize> = (0..points.len()).filter(|&i| !stray[i]).collect();
    if keep.len() == points.len() {
        return Ok(None);
    }
    cloud.stats.strays_removed = points.len() - keep.len();
    cloud.stats.used = keep.len();
    *cloud.clean = cloud.clean.select(&keep);
    *cloud.points = keep.iter().map(|&i| points[i]).collect();
    *cloud.colors = (cloud.colors.take()).map(|c| keep.iter().map(|&i| c[i]).collect());
    let index = build_index(cloud.points, params.index, params.leaf_size)?;
    Ok(Some(Arc::from(index)))
}

/// Share of opposed neighbour normals above which the input's normals count as inconsistent.
const INCONSISTENT_NORMALS: f64 = 0.05;

/// When the input's normals are inconsistently oriented (more than 5% of sampled neighbour pairs
/// opposed), orient them by MST propagation before the carrier uses them. Returns how many were
/// flipped (0 when they were consistent or absent).
fn reorient_inconsistent_normals(
    clean: &mut PointCloud,
    points: &[Point3],
    index: &dyn SpatialIndex,
) -> usize {
    let Some(normals) = clean.normals.as_ref() else {
        return 0;
    };
    let share = crate::normals::inconsistent_fraction(points, normals, 8, |p, k, out| {
        index.nearest_k(p, k, out)
    });
    if share <= INCONSISTENT_NORMALS {
        return 0;
    }
    let (oriented, flipped) =
        crate::normals::reorient_normals(points, normals, &NormalParams::default());
    clean.normals = Some(oriented);
    flipped
}

/// Points per bucket of [`carrier_values`].
const CARRIER_BUCKET: usize = 64;

/// The carrier at every point: a local carrier's from the points gathered once per spatial bucket
/// of about [`CARRIER_BUCKET`] points ([`crate::rbf::carrier::LocalCarrier::gather`], the
/// polygonizer's sums: no index query per point), in parallel; an analytic one per point.
pub(crate) fn carrier_values(carrier: &Carrier, points: &[Point3]) -> Vec<f64> {
    let Carrier::Local(l) = carrier else {
        return points.par_iter().map(|p| carrier.value(p)).collect();
    };
    super::per_bucket(points, CARRIER_BUCKET, |_, pts| {
        let mut near = crate::rbf::carrier::NearPoints::new();
        l.gather(&Aabb::from_points(pts), &mut near);
        pts.iter().map(|p| l.value_near(p, &mut near)).collect()
    })
}

/// Fit the planned levels coarse to fine: level `l` interpolates `target`, what the carrier and the
/// coarser levels left at its centres; `target` is then updated at every point. The polynomial, when
/// asked, is fitted with the coarsest level. Returns the spline and the report.
pub(crate) fn fit_levels(
    points: &[Point3],
    index: &Arc<dyn SpatialIndex + Send>,
    plans: &[LevelPlan],
    mut target: Vec<f64>,
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<(Spline, MatrixReport), ReconError> {
    let mut levels = Vec::with_capacity(plans.len());
    let mut polynomial = None;
    let mut matrix = MatrixReport::default();
    for (l, plan) in plans.iter().enumerate() {
        let (centres, level_index) = if plan.members.len() == points.len() {
            (points.to_vec(), Arc::clone(index))
        } else {
            let c: Vec<Point3> = plan.members.iter().map(|&i| points[i as usize]).collect();
            let ix: Arc<dyn SpatialIndex + Send> =
                Arc::from(build_index(&c, params.index, params.leaf_size)?);
            (c, ix)
        };
        let rhs: Vec<f64> = plan.members.iter().map(|&i| target[i as usize]).collect();
        let rhs_rms = (rhs.iter().map(|v| v * v).sum::<f64>() / rhs.len().max(1) as f64).sqrt();
        let (a, perm, shape) = assemble_and_order(
            &centres,
            level_index.as_ref(),
            plan.radius,
            params,
            progress,
            timings,
        )?;
        let poly_kind = if l == 0 {
            params.polynomial
        } else {
            Polynomial::None
        };
        let solved = solve_weights(
            a, &perm.perm, &rhs, &centres, poly_kind, params, progress, timings,
        )?;
        let level = SplineLevel {
            centres,
            weights: solved.weights,
            support: plan.radius,
            index: level_index,
        };
        if l + 1 < plans.len() {
            subtract_level(
                &mut target,
                points,
                &level,
                params.kernel,
                solved.polynomial,
            );
        }
        polynomial = polynomial.or(solved.polynomial);
        matrix = MatrixReport {
            n: shape.n,
            nnz: shape.nnz,
            bandwidth: shape.bandwidth,
            profile_values: shape.profile_values,
            dense_values: shape.dense_values,
            factor_values: matrix.factor_values + solved.factor_values,
            solver_used: {
                let mut used = std::mem::take(&mut matrix.solver_used);
                used.add(solved.solver);
                used
            },
            levels: std::mem::take(&mut matrix.levels),
            blocks: 1,
        };
        matrix.levels.push(LevelReport {
            n: shape.n,
            nnz: shape.nnz,
            support: plan.radius,
            factor_values: solved.factor_values,
            iterations: solved.iterations,
            solver: solved.solver,
            rhs_rms,
        });
        levels.push(level);
        check_cancel(progress)?;
    }
    matrix.blocks = 1;
    Ok((Spline { levels, polynomial }, matrix))
}

/// `target_i −= s_l(P_i) + p(P_i)` for every point (parallel).
fn subtract_level(
    target: &mut [f64],
    points: &[Point3],
    level: &SplineLevel,
    kernel: Kernel,
    polynomial: Option<[f64; 4]>,
) {
    target
        .par_iter_mut()
        .zip(points.par_iter())
        .for_each_init(Vec::new, |hits, (t, p)| {
            *t -= level.value(kernel, p, hits) + linear_poly(polynomial, p);
        });
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
    progress.stage(crate::progress::Stage::Assemble);
    let t = Instant::now();
    let a = assemble_matrix(
        points,
        index,
        params.kernel,
        radius,
        params.smoothing.lambda(),
        progress,
    )?;
    timings.assemble += t.elapsed().as_secs_f64();
    progress.stage(crate::progress::Stage::Order);
    let t = Instant::now();
    let perm = compute_ordering(params.ordering, points, radius, &a, None)?;
    let shape = matrix_shape(&a, &perm)?;
    timings.order += t.elapsed().as_secs_f64();
    check_cancel(progress)?;
    Ok((a, perm, shape))
}

/// A solved level: weights, polynomial, factor size, iterations and the solver that ran.
struct Solved {
    weights: Vec<f64>,
    polynomial: Option<[f64; 4]>,
    factor_values: usize,
    iterations: Option<usize>,
    solver: &'static str,
}

/// Factorise `A` (or prepare conjugate gradients on it) and solve for the weights (and the linear
/// polynomial through the bordered system), within the memory budget (stages `factor`, `solve`).
#[allow(clippy::too_many_arguments)]
fn solve_weights(
    a: CsMat<f64>,
    perm: &[usize],
    rhs: &[f64],
    points: &[Point3],
    polynomial: Polynomial,
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<Solved, ReconError> {
    progress.stage(crate::progress::Stage::Factor);
    let t = Instant::now();
    let budget_values =
        (params.max_memory_mib as usize * (1 << 20) / 8).saturating_sub(2 * a.nnz());
    let solver = SolverParams {
        kind: params.solver,
        max_factor_values: budget_values,
        diagonal_shift: params.smoothing.lambda(),
        ..Default::default()
    };
    let (factor, fstats) = factorize_owned(a, Some(perm), &solver, progress)?;
    timings.factor += t.elapsed().as_secs_f64();
    progress.stage(crate::progress::Stage::Solve);
    let t = Instant::now();
    let (weights, poly) = match polynomial {
        Polynomial::None => {
            let mut x = rhs.to_vec();
            factor.solve_checked(&mut x)?;
            (x, None)
        }
        Polynomial::Linear => {
            let poly: Vec<[f64; 4]> = points.iter().map(|p| [1.0, p[0], p[1], p[2]]).collect();
            let (x, v) = solve_bordered(factor.as_ref(), &poly, rhs)?;
            (x, Some(v))
        }
    };
    timings.solve += t.elapsed().as_secs_f64();
    let iterations = factor.iterations();
    let solver = match (params.solver, iterations) {
        (_, Some(_)) => "cg",
        (SolverKind::Auto, None) => "sparse",
        (k, None) => k.name(),
    };
    Ok(Solved {
        weights,
        polynomial: poly,
        factor_values: fstats.factor_values.max(factor.factor_values()),
        iterations,
        solver,
    })
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
    progress.stage(crate::progress::Stage::Normals);
    clean.normals = Some(estimate_oriented_normals(points, &NormalParams::default()));
    true
}

/// Refuse before assembly when the matrix alone (values + indices, twice during assembly) would not fit.
/// With several levels the matrices hold about 4/3 of the finest level's values in all (levels
/// are fitted one after the other, so only one is alive at a time; the bound is conservative).
/// `alive` is the share of the points whose system is in memory at once (1 without blocks).
/// Blocks fitted at once ([`super::blocks::concurrent_blocks`], or one when two would not fit
/// `--max-memory-mib`), after checking that the systems alive at once fit it: the whole system,
/// or with blocks one wave of them (each core plus overlap: ~1.5× its core).
fn block_wave(
    support: &SupportEstimate,
    n: usize,
    levels: usize,
    params: &ReconParams,
) -> Result<usize, RbfError> {
    let alive = |wave: usize| {
        (params.blocks.max_points(n))
            .map_or(1.0, |m| (wave as f64 * 1.5 * m as f64 / n as f64).min(1.0))
    };
    let fits = |wave| check_memory(support, n, alive(wave), levels, params.max_memory_mib);
    let wave = super::blocks::concurrent_blocks();
    if wave > 1 && fits(wave).is_err() {
        fits(1)?;
        return Ok(1);
    }
    fits(wave)?;
    Ok(wave)
}

fn check_memory(
    s: &SupportEstimate,
    n: usize,
    alive: f64,
    levels: usize,
    budget_mib: u64,
) -> Result<(), RbfError> {
    let share = if levels > 1 { 4.0 / 3.0 } else { 1.0 } * alive;
    let mib = s.estimated_nnz * share * 32.0 / (1u64 << 20) as f64;
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
        // The winding number's integral decides; for an open sheet (about zero) the tangent planes
        // seen from the corners of a box around the data vote.
        let inward = local.points_inward().unwrap_or_else(|| {
            let outer = Aabb::from_points(points).inflated(0.25);
            let planes = |p: &Point3| local.nearest_planes(p);
            outer.corners().iter().filter(|p| planes(p) < 0.0).count() > 4
        });
        if inward {
            local.flip_normals();
            flipped = true;
        }
    }
    Ok((carrier, flipped))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rbf::Blocks;

    /// A support estimate whose whole system takes 100 MiB by [`check_memory`]'s rule.
    fn hundred_mib() -> SupportEstimate {
        SupportEstimate {
            radius: 0.01,
            mean_neighbours: 30.0,
            estimated_nnz: 100.0 * (1u64 << 20) as f64 / 32.0,
            spacing: 0.003,
        }
    }

    #[test]
    fn blocks_run_two_at_a_time_only_when_the_budget_holds_two() {
        // 10,000 points in blocks of 1,000: one block's system is 1.5 × 1,000 / 10,000 of the
        // whole, 15 MiB; two are 30 MiB.
        let params = |mib| ReconParams {
            blocks: Blocks::MaxPoints(1000),
            max_memory_mib: mib,
            ..ReconParams::default()
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        let s = hundred_mib();
        let wave = |mib| pool.install(|| block_wave(&s, 10_000, 1, &params(mib)));
        assert_eq!(wave(40).unwrap(), 2);
        assert_eq!(wave(20).unwrap(), 1);
        assert!(matches!(wave(10), Err(RbfError::TooLarge { .. })));
        // One thread: one block at a time whatever the budget.
        let single = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        assert_eq!(
            single
                .install(|| block_wave(&s, 10_000, 1, &params(1000)))
                .unwrap(),
            1
        );
        // Without blocks the whole system must fit.
        let whole = ReconParams {
            max_memory_mib: 99,
            ..ReconParams::default()
        };
        assert!(pool.install(|| block_wave(&s, 10_000, 1, &whole)).is_err());
    }
}
