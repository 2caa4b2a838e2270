//! Dense symmetric indefinite solve (of the variational systems) (faer Bunch–Kaufman `LBLᵀ`) and a
//! reciprocal condition estimate.
//!
//! The saddle-point matrix `[Φ P; Pᵀ 0]` is symmetric but indefinite, so Cholesky does not apply;
//! `LBLᵀ` costs `n³/3` flops, half of LU. The condition estimate is Hager's 1-norm estimator
//! (Hager 1984, as refined by Higham 1988): `O(n²)` per iteration, ≤ 5 iterations of two solves.

use faer::Mat;
use faer::Side;
use faer::linalg::solvers::{Lblt, Solve};

use super::LinalgError;
use crate::progress::Progress;

/// A factored symmetric system with its diagnostics.
#[derive(Clone)]
pub struct SymmetricSolver {
    factor: Lblt<f64>,
    n: usize,
    /// Reciprocal 1-norm condition estimate `1 / (‖A‖₁ ‖A⁻¹‖₁)` (1 = perfect, ~1e-16 = singular).
    pub rcond: f64,
}

impl SymmetricSolver {
    /// Factor `a` (only its lower triangle is read). Errors when the factor is not finite or the
    /// condition estimate is below `1e-15`.
    pub fn new(a: &Mat<f64>) -> Result<Self, LinalgError> {
        Self::factor(a)
    }

    /// [`SymmetricSolver::new`] that honours `progress.cancelled()` while it runs. faer's `LBLᵀ`
    /// is one call that cannot be interrupted (`n³/3` flops: ~10–20 s at 12,000 unknowns on two
    /// cores), so systems above 1,000 unknowns are factored on a helper thread that owns `a`; this
    /// thread polls the flag every 20 ms and returns [`LinalgError::Cancelled`] at once. The
    /// abandoned factorisation runs to its end in the background (bounded by the dense size
    /// limit of the caller) and then frees its memory.
    pub fn new_cancellable(a: Mat<f64>, progress: &dyn Progress) -> Result<Self, LinalgError> {
        if progress.cancelled() {
            return Err(LinalgError::Cancelled);
        }
        if a.nrows() <= 1000 {
            return Self::factor(&a);
        }
        super::run_abandonable(progress, move || Self::factor(&a))?
    }

    fn factor(a: &Mat<f64>) -> Result<Self, LinalgError> {
        let n = a.nrows();
        let factor = a.lblt(Side::Lower);
        let mut s = SymmetricSolver {
            factor,
            n,
            rcond: 0.0,
        };
        let est = s.inverse_norm1_estimate();
        let norm = norm1_symmetric_lower(a);
        s.rcond = if est.is_finite() && est > 0.0 && norm > 0.0 {
            1.0 / (norm * est)
        } else {
            0.0
        };
        if s.rcond.is_nan() || s.rcond < 1e-15 {
            return Err(LinalgError::SingularDense { n, rcond: s.rcond });
        }
        Ok(s)
    }

    /// System size.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Solve `A X = B` for all columns of `b` (n × k), in place.
    pub fn solve_in_place(&self, b: &mut Mat<f64>) {
        self.factor.solve_in_place(b.as_mut());
    }

    /// Hager/Higham estimate of `‖A⁻¹‖₁` (A symmetric, so `A⁻ᵀ = A⁻¹`).
    fn inverse_norm1_estimate(&self) -> f64 {
        let n = self.n;
        if n == 0 {
            return 0.0;
        }
        let mut x = Mat::<f64>::from_fn(n, 1, |_, _| 1.0 / n as f64);
        let mut est = 0.0;
        let mut last_j = usize::MAX;
        for _ in 0..5 {
            let mut y = x.clone();
            self.solve_in_place(&mut y);
            est = (0..n).map(|i| y[(i, 0)].abs()).sum::<f64>();
            let mut z = Mat::<f64>::from_fn(n, 1, |i, _| if y[(i, 0)] >= 0.0 { 1.0 } else { -1.0 });
            self.solve_in_place(&mut z);
            let (j, zmax) = (0..n)
                .map(|i| (i, z[(i, 0)].abs()))
                .fold((0, -1.0), |a, b| if b.1 > a.1 { b } else { a });
            let ztx: f64 = (0..n).map(|i| z[(i, 0)] * x[(i, 0)]).sum();
            if zmax <= ztx || j == last_j {
                break;
            }
            last_j = j;
            x = Mat::<f64>::zeros(n, 1);
            x[(j, 0)] = 1.0;
        }
        // Higham's alternating vector guards against Hager's worst cases.
        let denom = (n.max(2) - 1) as f64;
        let mut v = Mat::<f64>::from_fn(n, 1, |i, _| {
            let s = if i % 2 == 0 { 1.0 } else { -1.0 };
            s * (1.0 + i as f64 / denom)
        });
        self.solve_in_place(&mut v);
        let alt = 2.0 * (0..n).map(|i| v[(i, 0)].abs()).sum::<f64>() / (3.0 * n as f64);
        est.max(alt)
    }
}

/// `‖A‖₁` of a symmetric matrix from its lower triangle.
fn norm1_symmetric_lower(a: &Mat<f64>) -> f64 {
    let n = a.nrows();
    let mut col = vec![0.0; n];
    for j in 0..n {
        for i in j..n {
            let v = a[(i, j)].abs();
            col[j] += v;
            if i != j {
                col[i] += v;
            }
        }
    }
    col.into_iter().fold(0.0, f64::max)
}

/// Build an `n × n` matrix column by column in parallel (`f(i, j)` only called for `i ≥ j`; the
/// strict upper triangle is left zero because `LBLᵀ` reads the lower one).
pub fn lower_from_fn(n: usize, f: impl Fn(usize, usize) -> f64 + Sync) -> Mat<f64> {
    match lower_from_fn_cancellable(n, f, &crate::progress::NoProgress) {
        Ok(a) => a,
        Err(_) => unreachable!("NoProgress never cancels"),
    }
}

/// [`lower_from_fn`] that skips the remaining columns once `progress.cancelled()` turns true and
/// then answers [`LinalgError::Cancelled`] (an `n²` build of a 12,000-unknown system takes seconds).
/// The columns are written in place (no second `n²` buffer to copy).
pub fn lower_from_fn_cancellable(
    n: usize,
    f: impl Fn(usize, usize) -> f64 + Sync,
    progress: &dyn Progress,
) -> Result<Mat<f64>, LinalgError> {
    use rayon::prelude::*;
    use std::sync::atomic::{AtomicBool, Ordering};
    let mut a = Mat::<f64>::zeros(n, n);
    // Asking `progress` costs a clock read: every 16th column asks, and its answer stops
    // every column after it.
    let stopped = AtomicBool::new(false);
    a.par_col_iter_mut().enumerate().for_each(|(j, mut col)| {
        if stopped.load(Ordering::Relaxed) {
            return;
        }
        if j % 16 == 0 && progress.cancelled() {
            stopped.store(true, Ordering::Relaxed);
            return;
        }
        for i in j..n {
            col[i] = f(i, j);
        }
    });
    if stopped.load(Ordering::Relaxed) || progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    Ok(a)
}

/// Mirror the lower triangle into the upper one (for products with the full matrix).
pub fn symmetrize_lower(a: &mut Mat<f64>) {
    let n = a.nrows();
    for j in 0..n {
        for i in j + 1..n {
            a[(j, i)] = a[(i, j)];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rcond_of_diagonal_and_indefinite() {
        let a = Mat::<f64>::from_fn(3, 3, |i, j| if i == j { [1.0, -1e-3, 4.0][i] } else { 0.0 });
        let s = SymmetricSolver::new(&a).unwrap();
        assert!((s.rcond - 1e-3 / 4.0).abs() < 1e-12, "{}", s.rcond);
        let mut b = Mat::<f64>::from_fn(3, 1, |i, _| i as f64 + 1.0);
        s.solve_in_place(&mut b);
        assert!((b[(1, 0)] + 2000.0).abs() < 1e-9);
    }

    #[test]
    fn singular_is_an_error() {
        let a = Mat::<f64>::from_fn(3, 3, |i, j| (i + 1) as f64 * (j + 1) as f64);
        assert!(matches!(
            SymmetricSolver::new(&a),
            Err(LinalgError::SingularDense { n: 3, .. })
        ));
    }
}
