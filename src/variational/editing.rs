//! Interactive editing of a 2D Turk–O'Brien curve: constraints of a second sample set are added
//! to the solved system by the Schur-complement update of [`IncrementalSystem`] (Jiang & Turk)
//! instead of refitting, then contoured and drawn like [`super::run_workbench`].
//!
//! The extra samples use the base's normalisation frame and the base's pseudo-normal offset
//! distance, so the combined constraint set is exactly the one a fresh solve would see; the run
//! also performs that fresh solve (timed) and reports the largest coefficient and value
//! differences. Cost: `O(N³/3)` for the base factor (done once per editing run in an interactive
//! tool), `O(N²M)` for the update, against `O((N+M)³/3)` for the fresh solve.

use std::time::Instant;

use super::Frame;
use super::constraints::{
    Offset, PseudoNormalParams, Sample, Sides, ValueConstraint, VariationalError,
    expand_pseudo_normals, offset_distance, validate_samples,
};
use super::incremental::IncrementalSystem;
use super::kernel::{RadialKernel, RbfExpansion};
use super::turk_obrien::{FitInfo, TurkObrienFit};
use super::workbench::{CurveMethod, CurveParams, FittedCurve, WorkbenchOutput, finish_workbench};

/// What the incremental update cost and how far it is from a fresh solve.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct IncrementalReport {
    /// Value constraints of the base system (samples + pseudo-normal points).
    pub base_constraints: usize,
    /// Samples read from the extra file.
    pub added_samples: usize,
    /// Value constraints added (extra samples + their pseudo-normal points).
    pub added_constraints: usize,
    /// Base factor + solve (s).
    pub base_solve_s: f64,
    /// Schur-complement update (s).
    pub update_s: f64,
    /// Fresh factor + solve of the combined system (s).
    pub fresh_solve_s: f64,
    /// `fresh_solve_s / update_s`.
    pub speedup: f64,
    /// Largest coefficient difference (weights and polynomial) relative to the largest fresh
    /// coefficient.
    pub max_coefficient_difference_rel: f64,
    /// Largest `|f_update − f_fresh|` at the constraints (normalised units).
    pub max_value_difference: f64,
    /// True when the batch was larger than the update threshold and the system was refactored.
    pub rebased: bool,
}

fn normalise(frame: &Frame<2>, s: &[Sample<2>]) -> Vec<Sample<2>> {
    s.iter()
        .map(|x| Sample {
            p: frame.forward(&x.p),
            ..*x
        })
        .collect()
}

fn coefficients(e: &RbfExpansion<2>) -> impl Iterator<Item = f64> + '_ {
    e.alpha.iter().chain(&e.poly).copied()
}

/// Fit `base` with Turk–O'Brien (pseudo-normals outside), add the constraints of `extra` by the
/// Schur-complement update, contour, analyse and draw the combined curve. The report's
/// `incremental` field holds the timings and differences against a fresh solve.
///
/// Errors: [`VariationalError::InvalidParameter`] unless `p.method` is
/// [`CurveMethod::TurkObrien`]; the usual validation errors (rows of `extra` counted from 0 in
/// that set); coincident base/extra points with different values.
pub fn run_workbench_incremental(
    base: &[Sample<2>],
    extra: &[Sample<2>],
    p: &CurveParams,
) -> Result<WorkbenchOutput, VariationalError> {
    if p.method != CurveMethod::TurkObrien {
        return Err(VariationalError::InvalidParameter {
            name: "method",
            value: 0.0,
            reason: "adding constraints incrementally works with turk-obrien (value constraints \
                     with pseudo-normals) only; refit with the other methods",
        });
    }
    validate_samples(base)?;
    validate_samples(extra)?;
    let t0 = Instant::now();
    let frame = Frame::of_points(base.iter().map(|s| s.p));
    let (nb, ne) = (normalise(&frame, base), normalise(&frame, extra));
    let delta = offset_distance(&nb, &p.offset, 1.0)?;
    let pp = PseudoNormalParams {
        offset: Offset::Normalized(delta),
        sides: Sides::Outside,
    };
    let base_c = expand_pseudo_normals(&nb, &pp, 1.0)?;
    let extra_c = expand_pseudo_normals(&ne, &pp, 1.0)?;
    let kernel = RadialKernel::ThinPlate;
    let mut inc = IncrementalSystem::new(&base_c, kernel)?;
    let base_solve_s = t0.elapsed().as_secs_f64();
    let rebased = extra_c.len() > inc.rebase_above;
    let t1 = Instant::now();
    inc.add(&extra_c)?;
    let update_s = t1.elapsed().as_secs_f64();
    let all: Vec<ValueConstraint<2>> = inc.constraints();
    let t2 = Instant::now();
    let fresh = IncrementalSystem::new(&all, kernel)?;
    let fresh_solve_s = t2.elapsed().as_secs_f64();
    let (e, ef) = (inc.expansion(), fresh.expansion());
    let scale = coefficients(&ef).map(f64::abs).fold(0.0, f64::max);
    let coef_diff = coefficients(&e)
        .zip(coefficients(&ef))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let pts: Vec<[f64; 2]> = all.iter().map(|c| c.p).collect();
    let (mut v, mut vf) = (vec![0.0; pts.len()], vec![0.0; pts.len()]);
    e.values_into(&pts, &mut v);
    ef.values_into(&pts, &mut vf);
    let max_value_difference = v
        .iter()
        .zip(&vf)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let max_residual = v
        .iter()
        .zip(&all)
        .map(|(a, c)| (a - c.value).abs())
        .fold(0.0, f64::max);
    let report = IncrementalReport {
        base_constraints: base_c.len(),
        added_samples: extra.len(),
        added_constraints: extra_c.len(),
        base_solve_s,
        update_s,
        fresh_solve_s,
        speedup: fresh_solve_s / update_s.max(1e-12),
        max_coefficient_difference_rel: if scale > 0.0 {
            coef_diff / scale
        } else {
            coef_diff
        },
        max_value_difference,
        rebased,
    };
    let info = FitInfo {
        unknowns: all.len() + 3,
        rcond: inc.rcond(),
        max_residual,
        kernel,
    };
    let constraints: Vec<ValueConstraint<2>> = all
        .iter()
        .map(|c| ValueConstraint {
            p: frame.inverse(&c.p),
            ..*c
        })
        .collect();
    let fitted = FittedCurve {
        field: Box::new(TurkObrienFit {
            frame,
            parts: vec![e],
            info,
            constraints: constraints.clone(),
        }),
        extra: constraints,
        solve: Some(info),
        training: None,
    };
    let samples: Vec<Sample<2>> = base.iter().chain(extra).copied().collect();
    let mut out = finish_workbench(&samples, fitted, p, base_solve_s + update_s)?;
    out.report.incremental = Some(report);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variational::datasets;

    fn circle(n: usize, phase: f64) -> Vec<Sample<2>> {
        (0..n)
            .map(|k| {
                let a = phase + k as f64 * std::f64::consts::TAU / n as f64;
                Sample::on_curve([a.cos(), a.sin()], Some([a.cos(), a.sin()]))
            })
            .collect()
    }

    /// The update equals a fresh solve of the same constraints, and the added points are on the
    /// curve.
    #[test]
    fn added_constraints_match_fresh_solve_and_are_interpolated() {
        let base = datasets::koch(2);
        // Extra points on the snowflake's circumcircle-ish: pull the curve out at three places.
        let extra = circle(3, 0.3)
            .into_iter()
            .map(|s| Sample {
                p: [s.p[0] * 0.75, s.p[1] * 0.75],
                ..s
            })
            .collect::<Vec<_>>();
        let p = CurveParams {
            grid: 100,
            ..Default::default()
        };
        let out = run_workbench_incremental(&base, &extra, &p).unwrap();
        let r = out.report.incremental.unwrap();
        assert_eq!(r.added_samples, 3);
        assert_eq!(r.added_constraints, 6);
        assert_eq!(r.base_constraints, 2 * base.len());
        assert!(!r.rebased);
        assert!(r.max_coefficient_difference_rel <= 1e-9, "{r:?}");
        assert!(r.max_value_difference <= 1e-9, "{r:?}");
        assert!(out.report.solve.unwrap().max_residual <= 1e-9);
        assert!(out.report.quality.interpolation_failures.is_empty());
        let j = serde_json::to_value(&out.report).unwrap();
        for k in [
            "update_s",
            "fresh_solve_s",
            "max_coefficient_difference_rel",
        ] {
            assert!(j["incremental"][k].is_number(), "{k}");
        }
    }

    #[test]
    fn other_methods_and_bad_extra_are_errors() {
        let base = circle(12, 0.0);
        let p = CurveParams {
            method: CurveMethod::ShenLinear,
            ..Default::default()
        };
        assert!(matches!(
            run_workbench_incremental(&base, &circle(2, 0.1), &p),
            Err(VariationalError::InvalidParameter { name: "method", .. })
        ));
        // A point coincident with a base point but with another value.
        let clash = vec![Sample {
            value: -1.0,
            ..base[3]
        }];
        let err = run_workbench_incremental(&base, &clash, &CurveParams::default());
        assert!(err.is_err());
        // The field of an accepted edit is the combined curve.
        let out =
            run_workbench_incremental(&base, &circle(4, 0.2), &CurveParams::default()).unwrap();
        assert_eq!(out.report.samples, 16);
        assert_eq!(out.report.quality.components, 1);
        assert!(out.report.quality.interpolation_failures.is_empty());
    }
}
