//! Wendland's compactly supported radial basis functions (Wendland 1995), positive definite in ℝ³.
//!
//! With `r = d / R` (distance over support radius): `φ(r) = 0` for `r ≥ 1`, so the interpolation
//! matrix `A_ij = φ(|P_i − P_j| / R)` is sparse. Each kernel comes with the derivative needed for
//! analytic field gradients (outward normals of the output mesh).

use std::fmt;
use std::str::FromStr;

/// The Wendland kernel family member (`ψ_{3,k}`), by smoothness.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kernel {
    /// `(1 − r)²₊`: C⁰, the seed paper's kernel (cone-shaped at each centre).
    WendlandC0,
    /// `(1 − r)⁴₊ (4r + 1)`: C², the default (smooth normals, still short support).
    #[default]
    WendlandC2,
    /// `(1 − r)⁶₊ (35r² + 18r + 3)`: C⁴, smoother, wider effective bump.
    WendlandC4,
}

impl Kernel {
    /// All kernels, for tests and parameter listings.
    pub const ALL: [Kernel; 3] = [Kernel::WendlandC0, Kernel::WendlandC2, Kernel::WendlandC4];

    /// `φ(r)` for the scaled distance `r = d / R ≥ 0`.
    #[inline]
    pub fn value(self, r: f64) -> f64 {
        if r >= 1.0 {
            return 0.0;
        }
        let s = 1.0 - r;
        match self {
            Kernel::WendlandC0 => s * s,
            Kernel::WendlandC2 => {
                let s2 = s * s;
                s2 * s2 * (4.0 * r + 1.0)
            }
            Kernel::WendlandC4 => {
                let s2 = s * s;
                s2 * s2 * s2 * (35.0 * r * r + 18.0 * r + 3.0)
            }
        }
    }

    /// `φ'(r) / r` for `r > 0` (finite at `r → 0` for C² and C⁴), so that
    /// `∇_x φ(|x − c| / R) = φ'(r)/r · (x − c) / R²`. For C⁰ the value at `r = 0` is taken as 0
    /// (the cone's tip has no gradient).
    #[inline]
    pub fn derivative_over_r(self, r: f64) -> f64 {
        if r >= 1.0 {
            return 0.0;
        }
        let s = 1.0 - r;
        match self {
            Kernel::WendlandC0 => {
                if r > 0.0 {
                    -2.0 * s / r
                } else {
                    0.0
                }
            }
            Kernel::WendlandC2 => -20.0 * s * s * s,
            Kernel::WendlandC4 => {
                let s2 = s * s;
                -56.0 * s2 * s2 * s * (5.0 * r + 1.0)
            }
        }
    }

    /// The command-line / report name.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::WendlandC0 => "wendland-c0",
            Kernel::WendlandC2 => "wendland-c2",
            Kernel::WendlandC4 => "wendland-c4",
        }
    }
}

impl fmt::Display for Kernel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Kernel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Kernel::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| {
                format!("unknown kernel '{s}' (use wendland-c0, wendland-c2 or wendland-c4)")
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_match_closed_forms_and_vanish_outside_support() {
        for i in 0..=100 {
            let r = i as f64 / 100.0;
            let s = 1.0 - r;
            assert!((Kernel::WendlandC0.value(r) - s.powi(2)).abs() < 1e-15);
            assert!((Kernel::WendlandC2.value(r) - s.powi(4) * (4.0 * r + 1.0)).abs() < 1e-15);
            let c4 = s.powi(6) * (35.0 * r * r + 18.0 * r + 3.0);
            assert!((Kernel::WendlandC4.value(r) - c4).abs() < 1e-13);
        }
        for k in Kernel::ALL {
            assert_eq!(k.value(1.0), 0.0);
            assert_eq!(k.value(1.5), 0.0);
            assert_eq!(k.derivative_over_r(1.2), 0.0);
        }
    }

    #[test]
    fn derivatives_match_finite_differences() {
        for k in Kernel::ALL {
            for i in 1..99 {
                let r = i as f64 / 100.0;
                let h = 1e-6;
                let fd = (k.value(r + h) - k.value(r - h)) / (2.0 * h);
                let an = k.derivative_over_r(r) * r;
                assert!(
                    (fd - an).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{k} r={r}: {fd} vs {an}"
                );
            }
        }
    }

    #[test]
    fn names_round_trip() {
        for k in Kernel::ALL {
            assert_eq!(k.name().parse::<Kernel>().unwrap(), k);
        }
        assert!("gauss".parse::<Kernel>().is_err());
    }
}
