//! The one error type of the `io` stage: every variant names the file (or `<input>` for in-memory
//! data), the format, and what the user can do about it.

use std::path::PathBuf;

/// Everything that can go wrong while reading or writing point clouds and meshes.
///
/// Every message starts with the file name and ends with a hint, e.g.
/// `kitten.ply: truncated binary PLY: header declares 5210 vertices (125040 bytes) but only 4096 bytes follow; re-export the file`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// The file could not be opened (missing, permissions, is a directory, ...).
    #[error("{}: cannot open: {source}; check the path and its permissions", path.display())]
    Open {
        /// File that failed to open.
        path: PathBuf,
        /// Underlying OS error.
        source: std::io::Error,
    },
    /// The file opened but reading it failed.
    #[error("{}: read failed: {source}; check the disk or copy the file locally", path.display())]
    Read {
        /// File being read.
        path: PathBuf,
        /// Underlying OS error.
        source: std::io::Error,
    },
    /// The file is empty or contains no points / vertices at all.
    #[error("{}: {what}; supply a file with at least one point", path.display())]
    Empty {
        /// File (or `<input>`).
        path: PathBuf,
        /// What was found, e.g. "file is empty (0 bytes)" or "PLY declares 0 vertices".
        what: String,
    },
    /// The format could not be determined from the extension or the content.
    #[error("{}: unknown format ({detail}); supported point formats: .ply .xyz .pts .csv .txt .obj .las .laz .e57, mesh formats: .ply .obj .off .glb", path.display())]
    UnknownFormat {
        /// File (or `<input>`).
        path: PathBuf,
        /// Why detection failed.
        detail: String,
    },
    /// A syntax error at a known line (1-based) of a text file or text header.
    #[error("{}:{line}: {format} parse error: {message}; fix or re-export the file", path.display())]
    Parse {
        /// File (or `<input>`).
        path: PathBuf,
        /// Format being parsed ("PLY", "XYZ", ...).
        format: &'static str,
        /// 1-based line number.
        line: usize,
        /// What was wrong.
        message: String,
    },
    /// Structurally invalid data that has no line number (binary data, index out of range, ...).
    #[error("{}: invalid {format}: {message}; fix or re-export the file", path.display())]
    Invalid {
        /// File (or `<input>`).
        path: PathBuf,
        /// Format being parsed.
        format: &'static str,
        /// What was wrong.
        message: String,
    },
    /// A required column / property is absent (e.g. no `x`).
    #[error("{}: {format} has no `{field}` column/property; x, y and z are required (normals nx, ny, nz are optional)", path.display())]
    MissingField {
        /// File (or `<input>`).
        path: PathBuf,
        /// Format being parsed.
        format: &'static str,
        /// Name of the missing field.
        field: String,
    },
    /// The data ends before what the header declares.
    #[error("{}: truncated {format}: {what} ({expected} bytes) but only {found} bytes follow; re-export the file", path.display())]
    Truncated {
        /// File (or `<input>`).
        path: PathBuf,
        /// Format, e.g. "binary PLY".
        format: &'static str,
        /// What was expected, e.g. "header declares 5210 vertices".
        what: String,
        /// Bytes needed (at least).
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// More points than [`crate::io::ReadLimits::max_points`].
    #[error("{}: {declared} points declared or found, more than the limit of {limit}; subsample the input or raise the point limit", path.display())]
    TooManyPoints {
        /// File (or `<input>`).
        path: PathBuf,
        /// Points declared by the header (or found so far in text data).
        declared: u64,
        /// The limit in force.
        limit: usize,
    },
    /// Reading the points would need more memory than [`crate::io::ReadLimits::max_memory_mib`]
    /// (see [`crate::io::reader_peak_mib`]); refused before the point arrays are allocated.
    #[error("{}: {points} points ({counted}) need about {needed_mib:.0} MiB just to read, more than the memory budget of {budget_mib} MiB; subsample the scan or raise the budget (--max-memory-mib)", path.display())]
    OverMemory {
        /// File (or `<input>`).
        path: PathBuf,
        /// Number of points the estimate is for.
        points: u64,
        /// Where that number comes from, e.g. "declared by the file's header".
        counted: &'static str,
        /// Memory the reader would need, MiB.
        needed_mib: f64,
        /// The budget in force, MiB.
        budget_mib: u64,
    },
    /// The file is larger than [`crate::io::ReadLimits::max_bytes`].
    #[error("{}: {bytes} bytes, more than the limit of {limit} bytes; subsample the input or raise the size limit", path.display())]
    TooLarge {
        /// File (or `<input>`).
        path: PathBuf,
        /// Size of the file in bytes.
        bytes: u64,
        /// The limit in force, bytes.
        limit: u64,
    },
    /// A valid but unsupported feature (binary OFF, external glTF buffers, sparse accessors, ...).
    #[error("{}: {format}: {feature} is not supported; convert the file (e.g. to binary PLY or GLB)", path.display())]
    Unsupported {
        /// File (or `<input>`).
        path: PathBuf,
        /// Format being read.
        format: &'static str,
        /// The unsupported feature.
        feature: String,
    },
    /// The mesh cannot be written in the requested format (empty, bad indices, non-finite coordinates).
    #[error("cannot encode {format}: {message}")]
    Encode {
        /// Target format.
        format: &'static str,
        /// What is wrong with the mesh.
        message: String,
    },
    /// Writing the output failed; nothing was left at the destination.
    #[error("{}: write failed: {source}; check that the directory exists and is writable", path.display())]
    Write {
        /// Destination path.
        path: PathBuf,
        /// Underlying OS error.
        source: std::io::Error,
    },
}
