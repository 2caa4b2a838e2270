//! The global (dense) methods behind `--method variational|mls`: same cleaning, normalisation,
//! polygonization and report as the CSRBF pipeline; only the fit differs (`crate::variational`).

use super::{FittedField, check_cancel, clean_and_normalize, residual_at};
use crate::error::ReconError;
use crate::geometry::PointCloud;
use crate::params::{Method, ReconParams};
use crate::polygonize::ScalarField;
use crate::progress::Progress;
use crate::rbf::{Support, estimate_support};
use crate::report::{MatrixReport, Timings};
use crate::spatial::{IndexKind, build_index};
use crate::variational::{VariationalParams, fit_mls_3d, fit_variational_3d_with};
use std::time::Instant;

/// Fit Turk–O'Brien (`r³`, pseudo-normals, dense LBLᵀ) or Shen's MLS to the cleaned, normalised cloud.
/// The fit's time is reported under `factor`; `matrix` describes the dense system (MLS has none: n = 0).
pub(super) fn fit_global(
    cloud: &PointCloud,
    params: &ReconParams,
    progress: &dyn Progress,
    timings: &mut Timings,
) -> Result<FittedField, ReconError> {
    let (clean, clean_stats, normalization, points) =
        clean_and_normalize(cloud, params, progress, timings)?;
    let point_colors = super::point_colors(&clean, params);
    progress.stage(crate::progress::Stage::Index);
    let t = Instant::now();
    let index = build_index(&points, IndexKind::KdTree, 16)?;
    let support = estimate_support(&points, index.as_ref(), Support::Neighbours(8))?;
    timings.index = t.elapsed().as_secs_f64();
    check_cancel(progress)?;
    progress.stage(crate::progress::Stage::Factor);
    let t = Instant::now();
    let vp = VariationalParams::default();
    let normals = clean.normals.as_deref();
    let (field, matrix): (std::sync::Arc<dyn ScalarField + Send>, MatrixReport) =
        match params.method {
            Method::Mls => (
                std::sync::Arc::new(fit_mls_3d(&points, normals, &vp)?),
                MatrixReport::default(),
            ),
            _ => {
                let f = fit_variational_3d_with(&points, normals, &vp, progress)?;
                let n = f.fit.info.unknowns;
                let dense = MatrixReport {
                    n,
                    nnz: n * n,
                    bandwidth: n.saturating_sub(1),
                    profile_values: n * (n + 1) / 2,
                    dense_values: n * n,
                    factor_values: n * n,
                    solver_used: crate::report::SolversUsed::one("dense-lblt"),
                    levels: Vec::new(),
                    blocks: 1,
                };
                (std::sync::Arc::new(f), dense)
            }
        };
    timings.factor = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let residual = residual_at(field.as_ref(), &points, progress)?;
    timings.residual = t.elapsed().as_secs_f64();
    Ok(FittedField {
        far_field: None,
        field,
        rbf: None,
        method: params.method,
        support_radius: 4.0 * support.spacing,
        carrier: None,
        carrier_bounds: None,
        local_fit: None,
        normalization,
        points,
        clean: clean_stats,
        support,
        matrix,
        residual,
        normals_flipped: false,
        normals_estimated: false,
        normals_reoriented: 0,
        noise: Default::default(),
        smoothing: 0.0,
        color_mode: point_colors.as_ref().map(|_| params.color),
        point_colors,
    })
}
