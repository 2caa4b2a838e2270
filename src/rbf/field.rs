//! The fitted implicit field `f(x) = g(x) + Σ λ_i φ(|x − P_i| / R) + p(x)` (normalised units),
//! evaluated with the spatial index so only the centres within `R` of `x` are visited
//! (`O(log n + k)` per evaluation). One neighbour query serves both the spline and a local carrier.
//! Implements [`ScalarField`], including the batched [`ScalarField::values_in`] that gathers the
//! candidate centres once per small box of grid corners.

use super::{Carrier, Kernel};
use crate::geometry::{Aabb, Point3, dist2, sub};
use crate::polygonize::ScalarField;
use crate::spatial::SpatialIndex;
use std::sync::Arc;

/// A solved CSRBF implicit field.
pub struct RbfField {
    /// Centres `P_i`, normalised units.
    pub centres: Vec<Point3>,
    /// Spline weights `λ_i`.
    pub weights: Vec<f64>,
    /// Linear polynomial `[v₀, v_x, v_y, v_z]` (`p(x) = v₀ + v·x`), when fitted.
    pub polynomial: Option<[f64; 4]>,
    /// Kernel `φ`.
    pub kernel: Kernel,
    /// Support radius `R`, normalised units.
    pub support: f64,
    /// Carrier solid `g`.
    pub carrier: Carrier,
    /// Index over `centres`.
    pub index: Arc<dyn SpatialIndex + Send>,
}

impl RbfField {
    /// `f(x)` given `candidates`, a superset of the centres within `R` of `x`.
    fn value_with(&self, x: &Point3, candidates: &[u32]) -> f64 {
        let r2 = self.support * self.support;
        let inv_r = 1.0 / self.support;
        let mut spline = 0.0;
        for &i in candidates {
            let d2 = dist2(*x, self.centres[i as usize]);
            if d2 < r2 {
                spline += self.weights[i as usize] * self.kernel.value(d2.sqrt() * inv_r);
            }
        }
        let g = match &self.carrier {
            Carrier::Local(l) => l.value_gradient_with(x, candidates).0,
            c => c.value(x),
        };
        g + spline + self.poly_value(x)
    }

    fn poly_value(&self, x: &Point3) -> f64 {
        self.polynomial
            .map_or(0.0, |v| v[0] + v[1] * x[0] + v[2] * x[1] + v[3] * x[2])
    }

    fn poly_gradient_norm(&self) -> f64 {
        self.polynomial
            .map_or(0.0, |v| (v[1] * v[1] + v[2] * v[2] + v[3] * v[3]).sqrt())
    }
}

impl ScalarField for RbfField {
    fn value(&self, x: &Point3) -> f64 {
        let mut hits = Vec::with_capacity(64);
        self.index.within(x, self.support, &mut hits);
        self.value_with(x, &hits)
    }

    fn values_in(&self, region: &Aabb, points: &[Point3], out: &mut [f64]) {
        let mut hits = Vec::with_capacity(256);
        self.index.within(
            &region.center(),
            0.5 * region.diagonal() + self.support,
            &mut hits,
        );
        for (p, o) in points.iter().zip(out.iter_mut()) {
            *o = self.value_with(p, &hits);
        }
    }

    fn gradient(&self, x: &Point3) -> Point3 {
        let mut hits = Vec::with_capacity(64);
        self.index.within(x, self.support, &mut hits);
        let mut g = match &self.carrier {
            Carrier::Local(l) => l.value_gradient_with(x, &hits).1,
            c => c.gradient(x),
        };
        if let Some(v) = self.polynomial {
            for k in 0..3 {
                g[k] += v[k + 1];
            }
        }
        let inv_r = 1.0 / self.support;
        for &i in &hits {
            let c = self.centres[i as usize];
            let r = dist2(*x, c).sqrt() * inv_r;
            let s = self.weights[i as usize] * self.kernel.derivative_over_r(r) * inv_r * inv_r;
            let d = sub(*x, c);
            for k in 0..3 {
                g[k] += s * d[k];
            }
        }
        g
    }

    /// Active when some centre's support reaches the cell; elsewhere `f = g + p`, decided by the
    /// carrier: a Lipschitz bound for the analytic carriers, sign changes or a small value at the
    /// 8 corners and the centre for the local carrier.
    fn may_contain_zero(&self, cell: &Aabb) -> bool {
        let c = cell.center();
        let half = 0.5 * cell.diagonal();
        let mut nn = Vec::with_capacity(1);
        self.index.nearest_k(&c, 1, &mut nn);
        if nn.first().is_some_and(|&(_, d)| d <= self.support + half) {
            return true;
        }
        let far = |x: &Point3| self.carrier.value(x) + self.poly_value(x);
        if let Some(l) = self.carrier.lipschitz() {
            return far(&c).abs() <= (l + self.poly_gradient_norm()) * half;
        }
        let mut samples = vec![far(&c)];
        samples.extend(cell.corners().iter().map(far));
        let pos = samples.iter().filter(|v| **v > 0.0).count();
        pos != 0 && pos != samples.len() || samples.iter().any(|v| v.abs() <= 0.5 * half)
    }
}
