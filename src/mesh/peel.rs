//! Peeling an open surface's border back towards its data without changing its topology.
//!
//! The open-scan trim ([`super::trim`]) keeps every triangle within the support radius `R` of a
//! point: a gap narrower than about `2R` between returns stays bridged, so a scan piece stays one
//! sheet. But the same rule lets the border overhang the data by up to `R` (a roof's sheet hanging
//! down past its last return, a sheet reaching out beyond a scene's edge), surface no data show.
//! A tighter trim radius removes that overhang but also cuts the bridges, splitting pieces and
//! opening holes. The peel keeps what the tighter radius cannot: it removes border triangles whose
//! centroid is farther than `max_distance` from every point and has no point within the support
//! radius on the side opposite its nearest one (an overhang beyond the data, not a gap between
//! them), farthest first, and only those whose removal is an *elementary collapse*:
//! - a triangle with one border edge whose opposite vertex is not on a border (the border moves
//!   across it; the sheet stays a disk locally), or
//! - a triangle with two border edges meeting at a vertex no other triangle uses (an ear).
//!
//! Each collapse keeps the surface's homotopy type: the number of pieces, of boundary loops and of
//! handles (the Euler characteristic) is the same before and after, and no vertex becomes
//! non-manifold. A bridge across a gap between data stays whole (points lie on both sides of it);
//! surface beyond the data goes. Measured on the outdoor LiDAR scene `b9_training` with
//! `max_distance` = `R/2`: mesh→scan mean distance 1.72e-3 → 9.5e-4 of the diagonal, same 12
//! pieces and 51 loops.

use super::reach::{Reach, centroid, centroid_reach};
use crate::geometry::{Point3, TriMesh};
use crate::spatial::{KdTree, SpatialIndex};
use rayon::prelude::*;
use std::collections::BinaryHeap;

/// No neighbour across an edge (a border edge of the input).
const NONE: u32 = u32::MAX;
/// More than one neighbour across an edge (a non-manifold edge): never a border, never peeled.
const MANY: u32 = u32::MAX - 1;

/// Cosine of the half-angle of the cone, around the direction away from a centroid's nearest
/// point, in which a point within the support radius puts the centroid *between* data (a gap the
/// trim bridges) rather than beyond them (an overhang): 45°, so the two points lie at least 135°
/// apart as seen from it, halfway between a straight border of the data (whose points all lie
/// within 90° of the nearest one) and a gap (a point straight across, 180°). Measured on b9
/// (mesh→scan, peel at R/2): 45° 9.45e-4, 60° 9.85e-4; without the test 8.68e-4, but the peel
/// then cuts notches along the bridges.
const OPPOSITE_COS: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// Peels `mesh`'s border: removes, farthest first, the triangles whose centroid is farther than
/// `max_distance` from every one of `points` and not between them ([`between_data`] within
/// `radius`, the support radius), and whose removal is an elementary collapse (see the module
/// doc), until none is left. Distances in the mesh's units. Keeps the pieces, boundary loops,
/// Euler characteristic and manifoldness. A closed mesh has no border and is returned unchanged.
/// Returns how many triangles were removed. `O(t log t)` plus a radius query per triangle beyond
/// `max_distance`.
pub fn peel_border(mesh: &mut TriMesh, points: &[Point3], max_distance: f64, radius: f64) -> usize {
    let Ok(tree) = KdTree::build(points) else {
        return 0;
    };
    let reach = centroid_reach(mesh, (&tree, points), max_distance);
    // Only the triangles beyond `max_distance` are peeled, farthest first: the others' distance
    // is never read.
    let dist: Vec<f64> = (reach.iter())
        .map(|r| match r {
            Reach::Within => 0.0,
            Reach::Beyond(hit) => hit.map_or(f64::INFINITY, |(_, d)| d),
        })
        .collect();
    let overhang: Vec<bool> = (mesh.triangles.par_iter().zip(&reach))
        .map_init(Vec::new, |near, (t, r)| match *r {
            Reach::Within => false,
            Reach::Beyond(None) => true,
            Reach::Beyond(Some((i, d))) => {
                let c = centroid(mesh, t);
                !between_data(c, (points[i as usize], d), (&tree, points), radius, near)
            }
        })
        .collect();
    let drop = peel_flags(&mesh.triangles, mesh.vertices.len(), &dist, &overhang);
    super::trim::remove_triangles(mesh, &drop)
}

/// Whether the centroid `c` lies between data: some point within `radius` of it (the `points`,
/// indexed by `tree`) lies in the cone of half-angle 45° ([`OPPOSITE_COS`]) around the direction
/// away from its nearest point `p`, at distance `d`. False beside a border of the data (an
/// overhang) or with no point within `radius`. `near` is scratch space.
fn between_data(
    c: Point3,
    (p, d): (Point3, f64),
    (tree, points): (&KdTree, &[Point3]),
    radius: f64,
    near: &mut Vec<u32>,
) -> bool {
    if d <= 0.0 {
        return true;
    }
    let u = [0, 1, 2].map(|k| (p[k] - c[k]) / d);
    near.clear();
    tree.within(&c, radius, near);
    near.iter().any(|&j| {
        let q = points[j as usize];
        let v = [0, 1, 2].map(|k| q[k] - c[k]);
        let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v[0] * u[0] + v[1] * u[1] + v[2] * u[2] <= -OPPOSITE_COS * l
    })
}

/// Per triangle, its neighbour across edge `i` (from vertex `i` to vertex `i + 1`): a triangle,
/// [`NONE`] or [`MANY`].
fn neighbours(triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut adj = vec![[NONE; 3]; triangles.len()];
    let half = super::topology::sorted_half_edges(triangles);
    let mut i = 0;
    while i < half.len() {
        let mut j = i + 1;
        while j < half.len() && half[j].0 == half[i].0 {
            j += 1;
        }
        let (lo, hi) = ((half[i].0 >> 32) as u32, half[i].0 as u32);
        let group = &half[i..j];
        for &(_, t) in group {
            let tri = triangles[t as usize];
            let Some(k) = (0..3).find(|&k| {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                a.min(b) == lo && a.max(b) == hi
            }) else {
                continue;
            };
            adj[t as usize][k] = match group {
                [_] => NONE,
                [(_, a), (_, b)] => {
                    if *a == t {
                        *b
                    } else {
                        *a
                    }
                }
                _ => MANY,
            };
        }
        i = j;
    }
    adj
}

/// The peel on bare triangles (`n` vertices): which of them it removes, farthest first by their
/// centroid distances `dist`, of those flagged `overhang`.
fn peel_flags(triangles: &[[u32; 3]], n: usize, dist: &[f64], overhang: &[bool]) -> Vec<bool> {
    let adj = neighbours(triangles);
    let mut dead = vec![false; triangles.len()];
    // Live triangles and live border edges at each vertex.
    let mut uses = vec![0u32; n];
    let mut borders = vec![0u32; n];
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            uses[tri[k] as usize] += 1;
            if adj[t][k] == NONE {
                borders[tri[k] as usize] += 1;
                borders[tri[(k + 1) % 3] as usize] += 1;
            }
        }
    }
    let is_border = |adj: &[u32; 3], k: usize, dead: &[bool]| {
        adj[k] == NONE || (adj[k] != MANY && dead[adj[k] as usize])
    };
    // Distances are non-negative, so their bit patterns order like them; ties go by index.
    let mut heap: BinaryHeap<(u64, u32)> = (0..triangles.len())
        .filter(|&t| overhang[t] && adj[t].contains(&NONE))
        .map(|t| (dist[t].to_bits(), t as u32))
        .collect();
    while let Some((_, t)) = heap.pop() {
        let t = t as usize;
        if dead[t] {
            continue;
        }
        let tri = triangles[t];
        let edges: Vec<usize> = (0..3).filter(|&k| is_border(&adj[t], k, &dead)).collect();
        let collapsible = !adj[t].contains(&MANY)
            && match edges[..] {
                // The vertex opposite the border edge must be inside the sheet.
                [k] => borders[tri[(k + 2) % 3] as usize] == 0,
                // An ear: the vertex shared by the two border edges belongs to this triangle only.
                [k, l] => {
                    let shared = if (k + 1) % 3 == l { tri[l] } else { tri[k] };
                    uses[shared as usize] == 1
                }
                _ => false,
            };
        if !collapsible {
            continue;
        }
        dead[t] = true;
        for k in 0..3 {
            uses[tri[k] as usize] -= 1;
            let (a, b) = (tri[k] as usize, tri[(k + 1) % 3] as usize);
            if edges.contains(&k) {
                borders[a] -= 1;
                borders[b] -= 1;
            } else {
                borders[a] += 1;
                borders[b] += 1;
                let o = adj[t][k] as usize;
                if overhang[o] {
                    heap.push((dist[o].to_bits(), o as u32));
                }
            }
        }
    }
    dead
}

#[cfg(test)]
#[path = "peel_tests.rs"]
mod tests;
