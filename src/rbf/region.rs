//! A fitted field prepared for one region of space ([`crate::polygonize::ScalarField::prepare`]:
//! a polygonizer tile): the region is cut into parts; the first few points of each part are
//! evaluated with per-point index queries, later ones from the centres of each level and the local
//! carrier's points gathered once for the part. Both give the same values and gradients, bit for
//! bit: each sum visits the same centres in ascending id order.
//!
//! A gathered list holds everything within reach of any point of its box, so its length grows
//! with the box: for a box of half diagonal `h`, the centres within `R + h` of its centre, and for
//! the carrier's K nearest points up to `d_K + 2h`. Tiles are a fixed number of grid cells, and on
//! dense data (10⁶ points) a cell is wider than the support radius `R`: a tile's lists then held
//! thousands of points, each scanned at every evaluation (and sorted into shells once per
//! tile), most of them far out of reach. So a region wider than [`PART_SUPPORTS`] finest
//! supports is split into up to [`MAX_SPLIT`]³ parts of equal size, each gathered once
//! [`POINTS_BEFORE_GATHER`] points fell in it (parts with fewer, e.g. the few grid corners of a
//! part on 10⁶ points, are never gathered). A point is evaluated from the lists of the part that
//! contains it; the values do not depend on the split.
//!
//! A partition-of-unity field (blocks, [`super::pou`]) is prepared the same way: each block whose
//! outer box meets the region has its own lists per part, and the blend `Σ w_b U_b / Σ w_b` is
//! summed over those blocks in block order (a block that does not reach a point has weight 0
//! there and adds exact zeros), so a corner shared by two tiles gets the same bits from both.

use super::Carrier;
use super::carrier::NearPoints;
use super::field::{CentreList, Correction, RbfField, Spline, blended_gradient};
use super::pou::PouBlock;
use crate::geometry::{Aabb, Point3};
use crate::polygonize::RegionField;

/// Most points a part of a prepared region evaluates with per-point index queries before it
/// gathers its lists: a gather costs about as much as this many point queries (the polygonizer's
/// probe of a tile, 9 points, mostly on tiles the surface does not cross; on 10⁶ points, where a
/// grid cell is wider than the support radius, a part holds only a few grid corners and gathering
/// every part cost a third more than querying per point).
const POINTS_BEFORE_GATHER: u8 = 9;

/// Widest part of a region, in finest support radii (or carrier radii, the smaller).
const PART_SUPPORTS: f64 = 2.0;

/// Most parts per axis.
const MAX_SPLIT: usize = 4;

/// One spline's lists: per level, the centre ids within `R_l` of a part (ascending) and their
/// coordinates.
type Lists = Vec<(Vec<u32>, CentreList)>;

/// The lists of one part: per spline of the region (see [`PreparedRegion::splines`]); the local
/// carrier's points near it (`None` for an analytic carrier).
struct Gathered {
    lists: Vec<Lists>,
    near: Option<NearPoints>,
}

/// See the module documentation.
pub(super) struct PreparedRegion<'a> {
    field: &'a RbfField,
    /// The global spline (no weight), or the blocks whose outer box meets the region, in block
    /// order (with their weights).
    splines: Vec<(&'a Spline, Option<&'a PouBlock>)>,
    region: Aabb,
    /// Points of each part evaluated with per-point queries so far.
    single: Vec<u8>,
    /// Parts per axis.
    split: usize,
    /// The parts' lists (`split³`, x fastest), gathered on first use.
    parts: Vec<Option<Gathered>>,
    hits: Vec<u32>,
    d2: Vec<f64>,
    /// Whether the values include the carrier (else the spline part alone).
    with_carrier: bool,
}

impl<'a> PreparedRegion<'a> {
    pub(super) fn new(field: &'a RbfField, region: &Aabb) -> Self {
        let splines = match &field.correction {
            Correction::Global(s) => vec![(s, None)],
            Correction::Blocks(blocks) => (blocks.iter())
                .filter(|b| b.outer.intersects(region))
                .map(|b| (&b.spline, Some(b)))
                .collect(),
        };
        let mut reach = field.finest_support;
        if field.carrier_radius > 0.0 {
            reach = reach.min(field.carrier_radius);
        }
        let width = region.extent().into_iter().fold(0.0f64, f64::max);
        let split = if reach > 0.0 && width.is_finite() {
            ((width / (PART_SUPPORTS * reach)).ceil() as usize).clamp(1, MAX_SPLIT)
        } else {
            1
        };
        PreparedRegion {
            field,
            splines,
            region: *region,
            single: vec![0; split * split * split],
            split,
            parts: (0..split * split * split).map(|_| None).collect(),
            hits: Vec::new(),
            d2: Vec::new(),
            with_carrier: true,
        }
    }

    /// The spline part alone (blocks blended), without the carrier: nothing of the carrier is
    /// gathered or evaluated. Gradients are not available (they panic).
    pub(super) fn correction_only(field: &'a RbfField, region: &Aabb) -> Self {
        PreparedRegion {
            with_carrier: false,
            ..Self::new(field, region)
        }
    }

    /// The part holding `x`, its lists gathered, or `None` while it evaluates per point (its
    /// first [`POINTS_BEFORE_GATHER`] points).
    fn gathered_part(&mut self, x: &Point3) -> Option<usize> {
        let k = self.part_of(x);
        if self.parts[k].is_none() && self.single[k] < POINTS_BEFORE_GATHER {
            self.single[k] += 1;
            return None;
        }
        self.gather(k);
        Some(k)
    }

    /// Gathers at once the lists of every part that `points` would take past
    /// [`POINTS_BEFORE_GATHER`] (a batch of a residual bucket's data points or of a dense tile's
    /// corners), instead of evaluating its first points one by one.
    fn gather_busy_parts(&mut self, points: &[Point3]) {
        if points.len() <= usize::from(POINTS_BEFORE_GATHER) {
            return;
        }
        let mut count = [0usize; MAX_SPLIT * MAX_SPLIT * MAX_SPLIT];
        for p in points {
            count[self.part_of(p)] += 1;
        }
        for (k, &n) in count[..self.parts.len()].iter().enumerate() {
            if n + usize::from(self.single[k]) > usize::from(POINTS_BEFORE_GATHER) {
                self.gather(k);
            }
        }
    }

    /// The part holding `x` (the nearest one for a point outside the region).
    fn part_of(&self, x: &Point3) -> usize {
        if self.split == 1 {
            return 0;
        }
        let (e, s) = (self.region.extent(), self.split);
        let axis = |k: usize| {
            let t = if e[k] > 0.0 {
                (x[k] - self.region.min[k]) / e[k] * s as f64
            } else {
                0.0
            };
            (t.floor().max(0.0) as usize).min(s - 1)
        };
        (axis(2) * s + axis(1)) * s + axis(0)
    }

    /// The box of part `k`, widened by a rounding margin so it holds every point
    /// [`Self::part_of`] assigns to it.
    fn part_box(&self, k: usize) -> Aabb {
        if self.split == 1 {
            return self.region;
        }
        let (e, s) = (self.region.extent(), self.split);
        let idx = [k % s, (k / s) % s, k / (s * s)];
        let margin = 1e-9 * e.into_iter().fold(0.0f64, f64::max);
        let at = |a: usize, i: usize| self.region.min[a] + e[a] * i as f64 / s as f64;
        Aabb {
            min: [0, 1, 2].map(|a| at(a, idx[a]) - margin),
            max: [0, 1, 2].map(|a| at(a, idx[a] + 1) + margin),
        }
    }

    /// Gathers the lists of part `k` if not yet.
    fn gather(&mut self, k: usize) {
        if self.parts[k].is_some() {
            return;
        }
        let bx = self.part_box(k);
        let near = match &self.field.carrier {
            Carrier::Local(l) if self.with_carrier => {
                let mut near = NearPoints::new();
                l.gather(&bx, &mut near);
                Some(near)
            }
            _ => None,
        };
        self.parts[k] = Some(Gathered {
            lists: self.splines.iter().map(|(s, _)| s.gather(&bx)).collect(),
            near,
        });
    }

    /// `f(x)` with per-point queries (the centres sorted as the gathered lists are).
    fn single_value(&mut self, x: &Point3) -> f64 {
        let (f, hits) = (self.field, &mut self.hits);
        let v = blend(&self.splines, x, |s, _| s.value_sorted(f.kernel, x, hits));
        if !self.with_carrier {
            return v;
        }
        v + match &f.carrier {
            // Outside any gathered region: a sorted radius query, as a tile's list sums.
            Carrier::Local(l) => l.value_near(x, &mut NearPoints::new()),
            carrier => carrier.value(x),
        }
    }

    /// `∇f(x)` with per-point queries (the sums of [`RegionField::gradients`], same order).
    fn single_gradient(&mut self, x: &Point3) -> Point3 {
        let (f, hits) = (self.field, &mut self.hits);
        let carrier = match &f.carrier {
            Carrier::Local(l) => l.value_gradient_near(x, &mut NearPoints::new()).1,
            carrier => carrier.gradient(x),
        };
        if let [(s, None)] = self.splines[..] {
            let mut o = carrier;
            s.add_gradient_sorted(f.kernel, x, hits, &mut o);
            return o;
        }
        let splines = &self.splines;
        let g = blended_gradient(
            splines.len(),
            |b| splines[b].1.map_or((1.0, [0.0; 3]), |blk| blk.weight(x)),
            |b| {
                let u = splines[b].0.value_sorted(f.kernel, x, hits);
                let mut du = [0.0; 3];
                splines[b].0.add_gradient_sorted(f.kernel, x, hits, &mut du);
                (u, du)
            },
        );
        [0, 1, 2].map(|a| g[a] + carrier[a])
    }
}

/// The correction at `x`: the global spline's value, or the blend `Σ w_b U_b / Σ w_b` (0 where no
/// block reaches), `value(spline, k)` giving spline `k`'s `U`.
fn blend(
    splines: &[(&Spline, Option<&PouBlock>)],
    x: &Point3,
    mut value: impl FnMut(&Spline, usize) -> f64,
) -> f64 {
    if let [(s, None)] = splines {
        return value(s, 0);
    }
    let (mut sw, mut swu) = (0.0, 0.0);
    for (k, (s, b)) in splines.iter().enumerate() {
        let w = b.map_or(1.0, |b| b.weight(x).0);
        sw += w;
        swu += w * value(s, k);
    }
    if sw > 0.0 { swu / sw } else { 0.0 }
}

impl RegionField for PreparedRegion<'_> {
    fn values(&mut self, points: &[Point3], out: &mut [f64]) {
        self.gather_busy_parts(points);
        let f = self.field;
        for (p, o) in points.iter().zip(out.iter_mut()) {
            let Some(k) = self.gathered_part(p) else {
                *o = self.single_value(p);
                continue;
            };
            let part = self.parts[k].as_mut().expect("gathered");
            let d2 = &mut self.d2;
            let lists = &part.lists;
            *o = blend(&self.splines, p, |s, i| {
                s.value_from(&lists[i], f.kernel, p, d2)
            });
            if !self.with_carrier {
                continue;
            }
            *o += match (&f.carrier, &mut part.near) {
                (Carrier::Local(l), Some(near)) => l.value_near(p, near),
                (carrier, _) => carrier.value(p),
            };
        }
    }

    fn gradients(&mut self, points: &[Point3], out: &mut [Point3]) {
        assert!(self.with_carrier, "gradients of the spline part alone");
        self.gather_busy_parts(points);
        let f = self.field;
        for (p, o) in points.iter().zip(out.iter_mut()) {
            let Some(k) = self.gathered_part(p) else {
                *o = self.single_gradient(p);
                continue;
            };
            let part = self.parts[k].as_mut().expect("gathered");
            let carrier = match (&f.carrier, &mut part.near) {
                (Carrier::Local(l), Some(near)) => l.value_gradient_near(p, near).1,
                (carrier, _) => carrier.gradient(p),
            };
            if let [(s, None)] = self.splines[..] {
                // The carrier first, then the spline: the order of the per-point gradient.
                *o = carrier;
                s.add_gradient_from(&part.lists[0], f.kernel, p, o);
                continue;
            }
            let (splines, lists, d2) = (&self.splines, &part.lists, &mut self.d2);
            let g = blended_gradient(
                splines.len(),
                |b| splines[b].1.map_or((1.0, [0.0; 3]), |blk| blk.weight(p)),
                |b| {
                    let u = splines[b].0.value_from(&lists[b], f.kernel, p, d2);
                    let mut du = [0.0; 3];
                    splines[b]
                        .0
                        .add_gradient_from(&lists[b], f.kernel, p, &mut du);
                    (u, du)
                },
            );
            *o = [0, 1, 2].map(|a| g[a] + carrier[a]);
        }
    }
}
