//! PCA normals: the eigenvector of the smallest eigenvalue of the covariance of each point's k
//! nearest neighbours (itself included; more where those lie along a line, as on scan lines:
//! [`collinear`]), fitted to the point's own sheet where the neighbourhood
//! reaches across a thin part ([`sheet_normal`]). Also returns the k-NN lists that the orientation
//! graph is built from. Neighbours come from [`crate::spatial::KdTree`]. `O(n k log n)`, parallel.

use crate::geometry::pca::pca;
use crate::geometry::{Point3, cross, dist2, dot, normalized, sub};
use crate::spatial::{KdTree, SpatialIndex};
use rayon::prelude::*;

/// Unoriented unit normals and, per point, its neighbour indices (without itself, nearest first).
///
/// Falls back to `+z` normals and empty neighbour lists when the index cannot be built (more than
/// `u32::MAX` points).
pub fn estimate_normals(points: &[Point3], k: usize) -> (Vec<Point3>, Vec<Vec<u32>>) {
    let Ok(tree) = KdTree::build(points) else {
        return (
            vec![[0.0, 0.0, 1.0]; points.len()],
            vec![Vec::new(); points.len()],
        );
    };
    let want = (k + 1).min(points.len()).max(1);
    points
        .par_iter()
        .enumerate()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(nn, local), (i, p)| {
                tree.nearest_k(p, want, nn);
                local.clear();
                local.extend(nn.iter().map(|&(j, _)| points[j as usize]));
                // Scan lines: the k nearest may all lie on the point's own line, whose plane is
                // any plane through it. Widen until the neighbourhood spans a surface.
                let mut m = want;
                while m < WIDEST * want && m < points.len() && collinear(local) {
                    m = (2 * m).min(WIDEST * want).min(points.len());
                    tree.nearest_k(p, m, nn);
                    local.clear();
                    local.extend(nn.iter().map(|&(j, _)| points[j as usize]));
                }
                let n = sheet_normal(local, *p);
                let nbrs = nn
                    .iter()
                    .map(|&(j, _)| j)
                    .filter(|&j| j as usize != i)
                    .collect();
                (n, nbrs)
            },
        )
        .unzip()
}

/// A neighbourhood whose second variance is below this share of its first lies along a line (the
/// points of one scan line of a LiDAR or a profile scanner): width / length below about 0.22.
/// Measured share of points below it with 12 neighbours: 79 % of a scan-line height field (lines
/// 7.5 spacings apart), none on the closed statues, 0.02 % on b9, 0.9 % on radar.
const LINE_SHARE: f64 = 0.05;
/// Widest neighbourhood tried on a line, as a multiple of the requested one.
const WIDEST: usize = 8;

/// Whether the points of `local` lie along a line ([`LINE_SHARE`]).
fn collinear(local: &[Point3]) -> bool {
    let v = pca(local).variances;
    v[1] < LINE_SHARE * v[0]
}

/// Refits of the plane to the point's own sheet.
const SHEET_ROUNDS: usize = 3;
/// Neighbours (nearest first) whose planes through the point are tried when PCA's is not flat.
const TRIAL_NEIGHBOURS: usize = 8;
/// PCA plane flat enough to be kept without trials: smallest variance below this share of the
/// total.
const FLAT_SHARE: f64 = 0.02;
/// Trial planes count the points within this share of the neighbourhood's radius.
const TRIAL_BAND: f64 = 0.05;

/// The normal line at `p` from its neighbourhood `local` (`p` first, then nearest first): the
/// PCA normal, unless the neighbourhood holds two sheets, the two faces of a part thinner than
/// the neighbourhood (a plate, two touching sheets). A plane through both faces tilts by up to
/// 70° where one face outnumbers the other, and offsets along it show no gap; so when PCA's plane
/// is not flat, the plane through `p` and two of its nearest neighbours that holds most points
/// within a thin band is tried too. A candidate normal is accepted when the offsets along it split
/// at a clear gap (see [`own_sheet`]); the plane is then refitted to the group holding `p`, up to
/// [`SHEET_ROUNDS`] times, as long as the split persists ([`refit_own_sheet`]). A curved or noisy
/// single sheet (offsets without a gap) keeps its PCA normal.
fn sheet_normal(local: &[Point3], p: Point3) -> Point3 {
    let fit = pca(local);
    let radius = local
        .iter()
        .map(|q| dist2(*q, p))
        .fold(0.0, f64::max)
        .sqrt();
    let total: f64 = fit.variances.iter().sum();
    let mut candidates = vec![fit.axes[2]];
    if fit.variances[2] > FLAT_SHARE * total {
        candidates.extend(densest_plane(local, p, radius));
    }
    candidates
        .into_iter()
        .find_map(|n| refit_own_sheet(local, p, n, radius))
        .unwrap_or(fit.axes[2])
}

/// The normal of the plane through `p` and two of its [`TRIAL_NEIGHBOURS`] nearest (`local[1..]`)
/// that has most of `local` within `TRIAL_BAND × radius`; the first such plane on ties.
fn densest_plane(local: &[Point3], p: Point3, radius: f64) -> Option<Point3> {
    let near = &local[1..local.len().min(TRIAL_NEIGHBOURS + 1)];
    let band = TRIAL_BAND * radius;
    let mut best: Option<(usize, Point3)> = None;
    for (a, qa) in near.iter().enumerate() {
        for qb in &near[a + 1..] {
            let Some(n) = normalized(cross(sub(*qa, p), sub(*qb, p))) else {
                continue;
            };
            let inside = local
                .iter()
                .filter(|q| dot(sub(**q, p), n).abs() < band)
                .count();
            if best.is_none_or(|(b, _)| inside > b) {
                best = Some((inside, n));
            }
        }
    }
    best.map(|(_, n)| n)
}

/// Starting from the normal `n`, the plane refitted to `p`'s own sheet; `None` unless the offsets
/// split into two sheets along `n` and along every refitted normal (a sub-cluster of one noisy
/// sheet may split along a steep trial plane, but not along its own refitted plane).
fn refit_own_sheet(local: &[Point3], p: Point3, mut n: Point3, radius: f64) -> Option<Point3> {
    let mut offsets: Vec<f64> = Vec::with_capacity(local.len());
    let mut own: Vec<Point3> = Vec::with_capacity(local.len());
    for round in 0..=SHEET_ROUNDS {
        offsets.clear();
        offsets.extend(local.iter().map(|q| dot(sub(*q, p), n)));
        let (lo, hi) = own_sheet(&offsets, radius)?;
        if round == SHEET_ROUNDS {
            break;
        }
        own.clear();
        own.extend(
            local
                .iter()
                .zip(&offsets)
                .filter(|&(_, &h)| h >= lo && h <= hi)
                .map(|(q, _)| *q),
        );
        n = pca(&own).axes[2];
    }
    Some(n)
}

/// The offset range `[lo, hi]` of the group holding offset 0 when the sorted `offsets` split at
/// their largest gap into two groups, the one holding 0 of at least 4 points, with the gap above
/// `radius / 4` and above twice each group's spread; `None` for one sheet.
fn own_sheet(offsets: &[f64], radius: f64) -> Option<(f64, f64)> {
    let mut h = offsets.to_vec();
    h.sort_by(f64::total_cmp);
    let (cut, gap) = h
        .windows(2)
        .enumerate()
        .map(|(i, w)| (i + 1, w[1] - w[0]))
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let (below, above) = h.split_at(cut);
    let spread = |g: &[f64]| g[g.len() - 1] - g[0];
    if gap <= 0.25 * radius || gap <= 2.0 * spread(below).max(spread(above)) {
        return None;
    }
    let own = if below[below.len() - 1] >= 0.0 {
        below
    } else {
        above
    };
    (own.len() >= 4).then(|| (own[0], own[own.len() - 1]))
}

/// Area represented by each point: `π d² / m` where `d` is the distance to the farthest of its `m`
/// listed neighbours (the disc the neighbourhood covers, shared by its points). Zero without
/// neighbours.
pub(crate) fn point_areas(points: &[Point3], neighbours: &[Vec<u32>]) -> Vec<f64> {
    points
        .iter()
        .zip(neighbours)
        .map(|(p, list)| {
            let d2 = list
                .iter()
                .map(|&j| crate::geometry::dist2(*p, points[j as usize]))
                .fold(0.0, f64::max);
            std::f64::consts::PI * d2 / list.len().max(1) as f64
        })
        .collect()
}
