//! Small handles removed from a closed mesh: topological noise (Guskov & Wood, *Topological noise
//! removal*, Graphics Interface 2001; Wood et al., *Removing excess topology from isosurfaces*,
//! ACM TOG 2004).
//!
//! Where two parts of a surface come closer than the data can separate (a limb beside the body, an
//! ear beside the head), the zero set can join them with a thin bridge or open a pinhole through a
//! thin wall: a handle whose shortest non-separating loop is much shorter than any real feature.
//! A surface of genus 0 is left at once. Otherwise the seeds are a geodesic net of spacing
//! `max_loop / 2`, each growing a geodesic ball (Dijkstra over the edges) of radius `max_loop`, which
//! holds every loop of length `max_loop` through a vertex within `max_loop / 2` of the seed. A ball
//! is a disc (`χ = 1`) on the surface away from handles; one that is not carries cycles, whose
//! generators come from a tree–cotree split of the ball (the Dijkstra tree; a spanning forest of its
//! triangles plus one node for everything outside, taking the longest fundamental cycles first, so
//! the generators left are the shortest: Erickson & Whittlesey's greedy system of loops). A
//! generator is a handle loop when cutting the surface along it leaves it connected (a simple closed
//! curve separates a closed orientable surface exactly when it bounds). Handle loops are tried
//! shortest first, each shortened by the same search from the vertices near it, and cut when at
//! most `max_loop` long: the triangles at the loop's vertices (an annulus) are removed and each of
//! the two borders left is closed by a fan around its centroid, which lowers the genus by one. The
//! cuts of a round are checked together (closed, manifold, oriented, genus lower by their number;
//! else the round is redone one cut at a time), and the input is restored if the final check
//! fails. Real handles longer than `max_loop` around (a torus's tube, a cup's handle) are never
//! touched.
//!
//! Cost: one ball per net seed, `O(V · b log b / s)` for balls of `b` vertices and `s` vertices per
//! seed (in parallel), plus a cut test (at most `O(F)`) per candidate loop.

use std::collections::{HashMap, HashSet};

use crate::geometry::{Point3, TriMesh, add, cross, norm, normalized, scale, sub};

/// What [`remove_small_handles`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HandleStats {
    /// Handles cut.
    pub removed: usize,
    /// Length of each cut loop, mesh units, in the order they were cut.
    pub loop_lengths: Vec<f64>,
    /// Non-separating loops found but not cut (the cut did not leave a closed manifold one genus
    /// lower), or left because [`MAX_CUTS`] was reached.
    pub kept: usize,
}

/// Most handles cut in one call.
pub const MAX_CUTS: usize = 256;

/// Rounds of detection (a cut can expose a new short loop nearby). The rounds after the first
/// search only from the vertices within `max_loop` of the last round's cuts: a loop of at most
/// `max_loop` through such a vertex lies in one of their balls, and farther away the mesh, the
/// balls and the descent towards the shortest loop are what the last round saw (a loop it found
/// separating stays so when a handle elsewhere is cut; one it skipped because a cut touched it
/// passes through the cut).
const ROUNDS: usize = 4;

/// Cut every handle of the closed, manifold, oriented `mesh` whose shortest non-separating loop is
/// at most `max_loop` long (mesh units); a mesh with a border or a non-manifold edge is left
/// alone. Deterministic: the candidates are ordered by length, then by their vertices.
pub fn remove_small_handles(mesh: &mut TriMesh, max_loop: f64) -> HandleStats {
    let mut stats = HandleStats::default();
    if max_loop.is_nan() || max_loop <= 0.0 || mesh.triangles.is_empty() {
        return stats;
    }
    let Some(mut genus) = closed_genus(mesh) else {
        return stats;
    };
    if genus == 0 {
        return stats;
    }
    let start = genus;
    let original = mesh.clone();
    let mut failed: HashSet<Vec<u32>> = HashSet::new();
    // The vertices the last round's cuts changed; `None` in the first round (search everywhere).
    let mut changed: Option<Vec<u32>> = None;
    for _ in 0..ROUNDS {
        if genus == 0 || stats.removed >= MAX_CUTS {
            break;
        }
        let Some(adj) = Adjacency::new(mesh) else {
            break;
        };
        let spacing = max_loop / 2.0;
        let seeds = match &changed {
            None => net(mesh, &adj, spacing, 0..mesh.vertices.len() as u32),
            // Away from the cuts the balls, their loops and the loops' fates are the last round's:
            // only loops passing within `max_loop` of a cut can be new (see `ROUNDS`).
            Some(c) => net(
                mesh,
                &adj,
                spacing,
                around(mesh, &adj, c, max_loop).into_iter(),
            ),
        };
        let mut candidates = find_loops(mesh, &adj, &seeds, max_loop / 2.0 + spacing);
        candidates.retain(|c| !failed.contains(&c.key()));
        if candidates.is_empty() {
            break;
        }
        let before = (mesh.clone(), genus, stats.clone(), failed.clone());
        let (mut cut, mut touched) = cut_loops(
            mesh,
            adj,
            &candidates,
            max_loop,
            Cuts::Batch,
            &mut genus,
            &mut failed,
            &mut stats,
        );
        if cut > 0 && closed_genus(mesh) != Some(genus) {
            // A loop made separating by an earlier cut of the round was cut too: redo the round
            // one cut at a time.
            (*mesh, genus, stats, failed) = before;
            let Some(adj) = Adjacency::new(mesh) else {
                break;
            };
            (cut, touched) = cut_loops(
                mesh,
                adj,
                &candidates,
                max_loop,
                Cuts::OneByOne,
                &mut genus,
                &mut failed,
                &mut stats,
            );
        }
        if cut == 0 {
            break;
        }
        changed = Some(touched);
    }
    // Each cut was checked locally (two simple borders, Euler characteristic up by 2); the whole
    // mesh is checked once more.
    if stats.removed > 0 && closed_genus(mesh) != Some(start - stats.removed as i64) {
        *mesh = original;
        stats.kept += stats.removed;
        stats.removed = 0;
        stats.loop_lengths.clear();
    }
    stats
}

/// How a round applies its cuts.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Cuts {
    /// All cuts of the round against the round's adjacency (loops sharing no vertex with an
    /// earlier cut's triangles); checked once at the end of the round.
    Batch,
    /// The adjacency rebuilt after each cut (the fallback when a batch round fails its check).
    OneByOne,
}

/// Cuts the non-separating loops among `candidates` (shortest first) while the genus is
/// positive; returns how many, and the vertices the cuts changed (the removed bands' and the
/// caps' centres), ascending. `mesh.triangles` must be `adj.tris` on entry.
#[allow(clippy::too_many_arguments)]
fn cut_loops(
    mesh: &mut TriMesh,
    mut adj: Adjacency,
    candidates: &[Loop],
    max_loop: f64,
    mode: Cuts,
    genus: &mut i64,
    failed: &mut HashSet<Vec<u32>>,
    stats: &mut HandleStats,
) -> (usize, Vec<u32>) {
    let mut touched = vec![false; mesh.vertices.len()];
    let mut dead = vec![false; adj.tris.len()];
    let mut cut = 0;
    for c in candidates {
        if *genus == 0 {
            break;
        }
        if c.vertices.iter().any(|&v| touched[v as usize]) || !adj.non_separating(&c.vertices) {
            continue;
        }
        let Some(c) = shortest_handle_loop(mesh, &adj, c.clone(), max_loop) else {
            continue;
        };
        if c.vertices.iter().any(|&v| touched[v as usize]) {
            continue;
        }
        if stats.removed >= MAX_CUTS {
            stats.kept += 1;
            continue;
        }
        let Some(band) = cut_and_cap(mesh, &adj, &c.vertices, &mut dead) else {
            failed.insert(c.key());
            stats.kept += 1;
            continue;
        };
        *genus -= 1;
        for v in band {
            touched[v as usize] = true;
        }
        touched.resize(mesh.vertices.len(), true);
        stats.removed += 1;
        stats.loop_lengths.push(c.length);
        cut += 1;
        if mode == Cuts::OneByOne {
            compact(mesh, &mut dead);
            match Adjacency::new(mesh) {
                Some(a) => adj = a,
                None => break,
            }
            dead = vec![false; adj.tris.len()];
        }
    }
    compact(mesh, &mut dead);
    let changed = (0..touched.len() as u32)
        .filter(|&v| touched[v as usize])
        .collect();
    (cut, changed)
}

/// Drops the triangles flagged in `dead` (the first `dead.len()` of the mesh; the caps after
/// them stay) and clears the flags.
fn compact(mesh: &mut TriMesh, dead: &mut Vec<bool>) {
    let mut i = 0;
    mesh.triangles.retain(|_| {
        i += 1;
        !dead.get(i - 1).copied().unwrap_or(false)
    });
    dead.clear();
}

/// Steps of [`shortest_near`] from a net seed's loop towards the handle's shortest loop.
const DESCENT_STEPS: usize = 3;

/// The handle's shortest loop of at most `max_loop`, searched near `found` and then near each
/// shorter loop found, while that shortens it.
fn shortest_handle_loop(
    mesh: &TriMesh,
    adj: &Adjacency,
    found: Loop,
    max_loop: f64,
) -> Option<Loop> {
    let mut best = found;
    for _ in 0..DESCENT_STEPS {
        match shortest_near(mesh, adj, &best, max_loop) {
            Some(c) if c.length < best.length => best = c,
            _ => break,
        }
    }
    (best.length <= max_loop).then_some(best)
}

/// The shortest non-separating loop of at most `max_loop` through the vertices within
/// `max_loop / 4` of the non-separating loop `found` (a loop from a net seed passes within that
/// distance of a handle's shortest loop but may be longer), from the balls of radius
/// `max_loop / 2` around each: the shortest non-separating loop through a vertex is a generator of
/// its shortest-path tree.
fn shortest_near(mesh: &TriMesh, adj: &Adjacency, found: &Loop, max_loop: f64) -> Option<Loop> {
    let mut ball = Ball::new(mesh.vertices.len(), adj.tris.len());
    let mut near: Vec<u32> = Vec::new();
    for &v in &found.vertices {
        ball.dijkstra(mesh, adj, v, max_loop / 8.0);
        near.extend(&ball.inside);
    }
    near.sort_unstable();
    near.dedup();
    let loops = find_loops(mesh, adj, &near, max_loop / 2.0);
    loops.into_iter().find(|c| adj.non_separating(&c.vertices))
}

/// Total genus when the mesh is closed, manifold and oriented.
fn closed_genus(mesh: &TriMesh) -> Option<i64> {
    let t = super::topology::analyze(mesh);
    (t.watertight && t.manifold && t.oriented)
        .then_some(t.genus)
        .flatten()
}

/// A closed edge path on the mesh.
#[derive(Debug, Clone)]
struct Loop {
    /// Length, mesh units.
    length: f64,
    /// Vertices in order (the last joins the first).
    vertices: Vec<u32>,
}

impl Loop {
    /// The vertex set, sorted: the same loop found from different seeds has the same key.
    fn key(&self) -> Vec<u32> {
        let mut k = self.vertices.clone();
        k.sort_unstable();
        k
    }
}
/// Removes the triangles at the loop's vertices (flags them in `dead`) and closes each of the two
/// borders left with a fan around its centroid (appended). Returns the vertices of the removed
/// triangles, or `None` (mesh unchanged) unless exactly two simple borders are left and the band
/// is an annulus.
fn cut_and_cap(
    mesh: &mut TriMesh,
    adj: &Adjacency,
    cycle: &[u32],
    dead: &mut [bool],
) -> Option<Vec<u32>> {
    let mut band: Vec<u32> = cycle
        .iter()
        .flat_map(|&v| adj.triangles_at(v).iter().copied())
        .collect();
    band.sort_unstable();
    band.dedup();
    let in_band: HashSet<u32> = band.iter().copied().collect();
    // The removed triangles' half-edges facing kept ones, in the removed triangles' direction:
    // the borders as the caps must traverse them.
    let mut next: HashMap<u32, u32> = HashMap::new();
    for &t in &band {
        for k in 0..3 {
            if !in_band.contains(&adj.across[t as usize][k]) {
                let tri = adj.tris[t as usize];
                if next.insert(tri[k], tri[(k + 1) % 3]).is_some() {
                    return None; // a border that touches itself
                }
            }
        }
    }
    let mut borders: Vec<Vec<u32>> = Vec::new();
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut used = HashSet::new();
    for s in starts {
        if used.contains(&s) {
            continue;
        }
        let mut border = vec![s];
        used.insert(s);
        let mut v = *next.get(&s)?;
        while v != s {
            if !used.insert(v) {
                return None;
            }
            border.push(v);
            v = *next.get(&v)?;
        }
        borders.push(border);
    }
    if borders.len() != 2 || borders.iter().any(|b| b.len() < 3) {
        return None;
    }
    // The band must be an open annulus (V − E + F = 0 over its vertices whose every triangle
    // goes, its edges between two removed triangles, its triangles): then removing it and adding
    // the two caps raises the Euler characteristic by 2, and the genus drops by one.
    let gone = |v: u32| adj.triangles_at(v).iter().all(|t| in_band.contains(t));
    let mut inner: Vec<u32> = band.iter().flat_map(|&t| adj.tris[t as usize]).collect();
    inner.sort_unstable();
    inner.dedup();
    let v_inner = inner.iter().filter(|&&v| gone(v)).count() as i64;
    let e_inner = band
        .iter()
        .map(|&t| {
            (0..3)
                .filter(|&k| {
                    let u = adj.across[t as usize][k];
                    in_band.contains(&u) && u > t
                })
                .count()
        })
        .sum::<usize>() as i64;
    if v_inner - e_inner + band.len() as i64 != 0 {
        return None;
    }
    for &t in &band {
        dead[t as usize] = true;
    }
    for border in borders {
        cap(mesh, &border);
    }
    Some(inner)
}

/// Closes `border` (in the direction the cap traverses it) with a fan around a new vertex at
/// its centroid.
fn cap(mesh: &mut TriMesh, border: &[u32]) {
    let p = &mesh.vertices;
    let centroid = scale(
        border.iter().fold([0.0; 3], |s, &v| add(s, p[v as usize])),
        1.0 / border.len() as f64,
    );
    let c = mesh.vertices.len() as u32;
    let mut normal = [0.0; 3];
    for i in 0..border.len() {
        let (a, b) = (border[i], border[(i + 1) % border.len()]);
        normal = add(
            normal,
            cross(
                sub(mesh.vertices[a as usize], centroid),
                sub(mesh.vertices[b as usize], centroid),
            ),
        );
        mesh.triangles.push([a, b, c]);
    }
    let had_normals = mesh.normals.len() == mesh.vertices.len();
    let had_colors = mesh.colors.len() == mesh.vertices.len();
    if had_colors {
        let mut rgb = [0.0f32; 3];
        for &v in border {
            for (s, x) in rgb.iter_mut().zip(mesh.colors[v as usize]) {
                *s += x / border.len() as f32;
            }
        }
        mesh.colors.push(rgb);
    }
    mesh.vertices.push(centroid);
    if had_normals {
        let n: Point3 = normalized(normal).unwrap_or([0.0, 0.0, 1.0]);
        debug_assert!(norm(n) > 0.0);
        mesh.normals.push(n);
    }
}

mod adjacency;
mod ball;
#[cfg(test)]
mod tests;

use adjacency::Adjacency;
use ball::{Ball, around, find_loops, net};
