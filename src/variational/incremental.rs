//! Adding constraints to a solved Turk–O'Brien system without refactoring (Jiang & Turk,
//! *Modeling of Interpolating Implicit Surfaces*, §2: block inversion / Schur complement).
//!
//! The base system `A w = b` (`N = n + D + 1` unknowns: kernel weights and the linear polynomial)
//! is factored once (`LBLᵀ`). Adding `m` value constraints borders it:
//! `[A Cᵀ; C E] [w; w̄] = [b; b̄]`, `C` = kernel and polynomial rows of the new points against the
//! old unknowns, `E` = kernel block among the new points. With `Z = A⁻¹Cᵀ` and the Schur complement
//! `S = E − C Z` (m × m): `w̄ = S⁻¹(b̄ − C w₀)`, `w = w₀ − Z w̄`, where `w₀ = A⁻¹ b`. The new
//! polynomial side conditions (`Σ w = 0`, `Σ w x = 0`) come out right because the polynomial
//! columns of `C` carry `[1, y]` for every new point. Cost per batch of `M`: `O(N²M)` for the new
//! columns of `Z` (two triangular solves each) plus `O(N m²)` to rebuild `S` and `O(m³)` to factor
//! it (`m` = all constraints added since the last refactor), against `O((N+m)³)` for a fresh solve.
//! After `m` exceeds [`IncrementalSystem::rebase_above`] the system is refactored from scratch
//! (the `N m²` term would otherwise grow).
//!
//! **Sparse CSRBF factor.** The same bordering applies to the compactly supported system of the
//! main pipeline: adding a centre adds a row/column and leaves every existing entry unchanged, so
//! with `A = LLᵀ` (sparse Cholesky) the bordered factor is `[L 0; (L⁻¹Cᵀ)ᵀ chol(S)]`,
//! `S = E − (L⁻¹Cᵀ)ᵀ(L⁻¹Cᵀ)` — one sparse forward solve per new row (`O(nnz(L))` each; `C` is
//! sparse because only centres within the support radius interact). `L⁻¹Cᵀ` fills in along the
//! elimination tree, so the bordered rows are denser than `L`'s; for many additions a periodic
//! refactor (symbolic structure reused) is cheaper. Removing or moving a centre is a rank-2
//! up/down-date of the factor instead. (Not implemented here: this module is the dense variant.)

use faer::Mat;

use super::constraints::{
    Origin, ValueConstraint, VariationalError, check_affine_rank, check_coincident,
};
use super::kernel::{RadialKernel, RbfExpansion};
use super::turk_obrien::value_matrix;
use crate::linalg::dense::{SymmetricSolver, lower_from_fn, symmetrize_lower};

/// A solved value-constraint system that accepts more constraints cheaply.
#[derive(Clone)]
pub struct IncrementalSystem<const D: usize> {
    kernel: RadialKernel,
    base: Vec<ValueConstraint<D>>,
    solver: SymmetricSolver,
    w0: Vec<f64>,
    added: Vec<ValueConstraint<D>>,
    /// `Z = A⁻¹Cᵀ`, `N × m`.
    z: Mat<f64>,
    /// Current solution: kernel weights for base then added points, then the polynomial.
    alpha: Vec<f64>,
    poly: Vec<f64>,
    /// Refactor from scratch once more than this many constraints were added (default
    /// `max(64, N/4)`).
    pub rebase_above: usize,
}

impl<const D: usize> IncrementalSystem<D> {
    /// Factor and solve the base system (`O(N³/3)`). Use normalised coordinates for conditioning.
    pub fn new(
        constraints: &[ValueConstraint<D>],
        kernel: RadialKernel,
    ) -> Result<Self, VariationalError> {
        check_coincident(constraints)?;
        let pts: Vec<[f64; D]> = constraints.iter().map(|c| c.p).collect();
        let rows: Vec<usize> = constraints.iter().map(|c| c.origin.row()).collect();
        check_affine_rank(&pts, &rows)?;
        let solver = SymmetricSolver::new(&value_matrix(&pts, kernel))?;
        let n = constraints.len();
        let mut b = Mat::<f64>::from_fn(n + D + 1, 1, |i, _| {
            constraints.get(i).map_or(0.0, |c| c.value)
        });
        solver.solve_in_place(&mut b);
        let w0: Vec<f64> = (0..n + D + 1).map(|i| b[(i, 0)]).collect();
        Ok(IncrementalSystem {
            kernel,
            base: constraints.to_vec(),
            solver,
            alpha: w0[..n].to_vec(),
            poly: w0[n..].to_vec(),
            w0,
            added: Vec::new(),
            z: Mat::zeros(n + D + 1, 0),
            rebase_above: (n / 4).max(64),
        })
    }

    /// Number of constraints (base + added).
    pub fn len(&self) -> usize {
        self.base.len() + self.added.len()
    }

    /// True when there are no constraints (never, after a successful `new`).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Reciprocal condition estimate of the base system.
    pub fn rcond(&self) -> f64 {
        self.solver.rcond
    }

    /// Every constraint, base first.
    pub fn constraints(&self) -> Vec<ValueConstraint<D>> {
        self.base.iter().chain(&self.added).copied().collect()
    }

    /// Add constraints (`O(N²M)`); rows in errors count base + previously added + new.
    pub fn add(&mut self, new: &[ValueConstraint<D>]) -> Result<(), VariationalError> {
        let start = self.len();
        if let Some(k) = new
            .iter()
            .position(|c| c.p.iter().any(|x| !x.is_finite()) || !c.value.is_finite())
        {
            return Err(VariationalError::NonFinite {
                row: start + k,
                what: "coordinate or value",
            });
        }
        let mut all = self.constraints();
        all.extend(new.iter().enumerate().map(|(k, c)| ValueConstraint {
            origin: Origin::Sample(start + k),
            ..*c
        }));
        check_coincident(&all)?;
        if self.added.len() + new.len() > self.rebase_above {
            *self = Self::new(&all, self.kernel)?;
            return Ok(());
        }
        let n_big = self.base.len() + D + 1;
        let mut znew = Mat::<f64>::from_fn(n_big, new.len(), |i, r| self.c_entry(&new[r].p, i));
        self.solver.solve_in_place(&mut znew);
        let m_old = self.added.len();
        let mut z = Mat::<f64>::zeros(n_big, m_old + new.len());
        z.as_mut().get_mut(.., ..m_old).copy_from(self.z.as_ref());
        z.as_mut().get_mut(.., m_old..).copy_from(znew.as_ref());
        self.z = z;
        self.added.extend(all[start..].iter().copied());
        self.resolve()
    }

    /// Entry `i` of the bordered row of a new point `y` against the base unknowns.
    fn c_entry(&self, y: &[f64; D], i: usize) -> f64 {
        let n = self.base.len();
        if i < n {
            let r2: f64 = (0..D).map(|k| (y[k] - self.base[i].p[k]).powi(2)).sum();
            self.kernel.phi_r2(r2)
        } else if i == n {
            1.0
        } else {
            y[i - n - 1]
        }
    }

    /// Rebuild and factor `S`, update the solution (`O(N m²)`).
    fn resolve(&mut self) -> Result<(), VariationalError> {
        let m = self.added.len();
        let n_big = self.base.len() + D + 1;
        let c = Mat::<f64>::from_fn(m, n_big, |r, i| self.c_entry(&self.added[r].p, i));
        let cz = &c * &self.z;
        let mut s = lower_from_fn(m, |r, q| {
            let r2: f64 = (0..D)
                .map(|k| (self.added[r].p[k] - self.added[q].p[k]).powi(2))
                .sum();
            self.kernel.phi_r2(r2) - cz[(r, q)]
        });
        symmetrize_lower(&mut s);
        let schur = SymmetricSolver::new(&s)?;
        let w0 = Mat::<f64>::from_fn(n_big, 1, |i, _| self.w0[i]);
        let cw = &c * &w0;
        let mut wbar = Mat::<f64>::from_fn(m, 1, |r, _| self.added[r].value - cw[(r, 0)]);
        schur.solve_in_place(&mut wbar);
        let zw = &self.z * &wbar;
        let n = self.base.len();
        self.alpha = (0..n)
            .map(|i| self.w0[i] - zw[(i, 0)])
            .chain((0..m).map(|r| wbar[(r, 0)]))
            .collect();
        self.poly = (0..=D).map(|k| self.w0[n + k] - zw[(n + k, 0)]).collect();
        Ok(())
    }

    /// The current interpolant.
    pub fn expansion(&self) -> RbfExpansion<D> {
        RbfExpansion {
            kernel: self.kernel,
            centres: self.base.iter().chain(&self.added).map(|c| c.p).collect(),
            alpha: self.alpha.clone(),
            beta: Vec::new(),
            poly: self.poly.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rng(s: &mut u64) -> f64 {
        *s = s.wrapping_add(0x9E3779B97F4A7C15);
        let mut z = *s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58476D1CE4E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D049BB133111EB);
        (z ^ (z >> 31)) as f64 / u64::MAX as f64
    }

    fn random_constraints<const D: usize>(
        n: usize,
        seed: u64,
        row0: usize,
    ) -> Vec<ValueConstraint<D>> {
        let mut s = seed;
        (0..n)
            .map(|k| ValueConstraint {
                p: std::array::from_fn(|_| rng(&mut s) - 0.5),
                value: rng(&mut s) - 0.5,
                origin: Origin::Sample(row0 + k),
            })
            .collect()
    }

    fn fresh<const D: usize>(c: &[ValueConstraint<D>], kernel: RadialKernel) -> RbfExpansion<D> {
        IncrementalSystem::new(c, kernel).unwrap().expansion()
    }

    fn rel_diff<const D: usize>(a: &RbfExpansion<D>, b: &RbfExpansion<D>) -> f64 {
        let x: Vec<f64> = a.alpha.iter().chain(&a.poly).copied().collect();
        let y: Vec<f64> = b.alpha.iter().chain(&b.poly).copied().collect();
        let scale = y.iter().map(|v| v.abs()).fold(0.0, f64::max);
        x.iter()
            .zip(&y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
            / scale
    }

    #[test]
    fn incremental_equals_fresh_solve_2d_and_3d() {
        let base = random_constraints::<2>(300, 1, 0);
        let mut sys = IncrementalSystem::new(&base, RadialKernel::ThinPlate).unwrap();
        let mut all = base.clone();
        for (batch, m) in [1usize, 10, 37].into_iter().enumerate() {
            let add = random_constraints::<2>(m, 100 + batch as u64, all.len());
            sys.add(&add).unwrap();
            all.extend(add);
            let d = rel_diff(&sys.expansion(), &fresh(&all, RadialKernel::ThinPlate));
            assert!(d < 1e-9, "batch {batch}: {d}");
        }
        // The interpolant honours every constraint, old and new.
        let e = sys.expansion();
        for c in &all {
            assert!((e.value(&c.p) - c.value).abs() < 1e-8);
        }
        let base3 = random_constraints::<3>(200, 7, 0);
        let mut sys3 = IncrementalSystem::new(&base3, RadialKernel::Cubic).unwrap();
        let add3 = random_constraints::<3>(12, 8, 200);
        sys3.add(&add3).unwrap();
        let all3: Vec<_> = base3.into_iter().chain(add3).collect();
        assert!(rel_diff(&sys3.expansion(), &fresh(&all3, RadialKernel::Cubic)) < 1e-9);
    }

    #[test]
    fn rebase_and_errors() {
        let base = random_constraints::<2>(40, 3, 0);
        let mut sys = IncrementalSystem::new(&base, RadialKernel::ThinPlate).unwrap();
        sys.rebase_above = 5;
        let add = random_constraints::<2>(9, 4, 40);
        sys.add(&add).unwrap();
        assert_eq!(sys.len(), 49);
        let all: Vec<_> = base.iter().chain(&add).copied().collect();
        assert!(rel_diff(&sys.expansion(), &fresh(&all, RadialKernel::ThinPlate)) < 1e-9);
        let dup = [ValueConstraint {
            p: base[3].p,
            value: 0.7,
            origin: Origin::Sample(0),
        }];
        let e = sys.add(&dup).unwrap_err();
        assert!(
            matches!(
                e,
                VariationalError::ConflictingValues {
                    first: 3,
                    second: 49,
                    ..
                }
            ),
            "{e}"
        );
    }
}
