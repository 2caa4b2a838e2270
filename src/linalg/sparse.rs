//! Sparse supernodal Cholesky through faer (AMD ordering, supernodal or simplicial chosen by faer).
//!
//! The symbolic phase (AMD + elimination tree + supernodes, roughly O(nnz(A)) plus the AMD cost)
//! gives the exact factor size before the numeric phase, so oversized factors are refused before
//! they are allocated. Numeric work is O(Σ column_count²) on the AMD-ordered matrix and runs on
//! faer's global parallelism setting (the global rayon pool by default).
//! Reference: George & Liu (1981); Amestoy, Davis & Duff (1996) for AMD.

use std::time::Instant;

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::{LltError, LltRegularization};
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Conj, MatMut, Side};
use sprs::CsMat;

use super::{FactorStats, LinalgError, SolverParams, SpdFactor, check_size};
use crate::progress::Progress;

/// A faer sparse LLᵀ factor (AMD-permuted internally; solves in the original numbering).
#[derive(Debug)]
pub struct SparseFactor {
    /// Symbolic structure, including the AMD permutation.
    symbolic: SymbolicCholesky<usize>,
    /// Numeric values of L (`symbolic.len_val()` of them).
    values: Vec<f64>,
}

/// Copies an sprs matrix into a faer one. A symmetric matrix has the same arrays in CSR and CSC,
/// so either sprs storage works; sprs guarantees sorted, in-range indices.
fn to_faer(a: &CsMat<f64>) -> SparseColMat<usize, f64> {
    let n = a.rows();
    let indptr = a.indptr();
    let proper = indptr.to_proper();
    let base = proper[0];
    let col_ptr: Vec<usize> = proper.iter().map(|&p| p - base).collect();
    let sym = SymbolicSparseColMat::<usize>::new_checked(n, n, col_ptr, None, a.indices().to_vec());
    SparseColMat::<usize, f64>::new(sym, a.data().to_vec())
}

/// Symbolic Cholesky with AMD on the lower triangle.
fn symbolic(af: &SparseColMat<usize, f64>) -> Result<SymbolicCholesky<usize>, LinalgError> {
    factorize_symbolic_cholesky(
        af.symbolic(),
        Side::Lower,
        SymmetricOrdering::Amd,
        CholeskySymbolicParams::default(),
    )
    .map_err(|e| LinalgError::Backend(format!("faer symbolic Cholesky: {e:?}")))
}

/// Stored values of the faer factor of `a` (supernodal storage includes padding inside supernodes).
pub(crate) fn estimate_sparse(a: &CsMat<f64>) -> Result<usize, LinalgError> {
    Ok(symbolic(&to_faer(a))?.len_val())
}

/// faer's pivot failure in the original numbering.
fn not_positive_definite(symb: &SymbolicCholesky<usize>, e: LltError) -> LinalgError {
    match e {
        LltError::NonPositivePivot { index } => {
            // faer 0.24 reports the simplicial pivot one-based and the supernodal one
            // zero-based, both in the AMD-permuted numbering.
            let index = match symb.raw() {
                SymbolicCholeskyRaw::Simplicial(_) => index.saturating_sub(1),
                SymbolicCholeskyRaw::Supernodal(_) => index,
            };
            LinalgError::NotPositiveDefinite {
                pivot: symb
                    .perm()
                    .and_then(|p| p.arrays().0.get(index).copied())
                    .unwrap_or(index),
            }
        }
    }
}

/// AMD + symbolic, size check, then the numeric LLᵀ.
pub(crate) fn factorize_sparse(
    a: &CsMat<f64>,
    params: &SolverParams,
    progress: &dyn Progress,
) -> Result<(SparseFactor, FactorStats), LinalgError> {
    let t0 = Instant::now();
    let af = to_faer(a);
    let symb = symbolic(&af)?;
    let len = symb.len_val();
    check_size(len, len as u64 * 8 / 4, params.max_factor_values)?;
    let symbolic_s = t0.elapsed().as_secs_f64();
    progress.fraction(0.1);
    if progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    let t1 = Instant::now();
    // faer's numeric factorisation is one uninterruptible call: large ones run on a helper thread
    // so that a cancellation is answered at once (see `run_abandonable`).
    let numeric = move || -> Result<(SymbolicCholesky<usize>, Vec<f64>), LinalgError> {
        let par = faer::get_global_parallelism();
        let req = symb.factorize_numeric_llt_scratch::<f64>(par, Default::default());
        let mut buf = MemBuffer::try_new(req)
            .map_err(|_| LinalgError::Backend("faer: cannot allocate the workspace".into()))?;
        let mut values = vec![0.0f64; len];
        symb.factorize_numeric_llt(
            &mut values,
            af.as_ref(),
            Side::Lower,
            LltRegularization::default(),
            par,
            MemStack::new(&mut buf),
            Default::default(),
        )
        .map_err(|e| not_positive_definite(&symb, e))?;
        Ok((symb, values))
    };
    let (symb, values) = if len > 1 << 21 {
        super::run_abandonable(progress, numeric)??
    } else {
        numeric()?
    };
    let numeric_s = t1.elapsed().as_secs_f64();
    progress.fraction(1.0);
    if progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    Ok((
        SparseFactor {
            symbolic: symb,
            values,
        },
        FactorStats {
            factor_values: len,
            symbolic_s,
            numeric_s,
        },
    ))
}

impl SpdFactor for SparseFactor {
    fn n(&self) -> usize {
        self.symbolic.nrows()
    }

    /// # Panics
    /// If `b.len() != n` (a programming error of the caller).
    fn solve_in_place(&self, b: &mut [f64]) {
        let n = self.n();
        assert_eq!(b.len(), n, "right-hand side length must equal n");
        let par = faer::get_global_parallelism();
        let mut buf = MemBuffer::new(self.symbolic.solve_in_place_scratch::<f64>(1, par));
        let rhs = MatMut::from_column_major_slice_mut(b, n, 1);
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            par,
            MemStack::new(&mut buf),
        );
    }

    fn factor_values(&self) -> usize {
        self.values.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::SolverKind;
    use crate::linalg::test_support::*;
    use crate::progress::NoProgress;

    /// Both faer paths (simplicial for small sparse factors, supernodal for denser ones) report
    /// the pivot of an indefinite matrix in the original numbering.
    #[test]
    fn pivot_is_mapped_back_on_simplicial_and_supernodal_paths() {
        let params = SolverParams {
            kind: SolverKind::Sparse,
            ..Default::default()
        };
        let mut seen = [false; 2];
        for (n, k) in [(80, 10.0), (500, 60.0)] {
            let (_, mut a) = test_matrix(n, k, 31);
            let supernodal = matches!(
                symbolic(&to_faer(&a)).unwrap().raw(),
                SymbolicCholeskyRaw::Supernodal(_)
            );
            seen[usize::from(supernodal)] = true;
            for bad in [0, n / 3, n - 1] {
                let old = a.get(bad, bad).copied().unwrap();
                *a.get_mut(bad, bad).unwrap() = -0.5;
                let err = factorize_sparse(&a, &params, &NoProgress).err();
                assert_eq!(
                    err,
                    Some(LinalgError::NotPositiveDefinite { pivot: bad }),
                    "n {n} supernodal {supernodal}"
                );
                *a.get_mut(bad, bad).unwrap() = old;
            }
        }
        assert_eq!(seen, [true, true], "both faer paths must be exercised");
    }
}
