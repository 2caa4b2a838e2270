//! The library's top-level error: one variant per stage, each wrapping that stage's own error.

/// Anything that can stop a reconstruction.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReconError {
    /// A parameter is out of range.
    #[error(transparent)]
    Params(#[from] crate::params::ParamError),
    /// The cloud cannot be reconstructed (empty, degenerate, ...).
    #[error(transparent)]
    Input(#[from] crate::geometry::clean::InputError),
    /// The spatial index could not be built.
    #[error(transparent)]
    Spatial(#[from] crate::spatial::SpatialError),
    /// Support choice, assembly or carrier fitting failed.
    #[error(transparent)]
    Rbf(#[from] crate::rbf::RbfError),
    /// Ordering failed.
    #[error(transparent)]
    Ordering(#[from] crate::ordering::OrderingError),
    /// Factorisation or solve failed.
    #[error(transparent)]
    Linalg(#[from] crate::linalg::LinalgError),
    /// Mesh extraction failed.
    #[error(transparent)]
    Polygonize(#[from] crate::polygonize::PolygonizeError),
    /// A global (variational / MLS) fit failed.
    #[error(transparent)]
    Variational(#[from] crate::variational::VariationalError),
    /// Mesh post-processing failed.
    #[error(transparent)]
    Mesh(#[from] crate::mesh::optimize::OptimizeError),
    /// The whole reconstruction would not fit the memory budget (checked before any work).
    #[error(
        "{points} points need about {mib:.0} MiB to reconstruct (measured ~0.45 KiB per point plus \
         one block's system), more than the memory budget of {budget_mib} MiB; subsample the scan \
         or raise --max-memory-mib"
    )]
    TooManyPoints {
        /// Points in the input.
        points: u64,
        /// Estimated peak memory, MiB.
        mib: f64,
        /// The budget, MiB.
        budget_mib: u64,
    },
    /// The caller cancelled.
    #[error("cancelled")]
    Cancelled,
}

impl From<crate::rbf::CarrierError> for ReconError {
    fn from(e: crate::rbf::CarrierError) -> Self {
        ReconError::Rbf(e.into())
    }
}

impl ReconError {
    /// True for a stop the caller asked for, whichever stage noticed it.
    pub fn is_cancelled(&self) -> bool {
        use crate::linalg::LinalgError;
        use crate::polygonize::PolygonizeError;
        use crate::rbf::RbfError;
        use crate::variational::VariationalError;
        matches!(
            self,
            ReconError::Cancelled
                | ReconError::Linalg(LinalgError::Cancelled)
                | ReconError::Rbf(RbfError::Cancelled)
                | ReconError::Polygonize(PolygonizeError::Cancelled)
                | ReconError::Variational(VariationalError::Cancelled)
        )
    }

    /// True when the input data (not the parameters or the machine) is at fault: the HTTP API answers 422.
    pub fn is_input_problem(&self) -> bool {
        matches!(
            self,
            ReconError::Input(_) | ReconError::Rbf(crate::rbf::RbfError::Carrier(_))
        )
    }
}
