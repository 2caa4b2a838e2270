//! Global radial kernels of the variational (Turk–O'Brien) interpolant and the evaluation of an
//! RBF expansion with value and gradient (Hermite) functionals plus a linear polynomial.
//!
//! `f(x) = Σ_j α_j φ(x − x_j) − Σ_j β_j · ∇φ(x − x_j) + c_0 + c · x`. Evaluation is `O(n)` per
//! point. Kernels: thin plate `r² log r` (the 2D minimiser of the bending energy, Duchon 1977) and
//! `r³` (Turk & O'Brien 2002 in 3D; also used for Hermite constraints in 2D because the thin-plate
//! Hessian is singular at `r = 0`).

/// A conditionally positive definite radial kernel of order 2 (needs the linear polynomial).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RadialKernel {
    /// `φ(r) = r² log r` (thin plate, 2D).
    ThinPlate,
    /// `φ(r) = r³` (biharmonic in 3D).
    Cubic,
}

impl RadialKernel {
    /// `φ(r)` from `r²`.
    #[inline]
    pub fn phi_r2(self, r2: f64) -> f64 {
        match self {
            RadialKernel::ThinPlate => super::batch::thin_plate_r2(r2),
            RadialKernel::Cubic => r2 * r2.sqrt(),
        }
    }

    /// `φ'(r)/r` from `r²` (so `∇φ(d) = (φ'(r)/r) d`); 0 at `r = 0`.
    #[inline]
    pub fn dphi_over_r(self, r2: f64) -> f64 {
        if r2 <= 0.0 {
            return 0.0;
        }
        match self {
            RadialKernel::ThinPlate => super::batch::fast_ln(r2.max(1e-300)) + 1.0,
            RadialKernel::Cubic => 3.0 * r2.sqrt(),
        }
    }

    /// Second-derivative coefficient `b` with `Hφ(d) = (φ'/r) I + b d dᵀ`, `b = (φ'' − φ'/r)/r²`.
    /// For `r³`: `b = 3/r` (and `b d dᵀ → 0` at `r = 0`); for the thin plate `b = 2/r²`.
    #[inline]
    pub fn hess_b(self, r2: f64) -> f64 {
        if r2 <= 0.0 {
            return 0.0;
        }
        match self {
            RadialKernel::ThinPlate => 2.0 / r2,
            RadialKernel::Cubic => 3.0 / r2.sqrt(),
        }
    }

    /// Bound of the third-derivative tensor `‖D³φ‖` on `r ≥ r_lo` (by Banach's theorem the norm of
    /// a symmetric tensor is the maximum of its diagonal form, i.e. of `d³/dt³ φ` along lines):
    /// `6` for `r³`, `2√2/r_lo` for the thin plate (∞ when `r_lo = 0`).
    pub fn third_derivative_bound(self, r_lo: f64) -> f64 {
        match self {
            RadialKernel::Cubic => 6.0,
            RadialKernel::ThinPlate => {
                if r_lo > 0.0 {
                    2.0 * std::f64::consts::SQRT_2 / r_lo
                } else {
                    f64::INFINITY
                }
            }
        }
    }

    /// Bound of `‖D⁴φ‖` on `r ≥ r_lo`: `9/r_lo` for `r³` (∞ for the thin plate, unused there).
    pub fn fourth_derivative_bound(self, r_lo: f64) -> f64 {
        match self {
            RadialKernel::Cubic if r_lo > 0.0 => 9.0 / r_lo,
            _ => f64::INFINITY,
        }
    }
}

/// A solved RBF expansion in normalised coordinates.
#[derive(Debug, Clone, PartialEq)]
pub struct RbfExpansion<const D: usize> {
    /// Kernel φ.
    pub kernel: RadialKernel,
    /// Centres `x_j` (n × D, normalised units).
    pub centres: Vec<[f64; D]>,
    /// Value weights `α_j` (n).
    pub alpha: Vec<f64>,
    /// Gradient weights `β_j` (n × D, Hermite); empty when there are no gradient functionals.
    pub beta: Vec<[f64; D]>,
    /// Polynomial `[c_0, c_1..c_D]` (D + 1).
    pub poly: Vec<f64>,
}

impl<const D: usize> RbfExpansion<D> {
    /// `f(u)`: `O(n)`.
    pub fn value(&self, u: &[f64; D]) -> f64 {
        let mut s = self.poly[0] + (0..D).map(|k| self.poly[k + 1] * u[k]).sum::<f64>();
        for (j, c) in self.centres.iter().enumerate() {
            let d: [f64; D] = std::array::from_fn(|k| u[k] - c[k]);
            let r2: f64 = d.iter().map(|x| x * x).sum();
            s += self.alpha[j] * self.kernel.phi_r2(r2);
            if let Some(b) = self.beta.get(j) {
                let g = self.kernel.dphi_over_r(r2);
                s -= g * (0..D).map(|k| b[k] * d[k]).sum::<f64>();
            }
        }
        s
    }

    /// `∇f(u)`: `O(n)`.
    pub fn gradient(&self, u: &[f64; D]) -> [f64; D] {
        let mut g: [f64; D] = std::array::from_fn(|k| self.poly[k + 1]);
        for (j, c) in self.centres.iter().enumerate() {
            let d: [f64; D] = std::array::from_fn(|k| u[k] - c[k]);
            let r2: f64 = d.iter().map(|x| x * x).sum();
            let a = self.kernel.dphi_over_r(r2);
            for k in 0..D {
                g[k] += self.alpha[j] * a * d[k];
            }
            if let Some(b) = self.beta.get(j) {
                // −Hφ(d) β = −(a β + hb (d·β) d)
                let hb = self.kernel.hess_b(r2);
                let db: f64 = (0..D).map(|k| d[k] * b[k]).sum();
                for k in 0..D {
                    g[k] -= a * b[k] + hb * db * d[k];
                }
            }
        }
        g
    }

    /// Hessian `∇²f(u)` (exact; the thin-plate Hessian is infinite at a centre). Gradient
    /// functionals (`β`) are supported for `r³` only, the kernel Hermite fits use.
    pub fn hessian(&self, u: &[f64; D]) -> [[f64; D]; D] {
        let mut h = [[0.0; D]; D];
        for (j, c) in self.centres.iter().enumerate() {
            let d: [f64; D] = std::array::from_fn(|k| u[k] - c[k]);
            let r2: f64 = d.iter().map(|x| x * x).sum();
            let (a, b) = (self.kernel.dphi_over_r(r2), self.kernel.hess_b(r2));
            for p in 0..D {
                for q in 0..D {
                    h[p][q] += self.alpha[j] * (if p == q { a } else { 0.0 } + b * d[p] * d[q]);
                }
            }
            if let Some(be) = self.beta.get(j) {
                // −D³φ(d)[β] for r³: −3(δ_pq (d·β) + β_p d_q + d_p β_q)/r + 3 d_p d_q (d·β)/r³
                let r = r2.sqrt();
                if r > 0.0 {
                    let db: f64 = (0..D).map(|k| d[k] * be[k]).sum();
                    for p in 0..D {
                        for q in 0..D {
                            let delta = if p == q { db } else { 0.0 };
                            h[p][q] -= 3.0 * (delta + be[p] * d[q] + d[p] * be[q]) / r
                                - 3.0 * d[p] * d[q] * db / (r2 * r);
                        }
                    }
                }
            }
        }
        h
    }

    /// `B` with `|f(x) − f(u)| ≤ B` for `|x − u| ≤ rho`, from the second-order Taylor expansion at
    /// `u` (exact gradient and Hessian, so the cancellation between weights is kept) plus the
    /// remainder `ρ³/6 · sup‖D³f‖`, bounded term by term with
    /// [`RadialKernel::third_derivative_bound`] / [`RadialKernel::fourth_derivative_bound`].
    /// `O(n)`; infinite when the ball holds a centre whose kernel is not smooth enough there.
    pub fn variation_bound(&self, u: &[f64; D], rho: f64) -> f64 {
        let g = self.gradient(u);
        let h = self.hessian(u);
        let gn = g.iter().map(|x| x * x).sum::<f64>().sqrt();
        let hn = h.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
        gn * rho + 0.5 * hn * rho * rho + self.remainder_bound(u, rho)
    }

    /// The third-order Taylor remainder term of [`RbfExpansion::variation_bound`],
    /// `ρ³/6 · Σ_j (|α_j| ‖D³φ‖ + |β_j| ‖D⁴φ‖)` on the ball; `O(n)` without logarithms.
    pub fn remainder_bound(&self, u: &[f64; D], rho: f64) -> f64 {
        let mut rem = 0.0;
        for (j, c) in self.centres.iter().enumerate() {
            let r = (0..D).map(|k| (u[k] - c[k]).powi(2)).sum::<f64>().sqrt();
            let r_lo = r - rho;
            if self.alpha[j] != 0.0 {
                rem += self.alpha[j].abs() * self.kernel.third_derivative_bound(r_lo.max(0.0));
            }
            if let Some(b) = self.beta.get(j) {
                let bn = (0..D).map(|k| b[k] * b[k]).sum::<f64>().sqrt();
                if bn > 0.0 {
                    rem += bn * self.kernel.fourth_derivative_bound(r_lo.max(0.0));
                }
            }
        }
        rem * rho.powi(3) / 6.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fd_check(kernel: RadialKernel) {
        let e = RbfExpansion::<2> {
            kernel,
            centres: vec![[0.1, 0.2], [0.7, -0.3], [-0.4, 0.5]],
            alpha: vec![0.3, -0.8, 0.5],
            beta: if kernel == RadialKernel::Cubic {
                vec![[0.2, -0.1], [0.0, 0.4], [-0.3, 0.25]]
            } else {
                Vec::new()
            },
            poly: vec![0.1, 0.5, -0.2],
        };
        let u = [0.33, -0.12];
        let g = e.gradient(&u);
        let h = 1e-6;
        for k in 0..2 {
            let mut a = u;
            let mut b = u;
            a[k] += h;
            b[k] -= h;
            let fd = (e.value(&a) - e.value(&b)) / (2.0 * h);
            assert!(
                (fd - g[k]).abs() < 1e-6,
                "{kernel:?} axis {k}: {fd} vs {}",
                g[k]
            );
        }
        // Hessian against differences of the analytic gradient.
        let hs = e.hessian(&u);
        for k in 0..2 {
            let mut a = u;
            let mut b = u;
            a[k] += h;
            b[k] -= h;
            let (ga, gb) = (e.gradient(&a), e.gradient(&b));
            for m in 0..2 {
                let fd = (ga[m] - gb[m]) / (2.0 * h);
                assert!(
                    (fd - hs[m][k]).abs() < 1e-5,
                    "{kernel:?} H[{m}][{k}]: {fd} vs {}",
                    hs[m][k]
                );
            }
        }
        // The variation bound holds on a ball away from the centres.
        let rho = 0.05;
        let bound = e.variation_bound(&u, rho);
        let f0 = e.value(&u);
        let mut seen: f64 = 0.0;
        for k in 0..64 {
            let t = k as f64 * std::f64::consts::TAU / 64.0;
            for s in [0.3, 1.0] {
                let x = [u[0] + s * rho * t.cos(), u[1] + s * rho * t.sin()];
                seen = seen.max((e.value(&x) - f0).abs());
            }
        }
        assert!(seen <= bound, "{kernel:?}");
        if kernel == RadialKernel::Cubic {
            assert!(
                bound < 2.0 * seen,
                "the bound should be tight-ish: {bound} vs {seen}"
            );
        }
    }

    #[test]
    fn gradient_matches_finite_differences() {
        fd_check(RadialKernel::Cubic);
        fd_check(RadialKernel::ThinPlate);
    }

    #[test]
    fn closed_forms() {
        assert_eq!(RadialKernel::Cubic.phi_r2(4.0), 8.0);
        assert!((RadialKernel::ThinPlate.phi_r2(4.0) - 4.0 * 2f64.ln()).abs() < 1e-15);
        assert_eq!(RadialKernel::ThinPlate.phi_r2(0.0), 0.0);
    }
}
