//! Linear algebra: symmetric positive definite solvers for the CSRBF system. Knows no geometry.
//!
//! Matrices come in as full symmetric `sprs::CsMat<f64>` in CSC storage with sorted indices.

/// A factorised SPD matrix `A` that can solve `A x = b`.
pub trait SpdFactor: Send + Sync {
    /// Order `n` of the matrix.
    fn n(&self) -> usize;
    /// Overwrite `b` (length `n`) with `A⁻¹ b`.
    fn solve_in_place(&self, b: &mut [f64]);
    /// Number of stored values of the factor (the memory it holds, in f64 values).
    fn factor_values(&self) -> usize;
}
