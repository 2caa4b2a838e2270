//! Global coupling between patches through their dipole fields (the gradient of the generalized
//! winding number).
//!
//! An oriented point `p_j` with area `a_j` and normal `n_j` is a dipole whose winding number
//! `w_j(x) = a_j (p_j − x)·n_j / (4π |p_j − x|³)` has the gradient (its field)
//! `∇w_j(x) = (3 (r̂·μ) r̂ − μ) / (4π |r|³)` with `r = x − p_j`, `μ = a_j n_j`. For a closed surface
//! `w` is 1 inside and 0 outside, so the rest `R` of a surface seen from one of its patches `P` has a
//! field that crosses `P` from outside to inside: the flux `Σ_{i∈P} a_i n_i·∇w_R(p_i)` is negative
//! when `P` points outward consistently with `R`, positive when `P` is flipped. By divergence
//! freedom that flux equals the one through the hole `P` leaves in `R`, whatever `P`'s shape: a
//! whole limb, flipped as one piece by local propagation, is still seen flipped. The same kernel
//! between two points across a thin gap or a thin plate favours the consistent choice (the dipole
//! interaction of two opposed sheets), unlike `n_i·n_j`.
//!
//! The coupling `J_PQ` is the flux of `Q`'s field through `P` (symmetric in the continuum: the
//! dipole–dipole kernel is). It is computed on at most [`TARGET_BUDGET`] target points, with the
//! sources in the 27 grid cells around a target summed exactly and farther sources lumped per
//! (cell, patch) into one dipole at their area-weighted centre. Cost
//! `O(targets · (clusters + near points))`, parallel over patches.

use rayon::prelude::*;

use super::patches::Patches;
use crate::geometry::{Aabb, Point3, dot};

/// Most target points at which fluxes are evaluated (spread over patches by size, at least
/// [`MIN_TARGETS`] per patch).
const TARGET_BUDGET: usize = 30_000;
/// Fewest targets per patch (all its points when it has fewer).
const MIN_TARGETS: usize = 16;
/// Grid cells per bounding-box diagonal for the far-field clusters.
const CELLS_PER_DIAGONAL: f64 = 40.0;

/// Oriented points split into patches (the input of [`patch_couplings`]).
pub(crate) struct PatchedCloud<'a> {
    /// Positions.
    pub points: &'a [Point3],
    /// Unit normals, consistent inside each patch.
    pub normals: &'a [Point3],
    /// Area per point.
    pub areas: &'a [f64],
    /// The patches.
    pub patches: &'a Patches,
    /// Connected component of each patch; patches of different components do not interact.
    pub component: &'a [u32],
}

/// Sources of one patch inside one grid cell.
struct Cluster {
    cell: [i64; 3],
    patch: u32,
    /// Range in the cell-sorted point order.
    range: std::ops::Range<usize>,
    /// Total dipole moment `Σ a_j n_j`.
    moment: Point3,
    /// Area-weighted centre.
    centre: Point3,
}

/// The sources of a patched cloud, clustered per (grid cell, patch) for far-field sums.
struct Sources<'a> {
    cloud: &'a PatchedCloud<'a>,
    origin: Point3,
    cell: f64,
    /// Softening of the kernels (squared length, a quarter of the squared spacing).
    eps2: f64,
    order: Vec<u32>,
    clusters: Vec<Cluster>,
}

impl<'a> Sources<'a> {
    /// `None` for an empty or degenerate cloud.
    fn new(cloud: &'a PatchedCloud<'a>) -> Option<Self> {
        let n = cloud.points.len();
        if n == 0 {
            return None;
        }
        let mut areas = cloud.areas.to_vec();
        let spacing = areas.select_nth_unstable_by(n / 2, f64::total_cmp).1.sqrt();
        let bbox = Aabb::from_points(cloud.points);
        let cell = (bbox.diagonal() / CELLS_PER_DIAGONAL).max(4.0 * spacing);
        if cell <= 0.0 || !cell.is_finite() {
            return None;
        }
        let mut sources = Sources {
            cloud,
            origin: bbox.min,
            cell,
            eps2: 0.25 * spacing * spacing,
            order: Vec::new(),
            clusters: Vec::new(),
        };
        (sources.order, sources.clusters) = build_clusters(cloud, &|p| sources.cell_of(p));
        Some(sources)
    }

    fn cell_of(&self, p: &Point3) -> [i64; 3] {
        std::array::from_fn(|k| ((p[k] - self.origin[k]) / self.cell).floor() as i64)
    }

    /// For each cluster whose patch `skip` does not reject, `out(patch, Σ kernel(source, moment))`
    /// at `x`: exact over the cluster's points in the 27 cells around `x`, one lumped dipole
    /// farther away.
    fn visit(
        &self,
        x: &Point3,
        skip: impl Fn(u32) -> bool,
        kernel: impl Fn(Point3, Point3) -> f64,
        mut out: impl FnMut(u32, f64),
    ) {
        let ci = self.cell_of(x);
        let c = self.cloud;
        for cl in self.clusters.iter().filter(|cl| !skip(cl.patch)) {
            let near = (0..3).all(|k| (cl.cell[k] - ci[k]).abs() <= 1);
            let v = if near {
                self.order[cl.range.clone()]
                    .iter()
                    .map(|&j| {
                        let j = j as usize;
                        kernel(c.points[j], c.normals[j].map(|v| v * c.areas[j]))
                    })
                    .sum::<f64>()
            } else {
                kernel(cl.centre, cl.moment)
            };
            out(cl.patch, v);
        }
    }
}

/// Symmetric `m × m` coupling matrix (row-major, `m` patches); zero diagonal.
pub(crate) fn patch_couplings(cloud: &PatchedCloud) -> Vec<f64> {
    let m = cloud.patches.count;
    let Some(sources) = Sources::new(cloud).filter(|_| m >= 2) else {
        return vec![0.0; m * m];
    };
    let rows: Vec<Vec<f64>> = pick_targets(cloud)
        .par_iter()
        .enumerate()
        .map(|(p, list)| {
            let mut row = vec![0.0; m];
            let other =
                |q: u32| q as usize == p || cloud.component[q as usize] != cloud.component[p];
            for &(i, weight) in list {
                let (x, nx) = (cloud.points[i as usize], cloud.normals[i as usize]);
                let kernel = |s, mu| dot(nx, field(x, s, mu, sources.eps2));
                sources.visit(&x, other, kernel, |q, v| row[q as usize] += weight * v);
            }
            row
        })
        .collect();
    let mut k = vec![0.0; m * m];
    for p in 0..m {
        for q in 0..m {
            k[p * m + q] = 0.5 * (rows[p][q] + rows[q][p]);
        }
    }
    k
}

/// Per patch, the area-weighted mean over its targets of the winding number of the whole cloud
/// (every patch, every component). On a consistently outward closed surface it is ½ at every
/// point; a closed piece that points inward sees about −½.
pub(crate) fn patch_winding(cloud: &PatchedCloud) -> Vec<f64> {
    let targets = pick_targets(cloud);
    let flat: Vec<u32> = targets.iter().flatten().map(|&(i, _)| i).collect();
    let w = winding_at(cloud, &flat);
    let mut at = 0;
    targets
        .iter()
        .map(|list| {
            let (mut sum, mut weights) = (0.0, 0.0);
            for &(_, weight) in list {
                sum += weight * w[at];
                weights += weight;
                at += 1;
            }
            if weights > 0.0 { sum / weights } else { 0.0 }
        })
        .collect()
}

/// The winding number of the whole cloud (every patch, every component) at each of the points
/// `targets` (indices into `cloud.points`); all zero for an empty or degenerate cloud.
/// `O(targets · (clusters + near points))`, parallel.
pub(crate) fn winding_at(cloud: &PatchedCloud, targets: &[u32]) -> Vec<f64> {
    let Some(sources) = Sources::new(cloud) else {
        return vec![0.0; targets.len()];
    };
    targets
        .par_iter()
        .map(|&i| {
            let x = cloud.points[i as usize];
            let mut w = 0.0;
            let kernel = |s, mu| winding(x, s, mu, sources.eps2);
            sources.visit(&x, |_| false, kernel, |_, v| w += v);
            w
        })
        .collect()
}

/// The winding number at `x` of a dipole of moment `mu` at `s`, softened by `eps2`.
fn winding(x: Point3, s: Point3, mu: Point3, eps2: f64) -> f64 {
    crate::rbf::winding::dipole([s[0] - x[0], s[1] - x[1], s[2] - x[2]], mu, eps2)
}

/// The field `∇w` at `x` of a dipole of moment `mu` at `s`, softened by `eps2` (squared length).
fn field(x: Point3, s: Point3, mu: Point3, eps2: f64) -> Point3 {
    let r = [x[0] - s[0], x[1] - s[1], x[2] - s[2]];
    let d2 = dot(r, r) + eps2;
    let inv3 = 1.0 / (4.0 * std::f64::consts::PI * d2 * d2.sqrt());
    let rm = 3.0 * dot(r, mu) / d2;
    [
        (rm * r[0] - mu[0]) * inv3,
        (rm * r[1] - mu[1]) * inv3,
        (rm * r[2] - mu[2]) * inv3,
    ]
}

/// Points sorted by (cell, patch), and one cluster per run.
fn build_clusters(
    cloud: &PatchedCloud,
    cell_of: &dyn Fn(&Point3) -> [i64; 3],
) -> (Vec<u32>, Vec<Cluster>) {
    let cells: Vec<[i64; 3]> = cloud.points.iter().map(cell_of).collect();
    let label = &cloud.patches.label;
    let mut order: Vec<u32> = (0..cloud.points.len() as u32).collect();
    order.sort_unstable_by_key(|&i| (cells[i as usize], label[i as usize]));
    let mut clusters: Vec<Cluster> = Vec::new();
    let mut start = 0;
    while start < order.len() {
        let first = order[start] as usize;
        let key = (cells[first], label[first]);
        let mut end = start;
        let (mut moment, mut centre, mut area) = ([0.0; 3], [0.0; 3], 0.0);
        while end < order.len() && (cells[order[end] as usize], label[order[end] as usize]) == key {
            let j = order[end] as usize;
            let a = cloud.areas[j];
            for k in 0..3 {
                moment[k] += a * cloud.normals[j][k];
                centre[k] += a * cloud.points[j][k];
            }
            area += a;
            end += 1;
        }
        let centre = if area > 0.0 {
            centre.map(|v| v / area)
        } else {
            cloud.points[first]
        };
        clusters.push(Cluster {
            cell: key.0,
            patch: key.1,
            range: start..end,
            moment,
            centre,
        });
        start = end;
    }
    (order, clusters)
}

/// Per patch, the target points and their weights: an even stride through the patch, each weighted
/// by its area scaled so the targets carry the patch's whole area.
fn pick_targets(cloud: &PatchedCloud) -> Vec<Vec<(u32, f64)>> {
    let m = cloud.patches.count;
    let n = cloud.points.len();
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); m];
    for (i, &l) in cloud.patches.label.iter().enumerate() {
        members[l as usize].push(i as u32);
    }
    members
        .into_iter()
        .map(|list| {
            let want = (TARGET_BUDGET * list.len())
                .div_ceil(n)
                .max(MIN_TARGETS)
                .min(list.len())
                .max(1);
            let step = list.len().div_ceil(want).max(1);
            let total: f64 = list.iter().map(|&i| cloud.areas[i as usize]).sum();
            let chosen: Vec<u32> = list.iter().copied().step_by(step).collect();
            let sub: f64 = chosen.iter().map(|&i| cloud.areas[i as usize]).sum();
            let scale = if sub > 0.0 { total / sub } else { 0.0 };
            chosen
                .into_iter()
                .map(|i| (i, scale * cloud.areas[i as usize]))
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::synthetic::Shape;

    /// A sphere cut into two caps: the flux coupling says "consistent" when both point outward
    /// and "flipped" when one cap points inward.
    #[test]
    fn coupling_of_two_caps_has_the_sign_of_their_consistency() {
        let cloud = Shape::by_name("sphere").unwrap().sample(3000, 1);
        let normals = cloud.normals.unwrap();
        let area = 4.0 * std::f64::consts::PI * 0.16 / 3000.0;
        let areas = vec![area; 3000];
        let label: Vec<u32> = cloud.points.iter().map(|p| u32::from(p[0] > 0.7)).collect();
        let patches = Patches { label, count: 2 };
        let coupling = |normals: &[Point3]| {
            patch_couplings(&PatchedCloud {
                points: &cloud.points,
                normals,
                areas: &areas,
                patches: &patches,
                component: &[0, 0],
            })[1]
        };
        assert!(coupling(&normals) < 0.0);
        let flipped: Vec<Point3> = normals
            .iter()
            .zip(&patches.label)
            .map(|(n, &l)| if l == 1 { n.map(|v| -v) } else { *n })
            .collect();
        assert!(coupling(&flipped) > 0.0);
    }
}
