//! The Riemannian graph for orientation: the symmetric k-NN graph, each edge labelled with whether
//! its endpoints' normals agree and how sure that is.
//!
//! The sign rule is the *reflection* criterion (König & Gumhold 2009): if `p_i` and `p_j` lie on a
//! common sphere, the normal at `p_j` is `n_i` mirrored in the plane that bisects the edge,
//! `n_i − 2 (n_i·e) e` with `e` the unit edge. Its dot with `n_j` is the agreement `r_ij ∈ [−1, 1]`.
//! For an edge in the tangent plane this is Hoppe's `n_i·n_j`; across the tip of a thin limb or a
//! thin plate (normals opposed, edge along them) it still says "consistent" where `n_i·n_j` would
//! say "flip". The confidence is `|r_ij|`, set to 0 for edges far off the tangent planes (more than
//! 30° at either end), which on a surface sampled finer than its curvature only happen across
//! gaps: those edges are left to the global step ([`super::dipole`]). `O(n k log k)`.

use crate::geometry::{Point3, dot, normalized, sub};

/// Largest `|sin|` of the angle between an edge and either endpoint's tangent plane for the edge
/// to carry confidence (30°).
const MAX_OFF_TANGENT: f64 = 0.5;

/// An undirected edge `a < b` of the orientation graph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Edge {
    /// Lower endpoint index.
    pub a: u32,
    /// Higher endpoint index.
    pub b: u32,
    /// Whether the normals as given are consistent along this edge (`r_ab ≥ 0`).
    pub agree: bool,
    /// How sure the sign is, in `[0, 1]` (0 for edges off the tangent planes).
    pub confidence: f64,
}

/// Edges of the symmetrised k-NN graph (`neighbours[i]`: the neighbours of point `i`), each once,
/// sorted by decreasing confidence.
pub(crate) fn riemannian_edges(
    points: &[Point3],
    normals: &[Point3],
    neighbours: &[Vec<u32>],
) -> Vec<Edge> {
    let mut pairs: Vec<(u32, u32)> = neighbours
        .iter()
        .enumerate()
        .flat_map(|(i, list)| {
            list.iter()
                .filter(move |&&j| j as usize != i)
                .map(move |&j| (j.min(i as u32), j.max(i as u32)))
        })
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    let mut edges: Vec<Edge> = pairs
        .into_iter()
        .map(|(a, b)| {
            let (agree, confidence) = agreement(points, normals, a as usize, b as usize);
            Edge {
                a,
                b,
                agree,
                confidence,
            }
        })
        .collect();
    edges.sort_by(|x, y| y.confidence.total_cmp(&x.confidence));
    edges
}

/// `(r_ij ≥ 0, confidence)` for the edge `i`–`j` (see the module doc).
fn agreement(points: &[Point3], normals: &[Point3], i: usize, j: usize) -> (bool, f64) {
    let (ni, nj) = (normals[i], normals[j]);
    let Some(e) = normalized(sub(points[j], points[i])) else {
        return (dot(ni, nj) >= 0.0, 0.0);
    };
    let (ei, ej) = (dot(ni, e), dot(nj, e));
    let mirrored = [
        ni[0] - 2.0 * ei * e[0],
        ni[1] - 2.0 * ei * e[1],
        ni[2] - 2.0 * ei * e[2],
    ];
    let r = dot(mirrored, nj);
    let tangent = ei.abs().max(ej.abs()) <= MAX_OFF_TANGENT;
    (r >= 0.0, if tangent { r.abs().min(1.0) } else { 0.0 })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirrored_normals_agree_on_a_circle_and_across_a_thin_plate() {
        // Two points on the unit circle 40° apart, outward normals.
        let (t0, t1) = (0.0f64, 40f64.to_radians());
        let p = [[t0.cos(), t0.sin(), 0.0], [t1.cos(), t1.sin(), 0.0]];
        let (agree, c) = agreement(&p, &p, 0, 1);
        assert!(agree && (c - 1.0).abs() < 1e-12);
        let flipped = [p[0], [-p[1][0], -p[1][1], 0.0]];
        assert!(!agreement(&p, &flipped, 0, 1).0);
        // Bottom and top of a thin plate: normals opposed, edge along them.
        let q = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.01]];
        let n = [[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]];
        let (agree, c) = agreement(&q, &n, 0, 1);
        assert!(agree, "outward normals of a plate are consistent");
        assert_eq!(c, 0.0, "but the edge is off the tangent planes");
    }

    #[test]
    fn edges_are_symmetrised_and_sorted() {
        let p = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let n = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]];
        let nb = vec![vec![1, 2], vec![0], vec![]];
        let e = riemannian_edges(&p, &n, &nb);
        assert_eq!(e.len(), 2);
        assert!(e.iter().all(|e| e.a < e.b && e.confidence == 1.0));
        assert!(!e.iter().find(|e| e.b == 1).unwrap().agree);
    }
}
