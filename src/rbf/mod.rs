//! The CSRBF fit: Wendland kernels, carrier solids, support radius, sparse assembly and the implicit field.
//!
//! `f(x) = g(x) + Σ_i λ_i φ(|x − P_i| / R) [+ v₀ + v·x]`, with `g` the carrier (negative inside) and
//! `λ` solving `A λ = −g(P)` (plus the polynomial border when asked), so `f(P_i) = 0`.

pub(crate) mod assemble;
pub mod carrier;
pub(crate) mod field;
pub(crate) mod kernel;
pub(crate) mod levels;
pub(crate) mod noise;
pub(crate) mod pou;
mod region;
pub(crate) mod support;
pub(crate) mod winding;

pub use assemble::assemble_matrix;
pub use carrier::{Carrier, CarrierError, CarrierKind, CarrierParams, LocalFit, fit_carrier};
pub use field::{Correction, RbfField, Spline, SplineLevel, linear_poly};
pub use kernel::Kernel;
pub use levels::{LevelPlan, plan_levels};
pub use noise::{NoiseEstimate, estimate_noise};
pub use pou::{BlockPlan, Blocks, PouBlock, plan_blocks, plan_leaves};
pub use support::{Support, SupportEstimate, estimate_support};

/// Errors of the RBF stages (support choice, assembly).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RbfError {
    /// The support radius is not a positive finite number.
    #[error("support radius {0} is not a positive number (normalised units, e.g. --support 0.05)")]
    BadSupport(f64),
    /// The system would not fit in the memory budget.
    #[error(
        "support radius {support:.4} gives about {neighbours:.0} neighbours per point: the {n}×{n} matrix would hold ~{nnz:.2e} values \
         (~{mib:.0} MiB before factorisation, budget {budget_mib} MiB); use a smaller --support or --neighbours 20..60"
    )]
    TooLarge {
        /// Support radius, normalised units.
        support: f64,
        /// Estimated neighbours per point.
        neighbours: f64,
        /// Number of points.
        n: usize,
        /// Estimated non-zeros.
        nnz: f64,
        /// Estimated memory, MiB.
        mib: f64,
        /// Budget, MiB.
        budget_mib: u64,
    },
    /// A carrier could not be fitted.
    #[error(transparent)]
    Carrier(#[from] CarrierError),
    /// The caller cancelled.
    #[error("cancelled")]
    Cancelled,
}
