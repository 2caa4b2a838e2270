//! Prepare's estimates on full-density patches: the points of a few blocks' spills (their cores
//! and margins, duplicates merged) give the surface test, the normals' consistency, the support
//! radius and the noise, with the in-memory pipeline's own functions. Memory O(patch points),
//! at most [`super::prepare::PATCH_POINTS`].

use super::prepare::PATCH_POINTS;
use super::route;
use crate::error::ReconError;
use crate::geometry::{Aabb, Point3};
use crate::params::ReconParams;
use crate::rbf::{NoiseEstimate, SupportEstimate, estimate_noise, estimate_support};
use crate::spatial::{IndexKind, build_index};

/// Share of opposed neighbour normals above which the normals count as inconsistent (as in the
/// in-memory pipeline, which then reorients them; that needs the whole cloud, so here it refuses).
const INCONSISTENT_NORMALS: f64 = 0.05;

/// Blocks the patches are taken from (spread over the block order).
const PATCH_BLOCKS: usize = 4;

/// The blocks the patches come from: up to [`PATCH_BLOCKS`] spread evenly over `alive` (the
/// blocks with points), as many as keep the patches' points within [`super::prepare::PATCH_POINTS`] (one at least).
pub(super) fn pick_patches(alive: &[usize], spilled: &[usize]) -> Vec<usize> {
    let m = alive.len();
    let k = PATCH_BLOCKS.min(m);
    let mut picks: Vec<usize> = Vec::new();
    let mut total = 0;
    for j in 0..k {
        let b = alive[(2 * j + 1) * m / (2 * k)];
        if picks.contains(&b) {
            continue;
        }
        if !picks.is_empty() && total + spilled[b] > PATCH_POINTS {
            break;
        }
        total += spilled[b];
        picks.push(b);
    }
    picks
}

/// The surface test, the normals' consistency, the support and the noise, with the in-memory
/// pipeline's functions, on the points of the patch blocks `picks` (their cores and margins,
/// duplicates merged); the support radius is measured at the points of their cores (whose
/// neighbourhoods the margins complete), the rest over all of the patch. `dir` holds the spills
/// (`parts` parts per block). `used` scales the
/// support's non-zero estimate to the whole cloud.
#[allow(clippy::too_many_arguments)]
pub(super) fn estimate_on_patches(
    (dir, parts): (&std::path::Path, usize),
    picks: &[usize],
    cores: &[Aabb],
    normals: bool,
    tol: f64,
    used: usize,
    params: &ReconParams,
) -> Result<(SupportEstimate, NoiseEstimate), ReconError> {
    let mut recs = Vec::new();
    for &b in picks {
        recs.extend(route::read_block_spill(dir, b, parts, normals)?);
    }
    recs.sort_unstable_by_key(|r| r.id);
    recs.dedup_by_key(|r| r.id);
    let keep = route::keep_flags(&recs, tol)?;
    let kept: Vec<route::Record> = (recs.iter().zip(keep))
        .filter(|(_, k)| *k)
        .map(|(r, _)| *r)
        .collect();
    drop(recs);
    let points: Vec<Point3> = kept.iter().map(|r| r.p).collect();
    let index = build_index(&points, IndexKind::KdTree, 16)?;
    let knn = |p: &Point3, k: usize, out: &mut Vec<(u32, f64)>| index.nearest_k(p, k, out);
    crate::clean::check_local_shape(&points, knn)?;
    if normals {
        let ns: Vec<Point3> = kept.iter().map(|r| r.n).collect();
        let share = crate::normals::inconsistent_fraction(&points, &ns, 8, knn);
        if share > INCONSISTENT_NORMALS {
            return Err(ReconError::InconsistentNormals { share });
        }
    }
    let core: Vec<Point3> = (points.iter())
        .filter(|p| picks.iter().any(|&b| cores[b].contains(p)))
        .copied()
        .collect();
    let mut support = estimate_support(&core, index.as_ref(), params.support)?;
    support.estimated_nnz = support.mean_neighbours * used as f64;
    let noise = estimate_noise(&points, support.spacing, knn);
    Ok((support, noise))
}
