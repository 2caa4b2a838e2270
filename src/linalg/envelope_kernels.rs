//! Inner kernels of the envelope Cholesky: the row-oriented (bordering) factorisation loop and the
//! contiguous dot product it spends its time in.
//!
//! Jennings (1966) / George & Liu (1981, section 4.3): for row i with first column f_i,
//! `l_ij = (a_ij − Σ_{k=max(f_i,f_j)}^{j−1} l_ik l_jk) / l_jj` for j in f_i..i, then
//! `l_ii = sqrt(a_ii − Σ_k l_ik²)`. Work O(Σ row_len²/2) multiply-adds, no extra memory.
//!
//! The dot product uses 16 independent accumulators so that it vectorises. The loop is compiled
//! twice: for the baseline target and, on x86-64 machines that have them (detected at run time),
//! with AVX2 + FMA enabled; both give the same algorithm (rounding differs only by FMA contraction).

use crate::progress::Progress;

/// Why the factorisation loop stopped early.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum FactorStop {
    /// Non-positive (or non-finite) pivot at this row of the PERMUTED matrix.
    Pivot(usize),
    /// [`Progress::cancelled`] returned true.
    Cancelled,
}

/// Row layout of an envelope matrix: row i holds columns `first[i]..=i` at
/// `values[start[i]..start[i + 1]]` (the diagonal last).
pub(crate) struct Layout<'a> {
    /// First stored column of each row (n).
    pub first: &'a [usize],
    /// Row starts into the value array (n + 1).
    pub start: &'a [usize],
}

/// Dot product of two equally long slices, written so that it vectorises (16 accumulators).
#[inline(always)]
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let len = a.len().min(b.len());
    let (a, b) = (&a[..len], &b[..len]);
    let mut acc = [0.0f64; 16];
    let mut ca = a.chunks_exact(16);
    let mut cb = b.chunks_exact(16);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for k in 0..16 {
            acc[k] += x[k] * y[k];
        }
    }
    let (ra, rb) = (ca.remainder(), cb.remainder());
    let mut acc4 = [0.0f64; 4];
    let mut qa = ra.chunks_exact(4);
    let mut qb = rb.chunks_exact(4);
    for (x, y) in (&mut qa).zip(&mut qb) {
        for k in 0..4 {
            acc4[k] += x[k] * y[k];
        }
    }
    let mut tail = 0.0;
    for (x, y) in qa.remainder().iter().zip(qb.remainder()) {
        tail += x * y;
    }
    for k in 0..4 {
        acc4[k] += (acc[k] + acc[k + 4]) + (acc[k + 8] + acc[k + 12]);
    }
    (acc4[0] + acc4[1]) + (acc4[2] + acc4[3]) + tail
}

/// `y += alpha · x` over equally long slices.
#[inline(always)]
pub(crate) fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yv, xv) in y.iter_mut().zip(x) {
        *yv += alpha * xv;
    }
}

/// In-place Cholesky of the envelope matrix in `values`; writes 1 / l_ii into `inv_diag`.
///
/// Reports `progress.fraction` by cumulative work (Σ row_len²) about 200 times, and checks
/// `progress.cancelled()` at the same points.
pub(crate) fn factor_rows(
    layout: &Layout<'_>,
    values: &mut [f64],
    inv_diag: &mut [f64],
    progress: &dyn Progress,
) -> Result<(), FactorStop> {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above), which is the only
            // requirement of a `#[target_feature]` function.
            return unsafe { factor_rows_avx2(layout, values, inv_diag, progress) };
        }
    }
    factor_rows_generic(layout, values, inv_diag, progress)
}

/// [`factor_rows_generic`] compiled with AVX2 + FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn factor_rows_avx2(
    layout: &Layout<'_>,
    values: &mut [f64],
    inv_diag: &mut [f64],
    progress: &dyn Progress,
) -> Result<(), FactorStop> {
    factor_rows_generic(layout, values, inv_diag, progress)
}

/// The row-oriented envelope Cholesky (see the module documentation).
#[inline(always)]
fn factor_rows_generic(
    layout: &Layout<'_>,
    values: &mut [f64],
    inv_diag: &mut [f64],
    progress: &dyn Progress,
) -> Result<(), FactorStop> {
    let Layout { first, start } = *layout;
    let n = first.len();
    let total_work: f64 = (0..n)
        .map(|i| {
            let len = (start[i + 1] - start[i]) as f64;
            len * len
        })
        .sum();
    let step = (total_work / 200.0).max(1.0);
    let mut work = 0.0;
    let mut next_report = step;
    for i in 0..n {
        let fi = first[i];
        let (done, rest) = values.split_at_mut(start[i]);
        let row = &mut rest[..start[i + 1] - start[i]];
        for j in fi..i {
            let fj = first[j];
            let k0 = fi.max(fj);
            let row_j = &done[start[j] + (k0 - fj)..start[j + 1] - 1];
            let (li, rest_i) = row.split_at_mut(j - fi);
            let d = dot(&li[k0 - fi..], row_j);
            rest_i[0] = (rest_i[0] - d) * inv_diag[j];
        }
        let (off, diag) = row.split_at_mut(i - fi);
        let pivot = diag[0] - dot(off, off);
        if !(pivot > 0.0 && pivot.is_finite()) {
            return Err(FactorStop::Pivot(i));
        }
        let lii = pivot.sqrt();
        diag[0] = lii;
        inv_diag[i] = 1.0 / lii;
        let len = row.len() as f64;
        work += len * len;
        if work >= next_report {
            next_report = work + step;
            progress.fraction((work / total_work).min(1.0));
            if progress.cancelled() {
                return Err(FactorStop::Cancelled);
            }
        }
    }
    Ok(())
}
