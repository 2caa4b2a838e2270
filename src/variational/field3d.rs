//! 3D entry points: Turk–O'Brien and Shen MLS fields for the polygonizer
//! ([`crate::polygonize::ScalarField`], `f < 0` inside, gradient outwards).
//!
//! Both take points (normalised units, n × 3) and optional outward normals (n × 3, any length).
//! Set-up cost: Turk–O'Brien `O(N³/3)` dense `LBLᵀ` with `N ≈ 2n + 4` (pseudo-normals) or
//! `4n + 4` (Hermite); MLS `O(n)`. Evaluation is `O(n)` per point for both.
//!
//! Cell test (`may_contain_zero`): Turk–O'Brien proves a sign when `|f(c)| > B`, `B` a bound of
//! `|f − f(c)|` on the cell's circumscribed ball from the exact gradient and Hessian at `c` plus a
//! third-derivative remainder ([`super::kernel::RbfExpansion::variation_bound`]); one `O(n)` pass
//! per cell. MLS constant: an interval bound of `Σ w_i d_i` (see
//! [`super::mls::MlsField::may_change_sign`]); MLS linear: always `true` (no cheap bound).

use super::ImplicitField;
use super::constraints::{Sample, VariationalError};
use super::mls::{MlsField, MlsParams, fit_mls};
use super::turk_obrien::{TurkObrienFit, TurkObrienParams};
use crate::geometry::{Aabb, Point3};
use crate::polygonize::ScalarField;

/// Parameters of the 3D variational fits (one nested struct per method).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct VariationalParams {
    /// Turk–O'Brien parameters (default: pseudo-normals at 0.1 of the median spacing, `r³`).
    pub turk_obrien: TurkObrienParams,
    /// Shen MLS parameters (default: linear basis, true normals, `ε = 0`).
    pub mls: MlsParams,
}

/// A Turk–O'Brien field in 3D.
#[derive(Debug, Clone)]
pub struct VariationalField3 {
    /// The solved fit (with its diagnostics in `fit.info`).
    pub fit: TurkObrienFit<3>,
}

/// A Shen MLS field in 3D.
#[derive(Debug, Clone)]
pub struct MlsField3 {
    /// The field.
    pub field: MlsField<3>,
}

/// Fit Turk–O'Brien to a 3D point set (normalised units).
///
/// ```
/// use rbfsurf::variational::{fit_variational_3d, VariationalParams};
/// use rbfsurf::polygonize::ScalarField;
/// let p: Vec<[f64; 3]> = (0..40).map(|k| {
///     let z = 1.0 - 2.0 * (k as f64 + 0.5) / 40.0;
///     let r = (1.0 - z * z).sqrt();
///     let a = k as f64 * 2.399963;
///     [0.5 + 0.4 * r * a.cos(), 0.5 + 0.4 * r * a.sin(), 0.5 + 0.4 * z]
/// }).collect();
/// let n: Vec<[f64; 3]> = p.iter().map(|q| [q[0] - 0.5, q[1] - 0.5, q[2] - 0.5]).collect();
/// let f = fit_variational_3d(&p, Some(&n), &VariationalParams::default()).unwrap();
/// assert!(f.value(&[0.5, 0.5, 0.5]) < 0.0 && f.value(&[1.2, 0.5, 0.5]) > 0.0);
/// ```
pub fn fit_variational_3d(
    points: &[Point3],
    normals: Option<&[Point3]>,
    params: &VariationalParams,
) -> Result<VariationalField3, VariationalError> {
    fit_variational_3d_with(points, normals, params, &crate::progress::NoProgress)
}

/// [`fit_variational_3d`] that stops with [`VariationalError::Cancelled`] soon after
/// `progress.cancelled()` turns true (also inside the dense factorisation).
pub fn fit_variational_3d_with(
    points: &[Point3],
    normals: Option<&[Point3]>,
    params: &VariationalParams,
    progress: &dyn crate::progress::Progress,
) -> Result<VariationalField3, VariationalError> {
    let s = samples_3d(points, normals)?;
    Ok(VariationalField3 {
        fit: super::turk_obrien::fit_turk_obrien_with(&s, &params.turk_obrien, progress)?,
    })
}

/// Fit Shen's MLS implicit to a 3D point set (normalised units).
pub fn fit_mls_3d(
    points: &[Point3],
    normals: Option<&[Point3]>,
    params: &VariationalParams,
) -> Result<MlsField3, VariationalError> {
    let s = samples_3d(points, normals)?;
    Ok(MlsField3 {
        field: fit_mls(&s, &params.mls)?,
    })
}

/// Samples from points and optional normals (checks the lengths).
pub(super) fn samples_3d(
    points: &[Point3],
    normals: Option<&[Point3]>,
) -> Result<Vec<Sample<3>>, VariationalError> {
    if let Some(n) = normals
        && n.len() != points.len()
    {
        return Err(VariationalError::LengthMismatch {
            points: points.len(),
            normals: n.len(),
        });
    }
    Ok(points
        .iter()
        .enumerate()
        .map(|(i, &p)| Sample::on_curve(p, normals.map(|n| n[i])))
        .collect())
}

fn ball(cell: &Aabb) -> (Point3, f64) {
    (cell.center(), 0.5 * cell.diagonal())
}

impl ScalarField for VariationalField3 {
    fn value(&self, p: &Point3) -> f64 {
        ImplicitField::value(&self.fit, p)
    }

    fn gradient(&self, p: &Point3) -> Point3 {
        ImplicitField::gradient(&self.fit, p)
    }

    /// Vectorised batch ([`crate::variational::batch`]), same values as [`ScalarField::value`].
    fn values_in(&self, _region: &Aabb, points: &[Point3], out: &mut [f64]) {
        ImplicitField::values(&self.fit, points, out);
    }

    fn may_contain_zero(&self, cell: &Aabb) -> bool {
        let (c, rho) = ball(cell);
        let u = self.fit.frame.forward(&c);
        let rho = rho / self.fit.frame.scale;
        let f = self.fit.value_normalized(&u);
        let bound = self.fit.variation_bound_normalized(&u, rho) * (1.0 + 1e-9);
        // NaN-safe: only a proven margin skips the cell.
        f.abs().partial_cmp(&bound) != Some(std::cmp::Ordering::Greater)
    }
}

impl ScalarField for MlsField3 {
    fn value(&self, p: &Point3) -> f64 {
        ImplicitField::value(&self.field, p)
    }

    fn gradient(&self, p: &Point3) -> Point3 {
        ImplicitField::gradient(&self.field, p)
    }

    fn may_contain_zero(&self, cell: &Aabb) -> bool {
        let (c, rho) = ball(cell);
        self.field
            .may_change_sign(&self.field.frame.forward(&c), rho / self.field.frame.scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variational::turk_obrien::NormalMode;

    fn sphere(n: usize) -> (Vec<Point3>, Vec<Point3>) {
        let p: Vec<Point3> = (0..n)
            .map(|k| {
                let z = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let a = k as f64 * 2.399963229728653;
                [
                    0.5 + 0.4 * r * a.cos(),
                    0.5 + 0.4 * r * a.sin(),
                    0.5 + 0.4 * z,
                ]
            })
            .collect();
        let nrm = p
            .iter()
            .map(|q| [q[0] - 0.5, q[1] - 0.5, q[2] - 0.5])
            .collect();
        (p, nrm)
    }

    #[test]
    fn sphere_fields_are_close_to_the_sphere() {
        let (p, n) = sphere(150);
        let mut params = VariationalParams::default();
        let fields: Vec<Box<dyn ScalarField>> = vec![
            Box::new(fit_variational_3d(&p, Some(&n), &params).unwrap()),
            {
                params.turk_obrien.normals = NormalMode::Hermite;
                Box::new(fit_variational_3d(&p, Some(&n), &params).unwrap())
            },
            Box::new(fit_mls_3d(&p, Some(&n), &params).unwrap()),
        ];
        for (k, f) in fields.iter().enumerate() {
            for q in &p {
                assert!(f.value(q).abs() < 1e-8, "field {k}");
            }
            // Radial probes: the sign changes once, near radius 0.4.
            for d in [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.6, 0.0, 0.8]] {
                let at = |r: f64| f.value(&[0.5 + r * d[0], 0.5 + r * d[1], 0.5 + r * d[2]]);
                assert!(at(0.3) < 0.0 && at(0.5) > 0.0, "field {k}");
            }
            let g = f.gradient(&p[3]);
            assert!(
                g[0] * n[3][0] + g[1] * n[3][1] + g[2] * n[3][2] > 0.0,
                "field {k}: outward gradient"
            );
        }
    }

    #[test]
    fn cell_test_is_conservative() {
        let (p, n) = sphere(80);
        let f = fit_variational_3d(&p, Some(&n), &VariationalParams::default()).unwrap();
        let h = 0.05;
        let mut skipped = 0;
        for i in 0..20 {
            for j in 0..20 {
                let lo = [i as f64 * h, j as f64 * h, 0.5];
                let cell = Aabb {
                    min: lo,
                    max: [lo[0] + h, lo[1] + h, 0.5 + h],
                };
                if !f.may_contain_zero(&cell) {
                    skipped += 1;
                    let s: Vec<bool> = (0..27)
                        .map(|k| {
                            let t = [
                                (k % 3) as f64 / 2.0,
                                ((k / 3) % 3) as f64 / 2.0,
                                (k / 9) as f64 / 2.0,
                            ];
                            f.value(&[lo[0] + t[0] * h, lo[1] + t[1] * h, 0.5 + t[2] * h]) < 0.0
                        })
                        .collect();
                    assert!(s.iter().all(|&b| b == s[0]));
                }
            }
        }
        assert!(
            skipped > 100,
            "the bound should skip most cells far from the sphere ({skipped})"
        );
        assert!(matches!(
            fit_mls_3d(&p, Some(&n[..3]), &VariationalParams::default()),
            Err(VariationalError::LengthMismatch {
                points: 80,
                normals: 3
            })
        ));
    }
}
