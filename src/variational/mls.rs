//! Shen's moving-least-squares implicit (Shen 2007 thesis ch. 3–4; Shen, O'Brien & Shewchuk 2004),
//! in the four variants Mann tested (CS-2013-09 §3): constant or linear polynomial × pseudo-normal
//! points or true normals.
//!
//! At an evaluation point `x` the field is the weighted least-squares fit of a polynomial to data
//! `d_i(x)`, evaluated at `x`:
//! - pseudo-normals: `d_i = v_i` at the data points and at offset points `p ± δn` (values `±δ`);
//! - true normals: `d_i(x) = S_i(x) = v_i + (x − x_i)·n_i` (Shen's normal functions; applying the
//!   MLS to each coefficient `φ_ki` and recombining, as Mann does, gives exactly this because the
//!   MLS is linear in the data at fixed `x`).
//!
//! Weights `w(r) = 1/(r² + ε²)^p` with `p = 1` for pseudo-normals and `p = 2` for true normals
//! (Mann: Shen's eq. 3.18 squares `W`, and only the squared weight gives a usable constant
//! true-normal curve). `ε = 0` interpolates (`f(x_i) = v_i`, returned exactly at a data point),
//! `ε > 0` approximates.
//!
//! Numerics (Mann §3.7 saw the 3×3 normal equations go singular within 0.002 of a data point):
//! weights are rescaled by the largest one, the linear basis is centred at `x` (`f(x) = c_0`), the
//! small system is Jacobi-equilibrated and solved by Gaussian elimination with partial pivoting;
//! if it is still singular the constant fit is returned. Evaluation is exact — all `n` terms,
//! `O(n·(D+1)²)` per point, no truncation (the weights decay only like `r^{−2p}`, so a truncated
//! sum would need a bound on the far mass; the dense data this family targets do not need it).

use super::constraints::{
    Offset, PseudoNormalParams, Sample, Sides, VariationalError, expand_pseudo_normals,
    validate_samples,
};
use super::{Frame, ImplicitField};

/// The local polynomial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum MlsBasis {
    /// `c_0` (Shepard's method; Shen's implementation).
    Constant,
    /// `c_0 + c · (y − x)` (derived by Shen, implemented by Mann).
    Linear,
}

/// How normals make the data non-zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MlsNormals {
    /// Offset points on both sides (default offset 0.1 of the median spacing).
    Pseudo(PseudoNormalParams),
    /// Shen's true-normal functions `S_i`.
    True,
}

/// Exponent of the weight `1/(r² + ε²)^p`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum WeightPower {
    /// `p = 1` for pseudo-normals, `p = 2` for true normals (what Mann found Shen's derivation uses).
    Auto,
    /// `p = 1`.
    Single,
    /// `p = 2`.
    Squared,
}

/// Parameters of [`fit_mls`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MlsParams {
    /// Polynomial (default linear: Mann's best variant).
    pub basis: MlsBasis,
    /// Normal handling (default true normals).
    pub normals: MlsNormals,
    /// `ε` in normalised units (longest bbox edge = 1); 0 (default) interpolates. Range 0–0.5.
    pub epsilon: f64,
    /// Weight exponent (default `Auto`).
    pub weight: WeightPower,
}

impl Default for MlsParams {
    fn default() -> Self {
        MlsParams {
            basis: MlsBasis::Linear,
            normals: MlsNormals::True,
            epsilon: 0.0,
            weight: WeightPower::Auto,
        }
    }
}

impl MlsParams {
    /// Pseudo-normal placement Shen's method needs (both sides).
    pub fn pseudo_default() -> MlsNormals {
        MlsNormals::Pseudo(PseudoNormalParams {
            offset: Offset::SpacingFraction(0.1),
            sides: Sides::Both,
        })
    }
}

/// A fitted MLS field (evaluates in input units).
#[derive(Debug, Clone)]
pub struct MlsField<const D: usize> {
    /// Normalisation.
    pub frame: Frame<D>,
    /// Constraint points (normalised units).
    pub pts: Vec<[f64; D]>,
    /// Values `v_i`.
    pub vals: Vec<f64>,
    /// Unit normals for true-normal data (zero vectors otherwise).
    pub normals: Vec<[f64; D]>,
    /// Basis.
    pub basis: MlsBasis,
    /// `ε²` (normalised units²).
    pub eps2: f64,
    /// Weight exponent `p` (1 or 2).
    pub power: i32,
}

/// Build Shen's MLS field from samples (input units). `O(n)` set-up (`O(n²)` for the spacing).
///
/// ```
/// use rbfsurf::variational::{Sample, MlsParams, fit_mls, ImplicitField};
/// let pts: Vec<Sample<2>> = (0..6).map(|k| {
///     let a = k as f64 * std::f64::consts::TAU / 6.0;
///     Sample::on_curve([a.cos(), a.sin()], Some([a.cos(), a.sin()]))
/// }).collect();
/// let f = fit_mls(&pts, &MlsParams::default()).unwrap();
/// assert!(f.value(&[0.0, 0.0]) < 0.0 && f.value(&[1.5, 0.0]) > 0.0);
/// assert_eq!(f.value(&[1.0, 0.0]), 0.0);
/// ```
pub fn fit_mls<const D: usize>(
    samples: &[Sample<D>],
    params: &MlsParams,
) -> Result<MlsField<D>, VariationalError> {
    validate_samples(samples)?;
    if !(params.epsilon.is_finite() && params.epsilon >= 0.0) {
        return Err(VariationalError::InvalidParameter {
            name: "epsilon",
            value: params.epsilon,
            reason: "must be ≥ 0",
        });
    }
    let frame = Frame::of_points(samples.iter().map(|s| s.p));
    let norm: Vec<Sample<D>> = frame.normalize_samples(samples);
    let (pts, vals, normals) = match params.normals {
        MlsNormals::Pseudo(p) => {
            let c = expand_pseudo_normals(&norm, &p, 1.0)?;
            (
                c.iter().map(|v| v.p).collect(),
                c.iter().map(|v| v.value).collect(),
                vec![[0.0; D]; c.len()],
            )
        }
        MlsNormals::True => (
            norm.iter().map(|s| s.p).collect(),
            norm.iter().map(|s| s.value).collect(),
            norm.iter().map(|s| s.normal.unwrap_or([0.0; D])).collect(),
        ),
    };
    let power = match (params.weight, params.normals) {
        (WeightPower::Single, _) | (WeightPower::Auto, MlsNormals::Pseudo(_)) => 1,
        (WeightPower::Squared, _) | (WeightPower::Auto, MlsNormals::True) => 2,
    };
    Ok(MlsField {
        frame,
        pts,
        vals,
        normals,
        basis: params.basis,
        eps2: params.epsilon * params.epsilon,
        power,
    })
}

impl<const D: usize> MlsField<D> {
    /// Data value `d_i(u)`.
    #[inline]
    fn data(&self, i: usize, u: &[f64; D]) -> f64 {
        let n = &self.normals[i];
        self.vals[i] + (0..D).map(|k| (u[k] - self.pts[i][k]) * n[k]).sum::<f64>()
    }

    /// `f` at a normalised point.
    pub fn value_normalized(&self, u: &[f64; D]) -> f64 {
        let s: Vec<f64> = self
            .pts
            .iter()
            .map(|p| (0..D).map(|k| (u[k] - p[k]).powi(2)).sum::<f64>() + self.eps2)
            .collect();
        let (imin, smin) = s
            .iter()
            .copied()
            .enumerate()
            .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        if smin == 0.0 {
            return self.vals[imin];
        }
        let w: Vec<f64> = s.iter().map(|&si| (smin / si).powi(self.power)).collect();
        let constant = || {
            let (num, den) = (0..w.len()).fold((0.0, 0.0), |(a, b), i| {
                (a + w[i] * self.data(i, u), b + w[i])
            });
            num / den
        };
        match self.basis {
            MlsBasis::Constant => constant(),
            MlsBasis::Linear => self.linear(u, &w).unwrap_or_else(constant),
        }
    }

    /// Weighted linear fit centred at `u`; `None` when the normal equations are singular.
    fn linear(&self, u: &[f64; D], w: &[f64]) -> Option<f64> {
        let m = D + 1;
        let mut a = vec![0.0; m * m];
        let mut r = vec![0.0; m];
        let mut b = vec![0.0; m];
        for (i, &wi) in w.iter().enumerate() {
            b[0] = 1.0;
            for k in 0..D {
                b[k + 1] = self.pts[i][k] - u[k];
            }
            let di = self.data(i, u);
            for p in 0..m {
                r[p] += wi * b[p] * di;
                for q in 0..=p {
                    a[p * m + q] += wi * b[p] * b[q];
                }
            }
        }
        for p in 0..m {
            for q in 0..p {
                a[q * m + p] = a[p * m + q];
            }
        }
        solve_small(&mut a, &mut r, m).map(|c| c[0])
    }

    /// Conservative test: `false` only if `f` certainly keeps one sign on the ball of radius `rho`
    /// around `u` (normalised units). Exact interval bound for the constant basis (`f` has the sign
    /// of `Σ w_i d_i` with `w_i` and `d_i` bounded on the ball); always `true` for the linear basis.
    pub fn may_change_sign(&self, u: &[f64; D], rho: f64) -> bool {
        if self.basis == MlsBasis::Linear {
            return true;
        }
        let (mut lo_sum, mut hi_sum) = (0.0, 0.0);
        for i in 0..self.pts.len() {
            let r = (0..D)
                .map(|k| (u[k] - self.pts[i][k]).powi(2))
                .sum::<f64>()
                .sqrt();
            let rl = (r - rho).max(0.0);
            let (wlo, whi) = ((r + rho).powi(2) + self.eps2, rl * rl + self.eps2);
            if whi == 0.0 {
                return true;
            }
            let (wlo, whi) = (1.0 / wlo.powi(self.power), 1.0 / whi.powi(self.power));
            let spread = rho
                * (0..D)
                    .map(|k| self.normals[i][k].powi(2))
                    .sum::<f64>()
                    .sqrt();
            let d = self.data(i, u);
            let (dlo, dhi) = (d - spread, d + spread);
            lo_sum += if dlo >= 0.0 { wlo * dlo } else { whi * dlo };
            hi_sum += if dhi >= 0.0 { whi * dhi } else { wlo * dhi };
        }
        !(lo_sum > 0.0 || hi_sum < 0.0)
    }
}

impl<const D: usize> ImplicitField<D> for MlsField<D> {
    fn value(&self, x: &[f64; D]) -> f64 {
        self.value_normalized(&self.frame.forward(x))
    }

    /// Central differences with step `1e-6` normalised units (error `O(h²)` away from data points).
    fn gradient(&self, x: &[f64; D]) -> [f64; D] {
        let u = self.frame.forward(x);
        let h = 1e-6;
        std::array::from_fn(|k| {
            let (mut a, mut b) = (u, u);
            a[k] += h;
            b[k] -= h;
            (self.value_normalized(&a) - self.value_normalized(&b)) / (2.0 * h * self.frame.scale)
        })
    }

    fn sign_on_ball(&self, x: &[f64; D], rho: f64) -> Option<f64> {
        let u = self.frame.forward(x);
        (!self.may_change_sign(&u, rho / self.frame.scale)).then(|| self.value_normalized(&u))
    }
}

/// Solve the `m × m` system in place (Jacobi scaling + partial pivoting); `None` if singular.
fn solve_small(a: &mut [f64], r: &mut [f64], m: usize) -> Option<Vec<f64>> {
    let s: Vec<f64> = (0..m)
        .map(|p| 1.0 / a[p * m + p].abs().sqrt().max(f64::MIN_POSITIVE))
        .collect();
    for p in 0..m {
        r[p] *= s[p];
        for q in 0..m {
            a[p * m + q] *= s[p] * s[q];
        }
    }
    for col in 0..m {
        let piv =
            (col..m).max_by(|&i, &j| a[i * m + col].abs().total_cmp(&a[j * m + col].abs()))?;
        if a[piv * m + col].abs() < 1e-13 {
            return None;
        }
        for q in 0..m {
            a.swap(col * m + q, piv * m + q);
        }
        r.swap(col, piv);
        for i in col + 1..m {
            let f = a[i * m + col] / a[col * m + col];
            for q in col..m {
                a[i * m + q] -= f * a[col * m + q];
            }
            r[i] -= f * r[col];
        }
    }
    let mut x = vec![0.0; m];
    for i in (0..m).rev() {
        let s2: f64 = (i + 1..m).map(|q| a[i * m + q] * x[q]).sum();
        x[i] = (r[i] - s2) / a[i * m + i];
    }
    Some(x.iter().zip(&s).map(|(x, s)| x * s).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn circle(n: usize) -> Vec<Sample<2>> {
        (0..n)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / n as f64;
                Sample::on_curve([a.cos(), a.sin()], Some([a.cos(), a.sin()]))
            })
            .collect()
    }

    #[test]
    fn interpolates_at_data_and_nearby_for_eps_zero() {
        for basis in [MlsBasis::Constant, MlsBasis::Linear] {
            for normals in [MlsNormals::True, MlsParams::pseudo_default()] {
                let f = fit_mls(
                    &circle(12),
                    &MlsParams {
                        basis,
                        normals,
                        ..Default::default()
                    },
                )
                .unwrap();
                for s in circle(12) {
                    assert_eq!(f.value(&s.p), 0.0);
                    let near = [s.p[0] + 1e-9, s.p[1]];
                    assert!(f.value(&near).abs() < 1e-6, "{basis:?} {normals:?}");
                }
                assert!(
                    f.value(&[0.0, 0.0]) < 0.0 && f.value(&[3.0, 0.5]) > 0.0,
                    "{basis:?} {normals:?}"
                );
            }
        }
    }

    #[test]
    fn linear_true_normals_reproduce_a_line() {
        // Data from the plane f = y: every S_i is exactly y, so the MLS returns y everywhere.
        let s: Vec<Sample<2>> = [[-1.0, 0.0], [0.3, 0.0], [1.0, 0.0], [0.0, 1.0]]
            .iter()
            .map(|&p| Sample {
                p,
                normal: Some([0.0, 1.0]),
                value: p[1],
            })
            .collect();
        let f = fit_mls(&s, &MlsParams::default()).unwrap();
        for x in [[0.2, 0.7], [2.0, -1.0], [-0.5, 0.25]] {
            assert!((f.value(&x) - x[1]).abs() < 1e-12);
        }
    }

    #[test]
    fn epsilon_positive_approximates() {
        let p = MlsParams {
            epsilon: 0.2,
            basis: MlsBasis::Constant,
            ..Default::default()
        };
        let f = fit_mls(&circle(12), &p).unwrap();
        assert!(f.value(&circle(12)[0].p).abs() > 1e-3);
    }

    #[test]
    fn constant_sign_test_is_conservative() {
        let p = MlsParams {
            basis: MlsBasis::Constant,
            ..Default::default()
        };
        let f = fit_mls(&circle(8), &p).unwrap();
        let mut state = 7u64;
        for _ in 0..200 {
            let u = [crate_rand(&mut state) - 0.5, crate_rand(&mut state) - 0.5];
            let rho = 0.05;
            if !f.may_change_sign(&u, rho) {
                let s0 = f.value_normalized(&u).signum();
                for k in 0..16 {
                    let a = k as f64 * std::f64::consts::TAU / 16.0;
                    let v = [u[0] + rho * a.cos(), u[1] + rho * a.sin()];
                    assert_eq!(f.value_normalized(&v).signum(), s0);
                }
            }
        }
    }

    fn crate_rand(s: &mut u64) -> f64 {
        *s = s.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = *s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        (z ^ (z >> 31)) as f64 / u64::MAX as f64
    }
}
