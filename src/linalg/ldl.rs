//! Reference solver: sprs-ldl's up-looking sparse LDLᵀ (Davis's LDL algorithm), single-threaded.
//!
//! Uses the caller's ordering (`perm[new] = old`, identity when `None`). The symbolic phase
//! (elimination tree and column counts, O(nnz(L))) gives nnz(L) before the numeric phase, so
//! oversized factors are refused before allocation. sprs-ldl only reports exact zero pivots, so
//! the diagonal D is checked afterwards: any d_k ≤ 0 means the matrix is not positive definite.
//! Reference: T. A. Davis, "Algorithm 849: a concise sparse Cholesky factorization package", 2005.

use std::time::Instant;

use sprs::errors::LinalgError as SprsError;
use sprs::{CsMat, PermOwned, SymmetryCheck};
use sprs_ldl::{LdlNumeric, LdlSymbolic};

use super::{FactorStats, LinalgError, SolverParams, SpdFactor, check_size};
use crate::progress::Progress;

/// An sprs-ldl LDLᵀ factor of `P A Pᵀ`; solves in the original numbering.
#[derive(Debug)]
pub struct LdlFactor {
    /// The numeric factor (it holds the permutation).
    ldl: LdlNumeric<f64, usize>,
}

/// The sprs permutation for `perm` (`perm[new] = old` is also sprs's convention: `(P x)[i] = x[perm[i]]`).
fn sprs_perm(perm: Option<&[usize]>, n: usize) -> PermOwned {
    match perm {
        Some(p) => PermOwned::new(p.to_vec()),
        None => PermOwned::new((0..n).collect()),
    }
}

/// nnz(L) + n (the diagonal D) for the given ordering.
pub(crate) fn estimate_ldl(a: &CsMat<f64>, perm: Option<&[usize]>) -> usize {
    let n = a.rows();
    let symb = LdlSymbolic::new_perm(
        a.view(),
        sprs_perm(perm, n),
        SymmetryCheck::DontCheckSymmetry,
    );
    symb.nnz() + n
}

/// Symbolic phase, size check, numeric LDLᵀ, positivity check of D.
pub(crate) fn factorize_ldl(
    a: &CsMat<f64>,
    perm: Option<&[usize]>,
    params: &SolverParams,
    progress: &dyn Progress,
) -> Result<(LdlFactor, FactorStats), LinalgError> {
    let n = a.rows();
    let t0 = Instant::now();
    let symb = LdlSymbolic::new_perm(
        a.view(),
        sprs_perm(perm, n),
        SymmetryCheck::DontCheckSymmetry,
    );
    let values = symb.nnz() + n;
    check_size(values, symb.nnz() as u64 * 8, params.max_factor_values)?;
    let symbolic_s = t0.elapsed().as_secs_f64();
    progress.fraction(0.05);
    if progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    let original = |k: usize| perm.map_or(k, |p| p[k]);
    let t1 = Instant::now();
    let ldl = symb.factor(a.view()).map_err(|e| match e {
        SprsError::SingularMatrix(info) => LinalgError::NotPositiveDefinite {
            pivot: original(info.index),
        },
        other => LinalgError::Backend(format!("sprs-ldl: {other}")),
    })?;
    if let Some(k) = ldl.d().iter().position(|&d| !(d > 0.0 && d.is_finite())) {
        return Err(LinalgError::NotPositiveDefinite { pivot: original(k) });
    }
    let numeric_s = t1.elapsed().as_secs_f64();
    progress.fraction(1.0);
    if progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    Ok((
        LdlFactor { ldl },
        FactorStats {
            factor_values: values,
            symbolic_s,
            numeric_s,
        },
    ))
}

impl SpdFactor for LdlFactor {
    fn n(&self) -> usize {
        self.ldl.problem_size()
    }

    /// # Panics
    /// If `b.len() != n` (a programming error of the caller).
    fn solve_in_place(&self, b: &mut [f64]) {
        assert_eq!(b.len(), self.n(), "right-hand side length must equal n");
        let x: Vec<f64> = self.ldl.solve(&b[..]);
        b.copy_from_slice(&x);
    }

    fn factor_values(&self) -> usize {
        self.ldl.nnz() + self.n()
    }
}
