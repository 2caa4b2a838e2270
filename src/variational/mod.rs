//! Variational implicits: the small-N, high-fidelity end of the product.
//!
//! - [`turk_obrien`]: Turk & O'Brien (1999, 2002) interpolating implicits with global kernels
//!   (`r² log r` in 2D, `r³` in 3D) and a linear polynomial; pseudo-normal points, true normals as
//!   Hermite (gradient) constraints, and Mann's three-solve true-normal variant (CS-2013-09 §3.8).
//! - [`incremental`]: add constraints to a solved system by a Schur complement (Jiang & Turk).
//! - [`mls`]: Shen's moving-least-squares implicit (constant/linear × pseudo/true normals).
//! - 2D curves workbench: contouring by [`crate::polygonize::marching_squares`], [`quality`], [`svg`], [`datasets`], [`curve_io`],
//!   [`workbench`]; Jiang & Turk's neural approximator in [`mlp`]; 3D fields for the polygonizer in [`field3d`].
//!
//! Every fit works in normalised coordinates ([`Frame`]: bounding-box centre at the origin,
//! longest edge 1) and evaluates in the caller's units. Sign convention: `f < 0` inside.

pub mod adaptive;
pub(crate) mod batch;
pub(crate) mod constraints;
pub mod curve_io;
pub mod datasets;
pub(crate) mod editing;
pub(crate) mod field3d;
pub(crate) mod incremental;
pub(crate) mod kernel;
pub mod mlp;
pub(crate) mod mls;
pub(crate) mod quality;
pub(crate) mod svg;
pub(crate) mod turk_obrien;
pub mod workbench;

pub use constraints::{
    Offset, Origin, PointKind, PseudoNormalParams, Sample, Sides, ValueConstraint, VariationalError,
};
pub use editing::{IncrementalReport, run_workbench_incremental};
pub use field3d::{
    MlsField3, VariationalField3, VariationalParams, fit_mls_3d, fit_variational_3d,
    fit_variational_3d_with,
};
pub use incremental::IncrementalSystem;
pub use kernel::RadialKernel;
pub use mlp::{MlpFit, MlpParams, Smoothing, fit_mlp};
pub use mls::{MlsBasis, MlsField, MlsNormals, MlsParams, WeightPower, fit_mls};
pub use turk_obrien::{
    NormalMode, TurkObrienFit, TurkObrienParams, fit_turk_obrien, fit_turk_obrien_with,
};
pub use workbench::{CurveMethod, CurveParams, CurveReport, WorkbenchOutput, run_workbench};

/// A scalar field in `D` dimensions (input units), `f < 0` inside.
pub trait ImplicitField<const D: usize>: Sync {
    /// `f(x)`.
    fn value(&self, x: &[f64; D]) -> f64;
    /// `∇f(x)`.
    fn gradient(&self, x: &[f64; D]) -> [f64; D];
    /// `Some(f(x))` when `f` provably keeps the sign of `f(x)` on the ball of radius `rho`
    /// around `x` (input units); `None` when it may change sign or no bound is known (default).
    fn sign_on_ball(&self, _x: &[f64; D], _rho: f64) -> Option<f64> {
        None
    }
    /// Like [`ImplicitField::sign_on_ball`], but may also say that smaller balls around `x`,
    /// down to radius `rho_min`, are not worth testing ([`BallSign::Hopeless`], a cost hint only;
    /// the default never says so).
    fn ball_sign(&self, x: &[f64; D], rho: f64, _rho_min: f64) -> BallSign {
        match self.sign_on_ball(x, rho) {
            Some(f) => BallSign::Proven(f),
            None => BallSign::Unknown,
        }
    }
    /// `out[i] = f(xs[i])` for many points (default: one [`ImplicitField::value`] call each;
    /// fields with a vectorised path override it and must return the same values).
    fn values(&self, xs: &[[f64; D]], out: &mut [f64]) {
        for (o, x) in out.iter_mut().zip(xs) {
            *o = self.value(x);
        }
    }
}

/// Outcome of a sign test on a ball ([`ImplicitField::ball_sign`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BallSign {
    /// `f` keeps the sign of this value (`f` at the centre) on the ball.
    Proven(f64),
    /// No proof; a smaller ball may succeed.
    Unknown,
    /// No proof, and the bound is so loose that balls down to the smallest tested radius will
    /// not succeed either: do not split.
    Hopeless,
}

/// Similarity map to normalised coordinates: `u = (x − centre) / scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame<const D: usize> {
    /// Bounding-box centre (input units).
    pub centre: [f64; D],
    /// Longest bounding-box edge (input units; 1 for a degenerate box).
    pub scale: f64,
}

impl<const D: usize> Frame<D> {
    /// The frame of a point set.
    pub fn of_points(pts: impl Iterator<Item = [f64; D]> + Clone) -> Self {
        let (lo, hi) = constraints::bounds(pts);
        let e = (0..D).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        Frame {
            centre: std::array::from_fn(|k| {
                if lo[k].is_finite() {
                    0.5 * (lo[k] + hi[k])
                } else {
                    0.0
                }
            }),
            scale: if e > 0.0 && e.is_finite() { e } else { 1.0 },
        }
    }

    /// The samples mapped into this frame, normals made unit length.
    pub fn normalize_samples(
        &self,
        samples: &[constraints::Sample<D>],
    ) -> Vec<constraints::Sample<D>> {
        samples
            .iter()
            .map(|s| constraints::Sample {
                p: self.forward(&s.p),
                normal: s.normal.map(|n| constraints::unit(&n)),
                value: s.value,
            })
            .collect()
    }

    /// Input units → normalised.
    #[inline]
    pub fn forward(&self, x: &[f64; D]) -> [f64; D] {
        std::array::from_fn(|k| (x[k] - self.centre[k]) / self.scale)
    }

    /// Normalised → input units.
    #[inline]
    pub fn inverse(&self, u: &[f64; D]) -> [f64; D] {
        std::array::from_fn(|k| u[k] * self.scale + self.centre[k])
    }
}
