//! Assembly of the CSRBF interpolation matrix `A_ij = φ(|P_i − P_j| / R)` as a full symmetric
//! sparse matrix (CSC, sorted row indices), one column per point, in parallel (rayon).
//!
//! Cost `O(n · (query + k log k))` for `k` neighbours per point; memory `16 · nnz` bytes.

use super::{Kernel, RbfError};
use crate::geometry::{Point3, dist2};
use crate::progress::Progress;
use crate::spatial::SpatialIndex;
use rayon::prelude::*;
use sprs::CsMat;

/// Assemble `A + smoothing · I` for `points` (normalised units) with support radius `support`.
/// Entries with `|P_i − P_j| ≥ R` are exactly zero and not stored, so the pattern is symmetric.
/// `smoothing = 0` interpolates; `> 0` gives the smoothing spline (approximation of noisy data).
pub fn assemble_matrix(
    points: &[Point3],
    index: &dyn SpatialIndex,
    kernel: Kernel,
    support: f64,
    smoothing: f64,
    progress: &dyn Progress,
) -> Result<CsMat<f64>, RbfError> {
    let n = points.len();
    let r2 = support * support;
    let inv_r = 1.0 / support;
    const CHUNK: usize = 2048;
    type Column = Vec<(usize, f64)>;
    let chunks: Vec<Result<Vec<Column>, RbfError>> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let mut hits = Vec::new();
            let mut cols = Vec::with_capacity(CHUNK);
            for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                // Dense rows (a large support) make one column cost up to O(n): check often.
                if i % 32 == 0 && progress.cancelled() {
                    return Err(RbfError::Cancelled);
                }
                index.within(&points[i], support, &mut hits);
                let mut col: Vec<(usize, f64)> = hits
                    .iter()
                    .filter_map(|&j| {
                        let d2 = dist2(points[i], points[j as usize]);
                        let shift = if j as usize == i { smoothing } else { 0.0 };
                        (d2 < r2).then(|| (j as usize, kernel.value(d2.sqrt() * inv_r) + shift))
                    })
                    .collect();
                col.sort_unstable_by_key(|e| e.0);
                cols.push(col);
            }
            progress.fraction((c + 1) as f64 * CHUNK as f64 / n as f64);
            Ok(cols)
        })
        .collect();
    let mut indptr = Vec::with_capacity(n + 1);
    indptr.push(0usize);
    let mut indices = Vec::new();
    let mut data = Vec::new();
    for chunk in chunks {
        for col in chunk? {
            for (j, v) in col {
                indices.push(j);
                data.push(v);
            }
            indptr.push(indices.len());
        }
    }
    Ok(CsMat::new_csc((n, n), indptr, indices, data))
}
