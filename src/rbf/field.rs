//! The fitted implicit field `f(x) = g(x) + Σ_l Σ_i λ_{l,i} φ(|x − P_{l,i}| / R_l) + p(x)`
//! (normalised units): the carrier `g`, one CSRBF spline per level `l` (a single level is the seed's
//! method; several are the coarse-to-fine hierarchy of [`super::levels`]) and an optional linear
//! polynomial. Each level is evaluated with its own spatial index so only the centres within `R_l`
//! of `x` are visited (`O(L log n + k)` per evaluation). A local carrier shares the finest query.
//! Implements [`ScalarField`], including the batched [`ScalarField::values_in`] that gathers the
//! candidate centres once per small box of grid corners.

use super::pou::PouBlock;
use super::{Carrier, Kernel};
use crate::geometry::{Aabb, Point3, dist2, sub};
use crate::polygonize::{RegionField, ScalarField};
use crate::spatial::SpatialIndex;
use std::collections::HashMap;
use std::sync::Arc;

/// One level of the spline: centres, weights, support radius and an index over the centres.
pub struct SplineLevel {
    /// Centres `P_{l,i}`, normalised units.
    pub centres: Vec<Point3>,
    /// Weights `λ_{l,i}`.
    pub weights: Vec<f64>,
    /// Support radius `R_l`, normalised units.
    pub support: f64,
    /// Index over `centres`.
    pub index: Arc<dyn SpatialIndex + Send>,
}

impl SplineLevel {
    /// `Σ_i λ_i φ(|x − P_i| / R)` over `candidates` (a superset of the centres within `R` of `x`).
    pub fn value_with(&self, kernel: Kernel, x: &Point3, candidates: &[u32]) -> f64 {
        let r2 = self.support * self.support;
        let inv_r = 1.0 / self.support;
        let mut s = 0.0;
        for &i in candidates {
            let d2 = dist2(*x, self.centres[i as usize]);
            if d2 < r2 {
                s += self.weights[i as usize] * kernel.value(d2.sqrt() * inv_r);
            }
        }
        s
    }

    /// `Σ_i λ_i φ(|x − P_i| / R)`, querying the index.
    pub fn value(&self, kernel: Kernel, x: &Point3, hits: &mut Vec<u32>) -> f64 {
        self.index.within(x, self.support, hits);
        self.value_with(kernel, x, hits)
    }

    /// Gradient of this level's spline at `x`, added to `g`.
    fn add_gradient(&self, kernel: Kernel, x: &Point3, hits: &mut Vec<u32>, g: &mut Point3) {
        self.index.within(x, self.support, hits);
        self.add_gradient_with(kernel, x, hits, g);
    }

    /// Gradient of this level's spline at `x` over `candidates` (a superset of the centres within
    /// `R` of `x`), added to `g`.
    fn add_gradient_with(&self, kernel: Kernel, x: &Point3, candidates: &[u32], g: &mut Point3) {
        let r2 = self.support * self.support;
        let inv_r = 1.0 / self.support;
        for &i in candidates {
            let c = self.centres[i as usize];
            if dist2(*x, c) >= r2 {
                continue;
            }
            let r = dist2(*x, c).sqrt() * inv_r;
            let s = self.weights[i as usize] * kernel.derivative_over_r(r) * inv_r * inv_r;
            let d = sub(*x, c);
            for k in 0..3 {
                g[k] += s * d[k];
            }
        }
    }
}

/// Candidate centres of one level with their weights as struct of arrays, in the order given
/// (ascending ids), so a sum over them visits the centres as [`SplineLevel::value_with`] does
/// while the squared distances vectorise.
#[derive(Default)]
pub(super) struct CentreList {
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
    ws: Vec<f64>,
}

impl CentreList {
    /// The centres `ids` of `level`.
    fn fill(&mut self, level: &SplineLevel, ids: &[u32]) {
        for v in [&mut self.xs, &mut self.ys, &mut self.zs, &mut self.ws] {
            v.clear();
        }
        for &i in ids {
            let c = level.centres[i as usize];
            self.xs.push(c[0]);
            self.ys.push(c[1]);
            self.zs.push(c[2]);
            self.ws.push(level.weights[i as usize]);
        }
    }

    /// `Σ_i λ_i φ(|x − P_i| / R)` over the listed centres within `support` of `x`: the value
    /// of [`SplineLevel::value_with`] over the same ids, bit for bit (same arithmetic, same order).
    fn value(&self, kernel: Kernel, support: f64, x: &Point3, d2: &mut Vec<f64>) -> f64 {
        d2.clear();
        d2.extend(
            (self.xs.iter().zip(&self.ys).zip(&self.zs)).map(|((&px, &py), &pz)| {
                let (dx, dy, dz) = (x[0] - px, x[1] - py, x[2] - pz);
                dx * dx + dy * dy + dz * dz
            }),
        );
        let (r2, inv_r) = (support * support, 1.0 / support);
        let mut s = 0.0;
        for (&d, &w) in d2.iter().zip(&self.ws) {
            if d < r2 {
                s += w * kernel.value(d.sqrt() * inv_r);
            }
        }
        s
    }
}

/// `v₀ + v·x` for `[v₀, v_x, v_y, v_z]`, 0 without a polynomial.
pub fn linear_poly(v: Option<[f64; 4]>, x: &Point3) -> f64 {
    v.map_or(0.0, |v| v[0] + v[1] * x[0] + v[2] * x[1] + v[3] * x[2])
}

/// One spline `U(x) = Σ_l Σ_i λ_{l,i} φ(|x − P_{l,i}| / R_l) + p(x)`: the levels (coarse to fine)
/// and the optional linear polynomial. The whole correction of a global fit, or one block's.
pub struct Spline {
    /// Levels, coarse to fine (one for the seed's single-level method).
    pub levels: Vec<SplineLevel>,
    /// Linear polynomial `[v₀, v_x, v_y, v_z]` (`p(x) = v₀ + v·x`), when fitted.
    pub polynomial: Option<[f64; 4]>,
}

impl Spline {
    pub(super) fn poly_value(&self, x: &Point3) -> f64 {
        linear_poly(self.polynomial, x)
    }

    /// `∇p` (zero without a polynomial).
    fn poly_gradient(&self) -> Point3 {
        self.polynomial.map_or([0.0; 3], |v| [v[1], v[2], v[3]])
    }

    /// `U(x)` over the first `upto` levels (all: `usize::MAX`).
    pub fn value(&self, kernel: Kernel, x: &Point3, upto: usize, hits: &mut Vec<u32>) -> f64 {
        let mut v = self.poly_value(x);
        for l in self.levels.iter().take(upto) {
            v += l.value(kernel, x, hits);
        }
        v
    }

    /// Each level's centres within `R_l` of `region` (ids ascending: every point then sums its
    /// centres in the same order whatever the region, so a corner shared by two tiles or blocks
    /// gets bit-identical values).
    pub(super) fn gather(&self, region: &Aabb) -> Vec<(Vec<u32>, CentreList)> {
        let (c, half) = (region.center(), 0.5 * region.diagonal());
        (self.levels.iter())
            .map(|l| {
                let mut hits = Vec::with_capacity(256);
                l.index.within(&c, half + l.support, &mut hits);
                hits.sort_unstable();
                let mut list = CentreList::default();
                list.fill(l, &hits);
                (hits, list)
            })
            .collect()
    }

    /// `U(x)` from the gathered `lists` (the polynomial, then each level's sum over its list).
    pub(super) fn value_from(
        &self,
        lists: &[(Vec<u32>, CentreList)],
        kernel: Kernel,
        x: &Point3,
        d2: &mut Vec<f64>,
    ) -> f64 {
        let mut v = 0.0;
        v += self.poly_value(x);
        for (l, (_, list)) in self.levels.iter().zip(lists) {
            v += list.value(kernel, l.support, x, d2);
        }
        v
    }

    /// `∇U(x)` from the gathered `lists`, added to `g` (the polynomial's gradient first).
    pub(super) fn add_gradient_from(
        &self,
        lists: &[(Vec<u32>, CentreList)],
        kernel: Kernel,
        x: &Point3,
        g: &mut Point3,
    ) {
        let poly = self.poly_gradient();
        for k in 0..3 {
            g[k] += poly[k];
        }
        for (l, (hits, _)) in self.levels.iter().zip(lists) {
            l.add_gradient_with(kernel, x, hits, g);
        }
    }

    /// [`Self::add_gradient_from`] with a sorted index query per level instead of gathered
    /// lists (the same sums in the same order, bit for bit).
    pub(super) fn add_gradient_sorted(
        &self,
        kernel: Kernel,
        x: &Point3,
        hits: &mut Vec<u32>,
        g: &mut Point3,
    ) {
        let poly = self.poly_gradient();
        for k in 0..3 {
            g[k] += poly[k];
        }
        for l in &self.levels {
            l.index.within(x, l.support, hits);
            hits.sort_unstable();
            l.add_gradient_with(kernel, x, hits, g);
        }
    }

    /// [`Self::value_from`] with a sorted index query per level instead of gathered lists (the
    /// same sums in the same order, bit for bit).
    pub(super) fn value_sorted(&self, kernel: Kernel, x: &Point3, hits: &mut Vec<u32>) -> f64 {
        let mut v = self.poly_value(x);
        for l in &self.levels {
            l.index.within(x, l.support, hits);
            hits.sort_unstable();
            v += l.value_with(kernel, x, hits);
        }
        v
    }

    /// `(U(x), ∇U(x))`.
    fn value_gradient(&self, kernel: Kernel, x: &Point3, hits: &mut Vec<u32>) -> (f64, Point3) {
        let mut g = self.poly_gradient();
        let mut v = self.poly_value(x);
        for l in &self.levels {
            v += l.value(kernel, x, hits);
            l.add_gradient(kernel, x, hits, &mut g);
        }
        (v, g)
    }

    fn poly_gradient_norm(&self) -> f64 {
        self.polynomial
            .map_or(0.0, |v| (v[1] * v[1] + v[2] * v[2] + v[3] * v[3]).sqrt())
    }
}

/// How the carrier is corrected: one global spline, or a partition of unity of block splines.
pub enum Correction {
    /// `f = g + U` (the seed's global system, single- or multi-level).
    Global(Spline),
    /// `f = g + Σ_b w_b U_b / Σ_b w_b` over overlapping blocks ([`super::pou`]); `g` where no block
    /// reaches.
    Blocks(Vec<PouBlock>),
}

/// A solved CSRBF implicit field.
pub struct RbfField {
    /// The spline part.
    pub correction: Correction,
    /// Kernel `φ`.
    pub kernel: Kernel,
    /// Carrier solid `g`.
    pub carrier: Carrier,
    /// Index over the carrier's points (all data points), for a local carrier's neighbour queries
    /// and the polygonizer's "near the data" test.
    pub carrier_index: Arc<dyn SpatialIndex + Send>,
    /// Radius of the carrier's neighbour queries (its blending radius), normalised units.
    pub carrier_radius: f64,
    /// Finest support radius of the spline, normalised units.
    pub finest_support: f64,
    /// Whether the caller drops every piece of the zero set that no data point carries (the
    /// floaters: [`crate::mesh::floaters`] with the finest support radius as the band, or wider):
    /// the skip test then rules out every cell farther than the finest support radius from the
    /// data without sampling the far field there, since a piece of the surface lying wholly in
    /// such cells would be dropped, and one reaching nearer is followed into them.
    pub unsupported_dropped: bool,
}

impl RbfField {
    fn carrier_value(&self, x: &Point3, candidates: &[u32]) -> f64 {
        match &self.carrier {
            Carrier::Local(l) => l.value_with(x, candidates),
            c => c.value(x),
        }
    }

    /// The spline part at `x` over the first `upto` levels of each spline.
    fn correction_value(&self, x: &Point3, upto: usize, hits: &mut Vec<u32>) -> f64 {
        match &self.correction {
            Correction::Global(s) => s.value(self.kernel, x, upto, hits),
            Correction::Blocks(blocks) => {
                let (mut sw, mut swu) = (0.0, 0.0);
                for b in blocks {
                    let w = b.weight(x).0;
                    if w > 0.0 {
                        sw += w;
                        swu += w * b.spline.value(self.kernel, x, upto, hits);
                    }
                }
                if sw > 0.0 { swu / sw } else { 0.0 }
            }
        }
    }

    /// The spline part alone (every level; blocks blended) at `points`, all in `region`: the
    /// value [`ScalarField::values_in`] gives minus the carrier's (the full value is this plus the
    /// carrier's, summed in that order), gathered once per part of the region.
    pub fn correction_values_in(&self, region: &Aabb, points: &[Point3], out: &mut [f64]) {
        super::region::PreparedRegion::correction_only(self, region).values(points, out);
    }

    /// Carrier plus every level but the finest (the smooth far field).
    fn coarse_value(&self, x: &Point3, hits: &mut Vec<u32>) -> f64 {
        let upto = match &self.correction {
            Correction::Global(s) => s.levels.len().saturating_sub(1),
            Correction::Blocks(b) => b
                .iter()
                .map(|b| b.spline.levels.len())
                .min()
                .unwrap_or(1)
                .saturating_sub(1),
        };
        self.carrier.value(x) + self.correction_value(x, upto, hits)
    }
}

impl ScalarField for RbfField {
    fn value(&self, x: &Point3) -> f64 {
        let mut hits = Vec::with_capacity(64);
        let v = self.correction_value(x, usize::MAX, &mut hits);
        self.carrier_index.within(x, self.carrier_radius, &mut hits);
        v + self.carrier_value(x, &hits)
    }

    fn values_in(&self, region: &Aabb, points: &[Point3], out: &mut [f64]) {
        self.prepare(region).values(points, out);
    }

    fn gradients_in(&self, region: &Aabb, points: &[Point3], out: &mut [Point3]) {
        self.prepare(region).gradients(points, out);
    }

    /// Each level's centres within `R_l` of the region (of each block meeting it) and the local
    /// carrier's points ([`LocalCarrier::gather`](super::carrier::LocalCarrier::gather)) gathered
    /// once per part of the region ([`super::region`]).
    fn prepare<'a>(&'a self, region: &Aabb) -> Box<dyn RegionField + 'a> {
        Box::new(super::region::PreparedRegion::new(self, region))
    }

    fn gradient(&self, x: &Point3) -> Point3 {
        let mut hits = Vec::with_capacity(64);
        self.carrier_index.within(x, self.carrier_radius, &mut hits);
        let mut g = match &self.carrier {
            Carrier::Local(l) => l.value_gradient_with(x, &hits).1,
            c => c.gradient(x),
        };
        let gu = match &self.correction {
            Correction::Global(s) => s.value_gradient(self.kernel, x, &mut hits).1,
            Correction::Blocks(blocks) => blended_gradient(
                blocks.len(),
                |b| blocks[b].weight(x),
                |b| blocks[b].spline.value_gradient(self.kernel, x, &mut hits),
            ),
        };
        for k in 0..3 {
            g[k] += gu[k];
        }
        g
    }

    /// The polygonizer follows the zero set into skipped tiles from sampled ones, so a wrong
    /// answer can only lose a piece lying wholly in skipped cells, all farther than the finest
    /// support radius from the data (see [`crate::polygonize::polygonize_in`]).
    ///
    /// Active when a data point's support reaches the cell; elsewhere inactive when
    /// [`RbfField::unsupported_dropped`], else the field there is the carrier
    /// and the coarser levels, decided by a Lipschitz bound for a single-level global field with an
    /// analytic carrier, else by sign changes or a value below the cell's half diagonal at the 8
    /// corners and the centre (every point of the cell is within ~0.58 half diagonals of one of
    /// them, so a zero is caught wherever the far field's slope is below ~1.7; the local carrier
    /// is a distance, slope 1).
    fn may_contain_zero(&self, cell: &Aabb) -> bool {
        let mut hits = Vec::new();
        self.zero_test(cell, &mut |p| self.coarse_value(p, &mut hits))
    }

    /// As [`ScalarField::may_contain_zero`] per cell, each far-field sample taken once: the
    /// polygonizer's neighbouring tiles share their corners (the same grid points, bit for bit),
    /// so about two samples per tile instead of nine, and the same answers.
    fn may_contain_zero_each(&self, cells: &[Aabb], out: &mut [bool]) {
        let mut hits = Vec::new();
        let mut known: HashMap<[u64; 3], f64> = HashMap::new();
        for (cell, o) in cells.iter().zip(out.iter_mut()) {
            *o = self.zero_test(cell, &mut |p| {
                *known
                    .entry(p.map(f64::to_bits))
                    .or_insert_with(|| self.coarse_value(p, &mut hits))
            });
        }
    }
}

impl RbfField {
    /// [`ScalarField::may_contain_zero`] with the far field (carrier and coarser levels) at a
    /// point given by `sample`.
    fn zero_test(&self, cell: &Aabb, sample: &mut dyn FnMut(&Point3) -> f64) -> bool {
        let c = cell.center();
        let half = 0.5 * cell.diagonal();
        let mut nn = Vec::with_capacity(1);
        self.carrier_index.nearest_k(&c, 1, &mut nn);
        if nn
            .first()
            .is_some_and(|&(_, d)| d <= self.finest_support + half)
        {
            return true;
        }
        if self.unsupported_dropped {
            return false;
        }
        if let (Correction::Global(s), Some(l)) = (&self.correction, self.carrier.lipschitz())
            && s.levels.len() <= 1
        {
            let far = self.carrier.value(&c) + s.poly_value(&c);
            return far.abs() <= (l + s.poly_gradient_norm()) * half;
        }
        let mut samples = vec![sample(&c)];
        samples.extend(cell.corners().iter().map(sample));
        let pos = samples.iter().filter(|v| **v > 0.0).count();
        pos != 0 && pos != samples.len() || samples.iter().any(|v| v.abs() <= half)
    }
}

/// `∇(Σ w_b U_b / Σ w_b) = (Σ (∇w_b U_b + w_b ∇U_b) − Ū Σ ∇w_b) / Σ w_b` with `Ū` the blend, over
/// `n` blocks: `weight(b)` gives `(w_b, ∇w_b)`, `value_gradient(b)` gives `(U_b, ∇U_b)` (asked
/// only where `w_b > 0`); 0 where no block reaches.
pub(super) fn blended_gradient(
    n: usize,
    weight: impl Fn(usize) -> (f64, Point3),
    mut value_gradient: impl FnMut(usize) -> (f64, Point3),
) -> Point3 {
    let (mut sw, mut swu) = (0.0, 0.0);
    let (mut sdw, mut sdwu, mut swdu) = ([0.0; 3], [0.0; 3], [0.0; 3]);
    for b in 0..n {
        let (w, dw) = weight(b);
        if w <= 0.0 {
            continue;
        }
        let (u, du) = value_gradient(b);
        sw += w;
        swu += w * u;
        for k in 0..3 {
            sdw[k] += dw[k];
            sdwu[k] += dw[k] * u;
            swdu[k] += w * du[k];
        }
    }
    if sw <= 0.0 {
        return [0.0; 3];
    }
    let ubar = swu / sw;
    [0, 1, 2].map(|k| (sdwu[k] + swdu[k] - ubar * sdw[k]) / sw)
}
