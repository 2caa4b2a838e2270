//! Envelope (profile) storage and Cholesky factorisation of a symmetric positive definite matrix.
//!
//! Jennings (1966) storage as used by the seed paper (Kojekine et al., section 3.1–3.2) and George &
//! Liu (1981, chapter 4): the lower triangle is stored row by row, row i holding columns
//! `f_i..=i` contiguously, where `f_i` is the first non-zero column of row i of the (reordered)
//! matrix. Cholesky fill stays inside this envelope, so the factor overwrites the matrix in place.
//!
//! Complexity: sizing O(nnz), building O(nnz + profile), factorising O(Σ row_len²/2) flops,
//! one solve O(profile). Memory: one f64 per envelope entry plus O(n) indices.

use std::time::Instant;

use sprs::CsMat;

use super::envelope_kernels::{FactorStop, Layout, axpy, dot, factor_rows};
use super::{FactorStats, LinalgError, SolverParams, SpdFactor, check_size};
use crate::progress::Progress;

/// Envelope shape of a (reordered) symmetric matrix.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EnvelopeSize {
    /// First stored column `f_i` of each row of the reordered matrix (n entries, `f_i <= i`).
    pub first: Vec<usize>,
    /// Envelope size Σ (i − f_i + 1): the number of stored values, diagonal included.
    pub total: usize,
}

/// Computes the envelope of `P A Pᵀ` (with `perm[new] = old`; `None` = identity) in O(nnz).
///
/// `a` is a structurally symmetric n × n matrix; only its pattern is read. Errors if `a` is not
/// square or `perm` is not a permutation of `0..n`.
pub fn envelope_size(a: &CsMat<f64>, perm: Option<&[usize]>) -> Result<EnvelopeSize, LinalgError> {
    let n = super::validate(a, perm)?;
    let inv = inverse_perm(perm, n);
    let mut first: Vec<usize> = (0..n).collect();
    for (outer, vec) in a.outer_iterator().enumerate() {
        let i = inv[outer];
        for &inner in vec.indices() {
            let k = inv[inner];
            if k < first[i] {
                first[i] = k;
            }
        }
    }
    let total = first.iter().enumerate().map(|(i, &f)| i - f + 1).sum();
    Ok(EnvelopeSize { first, total })
}

/// `inv[old] = new` for `perm[new] = old`, or the identity.
fn inverse_perm(perm: Option<&[usize]>, n: usize) -> Vec<usize> {
    match perm {
        Some(p) => {
            let mut inv = vec![0; n];
            for (new, &old) in p.iter().enumerate() {
                inv[old] = new;
            }
            inv
        }
        None => (0..n).collect(),
    }
}

/// The Cholesky factor `L` of `P A Pᵀ` in envelope storage; solves in the original numbering.
#[derive(Debug, Clone)]
pub struct EnvelopeFactor {
    /// `perm[new] = old`, `None` for the identity.
    perm: Option<Vec<usize>>,
    /// First stored column of each row (n).
    first: Vec<usize>,
    /// Row starts into `values` (n + 1).
    start: Vec<usize>,
    /// Rows of `L`, columns `first[i]..=i` each (the envelope size).
    values: Vec<f64>,
    /// 1 / l_ii (n).
    inv_diag: Vec<f64>,
}

impl EnvelopeFactor {
    /// Lays `P A Pᵀ` out in envelope storage (lower triangle) without factorising it.
    fn build(a: &CsMat<f64>, perm: Option<&[usize]>, size: EnvelopeSize) -> Self {
        let n = size.first.len();
        let inv = inverse_perm(perm, n);
        let mut start = Vec::with_capacity(n + 1);
        start.push(0);
        for (i, &f) in size.first.iter().enumerate() {
            start.push(start[i] + i - f + 1);
        }
        let mut values = vec![0.0; size.total];
        for (outer, vec) in a.outer_iterator().enumerate() {
            let i = inv[outer];
            for (inner, &v) in vec.iter() {
                let k = inv[inner];
                if k <= i {
                    values[start[i] + k - size.first[i]] = v;
                }
            }
        }
        EnvelopeFactor {
            perm: perm.map(<[usize]>::to_vec),
            first: size.first,
            start,
            values,
            inv_diag: vec![0.0; n],
        }
    }

    /// Factorises in place; on failure maps the permuted pivot row back to the original numbering.
    fn factor(&mut self, progress: &dyn Progress) -> Result<(), LinalgError> {
        let layout = Layout {
            first: &self.first,
            start: &self.start,
        };
        factor_rows(&layout, &mut self.values, &mut self.inv_diag, progress).map_err(|stop| {
            match stop {
                FactorStop::Cancelled => LinalgError::Cancelled,
                FactorStop::Pivot(i) => LinalgError::NotPositiveDefinite {
                    pivot: self.perm.as_ref().map_or(i, |p| p[i]),
                },
            }
        })
    }

    /// Stored row `i` of `L` without its diagonal: columns `first[i]..i`.
    #[inline]
    fn off_diagonal(&self, i: usize) -> &[f64] {
        &self.values[self.start[i]..self.start[i + 1] - 1]
    }

    /// Solves `L Lᵀ y = y` in the permuted numbering.
    fn solve_permuted(&self, y: &mut [f64]) {
        let n = self.first.len();
        for i in 0..n {
            let f = self.first[i];
            let d = dot(self.off_diagonal(i), &y[f..i]);
            y[i] = (y[i] - d) * self.inv_diag[i];
        }
        for i in (0..n).rev() {
            let f = self.first[i];
            let xi = y[i] * self.inv_diag[i];
            y[i] = xi;
            axpy(-xi, self.off_diagonal(i), &mut y[f..i]);
        }
    }

    /// Entry `L[i][k]` of the factor in the permuted numbering (0 outside the envelope).
    #[cfg(test)]
    pub(crate) fn entry(&self, i: usize, k: usize) -> f64 {
        let f = self.first[i];
        if k < f || k > i {
            0.0
        } else {
            self.values[self.start[i] + k - f]
        }
    }
}

impl SpdFactor for EnvelopeFactor {
    fn n(&self) -> usize {
        self.first.len()
    }

    /// # Panics
    /// If `b.len() != n` (a programming error of the caller).
    fn solve_in_place(&self, b: &mut [f64]) {
        assert_eq!(b.len(), self.n(), "right-hand side length must equal n");
        match &self.perm {
            None => self.solve_permuted(b),
            Some(p) => {
                let mut y: Vec<f64> = p.iter().map(|&old| b[old]).collect();
                self.solve_permuted(&mut y);
                for (new, &old) in p.iter().enumerate() {
                    b[old] = y[new];
                }
            }
        }
    }

    fn factor_values(&self) -> usize {
        self.values.len()
    }
}

/// Sizes, checks the limit, builds and factorises the envelope of `P A Pᵀ`.
pub(crate) fn factorize_envelope(
    a: &CsMat<f64>,
    perm: Option<&[usize]>,
    params: &SolverParams,
    progress: &dyn Progress,
) -> Result<(EnvelopeFactor, FactorStats), LinalgError> {
    let t0 = Instant::now();
    let size = envelope_size(a, perm)?;
    let n = size.first.len() as u64;
    check_size(size.total, n * 8 * 3, params.max_factor_values)?;
    let total = size.total;
    let mut factor = EnvelopeFactor::build(a, perm, size);
    let symbolic_s = t0.elapsed().as_secs_f64();
    if progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    let t1 = Instant::now();
    factor.factor(progress)?;
    let numeric_s = t1.elapsed().as_secs_f64();
    progress.fraction(1.0);
    Ok((
        factor,
        FactorStats {
            factor_values: total,
            symbolic_s,
            numeric_s,
        },
    ))
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;
    use std::sync::atomic::{AtomicUsize, Ordering};

    use super::*;
    use crate::linalg::SolverKind;
    use crate::linalg::test_support::*;
    use crate::progress::NoProgress;

    /// Records fractions; cancels once it has seen `cancel_after` of them.
    struct Recorder {
        fractions: Mutex<Vec<f64>>,
        calls: AtomicUsize,
        cancel_after: usize,
    }

    impl Recorder {
        fn new(cancel_after: usize) -> Self {
            Recorder {
                fractions: Mutex::new(Vec::new()),
                calls: AtomicUsize::new(0),
                cancel_after,
            }
        }
    }

    impl Progress for Recorder {
        fn stage(&self, _stage: crate::progress::Stage) {}
        fn fraction(&self, done: f64) {
            self.calls.fetch_add(1, Ordering::Relaxed);
            self.fractions.lock().unwrap().push(done);
        }
        fn cancelled(&self) -> bool {
            self.calls.load(Ordering::Relaxed) >= self.cancel_after
        }
    }

    fn params() -> SolverParams {
        SolverParams {
            kind: SolverKind::Envelope,
            ..Default::default()
        }
    }

    /// Dense P A Pᵀ.
    fn permuted_dense(a: &CsMat<f64>, perm: Option<&[usize]>) -> Vec<Vec<f64>> {
        let d = to_dense(a);
        let n = d.len();
        let p: Vec<usize> = perm.map_or_else(|| (0..n).collect(), <[usize]>::to_vec);
        (0..n)
            .map(|i| (0..n).map(|j| d[p[i]][p[j]]).collect())
            .collect()
    }

    #[test]
    fn envelope_size_equals_brute_force_profile() {
        let (_, a) = test_matrix(120, 15.0, 11);
        for (name, perm) in orderings(120) {
            let d = permuted_dense(&a, perm.as_deref());
            let mut total = 0;
            for (i, row) in d.iter().enumerate() {
                let f = row.iter().position(|&v| v != 0.0).unwrap().min(i);
                total += i - f + 1;
            }
            let size = envelope_size(&a, perm.as_deref()).unwrap();
            assert_eq!(size.total, total, "{name}");
            let (f, _) = factorize_envelope(&a, perm.as_deref(), &params(), &NoProgress).unwrap();
            assert_eq!(f.factor_values(), total, "{name}");
        }
    }

    #[test]
    fn factor_times_transpose_reproduces_the_permuted_matrix() {
        let n = 70;
        let (_, a) = test_matrix(n, 14.0, 12);
        for (name, perm) in orderings(n) {
            let d = permuted_dense(&a, perm.as_deref());
            let (f, _) = factorize_envelope(&a, perm.as_deref(), &params(), &NoProgress).unwrap();
            for (i, row) in d.iter().enumerate() {
                for (j, &dij) in row.iter().enumerate().take(i + 1) {
                    let llt: f64 = (0..=j).map(|k| f.entry(i, k) * f.entry(j, k)).sum();
                    assert!((llt - dij).abs() < 1e-12, "{name} ({i},{j})");
                }
            }
        }
    }

    #[test]
    fn progress_is_monotone_and_cancellation_stops_midway() {
        let (_, a) = test_matrix(300, 20.0, 13);
        let rec = Recorder::new(usize::MAX);
        factorize_envelope(&a, None, &params(), &rec).unwrap();
        let fr = rec.fractions.lock().unwrap().clone();
        assert!(fr.len() > 20, "only {} reports", fr.len());
        assert!(fr.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(fr.last().copied(), Some(1.0));

        let rec = Recorder::new(5);
        let err = factorize_envelope(&a, None, &params(), &rec).err();
        assert_eq!(err, Some(LinalgError::Cancelled));
        let fr = rec.fractions.lock().unwrap().clone();
        assert_eq!(fr.len(), 5);
        assert!(fr[4] < 0.5);
    }

    #[test]
    fn dot_matches_naive_sum_for_all_tail_lengths() {
        let mut rng = SplitMix64(14);
        for len in 0..70 {
            let x: Vec<f64> = (0..len).map(|_| rng.next_f64() - 0.5).collect();
            let y: Vec<f64> = (0..len).map(|_| rng.next_f64() - 0.5).collect();
            let naive: f64 = x.iter().zip(&y).map(|(a, b)| a * b).sum();
            assert!((dot(&x, &y) - naive).abs() < 1e-13, "len {len}");
        }
    }

    #[test]
    fn empty_and_diagonal_matrices() {
        let empty: CsMat<f64> = sprs::TriMat::<f64>::new((0, 0)).to_csc();
        let (f, s) = factorize_envelope(&empty, None, &params(), &NoProgress).unwrap();
        assert_eq!((f.n(), s.factor_values), (0, 0));
        f.solve_in_place(&mut []);
        let mut t = sprs::TriMat::new((3, 3));
        for (i, v) in [4.0, 9.0, 16.0].into_iter().enumerate() {
            t.add_triplet(i, i, v);
        }
        let (f, s) = factorize_envelope(&t.to_csc(), None, &params(), &NoProgress).unwrap();
        assert_eq!(s.factor_values, 3);
        let mut b = vec![4.0, 9.0, 16.0];
        f.solve_in_place(&mut b);
        assert_eq!(b, vec![1.0, 1.0, 1.0]);
    }
}
