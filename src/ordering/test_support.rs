//! Test helpers for the ordering tests: shuffled sphere samples, radius patterns, bandwidths,
//! connected components (all by direct computation).

use sprs::CsMat;

use super::Permutation;
use crate::geometry::{Point3, dist2};
use crate::spatial::test_clouds::{sphere_surface, splitmix64};

/// `n` points on the sphere of radius 0.5 centred at (0.5, 0.5, 0.5), in random order.
pub(crate) fn shuffled_sphere(n: usize, seed: u64) -> Vec<Point3> {
    let mut pts = sphere_surface(n, seed);
    let mut s = seed ^ 0xabcdef;
    for i in (1..n).rev() {
        pts.swap(i, (splitmix64(&mut s) % (i as u64 + 1)) as usize);
    }
    pts
}

/// Symmetric CSC pattern with a 1.0 at `(i, j)` whenever `|p_i − p_j| ≤ r` (diagonal included),
/// by brute force (`O(n²)`).
pub(crate) fn radius_pattern(pts: &[Point3], r: f64) -> CsMat<f64> {
    let n = pts.len();
    let mut t = sprs::TriMat::new((n, n));
    for i in 0..n {
        for j in 0..n {
            if dist2(pts[i], pts[j]) <= r * r {
                t.add_triplet(i, j, 1.0);
            }
        }
    }
    t.to_csc()
}

/// Bandwidth of `P A Pᵀ` computed entry by entry.
pub(crate) fn bandwidth_of(a: &CsMat<f64>, p: &Permutation) -> usize {
    a.iter()
        .map(|(_, (i, j))| p.inv[i].abs_diff(p.inv[j]))
        .max()
        .unwrap_or(0)
}

/// Connected-component label (0, 1, …, in order of first index) of every row of a symmetric pattern.
pub(crate) fn components(a: &CsMat<f64>) -> Vec<usize> {
    let n = a.rows();
    let mut label = vec![usize::MAX; n];
    let mut next = 0;
    for s in 0..n {
        if label[s] != usize::MAX {
            continue;
        }
        label[s] = next;
        let mut stack = vec![s];
        while let Some(v) = stack.pop() {
            if let Some(col) = a.outer_view(v) {
                for &w in col.indices() {
                    if label[w] == usize::MAX {
                        label[w] = next;
                        stack.push(w);
                    }
                }
            }
        }
        next += 1;
    }
    label
}
