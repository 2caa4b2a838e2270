//! Linear algebra: symmetric positive definite solvers for the CSRBF system. Knows no geometry.
//!
//! Matrices come in as full symmetric `sprs::CsMat<f64>` in CSC storage with sorted indices
//! (both triangles stored). Three factorisations are offered through [`factorize`]:
//!
//! * [`SolverKind::Envelope`]: our own Jennings (1966) envelope / profile Cholesky, the method of
//!   the seed paper (Kojekine et al., section 3.2; George & Liu 1981, chapter 4). Storage and work
//!   follow the profile of the (reordered) matrix: O(profile) values, O(Σ row_len²) flops.
//! * [`SolverKind::Sparse`]: faer's supernodal sparse Cholesky with its own AMD ordering.
//! * [`SolverKind::Ldl`]: sprs-ldl's up-looking LDLᵀ, a single-threaded reference solver.
//! * [`SolverKind::Cg`]: Jacobi-preconditioned conjugate gradients; stores no factor (memory
//!   `O(nnz)`), the choice when a factor does not fit the memory budget.
//!
//! The polynomial border of the CSRBF system is handled by block elimination in [`solve_bordered`]
//! (George & Liu), reusing the factor of `A`.
//!
//! Permutation convention everywhere: `perm[new] = old`, i.e. position `new` of the reordered
//! matrix holds original row `perm[new]`. Factors take and return vectors in the ORIGINAL order.

mod bordered;
mod cg;
mod cg_first;
pub mod dense;
mod envelope;
mod envelope_kernels;
mod ldl;
pub(crate) mod small;
mod sparse;
#[cfg(test)]
mod test_support;

use std::fmt;
use std::str::FromStr;

use sprs::CsMat;

use crate::progress::Progress;

pub use bordered::solve_bordered;
pub use cg_first::{AUTO_CG_ITERATIONS, AUTO_CG_MIN_SHIFT};
pub use envelope::{EnvelopeFactor, envelope_size};

/// A factorised SPD matrix `A` that can solve `A x = b`.
pub trait SpdFactor: Send + Sync {
    /// Order `n` of the matrix.
    fn n(&self) -> usize;
    /// Overwrite `b` (length `n`) with `A⁻¹ b`.
    fn solve_in_place(&self, b: &mut [f64]);
    /// Number of stored values of the factor (the memory it holds, in f64 values).
    fn factor_values(&self) -> usize;
    /// Like [`SpdFactor::solve_in_place`], but reports a failed solve (an iterative solver that did
    /// not converge). Direct factors always succeed.
    fn solve_checked(&self, b: &mut [f64]) -> Result<(), LinalgError> {
        self.solve_in_place(b);
        Ok(())
    }
    /// Iterations of the most demanding solve so far, for iterative solvers; `None` for factors.
    fn iterations(&self) -> Option<usize> {
        None
    }
}

/// Which factorisation [`factorize`] uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SolverKind {
    /// Own Jennings envelope (profile) Cholesky; honours the given ordering (`"envelope"`).
    Envelope,
    /// faer supernodal Cholesky with AMD; ignores the given ordering (`"sparse"`, the default).
    #[default]
    Sparse,
    /// sprs-ldl LDLᵀ (reference, single-threaded); honours the given ordering (`"ldl"`).
    Ldl,
    /// Jacobi-preconditioned conjugate gradients; no factor, memory `O(nnz)` (`"cg"`).
    Cg,
    /// `sparse` when its factor fits [`SolverParams::max_factor_values`], else `cg`; on a
    /// smoothing system (`SolverParams::diagonal_shift` ≥ [`AUTO_CG_MIN_SHIFT`]) `cg` first, with
    /// [`AUTO_CG_ITERATIONS`] iterations before it factorises instead (`"auto"`).
    Auto,
}

impl SolverKind {
    /// All kinds, in a fixed order (for option lists and test grids).
    pub const ALL: [SolverKind; 5] = [
        SolverKind::Envelope,
        SolverKind::Sparse,
        SolverKind::Ldl,
        SolverKind::Cg,
        SolverKind::Auto,
    ];
    /// The direct (factorising) kinds.
    pub const DIRECT: [SolverKind; 3] = [SolverKind::Envelope, SolverKind::Sparse, SolverKind::Ldl];

    /// The name used on the command line, in the API and in reports.
    pub fn name(self) -> &'static str {
        match self {
            SolverKind::Envelope => "envelope",
            SolverKind::Sparse => "sparse",
            SolverKind::Ldl => "ldl",
            SolverKind::Cg => "cg",
            SolverKind::Auto => "auto",
        }
    }
}

impl fmt::Display for SolverKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Error returned when a solver name is not one of `envelope`, `sparse`, `ldl`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown solver {0:?}: expected one of \"envelope\", \"sparse\", \"ldl\", \"cg\", \"auto\""
)]
pub struct UnknownSolver(pub String);

impl FromStr for SolverKind {
    type Err = UnknownSolver;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        SolverKind::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| UnknownSolver(s.to_string()))
    }
}

/// Parameters of [`factorize`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverParams {
    /// Which factorisation to run.
    pub kind: SolverKind,
    /// Refuse (with [`LinalgError::TooLarge`]) factors that would store more f64 values than this.
    /// Default 400,000,000 values (about 3 GiB).
    pub max_factor_values: usize,
    /// Conjugate gradients: stop when `‖b − A x‖ ≤ cg_tolerance · ‖b‖` (default 1e-10).
    pub cg_tolerance: f64,
    /// Conjugate gradients: give up after this many iterations (default 5000).
    pub cg_max_iterations: usize,
    /// The `λ` added to the matrix diagonal (smoothing), in units of the unshifted diagonal
    /// (default 0). Informs [`SolverKind::Auto`]: from [`AUTO_CG_MIN_SHIFT`] on it runs conjugate
    /// gradients first.
    pub diagonal_shift: f64,
}

impl Default for SolverParams {
    fn default() -> Self {
        SolverParams {
            kind: SolverKind::default(),
            max_factor_values: 400_000_000,
            cg_tolerance: 1e-10,
            cg_max_iterations: 5000,
            diagonal_shift: 0.0,
        }
    }
}

/// Statistics of one factorisation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FactorStats {
    /// Stored values of the factor (f64 count; for the envelope solver this is the envelope size).
    pub factor_values: usize,
    /// Wall time of the symbolic phase (ordering / structure / envelope build), seconds.
    pub symbolic_s: f64,
    /// Wall time of the numeric factorisation, seconds.
    pub numeric_s: f64,
}

/// Errors of the linear algebra stage.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LinalgError {
    /// A pivot was not positive: the matrix is not (numerically) positive definite.
    #[error(
        "the matrix is not positive definite (non-positive pivot at row {pivot}); \
         check for duplicate points or use a smaller support radius"
    )]
    NotPositiveDefinite {
        /// Row of the offending pivot, in the ORIGINAL (unpermuted) numbering.
        pivot: usize,
    },
    /// The factor would exceed the configured size limit; nothing was allocated.
    #[error(
        "the factor would need {values} values ({mem}), more than the limit of {limit} values; \
         use a smaller support radius or fewer `--neighbours`, or the sparse solver",
        mem = format_bytes(*bytes)
    )]
    TooLarge {
        /// Number of f64 values the factor would store.
        values: usize,
        /// The configured limit ([`SolverParams::max_factor_values`]).
        limit: usize,
        /// Estimated memory in bytes.
        bytes: u64,
    },
    /// A dense symmetric system is singular to working precision.
    #[error(
        "the {n}×{n} system is singular (reciprocal condition estimate {rcond:.3e}); remove nearly coincident or degenerate constraints"
    )]
    SingularDense {
        /// System size.
        n: usize,
        /// Reciprocal 1-norm condition estimate.
        rcond: f64,
    },
    /// Inputs have inconsistent sizes (non-square matrix, wrong vector or permutation length).
    #[error("dimension mismatch in {what}: expected {expected}, got {got}")]
    DimensionMismatch {
        /// Which input was wrong.
        what: &'static str,
        /// Expected size.
        expected: usize,
        /// Actual size.
        got: usize,
    },
    /// The permutation is not a permutation of `0..n`.
    #[error("invalid ordering: entry {index} ({value}) is out of range or repeated")]
    InvalidPermutation {
        /// Position in the permutation.
        index: usize,
        /// The offending value.
        value: usize,
    },
    /// The 4×4 polynomial block is singular: the points are (nearly) coplanar or too few.
    #[error(
        "the linear polynomial block is singular (relative pivot {relative_pivot:.3e} in column {column}): \
         the points are (nearly) coplanar or fewer than 4; use `--polynomial none`"
    )]
    Singular {
        /// Column of the polynomial block (0 = constant, 1..=3 = x, y, z) whose pivot vanished.
        column: usize,
        /// The pivot divided by the original diagonal entry.
        relative_pivot: f64,
    },
    /// Conjugate gradients did not reach the tolerance.
    #[error(
        "conjugate gradients did not converge in {iterations} iterations (relative residual \
         {relative_residual:.3e}); use `--solver sparse` or a smaller support radius"
    )]
    NotConverged {
        /// Iterations run.
        iterations: usize,
        /// `‖b − A x‖ / ‖b‖` of the last iterate.
        relative_residual: f64,
    },
    /// The caller cancelled the work through [`Progress::cancelled`].
    #[error("cancelled")]
    Cancelled,
    /// An error reported by a backend library (faer or sprs).
    #[error("solver backend error: {0}")]
    Backend(String),
}

/// Human-readable size: "512.0 MiB" or "3.20 GiB".
fn format_bytes(bytes: u64) -> String {
    let mib = bytes as f64 / (1024.0 * 1024.0);
    if mib < 1024.0 {
        format!("{mib:.1} MiB")
    } else {
        format!("{:.2} GiB", mib / 1024.0)
    }
}

/// The [`LinalgError::TooLarge`] error for `values` f64 values plus `index_bytes` of indices,
/// or `Ok` when `values <= limit`.
fn check_size(values: usize, index_bytes: u64, limit: usize) -> Result<(), LinalgError> {
    if values > limit {
        Err(LinalgError::TooLarge {
            values,
            limit,
            bytes: values as u64 * 8 + index_bytes,
        })
    } else {
        Ok(())
    }
}

/// Checks that `a` is square and `perm` (if any) is a permutation of `0..n`; returns `n`.
fn validate(a: &CsMat<f64>, perm: Option<&[usize]>) -> Result<usize, LinalgError> {
    let n = a.rows();
    if a.cols() != n {
        return Err(LinalgError::DimensionMismatch {
            what: "matrix columns (the matrix must be square)",
            expected: n,
            got: a.cols(),
        });
    }
    if let Some(p) = perm {
        if p.len() != n {
            return Err(LinalgError::DimensionMismatch {
                what: "ordering length",
                expected: n,
                got: p.len(),
            });
        }
        let mut seen = vec![false; n];
        for (index, &value) in p.iter().enumerate() {
            if value >= n || seen[value] {
                return Err(LinalgError::InvalidPermutation { index, value });
            }
            seen[value] = true;
        }
    }
    Ok(n)
}

/// Runs `work` on a helper thread and waits for its result, polling `progress.cancelled()` every
/// 20 ms: a cancellation answers [`LinalgError::Cancelled`] within that period even while a
/// single uninterruptible library call (a dense or supernodal factorisation) is running. The
/// abandoned work finishes in the background, on a thread pool of its own (the shared rayon pool
/// stays free for the next job), and its result (and memory) is dropped then.
pub(crate) fn run_abandonable<T: Send + 'static>(
    progress: &dyn Progress,
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, LinalgError> {
    let (tx, rx) = std::sync::mpsc::sync_channel(1);
    // A pool of its own: abandoned work must not hold the shared rayon pool's threads, or the
    // next job's parallel stages would wait for it.
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(rayon::current_num_threads())
        .thread_name(|i| format!("rbfsurf-factor-{i}"))
        .build()
        .map_err(|e| LinalgError::Backend(format!("cannot start the factorisation pool: {e}")))?;
    std::thread::Builder::new()
        .name("rbfsurf-factor".into())
        .spawn(move || {
            let _ = tx.send(pool.install(work));
        })
        .map_err(|e| LinalgError::Backend(format!("cannot start the factorisation thread: {e}")))?;
    loop {
        match rx.recv_timeout(std::time::Duration::from_millis(20)) {
            Ok(v) => return Ok(v),
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                if progress.cancelled() {
                    return Err(LinalgError::Cancelled);
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Err(LinalgError::Backend(
                    "the factorisation thread stopped without a result (a panic)".into(),
                ));
            }
        }
    }
}

/// Factorises the SPD matrix `a` (n × n, full symmetric, CSC with sorted indices).
///
/// `perm` is an optional ordering (`perm[new] = old`) used by [`SolverKind::Envelope`] and
/// [`SolverKind::Ldl`]; `None` means the identity. [`SolverKind::Sparse`] uses faer's AMD and
/// ignores it. The size of the factor is computed first and checked against
/// [`SolverParams::max_factor_values`] before any large allocation. Progress fractions are
/// reported through `progress` (the envelope solver reports by work done and can be cancelled
/// mid-way; the backends are checked for cancellation between phases).
///
/// The returned factor solves in the original numbering.
///
/// # Example
/// ```
/// use rbfsurf::linalg::{factorize, SolverParams, SolverKind};
/// use rbfsurf::progress::NoProgress;
/// let mut t = sprs::TriMat::new((2, 2));
/// t.add_triplet(0, 0, 4.0); t.add_triplet(1, 1, 9.0);
/// t.add_triplet(0, 1, 1.0); t.add_triplet(1, 0, 1.0);
/// let a = t.to_csc();
/// let params = SolverParams { kind: SolverKind::Envelope, ..Default::default() };
/// let (f, stats) = factorize(&a, None, &params, &NoProgress).unwrap();
/// let mut b = vec![5.0, 10.0];
/// f.solve_in_place(&mut b);
/// assert!((b[0] - 1.0).abs() < 1e-12 && (b[1] - 1.0).abs() < 1e-12);
/// assert_eq!(stats.factor_values, 3);
/// ```
pub fn factorize(
    a: &CsMat<f64>,
    perm: Option<&[usize]>,
    params: &SolverParams,
    progress: &dyn Progress,
) -> Result<(Box<dyn SpdFactor>, FactorStats), LinalgError> {
    validate(a, perm)?;
    if progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    match params.kind {
        SolverKind::Envelope => {
            let (f, s) = envelope::factorize_envelope(a, perm, params, progress)?;
            Ok((Box::new(f), s))
        }
        SolverKind::Sparse => {
            let (f, s) = sparse::factorize_sparse(a, params, progress)?;
            Ok((Box::new(f), s))
        }
        SolverKind::Ldl => {
            let (f, s) = ldl::factorize_ldl(a, perm, params, progress)?;
            Ok((Box::new(f), s))
        }
        SolverKind::Cg => {
            let (f, s) = cg::prepare_cg(a.clone(), params, progress)?;
            Ok((Box::new(f), s))
        }
        SolverKind::Auto if params.diagonal_shift >= AUTO_CG_MIN_SHIFT => {
            let (f, s) = cg_first::prepare_cg_first(a.clone(), params, progress)?;
            Ok((Box::new(f), s))
        }
        SolverKind::Auto => match sparse::factorize_sparse(a, params, progress) {
            Err(LinalgError::TooLarge { .. }) => {
                let (f, s) = cg::prepare_cg(a.clone(), params, progress)?;
                Ok((Box::new(f), s))
            }
            other => other.map(|(f, s)| (Box::new(f) as Box<dyn SpdFactor>, s)),
        },
    }
}

/// [`factorize`] taking ownership of `a`: conjugate gradients keep the matrix itself instead of a
/// copy (the matrix is the whole memory of that solver); the direct solvers drop it after factoring.
pub fn factorize_owned(
    a: CsMat<f64>,
    perm: Option<&[usize]>,
    params: &SolverParams,
    progress: &dyn Progress,
) -> Result<(Box<dyn SpdFactor>, FactorStats), LinalgError> {
    validate(&a, perm)?;
    match params.kind {
        SolverKind::Cg => {}
        SolverKind::Auto if params.diagonal_shift >= AUTO_CG_MIN_SHIFT => {
            let (f, s) = cg_first::prepare_cg_first(a, params, progress)?;
            return Ok((Box::new(f), s));
        }
        SolverKind::Auto => match sparse::factorize_sparse(&a, params, progress) {
            Err(LinalgError::TooLarge { .. }) => {}
            other => return other.map(|(f, s)| (Box::new(f) as Box<dyn SpdFactor>, s)),
        },
        _ => return factorize(&a, perm, params, progress),
    }
    if progress.cancelled() {
        return Err(LinalgError::Cancelled);
    }
    let (f, s) = cg::prepare_cg(a, params, progress)?;
    Ok((Box::new(f), s))
}

/// Number of f64 values the factor of `a` would store with solver `kind` and ordering `perm`,
/// computed without the numeric factorisation.
///
/// Envelope: the envelope size Σ (i − f_i + 1), O(nnz). Sparse: faer's symbolic factorisation
/// (AMD + elimination tree, roughly O(nnz(A)·α)). Ldl: sprs-ldl's symbolic phase, nnz(L) + n.
pub fn estimate_factor_values(
    a: &CsMat<f64>,
    perm: Option<&[usize]>,
    kind: SolverKind,
) -> Result<usize, LinalgError> {
    validate(a, perm)?;
    match kind {
        SolverKind::Envelope => Ok(envelope_size(a, perm)?.total),
        SolverKind::Sparse => sparse::estimate_sparse(a),
        SolverKind::Ldl => Ok(ldl::estimate_ldl(a, perm)),
        SolverKind::Cg => Ok(0),
        SolverKind::Auto => sparse::estimate_sparse(a),
    }
}

/// Residual of `A x = b`: returns (root mean square, maximum absolute value) of `A x − b`.
///
/// `a` is n × n (any sprs storage), `x` and `b` have length n. If the sizes do not match,
/// both values are NaN. An empty system gives (0, 0).
pub fn residual(a: &CsMat<f64>, x: &[f64], b: &[f64]) -> (f64, f64) {
    let n = a.rows();
    if a.cols() != n || x.len() != n || b.len() != n {
        return (f64::NAN, f64::NAN);
    }
    if n == 0 {
        return (0.0, 0.0);
    }
    let mut r: Vec<f64> = b.iter().map(|v| -v).collect();
    for (outer, vec) in a.outer_iterator().enumerate() {
        for (inner, &v) in vec.iter() {
            if a.is_csc() {
                r[inner] += v * x[outer];
            } else {
                r[outer] += v * x[inner];
            }
        }
    }
    let sum_sq: f64 = r.iter().map(|v| v * v).sum();
    let max = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    ((sum_sq / n as f64).sqrt(), max)
}

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;
    use crate::progress::{CancelFlag, NoProgress};

    fn params(kind: SolverKind) -> SolverParams {
        SolverParams {
            kind,
            cg_tolerance: 1e-14,
            ..Default::default()
        }
    }

    #[test]
    fn every_solver_and_ordering_matches_dense_cholesky() {
        for (n, k, seed) in [(60, 12.0, 1), (150, 25.0, 2)] {
            let (_, a) = test_matrix(n, k, seed);
            let b = test_rhs(n);
            let reference = dense_cholesky_solve(&to_dense(&a), &b).expect("SPD test matrix");
            for kind in SolverKind::ALL {
                for (name, perm) in orderings(n) {
                    let (f, stats) = factorize(&a, perm.as_deref(), &params(kind), &NoProgress)
                        .unwrap_or_else(|e| panic!("{kind} {name}: {e}"));
                    assert_eq!(f.n(), n);
                    assert_eq!(stats.factor_values, f.factor_values(), "{kind} {name}");
                    let est = estimate_factor_values(&a, perm.as_deref(), kind).unwrap();
                    assert_eq!(est, stats.factor_values, "{kind} {name}");
                    let mut x = b.clone();
                    f.solve_in_place(&mut x);
                    let err = rel_diff(&x, &reference);
                    assert!(err < 1e-10, "{kind} {name}: rel diff {err:e}");
                    let (rms, max) = residual(&a, &x, &b);
                    assert!(rms < 1e-12 && max < 1e-11, "{kind} {name}: {rms:e} {max:e}");
                }
            }
        }
    }

    #[test]
    fn indefinite_matrix_reports_the_pivot_for_every_solver() {
        let n = 80;
        let (_, mut a) = test_matrix(n, 15.0, 3);
        let bad = 37;
        *a.get_mut(bad, bad).unwrap() = -1.0;
        for kind in SolverKind::ALL {
            for (name, perm) in orderings(n) {
                let err = factorize(&a, perm.as_deref(), &params(kind), &NoProgress)
                    .err()
                    .unwrap_or_else(|| panic!("{kind} {name}: factorised an indefinite matrix"));
                assert_eq!(
                    err,
                    LinalgError::NotPositiveDefinite { pivot: bad },
                    "{kind} {name}"
                );
            }
        }
    }

    #[test]
    fn oversized_factor_is_refused_with_its_size() {
        let (_, a) = test_matrix(100, 20.0, 4);
        for kind in SolverKind::DIRECT {
            let p = SolverParams {
                kind,
                max_factor_values: 10,
                ..Default::default()
            };
            let values = estimate_factor_values(&a, None, kind).unwrap();
            match factorize(&a, None, &p, &NoProgress).err() {
                Some(LinalgError::TooLarge {
                    values: v,
                    limit,
                    bytes,
                }) => {
                    assert_eq!((v, limit), (values, 10), "{kind}");
                    assert!(bytes >= 8 * values as u64, "{kind}");
                }
                other => panic!("{kind}: expected TooLarge, got {other:?}"),
            }
        }
        let msg = LinalgError::TooLarge {
            values: 500_000_000,
            limit: 400_000_000,
            bytes: 4_000_000_000,
        }
        .to_string();
        assert!(
            msg.contains("3.73 GiB") && msg.contains("--neighbours"),
            "{msg}"
        );
    }

    #[test]
    fn cancelled_before_start_returns_cancelled() {
        let (_, a) = test_matrix(50, 10.0, 5);
        let flag = CancelFlag::default();
        flag.cancel();
        for kind in SolverKind::ALL {
            let err = factorize(&a, None, &params(kind), &flag).err();
            assert_eq!(err, Some(LinalgError::Cancelled), "{kind}");
        }
    }

    #[test]
    fn bad_inputs_are_errors_not_panics() {
        let (_, a) = test_matrix(20, 8.0, 6);
        let p = params(SolverKind::Envelope);
        let short = vec![0usize; 19];
        assert!(matches!(
            factorize(&a, Some(&short), &p, &NoProgress).err(),
            Some(LinalgError::DimensionMismatch { .. })
        ));
        let mut dup: Vec<usize> = (0..20).collect();
        dup[3] = 4;
        assert_eq!(
            factorize(&a, Some(&dup), &p, &NoProgress).err(),
            Some(LinalgError::InvalidPermutation { index: 4, value: 4 })
        );
        let rect: CsMat<f64> = sprs::TriMat::<f64>::new((3, 4)).to_csc();
        for kind in SolverKind::ALL {
            assert!(matches!(
                estimate_factor_values(&rect, None, kind).err(),
                Some(LinalgError::DimensionMismatch { .. })
            ));
        }
        let (rms, max) = residual(&a, &[0.0; 3], &[0.0; 20]);
        assert!(rms.is_nan() && max.is_nan());
    }

    #[test]
    fn solver_kind_names_round_trip() {
        for kind in SolverKind::ALL {
            assert_eq!(kind.to_string().parse::<SolverKind>(), Ok(kind));
        }
        assert_eq!("LDL".parse::<SolverKind>(), Ok(SolverKind::Ldl));
        assert_eq!("cg".parse::<SolverKind>(), Ok(SolverKind::Cg));
        assert!("gmres".parse::<SolverKind>().is_err());
        assert_eq!(SolverKind::default(), SolverKind::Sparse);
        assert_eq!(SolverParams::default().max_factor_values, 400_000_000);
    }

    #[test]
    fn residual_of_csr_and_csc_agree() {
        let (_, a) = test_matrix(40, 10.0, 8);
        let x = test_rhs(40);
        let b: Vec<f64> = (0..40).map(|i| i as f64).collect();
        let (r1, m1) = residual(&a, &x, &b);
        let (r2, m2) = residual(&a.to_csr(), &x, &b);
        assert!((r1 - r2).abs() < 1e-12 && (m1 - m2).abs() < 1e-12);
        let dense = to_dense(&a);
        let r: Vec<f64> = (0..40)
            .map(|i| (0..40).map(|j| dense[i][j] * x[j]).sum::<f64>() - b[i])
            .collect();
        let max = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((m1 - max).abs() < 1e-12);
    }
}
