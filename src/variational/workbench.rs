//! The 2D curves workbench behind `rbfsurf curve`: fit one method to samples, contour the zero set
//! with marching squares, analyse it and draw it. The CLI is a thin adapter over
//! [`run_workbench`]. Cost: the fit (dense `O(N³)` for Turk–O'Brien, none for MLS), then
//! `(grid + 1)²` field evaluations of `O(N)` each, then the analysis (see [`super::quality`]).

use std::time::Instant;

use crate::progress::{NoProgress, Progress};

use super::Frame;
use super::ImplicitField;
use super::constraints::{
    Offset, PseudoNormalParams, Sample, Sides, ValueConstraint, VariationalError,
};
use super::mlp::{MlpParams, Smoothing, TrainingInfo, fit_mlp, pseudo_points};
use super::mls::{MlsBasis, MlsNormals, MlsParams, WeightPower, fit_mls};
use super::quality::{CurveQuality, analyse, curvatures};
use super::svg::{SvgInput, render};
use super::turk_obrien::{FitInfo, NormalMode, TurkObrienParams, fit_turk_obrien};
use crate::polygonize::marching_squares::{Grid2, Polyline};

/// The fitting method (also the `rbfsurf curve --method` values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum CurveMethod {
    /// Turk–O'Brien with pseudo-normal points (default).
    TurkObrien,
    /// Turk–O'Brien with true normals as gradient (Hermite) constraints.
    TurkObrienNormals,
    /// Turk–O'Brien with Mann's three-solve true normals (§3.8; disconnects on Koch K1+).
    TurkObrienMann,
    /// Shen MLS, constant basis, pseudo-normals.
    ShenConstant,
    /// Shen MLS, linear basis, pseudo-normals.
    ShenLinear,
    /// Shen MLS, constant basis, true normals.
    ShenConstantNormals,
    /// Shen MLS, linear basis, true normals.
    ShenLinearNormals,
    /// Jiang & Turk's MLP with thin-plate energy at auxiliary points (module `variational::mlp`).
    Mlp,
    /// MLP baseline (a): no regulariser (λ = 0).
    MlpNoreg,
    /// MLP baseline (b): thin-plate energy at the constraint points only.
    MlpConstraintCurvature,
    /// MLP baseline (c): dropout instead of the thin-plate energy.
    MlpDropout,
}

impl CurveMethod {
    /// The MLP regulariser of an MLP method, `None` for the other methods.
    pub fn mlp_smoothing(self) -> Option<Smoothing> {
        match self {
            CurveMethod::Mlp => Some(Smoothing::AuxiliaryPoints),
            CurveMethod::MlpNoreg => Some(Smoothing::Off),
            CurveMethod::MlpConstraintCurvature => Some(Smoothing::ConstraintPoints),
            CurveMethod::MlpDropout => Some(Smoothing::Dropout),
            _ => None,
        }
    }
}

/// Workbench parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CurveParams {
    /// Method (default Turk–O'Brien with pseudo-normals).
    pub method: CurveMethod,
    /// Marching-squares cells along the longer side (default 200).
    pub grid: usize,
    /// Shen's `ε` in normalised units (default 0 = interpolating).
    pub epsilon: f64,
    /// Shen's weight exponent (default `Auto`: squared for true normals).
    pub weight: WeightPower,
    /// Pseudo-normal offset (default 0.1 of the median data spacing).
    pub offset: Offset,
    /// Margin around the data's bounding box, as a fraction of its longest edge (default 0.25).
    pub margin: f64,
    /// Explicit plot/sampling rectangle (input units), overriding `margin`.
    pub bounds: Option<([f64; 2], [f64; 2])>,
    /// Curvature shown as full red/blue, per normalised unit (default 5, as in Mann's plots).
    pub kappa_scale: f64,
    /// Distance (input units) within which a data point counts as on the curve; `None` = one cell
    /// diagonal.
    pub tolerance: Option<f64>,
    /// Network and training parameters of the MLP methods (the method sets the smoothing).
    pub mlp: MlpParams,
}

impl Default for CurveParams {
    fn default() -> Self {
        CurveParams {
            method: CurveMethod::TurkObrien,
            grid: 200,
            epsilon: 0.0,
            weight: WeightPower::Auto,
            offset: Offset::SpacingFraction(0.1),
            margin: 0.25,
            bounds: None,
            kappa_scale: 5.0,
            tolerance: None,
            mlp: MlpParams::default(),
        }
    }
}

/// Wall-clock times of the stages (seconds).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CurveTimings {
    /// Fit (assembly + solve for Turk–O'Brien; set-up for MLS).
    pub fit: f64,
    /// Grid sampling + marching squares.
    pub contour: f64,
    /// Quality analysis and SVG.
    pub analyse: f64,
}

/// The JSON report of one workbench run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CurveReport {
    /// Method used.
    pub method: CurveMethod,
    /// Number of input samples.
    pub samples: usize,
    /// Dense solve diagnostics (Turk–O'Brien only).
    pub solve: Option<FitInfo>,
    /// Network parameters (MLP methods only).
    pub mlp: Option<MlpParams>,
    /// Training summary (MLP methods only).
    pub training: Option<TrainingInfo>,
    /// Sampling grid.
    pub grid: Grid2,
    /// Quality of the zero set.
    pub quality: CurveQuality,
    /// Stage timings.
    pub timings_s: CurveTimings,
    /// Incremental update diagnostics (`rbfsurf curve --add`), absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub incremental: Option<super::editing::IncrementalReport>,
}

/// Everything a run produces.
#[derive(Debug, Clone)]
pub struct WorkbenchOutput {
    /// The SVG document.
    pub svg: String,
    /// The report.
    pub report: CurveReport,
    /// The contour.
    pub lines: Vec<Polyline>,
}

/// A fitted 2D field with what the plot needs.
pub struct FittedCurve {
    /// The field (input units).
    pub field: Box<dyn ImplicitField<2>>,
    /// Generated pseudo-normal points to draw.
    pub extra: Vec<ValueConstraint<2>>,
    /// Dense solve diagnostics.
    pub solve: Option<FitInfo>,
    /// Training summary (MLP methods).
    pub training: Option<TrainingInfo>,
}

/// Fit the chosen method.
pub fn fit_curve(samples: &[Sample<2>], p: &CurveParams) -> Result<FittedCurve, VariationalError> {
    fit_curve_with_progress(samples, p, &NoProgress)
}

/// Fit an MLP method over the workbench's sampling box.
fn fit_mlp_curve(
    samples: &[Sample<2>],
    p: &CurveParams,
    smoothing: Smoothing,
    progress: &dyn Progress,
) -> Result<FittedCurve, VariationalError> {
    let grid = grid_for(samples, p)?;
    let mp = MlpParams { smoothing, ..p.mlp };
    let fit = fit_mlp(samples, (grid.min, grid.max), p.offset, &mp, progress)?;
    Ok(FittedCurve {
        extra: pseudo_points(&fit),
        solve: None,
        training: Some(fit.info),
        field: Box::new(fit),
    })
}

/// [`fit_curve`] reporting to `progress` (MLP training epochs; the other fits are not staged).
pub fn fit_curve_with_progress(
    samples: &[Sample<2>],
    p: &CurveParams,
    progress: &dyn Progress,
) -> Result<FittedCurve, VariationalError> {
    use CurveMethod as M;
    let pseudo = |sides| PseudoNormalParams {
        offset: p.offset,
        sides,
    };
    let to = |normals| TurkObrienParams {
        normals,
        ..Default::default()
    };
    let (normals, basis) = match p.method {
        M::TurkObrien | M::TurkObrienNormals | M::TurkObrienMann => {
            let mode = match p.method {
                M::TurkObrien => NormalMode::Pseudo(pseudo(Sides::Outside)),
                M::TurkObrienNormals => NormalMode::Hermite,
                _ => NormalMode::MannFunctional,
            };
            let fit = fit_turk_obrien(samples, &to(mode))?;
            let extra = fit.constraints.clone();
            let solve = Some(fit.info);
            return Ok(FittedCurve {
                field: Box::new(fit),
                extra,
                solve,
                training: None,
            });
        }
        M::ShenConstant => (MlsNormals::Pseudo(pseudo(Sides::Both)), MlsBasis::Constant),
        M::ShenLinear => (MlsNormals::Pseudo(pseudo(Sides::Both)), MlsBasis::Linear),
        M::ShenConstantNormals => (MlsNormals::True, MlsBasis::Constant),
        M::ShenLinearNormals => (MlsNormals::True, MlsBasis::Linear),
        M::Mlp | M::MlpNoreg | M::MlpConstraintCurvature | M::MlpDropout => {
            let sm = p
                .method
                .mlp_smoothing()
                .unwrap_or(Smoothing::AuxiliaryPoints);
            return fit_mlp_curve(samples, p, sm, progress);
        }
    };
    let f = fit_mls(
        samples,
        &MlsParams {
            basis,
            normals,
            epsilon: p.epsilon,
            weight: p.weight,
        },
    )?;
    let extra = if let MlsNormals::Pseudo(pp) = normals {
        let frame = f.frame;
        let norm: Vec<Sample<2>> = samples
            .iter()
            .map(|s| Sample {
                p: frame.forward(&s.p),
                ..*s
            })
            .collect();
        let mut c = super::constraints::expand_pseudo_normals(&norm, &pp, 1.0)?;
        c.iter_mut().for_each(|v| v.p = frame.inverse(&v.p));
        c
    } else {
        Vec::new()
    };
    Ok(FittedCurve {
        field: Box::new(f),
        extra,
        solve: None,
        training: None,
    })
}

/// The sampling grid for `samples` under `p` (square cells, `p.grid` along the longer side).
pub fn grid_for(samples: &[Sample<2>], p: &CurveParams) -> Result<Grid2, VariationalError> {
    if p.grid < 2 || p.grid > 10_000 {
        return Err(VariationalError::InvalidParameter {
            name: "grid",
            value: p.grid as f64,
            reason: "must be 2..=10000",
        });
    }
    let (lo, hi) = p.bounds.unwrap_or_else(|| {
        let f = Frame::of_points(samples.iter().map(|s| s.p));
        let m = p.margin * f.scale;
        let lo = [0, 1].map(|k| samples.iter().map(|s| s.p[k]).fold(f64::INFINITY, f64::min) - m);
        let hi = [0, 1].map(|k| {
            samples
                .iter()
                .map(|s| s.p[k])
                .fold(f64::NEG_INFINITY, f64::max)
                + m
        });
        (lo, hi)
    });
    let (wx, wy) = (hi[0] - lo[0], hi[1] - lo[1]);
    if !(wx > 0.0 && wy > 0.0 && wx.is_finite() && wy.is_finite()) {
        return Err(VariationalError::InvalidParameter {
            name: "bounds",
            value: wx.min(wy),
            reason: "need a non-empty finite rectangle",
        });
    }
    let cell = wx.max(wy) / p.grid as f64;
    Ok(Grid2 {
        min: lo,
        max: hi,
        nx: ((wx / cell).round() as usize).max(1),
        ny: ((wy / cell).round() as usize).max(1),
    })
}

/// Contour a field over `grid`, evaluating only nodes near the zero set (blocks where the field
/// proves its sign, [`ImplicitField::sign_on_ball`], are skipped; same curve as the full grid).
pub fn contour_field(field: &dyn ImplicitField<2>, grid: &Grid2) -> Vec<Polyline> {
    super::adaptive::contour_adaptive(field, grid)
}

/// Fit, contour, analyse and draw.
///
/// ```
/// use rbfsurf::variational::{datasets, run_workbench, CurveParams};
/// let out = run_workbench(&datasets::koch(1), &CurveParams { grid: 80, ..Default::default() }).unwrap();
/// assert_eq!(out.report.quality.components, 1);
/// assert!(out.svg.starts_with("<svg"));
/// ```
pub fn run_workbench(
    samples: &[Sample<2>],
    p: &CurveParams,
) -> Result<WorkbenchOutput, VariationalError> {
    run_workbench_with_progress(samples, p, &NoProgress)
}

/// [`run_workbench`] reporting to `progress` (stage `"train"` with a fraction per epoch for the
/// MLP methods, then `"contour"`); `Cancelled` when it asks to stop.
pub fn run_workbench_with_progress(
    samples: &[Sample<2>],
    p: &CurveParams,
    progress: &dyn Progress,
) -> Result<WorkbenchOutput, VariationalError> {
    let t0 = Instant::now();
    let fitted = fit_curve_with_progress(samples, p, progress)?;
    progress.stage(crate::progress::Stage::Contour);
    finish_workbench(samples, fitted, p, t0.elapsed().as_secs_f64())
}

/// Contour, analyse and draw an already fitted field (`fit_s`: the fit time to report).
pub fn finish_workbench(
    samples: &[Sample<2>],
    fitted: FittedCurve,
    p: &CurveParams,
    fit_s: f64,
) -> Result<WorkbenchOutput, VariationalError> {
    let t1 = Instant::now();
    let grid = grid_for(samples, p)?;
    let field = |x: &[f64; 2]| fitted.field.value(x);
    let lines = contour_field(fitted.field.as_ref(), &grid);
    let t2 = Instant::now();
    let frame = Frame::of_points(samples.iter().map(|s| s.p));
    let kappa = curvatures(&field, &lines, 1e-4 * frame.scale);
    let tol = p.tolerance.unwrap_or(grid.cell_diagonal());
    let quality = analyse(&field, samples, &lines, &kappa, tol);
    let title = format!(
        "{:?}: {} components, {} extra",
        p.method, quality.components, quality.extra_loops
    );
    let svg = render(&SvgInput {
        bounds: (grid.min, grid.max),
        lines: &lines,
        kappa: &kappa,
        kappa_scale: p.kappa_scale / frame.scale,
        samples,
        extra: &fitted.extra,
        title: &title,
    });
    let timings_s = CurveTimings {
        fit: fit_s,
        contour: (t2 - t1).as_secs_f64(),
        analyse: t2.elapsed().as_secs_f64(),
    };
    let report = CurveReport {
        method: p.method,
        samples: samples.len(),
        solve: fitted.solve,
        mlp: p
            .method
            .mlp_smoothing()
            .map(|smoothing| MlpParams { smoothing, ..p.mlp }),
        training: fitted.training,
        grid,
        quality,
        timings_s,
        incremental: None,
    };
    Ok(WorkbenchOutput { svg, report, lines })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variational::datasets;

    fn run(name: &str, method: CurveMethod, f: impl Fn(&mut CurveParams)) -> WorkbenchOutput {
        let mut p = CurveParams {
            method,
            grid: 120,
            margin: 0.5,
            ..Default::default()
        };
        f(&mut p);
        run_workbench(&datasets::by_name(name).unwrap(), &p).unwrap()
    }

    /// Mann §3.1/§3.5 and Fig. 20/22: constant Shen with pseudo-normals does not give one closed
    /// curve through the data (isolated zeros, or branches that bulge off to the sampling border)
    /// and bulges far beyond the square; the linear variants give one closed loop.
    #[test]
    fn shen_constant_pseudo_fails_where_linear_does_not() {
        for name in ["koch0", "square"] {
            let c = run(name, CurveMethod::ShenConstant, |_| {}).report.quality;
            let good =
                c.components == 1 && c.closed_loops == 1 && c.interpolation_failures.is_empty();
            assert!(!good, "{name}: {c:?}");
            for m in [CurveMethod::ShenLinear, CurveMethod::ShenLinearNormals] {
                let q = run(name, m, |_| {}).report.quality;
                let good =
                    q.components == 1 && q.closed_loops == 1 && q.interpolation_failures.is_empty();
                assert!(good, "{name} {m:?}: {q:?}");
            }
        }
        let square = |m| {
            run("square", m, |p| {
                p.bounds = Some(([-3.0, -3.0], [3.0, 3.0]));
                p.offset = Offset::Normalized(0.05);
            })
            .report
            .quality
        };
        let (c, l) = (
            square(CurveMethod::ShenConstant),
            square(CurveMethod::ShenLinear),
        );
        assert!(c.max_distance_to_data_polygon.unwrap() > 1.0, "{c:?}");
        assert!(l.max_distance_to_data_polygon.unwrap() < 0.8, "{l:?}");
    }

    /// Mann §3.9: constant Shen concentrates curvature (lumpy); linear with true normals (our MLS
    /// default) is the acceptable variant — one loop through all data on Shen's 27 points and K0–K3.
    #[test]
    fn shen_constant_is_lumpy_linear_true_normals_is_clean() {
        let kmax = |q: &CurveQuality| q.curvature_max.abs().max(q.curvature_min.abs());
        let c = run("shen27", CurveMethod::ShenConstant, |_| {})
            .report
            .quality;
        let l = run("shen27", CurveMethod::ShenLinearNormals, |_| {})
            .report
            .quality;
        assert!(kmax(&c) > 10.0 * kmax(&l), "{} vs {}", kmax(&c), kmax(&l));
        for name in ["shen27", "koch0", "koch1", "koch2", "koch3", "circle8"] {
            let q = run(name, CurveMethod::ShenLinearNormals, |_| {})
                .report
                .quality;
            assert_eq!(
                (q.components, q.closed_loops, q.extra_loops),
                (1, 1, 0),
                "{name}"
            );
            assert!(
                q.interpolation_failures.is_empty() && q.max_abs_residual_at_data == 0.0,
                "{name}"
            );
        }
    }

    /// Mann Fig. 21 and 27: with ε > 0 the constant curve grows past the data, the linear one
    /// shrinks inside it.
    #[test]
    fn epsilon_grows_constant_and_shrinks_linear() {
        let s = datasets::shen27();
        let mean_f = |m| {
            let p = CurveParams {
                method: m,
                epsilon: 0.15,
                ..Default::default()
            };
            let f = fit_curve(&s, &p).unwrap().field;
            s.iter().map(|x| f.value(&x.p)).sum::<f64>() / s.len() as f64
        };
        assert!(mean_f(CurveMethod::ShenConstant) < 0.0);
        assert!(mean_f(CurveMethod::ShenLinear) > 0.0);
    }

    #[test]
    fn report_serialises_and_bad_grid_is_an_error() {
        let out = run("koch1", CurveMethod::TurkObrien, |_| {});
        let j = serde_json::to_value(&out.report).unwrap();
        assert_eq!(j["method"], "turk-obrien");
        assert_eq!(j["quality"]["components"], 1);
        assert!(j["solve"]["rcond"].as_f64().unwrap() > 0.0);
        let p = CurveParams {
            grid: 1,
            ..Default::default()
        };
        assert!(matches!(
            run_workbench(&datasets::koch(1), &p),
            Err(VariationalError::InvalidParameter { name: "grid", .. })
        ));
    }
}
