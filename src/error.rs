//! The library's top-level error: one variant per stage, each wrapping that stage's own error,
//! plus the refusals of the pipeline itself (the memory budget, what the out-of-core path cannot
//! do) and the error of the out-of-core store ([`StoreError`]).

/// Anything that can stop a reconstruction.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReconError {
    /// A parameter is out of range.
    #[error(transparent)]
    Params(#[from] crate::params::ParamError),
    /// The cloud cannot be reconstructed (empty, degenerate, ...).
    #[error(transparent)]
    Input(#[from] crate::clean::InputError),
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
    /// Out of core, the local carrier needs normals and the input has none.
    #[error(
        "out-of-core reconstruction with the local carrier needs oriented normals in the input \
         (estimating them needs the whole cloud in memory); give points with normals, use \
         --carrier ellipsoid or sphere, or raise --max-memory-mib"
    )]
    NeedsNormals,
    /// Out of core, the normals disagree between neighbours (they cannot be reoriented there).
    #[error(
        "{:.0}% of neighbouring normals point in opposite directions; out-of-core reconstruction \
         cannot reorient them (that needs the whole cloud): orient the normals or raise --max-memory-mib",
        share * 100.0
    )]
    InconsistentNormals {
        /// Share of opposed neighbour pairs.
        share: f64,
    },
    /// An option the out-of-core task graph does not implement.
    #[error(
        "{0} is not available for out-of-core reconstruction (the cloud is over the memory budget); \
         leave it out or raise --max-memory-mib"
    )]
    OutOfCoreUnsupported(&'static str),
    /// Even out of core the reconstruction does not fit the budget.
    #[error(
        "{points} points need about {mib:.0} MiB even out of core (the subsample, the partition's \
         buffers and the smallest block's system), more than the memory budget of {budget_mib} MiB; \
         raise --max-memory-mib"
    )]
    OutOfCoreOverBudget {
        /// Points in the input.
        points: u64,
        /// Estimated out-of-core peak, MiB.
        mib: f64,
        /// The budget, MiB.
        budget_mib: u64,
    },
    /// More finite points than the out-of-core path's 32-bit point ids number.
    #[error(
        "more than 4294967295 finite points: out-of-core reconstruction numbers points with 32-bit \
         ids; split the scan"
    )]
    TooManyIds,
    /// The out-of-core store of intermediate results failed.
    #[error(transparent)]
    Store(#[from] StoreError),
    /// Streaming the input out of core failed (the readers' own error).
    #[error(transparent)]
    Read(crate::io::IoError),
    /// The caller cancelled.
    #[error("cancelled")]
    Cancelled,
}

impl From<crate::io::IoError> for ReconError {
    fn from(e: crate::io::IoError) -> Self {
        ReconError::Read(e)
    }
}

/// Why the out-of-core store of intermediate results failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// A temporary file could not be created, written or read.
    #[error(
        "out-of-core store {path}: {source}; free disk space there or set TMPDIR to a larger disk"
    )]
    Io {
        /// The file or directory.
        path: std::path::PathBuf,
        /// The system's error.
        source: std::io::Error,
    },
    /// A stored value is missing or does not decode (a bug or a damaged file).
    #[error("out-of-core store: {key} is missing or damaged ({what})")]
    Corrupt {
        /// The key.
        key: String,
        /// What was wrong.
        what: &'static str,
    },
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

/// What kind of failure an error is, for callers that answer users (an exit code, an HTTP status):
/// the stage errors say what went wrong, this says whose it is and what the caller can do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorKind {
    /// A parameter out of range (HTTP 400).
    BadParameter,
    /// The input's format is not one the readers know (HTTP 415).
    UnsupportedFormat,
    /// The input is over a size or point-count limit (HTTP 413).
    TooLarge,
    /// The input bytes are not a valid point file (HTTP 422).
    InvalidInput,
    /// The points parse but cannot give a surface: empty, degenerate, noise (HTTP 422).
    Unreconstructable,
    /// The reconstruction would need more memory than the budget (HTTP 422).
    OverBudget,
    /// The caller asked to stop (or its time limit passed).
    Cancelled,
    /// A fault of the machine or a bug: disk, encoding, a failed solve (HTTP 500).
    Internal,
}

impl ErrorKind {
    /// Stable machine-readable code (the HTTP API's `error.code`).
    pub fn code(self) -> &'static str {
        match self {
            ErrorKind::BadParameter => "bad_parameter",
            ErrorKind::UnsupportedFormat => "unsupported_media_type",
            ErrorKind::TooLarge => "too_large",
            ErrorKind::InvalidInput => "invalid_input",
            ErrorKind::Unreconstructable => "unreconstructable",
            ErrorKind::OverBudget => "system_too_large",
            ErrorKind::Cancelled => "cancelled",
            ErrorKind::Internal => "reconstruction_failed",
        }
    }

    /// The kind whose [`ErrorKind::code`] this is (a stored job keeps only the code).
    pub fn from_code(code: &str) -> Option<ErrorKind> {
        use ErrorKind::*;
        [
            BadParameter,
            UnsupportedFormat,
            TooLarge,
            InvalidInput,
            Unreconstructable,
            OverBudget,
            Cancelled,
            Internal,
        ]
        .into_iter()
        .find(|k| k.code() == code)
    }
}

impl ReconError {
    /// Whose failure this is (see [`ErrorKind`]).
    pub fn kind(&self) -> ErrorKind {
        if self.is_cancelled() {
            ErrorKind::Cancelled
        } else if self.is_input_problem() {
            ErrorKind::Unreconstructable
        } else {
            match self {
                ReconError::Params(_) => ErrorKind::BadParameter,
                ReconError::Rbf(crate::rbf::RbfError::TooLarge { .. })
                | ReconError::Linalg(crate::linalg::LinalgError::TooLarge { .. })
                | ReconError::Variational(crate::variational::VariationalError::TooLarge {
                    ..
                })
                | ReconError::Polygonize(
                    crate::polygonize::PolygonizeError::GridTooLarge { .. }
                    | crate::polygonize::PolygonizeError::TooManyVertices { .. },
                )
                | ReconError::TooManyPoints { .. }
                | ReconError::OutOfCoreOverBudget { .. }
                | ReconError::TooManyIds => ErrorKind::OverBudget,
                ReconError::NeedsNormals | ReconError::InconsistentNormals { .. } => {
                    ErrorKind::Unreconstructable
                }
                ReconError::OutOfCoreUnsupported(_) => ErrorKind::BadParameter,
                ReconError::Read(e) => e.kind(),
                _ => ErrorKind::Internal,
            }
        }
    }
}

impl crate::io::IoError {
    /// Whose failure this is (see [`ErrorKind`]): the reader's complaints about the bytes are the
    /// input's; open/read/write/encode failures are the machine's.
    pub fn kind(&self) -> ErrorKind {
        use crate::io::IoError as E;
        match self {
            E::UnknownFormat { .. } => ErrorKind::UnsupportedFormat,
            E::TooLarge { .. } | E::TooManyPoints { .. } => ErrorKind::TooLarge,
            E::OverMemory { .. } => ErrorKind::OverBudget,
            E::Open { .. } | E::Read { .. } | E::Write { .. } | E::Encode { .. } => {
                ErrorKind::Internal
            }
            _ => ErrorKind::InvalidInput,
        }
    }
}
