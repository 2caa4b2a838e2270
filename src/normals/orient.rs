//! Consistent orientation of unoriented normals, robust on thin parts:
//! 1. the Riemannian graph ([`super::graph`]): k-NN edges signed by the reflection criterion, with
//!    no confidence for edges off the tangent planes (they jump across thin gaps);
//! 2. patches ([`super::patches`]): a maximum-confidence spanning forest over the confident edges,
//!    each tree oriented internally; where the local evidence is weak the tree is cut;
//! 3. a global sign per patch ([`super::dipole`]): the flux of the other patches' winding-number
//!    field through each patch couples the patches; signs minimise the coupling energy
//!    `Σ s_P s_Q K_PQ` (a spanning tree over the strongest couplings, then single flips while
//!    any lowers the energy);
//! 4. per connected component of the k-NN graph, the sign that makes the enclosed volume
//!    `⅓ Σ a_i (p_i − c)·n_i` positive: outward for a closed surface, towards the convex side
//!    (the scanner, for one range image of a convex object) for an open one; then every patch
//!    whose mean winding number says it is a closed piece pointing inward is flipped;
//! 5. inward regions inside a patch ([`super::regions`]): points whose own winding number is
//!    about −½, connected through confident edges, are flipped (one misleading edge across a thin
//!    plate flips part of a patch, which the patch's mean does not show);
//! 6. ray parity ([`super::parity`]): where the points make a closed, clean surface (almost every
//!    point's rays agree), each point whose rays cross the other points' discs an odd number of
//!    times outward and even inward is flipped: what is left on plates thinner than the
//!    neighbourhood, where a wrong cluster keeps its own winding number near zero.
//!
//! It replaces MST propagation with cost `1 − |n_i·n_j|` (Hoppe et al. 1992), which flipped whole
//! thin limbs and near-touching sheets. Deterministic. Cost `O(n k log n)` plus the dipole sums.

use super::dipole::{PatchedCloud, patch_couplings, patch_winding};
use super::estimate::point_areas;
use super::graph::riemannian_edges;
use super::parity::parity_flips;
use super::patches::{Patches, components, grow_patches};
use super::regions::inward_regions;
use crate::geometry::{Point3, dot, sub};
use crate::mesh::incidence::SignedSets;

/// Edges at least this confident join points into one patch: the mirrored normal within 15° of
/// the other (looser thresholds join near-touching sheets, whose edges are ~20–30° off).
const MIN_CONFIDENCE: f64 = 0.966;
/// Patches are merged until each has at least `max(MIN_PATCH, n / MAX_PATCHES)` points.
const MIN_PATCH: usize = 8;
/// A patch whose points see a mean winding number below this is a closed piece pointing inward
/// (consistent outward normals see ½ on a closed surface; a piece of an open sheet, between −¼
/// and ¼ for a hemisphere either way).
const INWARD_WINDING: f64 = -0.3;
/// Bound on the number of patches (the coupling matrix is dense).
const MAX_PATCHES: usize = 1500;

/// Orient `normals` consistently (see the module doc); `neighbours[i]` lists the k nearest other
/// points of point `i`. Normals keep their lines; only signs change.
pub fn orient_normals(
    points: &[Point3],
    mut normals: Vec<Point3>,
    neighbours: &[Vec<u32>],
) -> Vec<Point3> {
    let n = points.len();
    if n == 0 {
        return normals;
    }
    let edges = riemannian_edges(points, &normals, neighbours);
    let component = components(n, &edges);
    let min_size = MIN_PATCH.max(n / MAX_PATCHES);
    let patches = grow_patches(&mut normals, &edges, MIN_CONFIDENCE, min_size);
    let areas = point_areas(points, neighbours);
    let mut patch_component = vec![0u32; patches.count];
    for (i, &l) in patches.label.iter().enumerate() {
        patch_component[l as usize] = component[i];
    }
    let coupling = patch_couplings(&PatchedCloud {
        points,
        normals: &normals,
        areas: &areas,
        patches: &patches,
        component: &patch_component,
    });
    let flip = patch_signs(&coupling, patches.count);
    apply_patch_flips(&mut normals, &patches, &flip);
    orient_components_outward(points, &mut normals, &areas, &component);
    let winding = patch_winding(&PatchedCloud {
        points,
        normals: &normals,
        areas: &areas,
        patches: &patches,
        component: &patch_component,
    });
    let inward: Vec<bool> = winding.iter().map(|&w| w < INWARD_WINDING).collect();
    apply_patch_flips(&mut normals, &patches, &inward);
    let flip = inward_regions(
        &PatchedCloud {
            points,
            normals: &normals,
            areas: &areas,
            patches: &patches,
            component: &patch_component,
        },
        &edges,
        MIN_CONFIDENCE,
        INWARD_WINDING,
    );
    flip_points(&mut normals, &flip);
    let inward = parity_flips(points, &normals, neighbours, &component);
    flip_points(&mut normals, &inward);
    normals
}

/// Flip the normals of the listed points.
fn flip_points(normals: &mut [Point3], points: &[u32]) {
    for &i in points {
        normals[i as usize] = normals[i as usize].map(|v| -v);
    }
}

/// Flip every normal whose patch is marked.
fn apply_patch_flips(normals: &mut [Point3], patches: &Patches, flip: &[bool]) {
    for (nrm, &l) in normals.iter_mut().zip(&patches.label) {
        if flip[l as usize] {
            *nrm = nrm.map(|v| -v);
        }
    }
}

/// Signs (`true` = flip) of `m` patches that lower `E(s) = Σ_{P≠Q} s_P s_Q K_PQ` for the symmetric
/// coupling `k` (row-major `m × m`): a maximum spanning forest over `|K_PQ|`, each coupling made
/// favourable (`s_P s_Q K_PQ < 0`) along the tree, then single flips, most favourable first, while
/// one lowers `E`. `O(m² log m)`.
fn patch_signs(k: &[f64], m: usize) -> Vec<bool> {
    let mut pairs: Vec<(u32, u32)> = (0..m as u32)
        .flat_map(|p| (p + 1..m as u32).map(move |q| (p, q)))
        .filter(|&(p, q)| k[p as usize * m + q as usize] != 0.0)
        .collect();
    let strength = |&(p, q): &(u32, u32)| k[p as usize * m + q as usize].abs();
    pairs.sort_by(|a, b| strength(b).total_cmp(&strength(a)));
    let mut sets = SignedSets::new(m);
    for &(p, q) in &pairs {
        sets.union(p, q, k[p as usize * m + q as usize] < 0.0);
    }
    let mut s: Vec<f64> = (0..m as u32)
        .map(|p| if sets.find(p).1 { -1.0 } else { 1.0 })
        .collect();
    let mut field: Vec<f64> = (0..m)
        .map(|p| (0..m).map(|q| k[p * m + q] * s[q]).sum())
        .collect();
    for _ in 0..4 * m {
        // The flip that lowers the energy most: largest positive s_P F_P.
        let Some((p, gain)) = (0..m)
            .map(|p| (p, s[p] * field[p]))
            .max_by(|a, b| a.1.total_cmp(&b.1))
        else {
            break;
        };
        if gain <= 1e-12 * (1.0 + field[p].abs()) {
            break;
        }
        s[p] = -s[p];
        for (q, f) in field.iter_mut().enumerate() {
            *f += 2.0 * k[q * m + p] * s[p];
        }
    }
    s.iter().map(|&v| v < 0.0).collect()
}

/// Per connected component (`component[i]` per point), flip all its normals when the enclosed
/// volume `Σ a_i (p_i − c)·n_i` (`c` the area-weighted centroid) is negative.
fn orient_components_outward(
    points: &[Point3],
    normals: &mut [Point3],
    areas: &[f64],
    component: &[u32],
) {
    let count = component.iter().map(|&c| c as usize + 1).max().unwrap_or(0);
    let mut centre = vec![[0.0; 3]; count];
    let mut area = vec![0.0; count];
    for ((p, &a), &c) in points.iter().zip(areas).zip(component) {
        let a = a.max(f64::MIN_POSITIVE);
        for k in 0..3 {
            centre[c as usize][k] += a * p[k];
        }
        area[c as usize] += a;
    }
    for (c, a) in centre.iter_mut().zip(&area) {
        *c = c.map(|v| v / a);
    }
    let mut volume = vec![0.0; count];
    for (((p, nrm), &a), &c) in points.iter().zip(normals.iter()).zip(areas).zip(component) {
        volume[c as usize] += a * dot(sub(*p, centre[c as usize]), *nrm);
    }
    for (nrm, &c) in normals.iter_mut().zip(component) {
        if volume[c as usize] < 0.0 {
            *nrm = nrm.map(|v| -v);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patch_signs_satisfy_a_frustration_free_coupling() {
        // Four patches whose true signs are +, −, +, −; K_PQ = −t_P t_Q (favourable when right).
        let t = [1.0, -1.0, 1.0, -1.0];
        let m = 4;
        let mut k = vec![0.0; m * m];
        for p in 0..m {
            for q in 0..m {
                if p != q {
                    k[p * m + q] = -t[p] * t[q] * (1.0 + (p + q) as f64);
                }
            }
        }
        let flip = patch_signs(&k, m);
        let s: Vec<f64> = flip.iter().map(|&f| if f { -1.0 } else { 1.0 }).collect();
        assert!((0..m).all(|p| s[p] * t[p] == s[0] * t[0]), "{flip:?}");
    }
}
