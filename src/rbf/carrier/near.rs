//! The local carrier at many points of one small region (a polygonizer tile, a residual bucket),
//! from the usable points gathered once for the region ([`LocalCarrier::gather`]: one K-nearest
//! query and one radius query) instead of index queries per point (a radius query per point,
//! and a K-nearest query wherever fewer than K usable points lie within `R`: most grid corners
//! off the data). The lists are struct of arrays, so the squared distances vectorise.
//!
//! The values are the ones [`LocalCarrier::value_with`] gives over a sorted candidate list, bit
//! for bit: each sum visits the same points in the same order.
//! - Within `R`: the inner list holds every usable point within `R + h` of the region's centre
//!   `c` (`h` its half diagonal), a superset of those within `R` of any `x` in the region, in
//!   ascending id order; the points within `R` are taken in that order.
//! - The K nearest (where fewer than K lie within `R`): `d_K` is 1-Lipschitz, so
//!   `d_K(x) ≤ d_K(c) + h` and the K nearest points of `x` lie within `d_K(c) + 2h` of `c`; the
//!   wide list holds those points, in shells by distance from `c`. For each `x` only the points
//!   within a bound `B ≥ d_K(x)` are candidates: `B = d_K(c) + |x − c|`, or from the previous
//!   point `x'` of the region, `d_K(x') + |x − x'|` (grid corners come in rows, so that bound is
//!   about one cell above `d_K(x)`), the smaller; only the shells up to `|x − c| + B` are
//!   scanned. The K smallest squared distances (ties by id: the k-d tree's choice) are then
//!   reported by (distance, id) as [`crate::spatial::SpatialIndex::nearest_k`] sorts them. The
//!   only possible difference from the tree: two usable points at exactly the same squared
//!   distance from `x` competing for the K-th place, where the tree's pick among the tied is its
//!   own (the K-th point has weight `ψ(1) = 0`, so the value can differ at most by rounding).
//!   When `d_K(c) + 2h` exceeds [`WIDEST`] times `R + h` (a region far from the data, where the
//!   list would be long), the k-d tree answers those points instead.
//! - A point outside the region is evaluated with index queries (candidates sorted).

use super::{FAR_NEIGHBOURS, LocalCarrier};
use crate::geometry::{Aabb, Point3, dist2};
use crate::spatial::SpatialIndex;

/// Relative margin on reaches and bounds, for the rounding of centres and distances.
const MARGIN: f64 = 1e-9;

/// Longest reach, in units of `R + h`, up to which the list is made long enough for the K
/// nearest points of every point of the region; beyond (regions far from the data) the k-d tree
/// answers those points.
const WIDEST: f64 = 3.0;

/// Shells of the wide list (see [`NearPoints`]).
const SHELLS: usize = 16;

/// Points as struct of arrays.
#[derive(Debug, Default)]
struct Soa {
    ids: Vec<u32>,
    xs: Vec<f64>,
    ys: Vec<f64>,
    zs: Vec<f64>,
}

impl Soa {
    fn clear(&mut self) {
        self.ids.clear();
        self.xs.clear();
        self.ys.clear();
        self.zs.clear();
    }

    /// The points `ids` of `points`, in that order (replacing the list).
    fn fill(&mut self, ids: &[u32], points: &[Point3]) {
        self.clear();
        self.ids.extend_from_slice(ids);
        for (k, out) in [&mut self.xs, &mut self.ys, &mut self.zs]
            .into_iter()
            .enumerate()
        {
            out.extend(ids.iter().map(|&id| points[id as usize][k]));
        }
    }

    /// `out[k] = |x − p_k|²` for the first `n` points (the arithmetic of [`dist2`]).
    fn distances(&self, x: &Point3, n: usize, out: &mut Vec<f64>) {
        out.clear();
        out.extend(
            (self.xs[..n].iter().zip(&self.ys[..n]).zip(&self.zs[..n])).map(|((&px, &py), &pz)| {
                let (dx, dy, dz) = (x[0] - px, x[1] - py, x[2] - pz);
                dx * dx + dy * dy + dz * dz
            }),
        );
    }
}

/// The usable points near one region, gathered by [`LocalCarrier::gather`], plus scratch space
/// for the evaluations. Reuse one per thread: gathering clears it.
#[derive(Debug, Default)]
pub struct NearPoints {
    /// Centre of the region.
    centre: Point3,
    /// Squared radius around `centre` within which points are served from the lists (the
    /// region's half diagonal with a margin); negative: none.
    covers2: f64,
    /// The points within `R + h` of the centre (every point within `R` of a covered point),
    /// ascending id.
    inner: Soa,
    /// Whether `wide` holds the K nearest points of every covered point.
    serve_knn: bool,
    /// The points within `reach = d_K(c) + 2h` of the centre, in [`SHELLS`] shells of equal
    /// width by distance from it (shell `s` holds the distances in `[s, s + 1) · reach / SHELLS`).
    wide: Soa,
    /// `reach`.
    wide_reach: f64,
    /// End of each shell in `wide`.
    shell_end: [usize; SHELLS],
    /// `d_K` at the centre.
    d_k_centre: f64,
    /// A covered point evaluated before and an upper bound on its `d_K` (`d_K` is 1-Lipschitz,
    /// so the next point's is bounded by this plus their distance).
    last: Option<(Point3, f64)>,
    /// Squared distances from the point being evaluated.
    d2: Vec<f64>,
    /// Ids within `R` of the point being evaluated, ascending.
    within: Vec<u32>,
    /// `(distance or squared distance, id)` candidates for the K nearest.
    order: Vec<(f64, u32)>,
    /// Ids of the K nearest, by increasing distance.
    knn: Vec<u32>,
}

impl NearPoints {
    /// An empty list (covers nothing until gathered).
    pub fn new() -> Self {
        NearPoints {
            covers2: -1.0,
            ..Self::default()
        }
    }

    /// Number of gathered points.
    pub fn len(&self) -> usize {
        if self.serve_knn {
            self.wide.ids.len()
        } else {
            self.inner.ids.len()
        }
    }

    /// Whether the K nearest points of every point of the region are served from the list (else
    /// the region is far from the data and the k-d tree answers where fewer than K usable points
    /// lie within `R`).
    pub fn serves_nearest(&self) -> bool {
        self.serve_knn
    }

    /// True when no point was gathered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn covers(&self, x: &Point3) -> bool {
        dist2(*x, self.centre) <= self.covers2
    }

    /// The K nearest points of the covered point `x` (`serve_knn`): their ids into `self.knn`
    /// by increasing distance (ties by id); returns the nearest's and the K-th's distances,
    /// `None` for an empty list. Only the points within a bound on `d_K(x)` are sorted: the
    /// bound from the centre (`d_K(c) + |x − c|`) or from the last point, the smaller; the wide
    /// list is ordered by distance from the centre, so only its prefix within `|x − c|` plus the
    /// bound is scanned.
    fn nearest_k(&mut self, x: &Point3) -> Option<(f64, f64)> {
        let e = dist2(*x, self.centre).sqrt();
        let mut bound = self.d_k_centre + e;
        if let Some((p, d)) = self.last {
            bound = bound.min(d + dist2(*x, p).sqrt());
        }
        let bound = bound * (1.0 + MARGIN);
        let shell = ((e + bound) * (1.0 + MARGIN) / self.wide_reach * SHELLS as f64) as usize;
        let n = self.shell_end[shell.min(SHELLS - 1)];
        self.wide.distances(x, n, &mut self.d2);
        // The k-d tree's choice: the K smallest squared distances (ties by id), kept sorted
        // by insertion, then reported by (distance, id).
        let b2 = bound * bound;
        let before = |a: (f64, u32), b: (f64, u32)| a.0 < b.0 || (a.0 == b.0 && a.1 < b.1);
        // A fixed array shifted in place: K is small, and a `Vec::insert` per candidate was a
        // library memmove call each (a tenth of a statue's polygonization).
        let mut best = [(0.0f64, 0u32); FAR_NEIGHBOURS];
        let mut len = 0;
        for (&d2, &id) in self.d2.iter().zip(&self.wide.ids) {
            if d2 > b2 {
                continue;
            }
            let item = (d2, id);
            if len == FAR_NEIGHBOURS && !before(item, best[FAR_NEIGHBOURS - 1]) {
                continue;
            }
            let mut at = len.min(FAR_NEIGHBOURS - 1);
            while at > 0 && before(item, best[at - 1]) {
                best[at] = best[at - 1];
                at -= 1;
            }
            best[at] = item;
            len = (len + 1).min(FAR_NEIGHBOURS);
        }
        self.order.clear();
        self.order
            .extend(best[..len].iter().map(|&(d2, id)| (d2.sqrt(), id)));
        if !self.order.is_sorted_by(|a, b| before(*a, *b)) {
            self.order
                .sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        }
        self.knn.clear();
        self.knn.extend(self.order.iter().map(|o| o.1));
        let (first, last) = (self.order.first()?.0, self.order.last()?.0);
        self.last = Some((*x, last));
        Some((first, last))
    }
}

impl LocalCarrier {
    /// Gathers into `near` the usable points that an evaluation anywhere in `region` can use
    /// (see the module documentation): one K-nearest query and one radius query.
    pub fn gather(&self, region: &Aabb, near: &mut NearPoints) {
        near.inner.clear();
        near.wide.clear();
        near.covers2 = -1.0;
        near.last = None;
        let (c, h) = (region.center(), 0.5 * region.diagonal() * (1.0 + MARGIN));
        if !(h.is_finite() && c.iter().all(|v| v.is_finite())) {
            return;
        }
        let mut knn = Vec::with_capacity(FAR_NEIGHBOURS);
        self.valid_tree.nearest_k(&c, FAR_NEIGHBOURS, &mut knn);
        near.d_k_centre = knn.last().map_or(0.0, |&(_, d)| d);
        let inner_reach = (self.radius + h) * (1.0 + MARGIN);
        let knn_reach = (near.d_k_centre + 2.0 * h) * (1.0 + MARGIN);
        near.serve_knn = knn_reach <= WIDEST * inner_reach;
        let reach = if near.serve_knn {
            inner_reach.max(knn_reach)
        } else {
            inner_reach
        };
        let mut items = Vec::with_capacity(256);
        self.valid_tree.within(&c, reach, &mut items);
        near.order.clear();
        near.order.extend(items.iter().map(|&i| {
            let id = self.valid_ids[i as usize];
            (dist2(self.points[id as usize], c).sqrt(), id)
        }));
        near.within.clear();
        near.within.extend(
            (near.order.iter())
                .filter(|o| o.0 <= inner_reach)
                .map(|o| o.1),
        );
        near.within.sort_unstable();
        near.inner.fill(&near.within, &self.points);
        if near.serve_knn {
            // A counting sort into the shells, keeping the query's order within each.
            near.wide_reach = reach;
            let shell = |d: f64| ((d / reach * SHELLS as f64) as usize).min(SHELLS - 1);
            let mut start = [0usize; SHELLS];
            for &(d, _) in &near.order {
                start[shell(d)] += 1;
            }
            let mut total = 0;
            for (s, count) in start.iter_mut().enumerate() {
                total += *count;
                near.shell_end[s] = total;
                *count = total - *count;
            }
            near.knn.clear();
            near.knn.resize(total, 0);
            for &(d, id) in &near.order {
                let s = shell(d);
                near.knn[start[s]] = id;
                start[s] += 1;
            }
            near.wide.fill(&near.knn, &self.points);
        }
        near.centre = c;
        near.covers2 = h * h;
    }

    /// `g(x)` from the points gathered in `near` (the value [`Self::value_with`] gives, bit for
    /// bit; see the module documentation).
    pub fn value_near(&self, x: &Point3, near: &mut NearPoints) -> f64 {
        self.evaluate_near::<false>(x, near).0
    }

    /// `(g(x), ∇g(x))` from the points gathered in `near` (as [`Self::value_gradient`]).
    pub fn value_gradient_near(&self, x: &Point3, near: &mut NearPoints) -> (f64, Point3) {
        self.evaluate_near::<true>(x, near)
    }

    fn evaluate_near<const GRAD: bool>(&self, x: &Point3, near: &mut NearPoints) -> (f64, Point3) {
        if !near.covers(x) {
            let mut hits = Vec::with_capacity(64);
            self.index.within(x, self.radius, &mut hits);
            hits.sort_unstable();
            return self.evaluate::<GRAD>(x, &hits);
        }
        near.inner.distances(x, near.inner.ids.len(), &mut near.d2);
        let r2 = self.radius * self.radius;
        near.within.clear();
        let mut nearest = (f64::INFINITY, 0usize);
        for (&d2, &id) in near.d2.iter().zip(&near.inner.ids) {
            if d2 < r2 {
                near.within.push(id);
                if d2 < nearest.0 {
                    nearest = (d2, id as usize);
                }
            }
        }
        if near.within.len() >= FAR_NEIGHBOURS {
            // K points lie within R, so d_K(x) < R.
            near.last = Some((*x, self.radius));
            let local = self.blend::<GRAD>(x, &near.within, self.radius, None);
            return self.add_far_field::<GRAD>(x, local, nearest.0.sqrt(), nearest.1);
        }
        if !near.serve_knn {
            return self.evaluate_widened::<GRAD>(x);
        }
        let Some((d1, rho)) = near.nearest_k(x) else {
            return (0.0, [0.0; 3]);
        };
        let local = self.blend_nearest::<GRAD>(x, &near.knn, rho);
        self.add_far_field::<GRAD>(x, local, d1, near.knn[0] as usize)
    }
}
