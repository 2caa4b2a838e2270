//! Simplification to a chord-error tolerance: meshoptimizer's edge-collapse simplifier
//! (`meshopt_simplify`, quadric error metrics after Garland & Heckbert 1997) with an absolute error
//! bound, so the triangle count follows the shape: flat parts lose most of their triangles, curved
//! parts keep what the tolerance asks for. Vertices are never moved (a collapse keeps one of the
//! edge's end points), so a vertex that lay on the surface still does, with its normal.
//!
//! The result is kept only when its topology is the input's (components, watertight, manifold,
//! oriented, boundary loops, Euler characteristic, genus). Edge collapses do not check the link
//! condition, so a collapse can fold two sheets onto a non-manifold edge, and a small piece can
//! collapse away; then the vertices around each such defect (all of a vanished piece's) are locked,
//! in a radius that starts at a quarter of the longest simplified edge there and doubles each
//! round, and the simplification redone (up to [`LOCK_ROUNDS`] times); when that does not help the
//! tolerance is halved, up to [`ATTEMPTS`] times, and the input is kept as it is when no attempt
//! preserves it. Open borders are locked (they stay exactly where trimming put them).
//! `O(F log F)` for `F` triangles.

use crate::geometry::TriMesh;
use crate::mesh::topology::{MeshTopology, analyze};
use std::collections::HashMap;

/// Tolerances tried: the given one, then halved each time.
pub const ATTEMPTS: usize = 3;

/// What [`simplify_to_tolerance`] did.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SimplifyStats {
    /// Triangles before.
    pub triangles_before: usize,
    /// Triangles after (equal to `triangles_before` when nothing was kept).
    pub triangles_after: usize,
    /// The tolerance of the kept attempt (mesh units; 0 when no attempt was kept).
    pub tolerance_used: f64,
    /// meshoptimizer's own measure of the kept result's deviation from the input mesh (mesh
    /// units, the largest quadric distance of a collapse); 0 when nothing was kept.
    pub error: f64,
}

impl SimplifyStats {
    /// Folds in the result of a part simplified separately: the largest error, the smallest
    /// tolerance among the parts that kept an attempt (the triangle counts are the caller's).
    fn absorb(&mut self, part: &SimplifyStats) {
        self.error = self.error.max(part.error);
        if part.tolerance_used > 0.0 {
            self.tolerance_used = if self.tolerance_used > 0.0 {
                self.tolerance_used.min(part.tolerance_used)
            } else {
                part.tolerance_used
            };
        }
    }
}

/// The invariants a simplification must keep.
fn signature(t: &MeshTopology) -> impl PartialEq + std::fmt::Debug {
    (
        t.components,
        t.watertight,
        t.manifold,
        t.oriented,
        t.boundary_loops,
        t.euler,
        t.genus,
        t.non_manifold_edges,
        t.non_manifold_vertices,
        t.degenerate_triangles,
    )
}

/// Removes triangles from `mesh` by edge collapses while the deviation stays below `tolerance`
/// (mesh units, e.g. normalised units inside the pipeline), keeping its topology and its open
/// borders (see the module doc). Vertices no triangle uses any more stay in `mesh.vertices`
/// (compact with [`crate::mesh::optimize_for_gpu`]). Deterministic.
///
/// # Example
/// ```
/// use rbfsurf::geometry::TriMesh;
/// use rbfsurf::mesh::simplify::simplify_to_tolerance;
/// // A flat 8 × 8 grid of squares (128 triangles) collapses to a few triangles.
/// let n = 9;
/// let vertices = (0..n * n).map(|i| [(i % n) as f64, (i / n) as f64, 0.0]).collect();
/// let mut triangles = Vec::new();
/// for j in 0..n - 1 {
///     for i in 0..n - 1 {
///         let v = (j * n + i) as u32;
///         triangles.push([v, v + 1, v + n as u32 + 1]);
///         triangles.push([v, v + n as u32 + 1, v + n as u32]);
///     }
/// }
/// let mut mesh = TriMesh { vertices, triangles, ..Default::default() };
/// let stats = simplify_to_tolerance(&mut mesh, 0.01);
/// assert!(stats.triangles_after < 128 && stats.triangles_after == mesh.triangles.len());
/// ```
pub fn simplify_to_tolerance(mesh: &mut TriMesh, tolerance: f64) -> SimplifyStats {
    if mesh.triangles.len() >= PIECE_TRIANGLES * 2 && tolerance.is_finite() && tolerance > 0.0 {
        // The input's topology is needed only once the pieces are done: measured meanwhile.
        let (before, pieces) = rayon::join(|| analyze(mesh), || first_pass(mesh, tolerance));
        if let Some(stats) = simplify_in_pieces(mesh, tolerance, &before, pieces) {
            return stats;
        }
        let locks = vec![false; mesh.vertices.len()];
        return simplify_whole(mesh, tolerance, &before, locks);
    }
    let before = analyze(mesh);
    let locks = vec![false; mesh.vertices.len()];
    simplify_whole(mesh, tolerance, &before, locks)
}

/// [`simplify_to_tolerance`] of the whole mesh at once, `before` its topology.
fn simplify_whole(
    mesh: &mut TriMesh,
    tolerance: f64,
    before: &MeshTopology,
    mut locks: Vec<bool>,
) -> SimplifyStats {
    let mut stats = SimplifyStats {
        triangles_before: mesh.triangles.len(),
        triangles_after: mesh.triangles.len(),
        ..Default::default()
    };
    if mesh.triangles.is_empty() || !(tolerance.is_finite() && tolerance > 0.0) {
        return stats;
    }
    // Single precision around the mesh's centre keeps ~1e-7 of its size.
    let bbox = crate::geometry::Aabb::from_points(&mesh.vertices);
    let c = bbox.center();
    let positions: Vec<[f32; 3]> = (mesh.vertices.iter())
        .map(|p| [0, 1, 2].map(|k| (p[k] - c[k]) as f32))
        .collect();
    let (indices, aside) = set_aside_flat_triangles(&positions, &mesh.triangles, &mut locks);
    let options = meshopt::SimplifyOptions::ErrorAbsolute | meshopt::SimplifyOptions::LockBorder;
    // Needed only after an attempt that changed the topology: computed then, once.
    let (mut original_border, mut pieces) = (None, None);
    let mut tol = tolerance;
    let mut scale = LOCK_SCALE_FIRST;
    for _ in 0..ATTEMPTS {
        for _ in 0..LOCK_ROUNDS {
            let mut error = 0.0f32;
            let kept = meshopt::simplify_with_locks_decoder(
                &indices,
                &positions,
                &locks,
                0,
                tol as f32,
                options,
                Some(&mut error),
            );
            let mut probe = TriMesh {
                triangles: (kept.chunks_exact(3).map(|t| [t[0], t[1], t[2]]))
                    .chain(aside.iter().copied())
                    .collect(),
                vertices: std::mem::take(&mut mesh.vertices),
                ..TriMesh::default()
            };
            let same = signature(&analyze(&probe)) == signature(before);
            mesh.vertices = std::mem::take(&mut probe.vertices);
            if same {
                stats.triangles_after = probe.triangles.len();
                stats.tolerance_used = tol;
                stats.error = error as f64;
                mesh.triangles = probe.triangles;
                return stats;
            }
            let original_border =
                original_border.get_or_insert_with(|| border_edges(&mesh.triangles));
            let mut local = false;
            while let Some(changed) =
                lock_around_defects(mesh, &probe.triangles, original_border, &mut locks, scale)
            {
                local = changed;
                if changed || scale >= LOCK_SCALE_MAX {
                    break;
                }
                scale *= 2.0;
            }
            scale = (scale * 2.0).min(LOCK_SCALE_MAX);
            let pieces = pieces.get_or_insert_with(|| vertex_components(mesh));
            let vanished = lock_vanished_components(pieces, &probe.triangles, &mut locks);
            if !(local || vanished) {
                break;
            }
        }
        tol *= 0.5;
    }
    stats
}

/// Triangles per piece of the parallel simplification (meshes of fewer than twice this many are
/// simplified whole).
const PIECE_TRIANGLES: usize = 20_000;

/// Most pieces of the parallel simplification.
const MAX_PIECES: usize = 16;

/// [`simplify_to_tolerance`] in pieces, in parallel: the triangles are split by centroid into
/// boxes (median cuts across the longest axis, [`split_pieces`]) and each piece is simplified
/// alone with its border, the cut included, locked (a vertex shared with another piece lies on
/// the piece's border, which meshoptimizer keeps). So a piece whose topology an attempt changes is
/// redone alone (locks, halved tolerance) rather than the whole mesh, and a piece no attempt can
/// simplify is halved and its halves tried (down to [`MIN_PIECE`] triangles). The strips along the
/// cuts keep the grid's triangles (a few per cent more triangles); every triangle is still within
/// the tolerance of the original mesh (each piece is simplified once, from the original).
/// Where the assembled mesh has a defect along a cut (two pieces each made the same edge), the
/// vertices around it are locked and the pieces holding them redone, up to [`SEAM_ROUNDS`] times.
/// `None` when the assembled mesh's topology is still not `before`'s (the caller then simplifies
/// the mesh whole).
fn simplify_in_pieces(
    mesh: &mut TriMesh,
    tolerance: f64,
    before: &MeshTopology,
    (pieces, mut done): FirstPass,
) -> Option<SimplifyStats> {
    use rayon::prelude::*;
    let mut locks = vec![false; mesh.vertices.len()];
    let mut original_border = None;
    for _ in 0..SEAM_ROUNDS {
        let triangles: Vec<[u32; 3]> = done.iter().flat_map(|d| d.0.iter().copied()).collect();
        let probe = TriMesh {
            vertices: std::mem::take(&mut mesh.vertices),
            triangles,
            ..TriMesh::default()
        };
        let same = signature(&analyze(&probe)) == signature(before);
        if same {
            let mut stats = SimplifyStats {
                triangles_before: mesh.triangles.len(),
                ..Default::default()
            };
            done.iter().for_each(|d| stats.absorb(&d.1));
            stats.triangles_after = probe.triangles.len();
            mesh.vertices = probe.vertices;
            mesh.triangles = probe.triangles;
            return Some(stats);
        }
        // Two pieces can each make an edge between the same two vertices of their common cut (a
        // collapse inside each, both allowed alone): lock around such seam defects and redo the
        // pieces that hold a newly locked vertex.
        let previous = locks.clone();
        let border = original_border.get_or_insert_with(|| border_edges(&mesh.triangles));
        let found = lock_around_defects(
            &probe,
            &probe.triangles,
            border,
            &mut locks,
            LOCK_SCALE_FIRST,
        );
        mesh.vertices = probe.vertices;
        if found != Some(true) {
            return None;
        }
        let redo: Vec<usize> = (0..pieces.len())
            .filter(|&i| {
                (pieces[i].iter().flatten()).any(|&v| locks[v as usize] && !previous[v as usize])
            })
            .collect();
        let again: Vec<(Vec<[u32; 3]>, SimplifyStats)> = redo
            .par_iter()
            .map(|&i| simplify_piece(&mesh.vertices, &pieces[i], tolerance, &locks))
            .collect();
        for (i, d) in redo.into_iter().zip(again) {
            done[i] = d;
        }
    }
    None
}

/// The pieces of [`simplify_in_pieces`] and each one simplified alone, nothing locked beyond
/// its border.
type FirstPass = (Vec<Vec<[u32; 3]>>, Vec<(Vec<[u32; 3]>, SimplifyStats)>);

/// Splits `mesh` into pieces of about [`PIECE_TRIANGLES`] (at most [`MAX_PIECES`]) and simplifies
/// each alone, in parallel.
fn first_pass(mesh: &TriMesh, tolerance: f64) -> FirstPass {
    use rayon::prelude::*;
    let mut levels = 0;
    while PIECE_TRIANGLES << (levels + 1) <= mesh.triangles.len() && 1 << (levels + 1) <= MAX_PIECES
    {
        levels += 1;
    }
    let pieces = split_pieces(&mesh.vertices, &mesh.triangles, levels);
    let locks = vec![false; mesh.vertices.len()];
    let done = pieces
        .par_iter()
        .map(|piece| simplify_piece(&mesh.vertices, piece, tolerance, &locks))
        .collect();
    (pieces, done)
}

/// Rounds of [`simplify_in_pieces`] that lock around defects where the pieces meet.
const SEAM_ROUNDS: usize = 4;

/// Fewest triangles of a piece that is halved when no attempt could simplify it.
const MIN_PIECE: usize = 2_000;

/// Simplifies the triangles `piece` of the mesh over `vertices` alone (its border, the cut
/// included, locked; halved when no attempt keeps its topology); returns its triangles in the
/// mesh's vertex ids.
fn simplify_piece(
    vertices: &[crate::geometry::Point3],
    piece: &[[u32; 3]],
    tolerance: f64,
    extra_locks: &[bool],
) -> (Vec<[u32; 3]>, SimplifyStats) {
    let mut ids: Vec<u32> = piece.iter().flatten().copied().collect();
    ids.sort_unstable();
    ids.dedup();
    let local = |v: u32| ids.binary_search(&v).expect("a vertex of the piece") as u32;
    let mut part = TriMesh {
        vertices: ids.iter().map(|&v| vertices[v as usize]).collect(),
        triangles: piece.iter().map(|t| t.map(local)).collect(),
        ..TriMesh::default()
    };
    let before = analyze(&part);
    let mut locks = pinch_rings(&part.triangles, part.vertices.len());
    for (l, &v) in locks.iter_mut().zip(&ids) {
        *l |= extra_locks[v as usize];
    }
    let stats = simplify_whole(&mut part, tolerance, &before, locks);
    if stats.tolerance_used == 0.0 && piece.len() >= 2 * MIN_PIECE {
        let mut out = (Vec::new(), stats);
        for half in split_pieces(vertices, piece, 1) {
            let (t, st) = simplify_piece(vertices, &half, tolerance, extra_locks);
            out.0.extend(t);
            out.1.absorb(&st);
        }
        out.1.triangles_after = out.0.len();
        return out;
    }
    let back = part
        .triangles
        .iter()
        .map(|t| t.map(|v| ids[v as usize]))
        .collect();
    (back, stats)
}

/// Locks for the vertices around every pinch of a piece's border (a vertex with more than two
/// border edges, where the cut meets itself): the vertex and its neighbours. A collapse next to a
/// pinch can join its two fans, which changes the piece's topology (a boundary loop and the Euler
/// characteristic) without any defect to lock around.
fn pinch_rings(triangles: &[[u32; 3]], vertices: usize) -> Vec<bool> {
    let mut border = vec![0u32; vertices];
    for (e, n) in edge_uses(triangles) {
        if n == 1 {
            border[e.0 as usize] += 1;
            border[e.1 as usize] += 1;
        }
    }
    let mut locks = vec![false; vertices];
    for t in triangles {
        if t.iter().any(|&v| border[v as usize] > 2) {
            for &v in t {
                locks[v as usize] = true;
            }
        }
    }
    locks
}

/// Splits `triangles` into `2^levels` pieces by their centroids: each box is cut across its
/// longest axis at the median. Deterministic: ties are broken by the triangles' order, and each
/// piece keeps the input's order.
fn split_pieces(
    vertices: &[crate::geometry::Point3],
    triangles: &[[u32; 3]],
    levels: usize,
) -> Vec<Vec<[u32; 3]>> {
    use rayon::prelude::*;
    let centroid = |t: &[u32; 3]| {
        [0, 1, 2].map(|k| t.iter().map(|&v| vertices[v as usize][k]).sum::<f64>() / 3.0)
    };
    let mut pieces: Vec<Vec<(crate::geometry::Point3, usize)>> = vec![
        triangles
            .par_iter()
            .enumerate()
            .map(|(i, t)| (centroid(t), i))
            .collect(),
    ];
    for _ in 0..levels {
        pieces = pieces
            .into_par_iter()
            .flat_map_iter(|mut p| {
                let bbox = crate::geometry::Aabb::from_points(p.iter().map(|c| &c.0));
                let e = bbox.extent();
                let axis = (0..3).fold(0, |a, k| if e[k] > e[a] { k } else { a });
                let at = p.len() / 2;
                if at > 0 {
                    p.select_nth_unstable_by(at, |a, b| {
                        a.0[axis].total_cmp(&b.0[axis]).then(a.1.cmp(&b.1))
                    });
                }
                let high = p.split_off(at);
                [p, high]
            })
            .collect();
    }
    pieces
        .into_par_iter()
        .map(|p| {
            let mut ids: Vec<usize> = p.into_iter().map(|c| c.1).collect();
            ids.sort_unstable();
            ids.into_iter().map(|i| triangles[i]).collect()
        })
        .collect()
}

/// The index buffer meshoptimizer gets, and the triangles set aside: those with two corners at one
/// single-precision position (`positions`), with their vertices locked. meshoptimizer takes
/// vertices at one position for one point and drops such a triangle as degenerate, whatever the
/// locks: on a 10⁶-point torus a cluster of grid vertices a few 1e-9 apart (one `f32` position)
/// lost its triangles that way, which opened a hole in every attempt, so the topology check
/// refused them all and nothing was simplified. Set aside, their edges are borders of what
/// meshoptimizer sees (kept in place) and the triangles are added back unchanged.
fn set_aside_flat_triangles(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    locks: &mut [bool],
) -> (Vec<u32>, Vec<[u32; 3]>) {
    let at = |v: u32| positions[v as usize].map(f32::to_bits);
    let (mut indices, mut aside) = (Vec::with_capacity(3 * triangles.len()), Vec::new());
    for t in triangles {
        if at(t[0]) == at(t[1]) || at(t[1]) == at(t[2]) || at(t[0]) == at(t[2]) {
            for &v in t {
                locks[v as usize] = true;
            }
            aside.push(*t);
        } else {
            indices.extend_from_slice(t);
        }
    }
    (indices, aside)
}

/// Rounds of locking the vertices around an attempt's defects before the tolerance is halved.
const LOCK_ROUNDS: usize = 5;

/// The first round locks the vertices within this many times the longest simplified edge at a
/// defect; each later round (and a round that would lock nothing new) doubles it, up to
/// [`LOCK_SCALE_MAX`]. On flat parts a simplified edge spans much of a piece, so locking its
/// whole reach at once froze half of a building's wall piece (27,268 triangles kept 25,494);
/// a defect is usually undone by locking the nearest few collapses.
const LOCK_SCALE_FIRST: f64 = 0.25;

/// Largest lock radius, in longest simplified edges at the defect.
const LOCK_SCALE_MAX: f64 = 2.0;

/// Undirected edges used by exactly one triangle, ascending.
fn border_edges(triangles: &[[u32; 3]]) -> Vec<(u32, u32)> {
    edge_uses(triangles)
        .into_iter()
        .filter(|&(_, n)| n == 1)
        .map(|(e, _)| e)
        .collect()
}

/// The connected component of every vertex (`u32::MAX` for a vertex no triangle uses).
fn vertex_components(mesh: &TriMesh) -> Vec<u32> {
    let (labels, _) = crate::mesh::topology::triangle_components(mesh);
    let mut of = vec![u32::MAX; mesh.vertices.len()];
    for (t, &c) in mesh.triangles.iter().zip(&labels) {
        for &v in t {
            of[v as usize] = c;
        }
    }
    of
}

/// Locks every vertex of each input component (`pieces`: component per vertex) that lost all its
/// triangles in `triangles` (a small piece collapsed away). Returns whether anything new was locked.
fn lock_vanished_components(pieces: &[u32], triangles: &[[u32; 3]], locks: &mut [bool]) -> bool {
    let count = pieces
        .iter()
        .filter(|&&c| c != u32::MAX)
        .map(|&c| c as usize + 1)
        .max();
    let mut alive = vec![false; count.unwrap_or(0)];
    for t in triangles {
        if let Some(&c) = pieces.get(t[0] as usize)
            && c != u32::MAX
        {
            alive[c as usize] = true;
        }
    }
    let mut changed = false;
    for (v, &c) in pieces.iter().enumerate() {
        if c != u32::MAX && !alive[c as usize] && !locks[v] {
            locks[v] = true;
            changed = true;
        }
    }
    changed
}

/// Uses of every undirected edge `(lo, hi)`, ascending ([`crate::mesh::topology`]'s grouping).
fn edge_uses(triangles: &[[u32; 3]]) -> Vec<((u32, u32), u32)> {
    (crate::mesh::topology::collect_edges(triangles).into_iter())
        .map(|e| ((e.lo, e.hi), e.forward + e.backward))
        .collect()
}

/// Locks every vertex of `mesh` near a defect of the simplified `triangles` (an edge used three
/// times or more, a border edge the input did not have, a triangle repeating a vertex): within
/// `scale` times the longest simplified edge at the defect. Returns `None` when no defect is local
/// (the topology changed otherwise, e.g. a handle closed), else whether anything new was locked.
fn lock_around_defects(
    mesh: &TriMesh,
    triangles: &[[u32; 3]],
    original_border: &[(u32, u32)],
    locks: &mut [bool],
    scale: f64,
) -> Option<bool> {
    let mut reach: HashMap<u32, f64> = HashMap::new();
    let length = |(a, b): (u32, u32)| {
        crate::geometry::dist2(mesh.vertices[a as usize], mesh.vertices[b as usize]).sqrt()
    };
    let uses = edge_uses(triangles);
    for &(e, n) in &uses {
        if n >= 3 || (n == 1 && original_border.binary_search(&e).is_err()) {
            for v in [e.0, e.1] {
                let r = reach.entry(v).or_insert(0.0);
                *r = r.max(length(e));
            }
        }
    }
    // A border edge of the input that two triangles now share (a collapse zipped two border
    // stretches together: a loop splits, no new border edge shows it).
    for &e in original_border {
        let now = uses.binary_search_by_key(&e, |u| u.0).map(|i| uses[i].1);
        if now.is_ok_and(|n| n != 1) {
            for v in [e.0, e.1] {
                let r = reach.entry(v).or_insert(0.0);
                *r = r.max(length(e));
            }
        }
    }
    for t in triangles {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            for &v in t {
                reach.entry(v).or_insert(0.0);
            }
        }
    }
    if reach.is_empty() {
        return None;
    }
    // The longest simplified edge at each defect vertex sets how far its collapses reached.
    for t in triangles {
        for k in 0..3 {
            let e = (t[k], t[(k + 1) % 3]);
            for v in [e.0, e.1] {
                if let Some(r) = reach.get_mut(&v) {
                    *r = r.max(length(e));
                }
            }
        }
    }
    let mut centres: Vec<(u32, f64)> = reach.into_iter().collect();
    centres.sort_unstable_by_key(|c| c.0);
    let Ok(tree) = crate::spatial::KdTree::build(&mesh.vertices) else {
        return None;
    };
    let mut hits = Vec::new();
    let mut changed = false;
    for (v, r) in centres {
        crate::spatial::SpatialIndex::within(
            &tree,
            &mesh.vertices[v as usize],
            scale * r,
            &mut hits,
        );
        // The defect's own vertex, whatever the radius.
        hits.push(v);
        for &h in &hits {
            changed |= !locks[h as usize];
            locks[h as usize] = true;
        }
    }
    Some(changed)
}

#[cfg(test)]
#[path = "simplify_tests.rs"]
mod tests;
